"""SE(3) tools, named as in Solà et al., "A micro Lie theory for state estimation in
robotics" (2018), in closed form on numpy arrays, batched over any leading axes.

Tangent vectors are tau = [rho, theta] (translation first, then rotation), the order
of the paper's residual and of Pinocchio's Motion vectors (`pin.exp6`, `pin.log6`,
`pin.Jlog6`, which these match). Poses are homogeneous (..., 4, 4) arrays; a
`pin.SE3` is accepted wherever a pose is (numpy converts it to its 4x4 matrix).

  Exp(tau)      (...,6) -> (...,4,4)  SE(3) exponential (Sola eq. 172)
  Log(T)        (...,4,4) -> (...,6)  its inverse, rotation angle in [0, pi]
  Jr(tau)       (...,6) -> (...,6,6)  right Jacobian: Exp(tau + d) = Exp(tau) Exp(Jr(tau) d) + O(d^2)
  Jl(tau)       left Jacobian:  Exp(tau + d) = Exp(Jl(tau) d) Exp(tau) + O(d^2);  Jl(tau) = Jr(-tau)
  Jr_inv(tau)   inverse right Jacobian: Log(T Exp(d)) = Log(T) + Jr_inv(Log T) d + O(d^2)
  Jl_inv(tau)   inverse left Jacobian:  Log(Exp(d) T) = Log(T) + Jl_inv(Log T) d + O(d^2)
  Ad(T)         (...,4,4) -> (...,6,6) adjoint: T Exp(d) = Exp(Ad(T) d) T  (also `adjoint`)
  inverse(H)    batched inverse of homogeneous transforms
  frechet_mean  intrinsic mean of a set of poses (Log-Exp fixed point)

Jacobians (Sola et al. appendix D; Barfoot & Furgale 2014): Jl(tau) = [[J, Q], [0, J]]
with J the SO(3) left Jacobian of theta and Q = Q(rho, theta); Jl_inv = [[J^-1, -J^-1 Q J^-1],
[0, J^-1]]. The scalar coefficients (sin t / t, (1 - cos t) / t^2, ...) cancel
catastrophically for small angles, so below `SERIES_BELOW` rad they are evaluated by their
Taylor series (10 terms: truncation error < 3e-16 relative at the threshold) and above it
in closed form (relative error <= 2e-15 at the threshold, decreasing with the angle;
1.4e-14 for the one coefficient that only enters multiplied by theta^4). Tiny rotations
(1e-9 rad and below, down to exactly zero) are thus exact to rounding. Pinocchio's
exp6/log6 agree to ~1e-13 (their own error reaches ~1e-12 near 2e-3 rad); its Jlog6/Jexp6
(a short series, then closed forms that cancel) are off by up to ~3e-7/4e-6 near 3e-4 rad.
"""

from __future__ import annotations

from fractions import Fraction
from math import factorial

import numpy as np

SERIES_BELOW = 1.0  # rad: Taylor series below, closed forms above (see the module docstring)

# |B_2n| (Bernoulli numbers), n = 1..10, for the series of 1 - (t/2) cot(t/2).
_BERNOULLI_ABS = [Fraction(1, 6), Fraction(1, 30), Fraction(1, 42), Fraction(1, 30), Fraction(5, 66),
                  Fraction(691, 2730), Fraction(7, 6), Fraction(3617, 510), Fraction(43867, 798),
                  Fraction(174611, 330)]
# Columns: the coefficients' Taylor series in t^2 (row k multiplies t^(2k)), k = 0..9:
#   a = sin t / t                          b = (1 - cos t) / t^2
#   c = (t - sin t) / t^3                  d = (t^2 + 2 cos t - 2) / (2 t^4)
#   e = (2t - 3 sin t + t cos t) / (2 t^5) f = (1 - (t/2) cot(t/2)) / t^2
_SERIES = np.array([[float(Fraction((-1) ** k, factorial(2 * k + 1))),
                     float(Fraction((-1) ** k, factorial(2 * k + 2))),
                     float(Fraction((-1) ** k, factorial(2 * k + 3))),
                     float(Fraction((-1) ** k, factorial(2 * k + 4))),
                     float(Fraction((-1) ** k * (k + 1), factorial(2 * k + 5))),
                     float(_BERNOULLI_ABS[k] / factorial(2 * k + 2))] for k in range(10)])
_POWERS = np.arange(len(_SERIES))


def _powers(theta: np.ndarray) -> np.ndarray:
    """(..., 10) the powers theta^(2k), k = 0..9, by repeated products (an integer power
    per element costs several times more)."""
    out = np.empty(theta.shape + (len(_POWERS),))
    out[..., 0] = 1.0
    out[..., 1] = theta * theta
    for k in range(2, len(_POWERS)):
        np.multiply(out[..., k - 1], out[..., 1], out=out[..., k])
    return out


def _coefficients(theta: np.ndarray) -> np.ndarray:
    """(..., 6) coefficients [a, b, c, d, e, f] (see _SERIES) at rotation angles theta >= 0."""
    theta = np.asarray(theta, dtype=float)
    small = theta < SERIES_BELOW
    if small.all():
        return _powers(theta) @ _SERIES
    t = np.maximum(theta, SERIES_BELOW)  # closed forms, evaluated away from 0 and used only there
    t2 = t * t
    h = 0.5 * t
    sin_h, cos_h = np.sin(h), np.cos(h)
    a = np.sin(t) / t
    b = 0.5 * (sin_h / h) ** 2
    c = (1.0 - a) / t2
    d = (0.5 - b) / t2
    e = (3.0 * c - b) / (2.0 * t2)
    f = (1.0 - h * cos_h / sin_h) / t2
    closed = np.stack([a, b, c, d, e, f], axis=-1)
    if not small.any():
        return closed
    series = _powers(np.minimum(theta, SERIES_BELOW)) @ _SERIES
    return np.where(small[..., None], series, closed)


def _tangent(tau, name: str) -> np.ndarray:
    tau = np.asarray(tau, dtype=float)
    if tau.shape[-1:] != (6,):
        raise ValueError(f"{name} takes tangent vectors tau of shape (..., 6), got {tau.shape}"
                         + ("; for a pose T pass Log(T)" if tau.shape[-2:] == (4, 4) else ""))
    return tau


def _pose(T, name: str) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"{name} takes homogeneous poses of shape (..., 4, 4), got {T.shape}")
    return T


def _hat(v: np.ndarray) -> np.ndarray:
    """(..., 3) -> (..., 3, 3) skew matrices, hat(v) u = v x u."""
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    u0, u1, u2 = u[..., 0], u[..., 1], u[..., 2]
    v0, v1, v2 = v[..., 0], v[..., 1], v[..., 2]
    out = np.empty(np.broadcast_shapes(u.shape, v.shape))
    out[..., 0] = u1 * v2 - u2 * v1
    out[..., 1] = u2 * v0 - u0 * v2
    out[..., 2] = u0 * v1 - u1 * v0
    return out


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", u, v)


def _outer(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., :, None] * v[..., None, :]


def _angle(w: np.ndarray) -> np.ndarray:
    return np.sqrt(_dot(w, w))


def _scale(k: np.ndarray, X: np.ndarray) -> np.ndarray:
    """k (...) times each matrix of X (..., m, n)."""
    return k[..., None, None] * X


def Exp(tau) -> np.ndarray:
    """(..., 6) tangent vectors [rho, theta] -> (..., 4, 4) poses."""
    tau = _tangent(tau, "Exp")
    rho, w = tau[..., :3], tau[..., 3:]
    theta = _angle(w)
    k = _coefficients(theta)
    a, b, c = k[..., 0], k[..., 1], k[..., 2]
    WW = _outer(w, w) - _scale(theta**2, np.eye(3))  # hat(w)^2
    T = np.zeros(tau.shape[:-1] + (4, 4))
    T[..., :3, :3] = np.eye(3) + _scale(a, _hat(w)) + _scale(b, WW)
    wxr = _cross(w, rho)
    T[..., :3, 3] = rho + b[..., None] * wxr + c[..., None] * _cross(w, wxr)  # J(theta) rho
    T[..., 3, 3] = 1.0
    return T


def Log(T) -> np.ndarray:
    """(..., 4, 4) poses -> (..., 6) tangent vectors [rho, theta], |theta| <= pi."""
    T = _pose(T, "Log")
    R, p = T[..., :3, :3], T[..., :3, 3]
    # sin(theta) u and cos(theta), u the unit axis.
    vee = np.empty(R.shape[:-1])
    vee[..., 0] = R[..., 2, 1] - R[..., 1, 2]
    vee[..., 1] = R[..., 0, 2] - R[..., 2, 0]
    vee[..., 2] = R[..., 1, 0] - R[..., 0, 1]
    vee *= 0.5
    s = _angle(vee)
    cos = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)
    theta = np.arctan2(s, cos)
    # theta / sin(theta) = atan2(s, cos) / s has no cancellation; it tends to 1 as s -> 0.
    ratio = np.where(s > 0, theta / np.where(s > 0, s, 1.0), 1.0)
    w = ratio[..., None] * vee
    near_pi = cos < -0.5  # theta > 2 pi / 3: the axis from the symmetric part, u u^T
    if np.any(near_pi):
        Rn, cn, vn = R[near_pi], cos[near_pi], vee[near_pi]
        uu = (0.5 * (Rn + np.swapaxes(Rn, -1, -2)) - cn[:, None, None] * np.eye(3)) / (1.0 - cn)[:, None, None]
        diag = np.diagonal(uu, axis1=-2, axis2=-1)
        j = np.argmax(diag, axis=-1)
        rows = np.arange(len(j))
        u = uu[rows, :, j] / np.sqrt(diag[rows, j])[:, None]
        sign = np.where(vn[rows, j] >= 0, 1.0, -1.0)  # the axis with sin(theta) u = vee, as Pinocchio
        w[near_pi] = (sign * theta[near_pi])[:, None] * u
    f = _coefficients(theta)[..., 5]
    wxp = _cross(w, p)
    rho = p - 0.5 * wxp + f[..., None] * _cross(w, wxp)  # J(theta)^-1 p
    return np.concatenate([rho, w], axis=-1)


def _left(tau: np.ndarray, inverse_: bool) -> np.ndarray:
    """Jl(tau) = [[J, Q], [0, J]] or its inverse [[J^-1, -J^-1 Q J^-1], [0, J^-1]].

    With W = hat(theta), P = hat(rho) (Barfoot & Furgale 2014),
      Q = P/2 + c (W P + P W + W P W) + d (W W P + P W W - 3 W P W) + e (W P W W + W W P W),
    which hat(x) hat(y) = y x^T - (x . y) I turns into vector operations: with s = theta . rho
    and u = theta x rho, W P W = -s W, W W P = u theta^T - s W, P W W = -theta u^T - s W,
    u theta^T - theta u^T = hat(theta x u) and W W = theta theta^T - |theta|^2 I, so
      Q = hat(rho/2 + s (d - c) theta + d theta x u) + c (rho theta^T + theta rho^T)
          - 2 e s theta theta^T + 2 s (e |theta|^2 - c) I."""
    rho, w = tau[..., :3], tau[..., 3:]
    theta = _angle(w)
    t2 = theta**2
    k = _coefficients(theta)
    b, c, d, e, f = (k[..., i, None] for i in range(1, 6))  # (..., 1), to scale vectors
    s = _dot(w, rho)[..., None]
    v = 0.5 * rho + s * (d - c) * w + d * _cross(w, _cross(w, rho))
    Q = _hat(v) + _outer(rho, c * w) + _outer(w, c * rho - 2.0 * e * s * w)
    Q += _scale((2.0 * s * (e * t2[..., None] - c))[..., 0], np.eye(3))
    out = np.zeros(tau.shape[:-1] + (6, 6))
    if inverse_:  # J^-1 = I - W/2 + f W W
        J = _hat(-0.5 * w) + _outer(f * w, w) + _scale(1.0 - f[..., 0] * t2, np.eye(3))
        out[..., :3, 3:] = -J @ Q @ J
    else:  # J = I + b W + c W W
        J = _hat(b * w) + _outer(c * w, w) + _scale(1.0 - c[..., 0] * t2, np.eye(3))
        out[..., :3, 3:] = Q
    out[..., :3, :3] = out[..., 3:, 3:] = J
    return out


def _inverse_pair(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Jr_inv(tau), Jl_inv(tau)) = (_left(-tau, True), _left(tau, True)) sharing what
    does not change sign with tau (the coefficients, s, the even parts of Q and J), each
    sum in `_left`'s order, so both are what `_left` gives bit for bit."""
    rho, w = tau[..., :3], tau[..., 3:]
    theta = _angle(w)
    t2 = theta**2
    k = _coefficients(theta)
    b, c, d, e, f = (k[..., i, None] for i in range(1, 6))
    s = _dot(w, rho)[..., None]
    v = 0.5 * rho + s * (d - c) * w + d * _cross(w, _cross(w, rho))  # odd in tau
    q1, q2 = _outer(rho, c * w), _outer(w, c * rho - 2.0 * e * s * w)  # even
    q3 = _scale((2.0 * s * (e * t2[..., None] - c))[..., 0], np.eye(3))
    j2, j3 = _outer(f * w, w), _scale(1.0 - f[..., 0] * t2, np.eye(3))
    out = []
    for sign in (-1.0, 1.0):
        Q = _hat(sign * v) + q1 + q2
        Q += q3
        J = _hat(-0.5 * (sign * w)) + j2 + j3
        A = np.zeros(tau.shape[:-1] + (6, 6))
        A[..., :3, 3:] = -J @ Q @ J
        A[..., :3, :3] = A[..., 3:, 3:] = J
        out.append(A)
    return out[0], out[1]


def Jr(tau) -> np.ndarray:
    """(..., 6) -> (..., 6, 6) right Jacobian of Exp."""
    return _left(-_tangent(tau, "Jr"), False)


def Jl(tau) -> np.ndarray:
    """(..., 6) -> (..., 6, 6) left Jacobian of Exp, Jl(tau) = Jr(-tau)."""
    return _left(_tangent(tau, "Jl"), False)


def Jr_inv(tau) -> np.ndarray:
    """(..., 6) -> (..., 6, 6) inverse right Jacobian at tau; at tau = Log(T) it is
    Pinocchio's Jlog6(T)."""
    return _left(-_tangent(tau, "Jr_inv"), True)


def Jr_Jl_inv(tau) -> tuple[np.ndarray, np.ndarray]:
    """(Jr_inv(tau), Jl_inv(tau)) together, for less than the two apart."""
    return _inverse_pair(_tangent(tau, "Jr_Jl_inv"))


def Jl_inv(tau) -> np.ndarray:
    """(..., 6) -> (..., 6, 6) inverse left Jacobian, Jl_inv(tau) = Jr_inv(-tau); at
    tau = Log(T) it is Jlog6(T^-1)."""
    return _left(_tangent(tau, "Jl_inv"), True)


def inverse(H) -> np.ndarray:
    """Batched inverse of homogeneous transforms (..., 4, 4)."""
    H = _pose(H, "inverse")
    out = np.zeros_like(H)
    Rt = np.swapaxes(H[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, H[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def adjoint(H) -> np.ndarray:
    """Batched SE(3) adjoint [[R, [p]x R], [0, R]] (translation-first tangent order)."""
    H = _pose(H, "adjoint")
    R = H[..., :3, :3]
    A = np.zeros(H.shape[:-2] + (6, 6))
    A[..., :3, :3] = R
    A[..., 3:, 3:] = R
    A[..., :3, 3:] = _hat(H[..., :3, 3]) @ R
    return A


Ad = adjoint


def frechet_mean(C, M0: np.ndarray | None = None, tol: float = 1e-15, max_iter: int = 50) -> np.ndarray:
    """Intrinsic (Frechet) mean of homogeneous poses C (N, 4, 4) by Log-Exp iteration,
    M <- M Exp(mean_k Log(M^-1 C_k)), initialised with Exp(mean_k Log C_k) unless M0
    is given; stops once the step's norm is below tol (or after max_iter steps). The
    fixed point has sum_k Log(M^-1 C_k) = 0."""
    C = _pose(C, "frechet_mean")
    M = Exp(Log(C).mean(axis=0)) if M0 is None else np.asarray(M0, dtype=float)
    for _ in range(max_iter):
        step = Log(inverse(M) @ C).mean(axis=0)
        M = M @ Exp(step)
        if np.linalg.norm(step) < tol:
            break
    return M
