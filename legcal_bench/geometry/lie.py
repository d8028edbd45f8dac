"""SE(3) tools, named as in Solà et al., "A micro Lie theory for state estimation in
robotics" (2018), on top of Pinocchio's exp6/log6/Jlog6.

Tangent vectors are tau = [rho, theta] (translation first, then rotation), the order
of the paper's residual and of Pinocchio's Motion vectors.

  Exp(tau)      SE(3) exponential (Sola eq. 172)
  Log(T)        its inverse
  Jr_inv(tau)   inverse right Jacobian: Log(T Exp(d)) = Log(T) + Jr_inv(Log T) d + O(d^2)
  Jl_inv(tau)   inverse left Jacobian:  Log(Exp(d) T) = Log(T) + Jl_inv(Log T) d + O(d^2)
  Ad(T)         adjoint: T Exp(d) = Exp(Ad(T) d) T

Batched helpers work on (N, 4, 4) homogeneous arrays: `inverse`, `adjoint`, and the
Frechet mean of a set of poses.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin


def Exp(tau: np.ndarray) -> pin.SE3:
    return pin.exp6(np.asarray(tau, dtype=float))


def Log(T: pin.SE3) -> np.ndarray:
    return pin.log6(T).vector


def Jr_inv(T: pin.SE3) -> np.ndarray:
    """Inverse right Jacobian at tau = Log(T) (Pinocchio's Jlog6)."""
    return pin.Jlog6(T)


def Jl_inv(T: pin.SE3) -> np.ndarray:
    """Inverse left Jacobian at tau = Log(T): Jl_inv(tau) = Jr_inv(-tau) = Jr_inv(T^-1)."""
    return pin.Jlog6(T.inverse())


def Ad(T: pin.SE3) -> np.ndarray:
    return T.action


def inverse(H: np.ndarray) -> np.ndarray:
    """Batched inverse of homogeneous transforms."""
    out = np.zeros_like(H)
    Rt = np.swapaxes(H[:, :3, :3], 1, 2)
    out[:, :3, :3] = Rt
    out[:, :3, 3] = -np.einsum("nij,nj->ni", Rt, H[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


def adjoint(H: np.ndarray) -> np.ndarray:
    """Batched SE(3) adjoint [[R, [p]x R], [0, R]] (translation-first tangent order)."""
    R, p = H[:, :3, :3], H[:, :3, 3]
    px = np.zeros((len(H), 3, 3))
    px[:, 0, 1], px[:, 0, 2], px[:, 1, 2] = -p[:, 2], p[:, 1], -p[:, 0]
    px[:, 1, 0], px[:, 2, 0], px[:, 2, 1] = p[:, 2], -p[:, 1], p[:, 0]
    A = np.zeros((len(H), 6, 6))
    A[:, :3, :3] = R
    A[:, 3:, 3:] = R
    A[:, :3, 3:] = px @ R
    return A


def frechet_mean(C: np.ndarray, M0: np.ndarray | None = None, tol: float = 1e-15, max_iter: int = 50) -> np.ndarray:
    """Intrinsic (Frechet) mean of homogeneous poses by Log-Exp iteration,
    M <- M Exp(mean_k Log(M^-1 C_k)), initialised with Exp(mean_k Log C_k) unless M0
    is given; the fixed point has sum_k Log(M^-1 C_k) = 0."""
    if M0 is None:
        M = Exp(np.mean([Log(pin.SE3(c)) for c in C], axis=0)).homogeneous
    else:
        M = M0
    for _ in range(max_iter):
        E = inverse(M[None])[0] @ C
        step = np.mean([Log(pin.SE3(e)) for e in E], axis=0)
        M = M @ Exp(step).homogeneous
        if np.linalg.norm(step) < tol:
            break
    return M


