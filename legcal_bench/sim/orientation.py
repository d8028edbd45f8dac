"""The gravity direction a robot's software estimates from its IMU.

A walking policy reads "gravity in the base frame" from an orientation filter on the
IMU, not from the simulator. `GravityFilter` is a complementary filter in the IMU
frame (Mahony's without the bias state): the gravity direction is carried by the gyro
(a world-fixed vector seen from a rotating frame: g' = exp(w dt)^T g) and pulled
toward the accelerometer's direction with time constant `tau_s`, so walking
accelerations (several m/s^2 for a few tenths of a second) move it little while a
constant tilt of the sensor (mounting, accelerometer bias) passes straight through, as
on a robot.

An IMU's filter runs at its sampling rate (~1 kHz), far above a policy's: the walking
simulator feeds it the rate and specific force averaged over each control period (what
a high-rate filter integrates), not one instantaneous sample per period, which aliases
the impacts of each footfall (the G1 walking, noise-free IMU: 0.49 deg mean error with
period means, 1.36 deg with one sample per 20 ms; tests/envs/test_walking.py).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

TAU_S = 1.0  # s: the accelerometer's pull (the tilt filter of a walking controller)


class GravityFilter:
    """Unit gravity direction ("down") in the IMU frame from gyro and accelerometer."""

    def __init__(self, tau_s: float = TAU_S):
        self.tau_s = float(tau_s)
        self.down = np.array([0.0, 0.0, -1.0])

    def reset(self, acc: np.ndarray) -> np.ndarray:
        """Start from the accelerometer alone (the robot standing still)."""
        self.down = -np.asarray(acc, dtype=float) / np.linalg.norm(acc)
        return self.down

    def update(self, acc: np.ndarray, gyro: np.ndarray, dt: float) -> np.ndarray:
        """One step of `dt` with the mean specific force `acc` and mean rate `gyro`."""
        acc = np.asarray(acc, dtype=float)
        g = pin.exp3(np.asarray(gyro, dtype=float) * dt).T @ self.down
        norm = np.sqrt(acc.dot(acc))  # np.linalg.norm's arithmetic for a vector, without its checks
        if norm > 1e-6:  # free fall leaves the gyro alone
            g = g + (dt / self.tau_s) * (-acc / norm - g)
        self.down = g / np.sqrt(g.dot(g))
        return self.down
