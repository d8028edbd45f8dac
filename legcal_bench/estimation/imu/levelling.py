"""The IMU's vertical: the up direction in the pelvis frame from the accelerometer,
and the levelling rotations that take it to +z (yaw arbitrary)."""

from __future__ import annotations

import numpy as np


def up_in_base(imu_acc: np.ndarray, R_BI: np.ndarray) -> np.ndarray:
    """Unit vertical (opposite to gravity) in the pelvis frame, from the accelerometer's
    specific force (which points up when the IMU is static). `R_BI` is
    `LegKinematics.R_BI`."""
    f = imu_acc / np.linalg.norm(imu_acc, axis=1, keepdims=True)
    return f @ R_BI.T


def levelling_rotations(up_B: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations R_WB taking each up vector to +z with the least rotation
    (yaw is arbitrary and every residual here is yaw-invariant): Rodrigues' formula
    about v = u x z, R = I + [v] + [v]^2 (1 - c) / s^2, batched."""
    up_B = np.asarray(up_B, dtype=float)
    n = len(up_B)
    v = np.stack([up_B[:, 1], -up_B[:, 0], np.zeros(n)], axis=1)  # u x e_z
    s2 = np.einsum("ni,ni->n", v, v)
    c = up_B[:, 2]
    V = np.zeros((n, 3, 3))
    V[:, 0, 1], V[:, 0, 2], V[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    V[:, 1, 0], V[:, 2, 0], V[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    aligned = s2 < 1e-30
    k = np.where(aligned, 0.0, (1 - c) / np.where(aligned, 1.0, s2))
    out = np.eye(3) + V + (V @ V) * k[:, None, None]
    # Exactly (anti-)parallel to z: the identity, or a half turn about x.
    out[aligned & (c > 0)] = np.eye(3)
    out[aligned & (c <= 0)] = np.diag([1.0, -1.0, -1.0])
    return out


def tilted(up_B: np.ndarray, axis: int, angle: float) -> np.ndarray:
    """The up vectors rotated by `angle` (rad) about pelvis axis `axis` (0 x, 1 y): what
    an IMU whose vertical is off by that rotation would report."""
    c, s = np.cos(angle), np.sin(angle)
    R = np.eye(3)
    i, j = [(1, 2), (2, 0)][axis]
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return np.asarray(up_B) @ R.T
