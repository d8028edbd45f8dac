"""A small calibrator, written as a third-party plug-in would be: per stance, the spread
of the inter-foot pose about its mean, and both soles level in the IMU's vertical,
solved by least squares with a finite-difference Jacobian. Any joint count: the
unknowns are one offset per joint of the leg map."""

import time

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from legcal_bench.calibrators.base import CalibrationResult, Calibrator, number_option
from legcal_bench.errors import CalibrationError
from legcal_bench.robots.kinematics import LegKinematics


class DispersionCalibrator(Calibrator):
    name = "dispersion"

    def __init__(self, frames: int = 60, height_weight: float = 1.0):  # --option frames=100
        self.frames = number_option("frames", frames, 2, integer=True)
        self.height_weight = number_option("height_weight", height_weight, 0.0)

    def settings(self):
        return {"frames": self.frames, "height_weight": self.height_weight}

    def calibrate(self, robot, recordings):
        t0 = time.perf_counter()
        kin = LegKinematics(robot)
        stances = [r for r in recordings if r.kind == "stance"]
        if len(stances) < 2:
            raise CalibrationError(f"dispersion: {len(stances)} stance recording(s); record two or more "
                                   "static double-support stances in different postures")
        data = []
        for r in stances:  # evenly spaced frames of each stance, with the IMU's up vector in the pelvis frame
            k = np.linspace(0, len(r.time) - 1, min(self.frames, len(r.time))).astype(int)
            up = r.imu_acc[k] / np.linalg.norm(r.imu_acc[k], axis=1, keepdims=True) @ kin.R_BI.T
            data.append((r.q_enc[k], up))

        def residual(dq):
            rows = []
            for q, up in data:
                left, right = kin.sole_poses_batch(q + dq)
                foot = np.linalg.inv(left) @ right  # the inter-foot transform of each frame
                pose = np.hstack([foot[:, :3, 3], Rotation.from_matrix(foot[:, :3, :3]).as_rotvec()])
                rows.append((pose - pose.mean(axis=0)).ravel())  # constant within a stance
                rows.append((left[:, :3, 2] - up).ravel())  # soles level in the IMU's vertical
                rows.append((right[:, :3, 2] - up).ravel())
                rows.append(self.height_weight * np.einsum("ni,ni->n", left[:, :3, 3] - right[:, :3, 3], up))
            return np.concatenate(rows)

        sol = least_squares(residual, np.zeros(len(robot.joint_names)), method="lm", xtol=1e-12, ftol=1e-12)
        return CalibrationResult(calibrator=self.name, robot=robot.name,
                                 offsets_rad=dict(zip(robot.joint_names, sol.x.tolist())),
                                 diagnostics={"cost": float(sol.cost), "evaluations": int(sol.nfev)},
                                 timing_s={"total": time.perf_counter() - t0}, settings=self.settings())
