"""The paper's residuals and their analytic Jacobians w.r.t. the offsets dq.

For frame k of contact segment s, with corrected angles q_k = q_enc_k + dq:

  inter-foot transform  C_k = T_BFL(q_k)^-1 T_BFR(q_k)
  feet residual         r_k = Log(M_s^-1 C_k) in R^6 (translation, then rotation),
                        M_s the segment's Frechet mean of the C_k
  flat-ground residual  [p_Lz - p_Rz, z_Lx, z_Ly, z_Rx, z_Ry] in the IMU-levelled frame W
                        (vertical = -gravity from the IMU, yaw arbitrary)

Jacobians. A right perturbation of the sole poses, T_BF(q + d) = T_BF Exp(J_F d)
with J_F the sole's local frame Jacobian, perturbs C_k on the right by
G_k d = [-Ad(C_k^-1) J_L | J_R] d, so with E_k = M^-1 C_k:

  fixed mean (the paper's inner solve):  dr_k = Jr_inv(E_k) G_k d
  mean re-estimated (variable projection): M(dq) keeps sum_k r_k = 0, so
      dr_k = A_k G_k d - B_k S^-1 sum_j A_j G_j d,   A = Jr_inv(E), B = Jl_inv(E), S = sum_j B_j
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from legcal_bench.kinematics import LegKinematics
from legcal_bench.lie import Jl_inv, Jr_inv, Log, adjoint, inverse

# d(R e_z)/d(omega) in the rotated frame: omega x e_z = [w_y, -w_x, 0].
_EZ_CROSS = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])


def up_in_base(imu_acc: np.ndarray, R_BI: np.ndarray) -> np.ndarray:
    """Unit vertical (opposite to gravity) in the pelvis frame, from the accelerometer's
    specific force (which points up when the IMU is static)."""
    f = imu_acc / np.linalg.norm(imu_acc, axis=1, keepdims=True)
    return f @ R_BI.T


def levelling_rotations(up_B: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations R_WB taking each up vector to +z with the least rotation
    (yaw is arbitrary and every residual here is yaw-invariant)."""
    z = np.array([0.0, 0.0, 1.0])
    out = np.empty((len(up_B), 3, 3))
    for k, u in enumerate(up_B):
        v = np.cross(u, z)
        s, c = np.linalg.norm(v), float(u @ z)
        if s < 1e-15:
            out[k] = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
            continue
        V = pin.skew(v)
        out[k] = np.eye(3) + V + V @ V * ((1 - c) / (s * s))
    return out


@dataclass
class FrameKinematics:
    """Per-frame kinematics at the corrected angles (batched arrays)."""

    C: np.ndarray  # (N, 4, 4) inter-foot transforms, homogeneous
    G: np.ndarray  # (N, 6, 12) right-perturbation Jacobian of C w.r.t. dq
    p_L: np.ndarray  # (N, 3) sole positions in the pelvis frame
    p_R: np.ndarray
    R_L: np.ndarray  # (N, 3, 3) sole rotations in the pelvis frame
    R_R: np.ndarray
    J_L: np.ndarray  # (N, 6, 6) local sole Jacobians w.r.t. the leg's own joints
    J_R: np.ndarray


def frame_kinematics(kin: LegKinematics, Q: np.ndarray) -> FrameKinematics:
    """Pinocchio forward kinematics and sole Jacobians for each row of Q (N, 12); the
    per-frame loop only calls Pinocchio, the algebra on its outputs is batched."""
    m, d = kin.model, kin.data
    fL, fR, fB = kin.sole_frame["left"], kin.sole_frame["right"], kin.pelvis_frame
    n = len(Q)
    HB, HL, HR = np.empty((n, 4, 4)), np.empty((n, 4, 4)), np.empty((n, 4, 4))
    JLf, JRf = np.empty((n, 6, m.nv)), np.empty((n, 6, m.nv))
    qf = kin.q_neutral.copy()
    for k in range(n):
        qf[kin.leg_q_idx] = Q[k]
        pin.computeJointJacobians(m, d, qf)
        pin.updateFramePlacements(m, d)
        HB[k], HL[k], HR[k] = d.oMf[fB].homogeneous, d.oMf[fL].homogeneous, d.oMf[fR].homogeneous
        JLf[k] = pin.getFrameJacobian(m, d, fL, pin.LOCAL)
        JRf[k] = pin.getFrameJacobian(m, d, fR, pin.LOCAL)
    Binv = inverse(HB)
    TL, TR = Binv @ HL, Binv @ HR
    C = inverse(TL) @ TR
    J_L, J_R = JLf[:, :, kin.leg_v_idx[:6]], JRf[:, :, kin.leg_v_idx[6:]]
    G = np.empty((n, 6, 12))
    G[:, :, :6] = -adjoint(inverse(C)) @ J_L
    G[:, :, 6:] = J_R
    return FrameKinematics(C, G, TL[:, :3, 3], TR[:, :3, 3], TL[:, :3, :3], TR[:, :3, :3], J_L, J_R)


def flat_residuals(fk: FrameKinematics, up_B: np.ndarray, R_WB: np.ndarray, with_jacobian: bool = True):
    """(N, 5) flat-ground residuals and (N, 5, 12) their Jacobians."""
    n = len(up_B)
    r = np.empty((n, 5))
    r[:, 0] = np.einsum("ni,ni->n", up_B, fk.p_L - fk.p_R)
    zL = np.einsum("nij,nj->ni", R_WB, fk.R_L[:, :, 2])
    zR = np.einsum("nij,nj->ni", R_WB, fk.R_R[:, :, 2])
    r[:, 1:3], r[:, 3:5] = zL[:, :2], zR[:, :2]
    if not with_jacobian:
        return r, None
    J = np.zeros((n, 5, 12))
    # Height: u . (R_L v_L - R_R v_R), v the local linear velocity.
    J[:, 0, :6] = np.einsum("ni,nij,njk->nk", up_B, fk.R_L, fk.J_L[:, :3])
    J[:, 0, 6:] = -np.einsum("ni,nij,njk->nk", up_B, fk.R_R, fk.J_R[:, :3])
    # Normals: d(R_WB R e_z) = R_WB R (omega x e_z).
    J[:, 1:3, :6] = np.einsum("nij,njk,kl,nlm->nim", R_WB[:, :2], fk.R_L, _EZ_CROSS, fk.J_L[:, 3:])
    J[:, 3:5, 6:] = np.einsum("nij,njk,kl,nlm->nim", R_WB[:, :2], fk.R_R, _EZ_CROSS, fk.J_R[:, 3:])
    return r, J


def feet_residuals(C: np.ndarray, G: np.ndarray, M: np.ndarray, mode: str = "fixed"):
    """(N, 6) residuals Log(M^-1 C_k) and (N, 6, 12) Jacobians.

    mode "fixed": M held constant (the paper's inner solve); "projected": M = M(dq)
    re-estimated with dq (variable projection; requires M to be the Frechet mean)."""
    n = len(C)
    E = inverse(M[None])[0] @ C
    r = np.empty((n, 6))
    A = np.empty((n, 6, 6))
    B = np.empty((n, 6, 6)) if mode == "projected" else None
    for k in range(n):
        Ek = pin.SE3(E[k])
        r[k] = Log(Ek)
        A[k] = Jr_inv(Ek)
        if B is not None:
            B[k] = Jl_inv(Ek)
    J = A @ G
    if mode == "projected":
        correction = np.linalg.solve(B.sum(axis=0), J.sum(axis=0))  # S^-1 sum_j A_j G_j
        J -= B @ correction
    return r, J
