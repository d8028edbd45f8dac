"""The IMU's vertical: the up direction in the pelvis frame from the accelerometer,
and the levelling rotations that take it to +z (yaw arbitrary)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin


def up_in_base(imu_acc: np.ndarray, R_BI: np.ndarray) -> np.ndarray:
    """Unit vertical (opposite to gravity) in the pelvis frame, from the accelerometer's
    specific force (which points up when the IMU is static). `R_BI` is
    `LegKinematics.R_BI`."""
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
