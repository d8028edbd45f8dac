"""IMU motion compensation: the accelerometer's specific force minus the IMU's own
acceleration, predicted from the encoder kinematics.

A static accelerometer reads f = R_WI^T (a - g): while the posture moves, the IMU's
acceleration a shows as tilt (1.5 mrad RMS in the default stances, 97-99 % of the old
zero-noise floor). In double support the feet are fixed, so the IMU's trajectory in a
sole frame follows from the leg angles alone: p_S(t) = T_BS(q(t))^-1 p_BI. Its second
derivative (Savitzky-Golay over `window_s`, on a uniform grid) rotated into the IMU
frame is subtracted:

    f_comp = f - R_BI^T R_BS(q) d2/dt2 [R_BS(q)^T (p_BI - p_BS(q))]

averaged over the two soles (each is a fixed frame; the average halves the effect of
either one rocking). The encoders' offsets bias this only to second order (a small
rotation of an acceleration that is itself small). Rotation of the sole frame is
ignored: it is fixed in the world by assumption.
"""

from __future__ import annotations

import numpy as np

from legcal_bench.estimation.problem.smoothing import savgol_resampled
from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics

IMU_WINDOW_S = 0.75  # smoothing window of the second derivative (0.5-1 s works: the motion is ~10 s slow)
POLYORDER = 3
IMU_MODES = ("compensated", "raw")  # raw: the paper's setting, the accelerometer as it reads


def imu_acceleration(kin: LegKinematics, time: np.ndarray, q: np.ndarray, window_s: float = IMU_WINDOW_S
                     ) -> np.ndarray:
    """(N, 3) the IMU's acceleration in the IMU frame (m/s^2) predicted from the leg angles
    `q` (N, n) (n: the leg joints) at `time` (N,), feet fixed. Zero for recordings too short to smooth."""
    time, q = np.asarray(time, dtype=float), np.asarray(q, dtype=float)
    n = len(time)
    if n < POLYORDER + 2:
        return np.zeros((n, 3))
    fk = frame_kinematics(kin, q)
    p_BI = kin.T_BI[:3, 3]
    acc_B = np.zeros((n, 3))
    for R, p in ((fk.R_L, fk.p_L), (fk.R_R, fk.p_R)):
        p_S = np.einsum("nji,nj->ni", R, p_BI - p)  # IMU position in the sole frame
        a_S = savgol_resampled(time, p_S, window_s, POLYORDER, deriv=2)
        if a_S is None:
            return np.zeros((n, 3))
        acc_B += 0.5 * np.einsum("nij,nj->ni", R, a_S)
    return acc_B @ kin.R_BI


def compensate(kin: LegKinematics, time: np.ndarray, q: np.ndarray, imu_acc: np.ndarray,
               window_s: float = IMU_WINDOW_S) -> np.ndarray:
    """The accelerometer's specific force with the IMU's predicted acceleration removed:
    what it would read if the posture held still."""
    ok = np.isfinite(q).all(axis=1) & np.isfinite(time)
    out = np.array(imu_acc, dtype=float, copy=True)
    if ok.sum() >= POLYORDER + 2:
        out[ok] -= imu_acceleration(kin, time[ok], q[ok], window_s)
    return out
