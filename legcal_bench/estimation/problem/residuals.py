"""The paper's residuals and their analytic Jacobians w.r.t. the offsets dq.

The kinematics they start from (C_k, its Jacobian G_k, sole poses and Jacobians) is
`legcal_bench.robots.kinematics.frame_kinematics`; the IMU vertical is
`legcal_bench.estimation.imu.levelling`.

For frame k of contact segment s, with corrected angles q_k = q_enc_k + dq:

  inter-foot transform  C_k = T_BFL(q_k)^-1 T_BFR(q_k)
  feet residual         r_k = Log(M_s^-1 C_k) in R^6 (translation, then rotation),
                        M_s the segment's Frechet mean of the C_k
  flat-ground residual  [p_Lz - p_Rz, z_Lx, z_Ly, z_Rx, z_Ry] in the IMU-levelled frame W
                        (vertical = -gravity from the IMU, yaw arbitrary)

Jacobians. A right perturbation of the sole poses, T_BF(q + d) = T_BF Exp(J_F d)
with J_F the sole's local frame Jacobian, perturbs C_k on the right by
G_k d = [-Ad(C_k^-1) J_L | J_R] d, so with E_k = M^-1 C_k:

  fixed mean (the paper's inner solve):  dr_k = Jr_inv(r_k) G_k d,  r_k = Log(E_k)
  mean re-estimated (variable projection): M(dq) keeps sum_k r_k = 0, so
      dr_k = A_k G_k d - B_k S^-1 sum_j A_j G_j d,   A = Jr_inv(r), B = Jl_inv(r), S = sum_j B_j
"""

from __future__ import annotations

import numpy as np

from legcal_bench.geometry.lie import Jl_inv, Jr_inv, Jr_Jl_inv, Log, inverse
from legcal_bench.robots.kinematics import FrameKinematics

# d(R e_z)/d(omega) in the rotated frame: omega x e_z = [w_y, -w_x, 0].
_EZ_CROSS = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])


def foot_height_difference(fk: FrameKinematics, up_B: np.ndarray) -> np.ndarray:
    """(N,) p_Lz - p_Rz along the IMU vertical: the flat-ground residual's first row (m)."""
    return np.einsum("ni,ni->n", up_B, fk.p_L - fk.p_R)


def _flat_rows(up: np.ndarray, R_WB: np.ndarray, p_L, p_R, R_L, R_R, JL: np.ndarray, JR: np.ndarray):
    """The flat-ground rows (N, 5) and their Jacobians through each sole, (N, 5, a) from
    the left sole's LOCAL Jacobian JL (N, 6, a) and (N, 5, b) from the right's."""
    n = len(up)
    r = np.empty((n, 5))
    r[:, 0] = np.einsum("ni,ni->n", up, p_L - p_R)
    zL = np.einsum("nij,nj->ni", R_WB, R_L[:, :, 2])
    zR = np.einsum("nij,nj->ni", R_WB, R_R[:, :, 2])
    r[:, 1:3], r[:, 3:5] = zL[:, :2], zR[:, :2]
    GL, GR = np.zeros((n, 5, JL.shape[-1])), np.zeros((n, 5, JR.shape[-1]))
    # Height: u . (R_L v_L - R_R v_R), v the local linear velocity.
    u = up[:, None, :]
    GL[:, 0] = (u @ R_L @ JL[:, :3])[:, 0]
    GR[:, 0] = -(u @ R_R @ JR[:, :3])[:, 0]
    # Normals: d(R_WB R e_z) = R_WB R (omega x e_z).
    GL[:, 1:3] = R_WB[:, :2] @ R_L @ _EZ_CROSS @ JL[:, 3:]
    GR[:, 3:5] = R_WB[:, :2] @ R_R @ _EZ_CROSS @ JR[:, 3:]
    return r, GL, GR


def flat_residuals(fk: FrameKinematics, up_B: np.ndarray, R_WB: np.ndarray, with_jacobian: bool = True):
    """(N, 5) flat-ground residuals and (N, 5, n) their Jacobians (n the leg joints: the
    left sole's columns, then the right's, leg-map order)."""
    r, GL, GR = _flat_rows(up_B, R_WB, fk.p_L, fk.p_R, fk.R_L, fk.R_R, fk.J_L, fk.J_R)
    if not with_jacobian:
        return r, None
    return r, np.concatenate([GL, GR], axis=2)


def flat_residuals_extended(ek, up0: np.ndarray, R_WB0: np.ndarray):
    """`flat_residuals` with model-gap effects (`legcal_bench.estimation.modelgap.effects.
    ExtendedKinematics`): sole Jacobians over all n columns and the IMU's vertical
    corrected, up = Q up0 and R_WB = R_WB0 Q^T, with dQ = Q [w]x per column (w in imu_W).
    Returns (N, 5) residuals and (N, 5, n) Jacobians."""
    Q, W = ek.imu_Q, ek.imu_W
    r, GL, GR = _flat_rows(up0 @ Q.T, R_WB0 @ Q.T, ek.p_L, ek.p_R, ek.R_L, ek.R_R, ek.JL, ek.JR)
    J = GL + GR
    cols = np.flatnonzero(np.abs(W).sum(axis=0) > 0)
    if cols.size:
        w = W[:, cols].T  # (c, 3) body-frame axes
        # d up = Q (w x up0); d(R_WB z) = -R_WB0 (w x (Q^T z)).
        dup = np.cross(w[None, :, :], up0[:, None, :]) @ Q.T  # (n, c, 3)
        J[:, 0, cols] += np.einsum("nci,ni->nc", dup, ek.p_L - ek.p_R)
        for rows, z_B in ((slice(1, 3), ek.R_L[:, :, 2]), (slice(3, 5), ek.R_R[:, :, 2])):
            qz = z_B @ Q  # Q^T z, as rows
            dz = -np.einsum("nij,ncj->nci", R_WB0, np.cross(w[None, :, :], qz[:, None, :]))
            J[:, rows, cols] += np.swapaxes(dz[:, :, :2], 1, 2)
    return r, J


def feet_residuals(C: np.ndarray, G: np.ndarray, M: np.ndarray, mode: str = "fixed"):
    """(N, 6) residuals Log(M^-1 C_k) and (N, 6, n) Jacobians (n the columns of G).

    mode "fixed": M held constant (the paper's inner solve); "projected": M = M(dq)
    re-estimated with dq (variable projection; requires M to be the Frechet mean);
    "both": (r, the fixed Jacobian, the projected one)."""
    r = Log(inverse(M) @ C)
    if mode == "fixed":
        return r, Jr_inv(r) @ G
    A, B = Jr_Jl_inv(r)
    J = A @ G
    projected = _project(J, B)
    return (r, J, projected) if mode == "both" else (r, projected)


def project_mean(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Fixed-mean feet columns J (N, 6, P) of one segment, A_k G_k, with the segment's
    Frechet mean re-estimated (variable projection): J_k - B_k S^-1 sum_j J_j, B = Jl_inv(r),
    S = sum_j B_j, r (N, 6) the feet residuals. Columns tested against each other must all
    be projected this way: a plain average instead differs from it by O(|r|), which breaks
    exact collinearities (a constant twist of one sole is a mean change) at ~1e-4 and
    leaves directions made of the residual itself."""
    return _project(J, Jl_inv(r))


def _project(J: np.ndarray, B: np.ndarray) -> np.ndarray:
    """`project_mean` with B = Jl_inv(r) given."""
    return J - B @ np.linalg.solve(B.sum(axis=0), J.sum(axis=0))


def flat_ground_errors(fk: FrameKinematics, up_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per frame, the flat-ground residual read as errors: the foot-height difference
    along the vertical (m, the residual's first row) and the angle of each sole normal
    to the vertical (rad, (N, 2)): atan2(|z x u|, z . u), which keeps its precision near
    zero where arccos loses half the digits."""
    h = foot_height_difference(fk, up_B)
    ang = np.empty((len(up_B), 2))
    for j, R in enumerate((fk.R_L, fk.R_R)):
        z = R[:, :, 2]
        ang[:, j] = np.arctan2(np.linalg.norm(np.cross(z, up_B), axis=1), np.einsum("ni,ni->n", z, up_B))
    return h, ang
