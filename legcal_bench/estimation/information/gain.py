"""The information a frame adds about the offsets: the static env's reward.

The objective a learned excitation policy would maximize (and what a stance design
maximizes): log det of the information matrix of the stance's matched residuals.
"""

from __future__ import annotations

import numpy as np

from legcal_bench.estimation.imu.levelling import levelling_rotations, up_in_base
from legcal_bench.estimation.problem.residuals import flat_residuals
from legcal_bench.paper import MATCHED_UNIT_SCALE
from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics


class InformationGain:
    """Running information matrix of one contact segment, for the static env's reward.

    Rows are the matched-setting residuals (feet rows in mm and mrad, flat rows in mm
    and mrad) linearised at dq = 0 from the logged encoders and IMU. Feet rows are
    taken about the segment mean (the mean absorbs what all frames share), so
    H = sum_k G_k^T G_k - N Gbar^T Gbar + sum_k F_k^T F_k. The reward of a frame is
    the increase of log det(H + EPS I); EPS = 1 (mm/rad)^2 keeps it finite from the
    first frame, far below the eigenvalues a single varied stance reaches (~1e4+).
    """

    EPS = 1.0
    SCALE = MATCHED_UNIT_SCALE  # mm and mrad, the paper's matched units

    def __init__(self, kin: LegKinematics):
        self.kin = kin
        self.n_joints = kin.legmap.n_joints
        self.reset()

    def reset(self) -> None:
        self.n = 0
        n = self.n_joints
        self.sum_G = np.zeros((6, n))
        self.sum_GtG = np.zeros((n, n))
        self.H_flat = np.zeros((n, n))
        self.logdet = n * np.log(self.EPS)

    @property
    def H(self) -> np.ndarray:
        if self.n == 0:
            return np.zeros((self.n_joints, self.n_joints))
        return self.sum_GtG - self.sum_G.T @ self.sum_G / self.n + self.H_flat

    def add(self, q_enc: np.ndarray, imu_acc: np.ndarray) -> float:
        fk = frame_kinematics(self.kin, q_enc[None])
        up = up_in_base(imu_acc[None], self.kin.R_BI)
        _, F = flat_residuals(fk, up, levelling_rotations(up))
        G, F = self.SCALE * fk.G[0], self.SCALE * F[0]
        self.n += 1
        self.sum_G += G
        self.sum_GtG += G.T @ G
        self.H_flat += F.T @ F
        new = np.linalg.slogdet(self.H + self.EPS * np.eye(self.n_joints))[1]
        gain, self.logdet = new - self.logdet, new
        return float(gain)
