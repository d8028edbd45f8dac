"""Yamane's sole-height calibrator (Yamane 2011), as the paper reimplemented it.

Unknowns: one root (pelvis) orientation per frame, of which only roll and pitch are
free (neither term sees yaw), and one shared vector of offsets dq (one per leg joint). Per frame k:

  IMU term     w_imu (R_k^T e_z - u_k)               u_k: the IMU's up vector in the pelvis frame
  sole term    w_h (z_kv - mean_v z_kv), v = 1..8    z_kv = e_z^T R_k p_v(q_k + dq): the heights of
                                                     the eight sole corners (four per foot)

with R_k = R_y(pitch_k) R_x(roll_k). The variance of the corner heights is zero when
both soles lie flat on one plane. Sole heights alone cannot see equal hip-pitch
offsets on both legs (they act as a pelvis pitch); the IMU term makes the problem
well-posed, and its weight decides how the method ranks.

Both terms (`legcal_bench.estimation.problem.terms.SoleHeightTerm`, `ImuTiltTerm`) go into one
`legcal_bench.estimation.problem.problem.Problem` with a shared offsets block and a per-frame
tilt block, so the Jacobian is block-sparse (2 unknowns per frame + the shared offsets), handed
to scipy's trust-region solver as a sparse matrix (LSMR inner solves) with
`solver="sparse"`; the default, `solver="projected"`, eliminates the per-frame tilts by
variable projection (each frame's roll and pitch solved for the current offsets, then LM
on the offsets with the projected Jacobian), three times faster here. The information
on the offsets has the per-frame tilts eliminated (Schur complement).

Bound: |dq| <= 0.08 rad (the paper's); offsets the data push against it (gross ones: a
re-mounted joint, a multi-turn encoder that lost a count) are solved for within
`bound_max` (±30°), the same minimum as that bound given by hand, as the inter-foot
calibrator does (`legcal_bench.estimation.problem.stance.StanceProblem.solve_gross`).

Weights: `weights="default"` uses w_h = 1000 /m and w_imu = 1000 /rad (1 mm of height
counts like 1 mrad of tilt; the paper gives no values); `weights="sensor"` derives them
from the recordings' declared sensor model (1/sigma of each residual).
"""

from __future__ import annotations

import time
from dataclasses import asdict

import numpy as np

from legcal_bench import paper
from legcal_bench.calibrators.base import CalibrationResult, Calibrator, number_option, preprocess_options
from legcal_bench.data.recording import Recording
from legcal_bench.errors import CalibrationError
from legcal_bench.estimation.checks.datacheck import data_warnings
from legcal_bench.estimation.imu.levelling import up_in_base
from legcal_bench.estimation.information.noise import noise_sigmas
from legcal_bench.estimation.imu.imu_motion import IMU_WINDOW_S
from legcal_bench.estimation.problem.preprocess import filter_warnings, select_frames
from legcal_bench.estimation.problem.problem import Block, Problem
from legcal_bench.estimation.problem.stance import (GROSS_BOUND_RAD, at_bound, bound_diagnostics, gross_report,
                                                    gross_warnings)
from legcal_bench.estimation.problem.terms import OFFSETS, TILT, ImuTiltTerm, SoleHeightTerm
from legcal_bench.estimation.information.uncertainty import (NO_NOISE, bound_warnings, imu_tilt_warnings, posterior,
                                                 uncertainty_warnings)
from legcal_bench.robots.kinematics import LegKinematics, pitch_sums
from legcal_bench.robots.legmap import LegMap


# "projected": the per-frame roll and pitch eliminated by variable projection, LM on the
# offsets (default); "sparse": all unknowns jointly, trust region with LSMR steps. Both
# reach the same optimum (to ~1e-9 rad, the cost's flatness in its weak directions).
SOLVERS = {"projected": "projected", "sparse": "trf"}


class YamaneCalibrator(Calibrator):
    name = "yamane"

    def __init__(self, weights: str = "default", w_h: float | None = None, w_imu: float | None = None,
                 n_max: int = paper.N_MAX_PER_STANCE, bound: float = paper.OFFSET_BOUND_RAD, tol: float = 1e-10,
                 solver: str = "projected", imu: str = "compensated", imu_window_s: float = IMU_WINDOW_S,
                 bound_max: float = GROSS_BOUND_RAD):
        if weights not in ("default", "sensor"):
            raise CalibrationError(f"weights {weights!r}: use default or sensor")
        if solver not in SOLVERS:
            raise CalibrationError(f"solver {solver!r}: use one of {', '.join(SOLVERS)}")
        self.solver = solver
        self.weights = weights
        # An explicit weight (0 included) replaces the setting's.
        self.w_h_opt = None if w_h is None else number_option("w_h", w_h, 0.0)
        self.w_imu_opt = None if w_imu is None else number_option("w_imu", w_imu, 0.0)
        self.bound = number_option("bound", bound, 0.0, np.pi, low_open=True)
        self.bound_max = number_option("bound_max", bound_max, 0.0, np.pi, low_open=True)
        self.tol = number_option("tol", tol, 0.0, 1.0, low_open=True)
        self.preprocess = preprocess_options(n_max, imu, imu_window_s)

    @classmethod
    def benchmark_variants(cls) -> dict[str, dict]:
        return {"default": {"weights": "default"}, "sensor": {"weights": "sensor"}}

    def settings(self) -> dict:
        return {"weights": self.weights, "w_h": self.w_h_opt, "w_imu": self.w_imu_opt, "bound": self.bound,
                "bound_max": self.bound_max, "n_max": self.preprocess.n_max, "solver": self.solver,
                "imu": self.preprocess.imu, "imu_window_s": self.preprocess.imu_window_s}

    def _weights(self, recordings: list[Recording], kin: LegKinematics) -> tuple[float, float]:
        w_h, w_imu = 1000.0, 1000.0
        if self.weights == "sensor":
            s = noise_sigmas(recordings[0].sensor_model, kin.dims.leg_length, kin.legmap.leg_joints)
            if s is not None:
                w_h, w_imu = 1.0 / s["height"], 1.0 / s["tilt"]
        return (w_h if self.w_h_opt is None else float(self.w_h_opt)), \
            (w_imu if self.w_imu_opt is None else float(self.w_imu_opt))

    def calibrate(self, robot: LegMap, recordings: list[Recording]) -> CalibrationResult:
        t0 = time.perf_counter()
        kin = LegKinematics(robot)
        stances = [r for r in recordings if r.kind == "stance"]
        if not stances:
            raise CalibrationError("no stance recordings (kind 'stance') to calibrate from")
        # The same frame selection as the inter-foot calibrator (same data for both).
        Q, acc, reports = [], [], []
        for r in stances:
            segs, rep = select_frames(kin, r.name, r.time, r.q_enc, r.imu_acc, r.imu_gyro, self.preprocess,
                                      r.motion)
            reports.append(rep)
            for s in segs:
                Q.append(s.q_enc)
                acc.append(s.imu_acc)
        if not Q:
            raise CalibrationError("no usable frames in any stance after filtering: "
                                   + "; ".join(f"{r.name}: {r.text()}" for r in reports))
        Q, acc = np.vstack(Q), np.vstack(acc)
        up = up_in_base(acc, kin.R_BI)
        w_h, w_imu = self._weights(stances, kin)
        n = len(Q)
        # Start each root orientation at the IMU's tilt: up = R^T e_z.
        roll0 = np.arctan2(up[:, 1], up[:, 2])
        pitch0 = np.arctan2(-up[:, 0], np.hypot(up[:, 1], up[:, 2]))
        terms = [SoleHeightTerm(kin, Q, w_h), ImuTiltTerm(up, w_imu)]

        def solve(bound: float):
            problem = Problem([Block(OFFSETS, robot.n_joints, bound=bound), Block(TILT, 2, per_frame=True)], terms)
            sol = problem.solve(x0, method=SOLVERS[self.solver], tol=self.tol, max_nfev=100)
            return problem, sol, problem.unpack(sol.x)[OFFSETS]

        x0 = Problem([Block(OFFSETS, robot.n_joints), Block(TILT, 2, per_frame=True)], terms).pack(
            {TILT: np.column_stack([roll0, pitch0])})
        t1 = time.perf_counter()
        # Gross offsets: the solve at bound_max. The projected solver's LM steps are
        # unbounded (the bound honoured by a re-solve only when they leave it), so it runs
        # there first: an answer within the paper's bound is that bound's own, bit for bit.
        grows = self.bound < self.bound_max
        early = grows and self.solver == "projected"
        problem, sol, dq = solve(self.bound_max if early else self.bound)
        gross, bound = None, self.bound
        if grows and at_bound(dq, self.bound):
            if not early:
                problem, sol, dq = solve(self.bound_max)
            bound = self.bound_max
            gross = gross_report("grow", self.bound, bound, dq, robot.joint_names, 0 if early else 1)
        t_solve = time.perf_counter() - t1
        w = np.linalg.eigvalsh(problem.information(sol.x)[0])
        conditioning = {"kappa_H_data": float(w[-1] / w[0]) if w[0] > 0 else float("inf"),
                        "eigenvalues_H_data": w.tolist()}
        # Posterior: the same rows divided by their declared noise, per-frame tilts eliminated.
        signs = kin.pitch_signs()
        sig = noise_sigmas(stances[0].sensor_model, kin.dims.leg_length, robot.leg_joints)
        warnings: list[str] = filter_warnings(reports)
        post = None
        if sig is not None:
            whitened = Problem([Block(OFFSETS, robot.n_joints, bound=bound), Block(TILT, 2, per_frame=True)],
                               [SoleHeightTerm(kin, Q, 1.0 / sig["height"]), ImuTiltTerm(up, 1.0 / sig["tilt"])])
            post = posterior(whitened.information(sol.x)[0], robot.joint_names, robot.joint_roles, signs)
            warnings += uncertainty_warnings(post)
        # A fixed tilt of the IMU's vertical moves the IMU rows only: d(up) = e_axis x up, so
        # the rows move by -w_imu e_axis x up; the offsets follow to first order.
        dr = np.zeros((n, 11, 2))
        for axis in range(2):
            dr[:, 8:, axis] = -w_imu * np.cross(np.eye(3)[axis], up)
        tilt_response = problem.shared_response(sol.x, dr.reshape(-1, 2))[:robot.n_joints]
        warnings += imu_tilt_warnings(tilt_response, stances[0].sensor_model.tilt_bound, signs)
        warnings += bound_warnings(dq, bound, robot.joint_names)
        warnings += gross_warnings(gross, dq, bound, robot.joint_names)
        warnings += data_warnings(kin, recordings, dq)
        return CalibrationResult(
            calibrator=self.name, robot=robot.name,
            offsets_rad={nm: float(v) for nm, v in zip(robot.joint_names, dq)},
            pitch_sums_rad=pitch_sums(dq, signs),
            conditioning=conditioning,
            diagnostics={"frames_used": int(n), "w_h": w_h, "w_imu": w_imu, "filter": [asdict(r) for r in reports],
                         "cost": float(sol.cost), "nfev": int(sol.nfev), "status": int(sol.status),
                         "posterior": post if post is not None else {"note": NO_NOISE},
                         "imu_tilt_response": tilt_response.tolist(),
                         "bound": bound_diagnostics(self.bound, bound, gross)},
            timing_s={"preprocess": t1 - t0, "solve": t_solve, "total": time.perf_counter() - t0},
            settings=self.settings(),
            warnings=warnings,
        )
