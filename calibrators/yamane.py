"""Yamane's sole-height calibrator (Yamane 2011), as the paper reimplemented it.

Unknowns: one root (pelvis) orientation per frame, of which only roll and pitch are
free (neither term sees yaw), and one shared 12-vector of offsets dq. Per frame k:

  IMU term     w_imu (R_k^T e_z - u_k)               u_k: the IMU's up vector in the pelvis frame
  sole term    w_h (z_kv - mean_v z_kv), v = 1..8    z_kv = e_z^T R_k p_v(q_k + dq): the heights of
                                                     the eight sole corners (four per foot)

with R_k = R_y(pitch_k) R_x(roll_k). The variance of the corner heights is zero when
both soles lie flat on one plane. Sole heights alone cannot see equal hip-pitch
offsets on both legs (they act as a pelvis pitch); the IMU term makes the problem
well-posed, and its weight decides how the method ranks.

The Jacobian is block-sparse (2 unknowns per frame + 12 shared), handed to scipy's
trust-region solver as a sparse matrix (LSMR inner solves).

Weights: `weights="default"` uses w_h = 1000 /m and w_imu = 1000 /rad (1 mm of height
counts like 1 mrad of tilt; the paper gives no values); `weights="sensor"` derives them
from the recordings' declared sensor model (1/sigma of each residual).
"""

from __future__ import annotations

import time

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix

from legcal_bench import paper
from legcal_bench.calibrators.base import CalibrationResult, Calibrator
from legcal_bench.data.recording import Recording
from legcal_bench.errors import CalibrationError
from legcal_bench.estimation.levelling import up_in_base
from legcal_bench.estimation.noise import noise_sigmas
from legcal_bench.estimation.preprocess import PreprocessConfig, select_frames
from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics, pitch_sums
from legcal_bench.robots.legmap import LegMap


def _rot(roll: np.ndarray, pitch: np.ndarray):
    """R = R_y(pitch) R_x(roll) and its two partial derivatives, batched (N, 3, 3)."""
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    n = len(roll)
    Rx, dRx = np.zeros((n, 3, 3)), np.zeros((n, 3, 3))
    Ry, dRy = np.zeros((n, 3, 3)), np.zeros((n, 3, 3))
    Rx[:, 0, 0] = 1
    Rx[:, 1, 1], Rx[:, 1, 2], Rx[:, 2, 1], Rx[:, 2, 2] = cr, -sr, sr, cr
    dRx[:, 1, 1], dRx[:, 1, 2], dRx[:, 2, 1], dRx[:, 2, 2] = -sr, -cr, cr, -sr
    Ry[:, 1, 1] = 1
    Ry[:, 0, 0], Ry[:, 0, 2], Ry[:, 2, 0], Ry[:, 2, 2] = cp, sp, -sp, cp
    dRy[:, 0, 0], dRy[:, 0, 2], dRy[:, 2, 0], dRy[:, 2, 2] = -sp, cp, -cp, -sp
    return Ry @ Rx, Ry @ dRx, dRy @ Rx


class YamaneCalibrator(Calibrator):
    name = "yamane"

    def __init__(self, weights: str = "default", w_h: float | None = None, w_imu: float | None = None,
                 n_max: int = paper.N_MAX_PER_STANCE, bound: float = paper.OFFSET_BOUND_RAD, tol: float = 1e-10):
        if weights not in ("default", "sensor"):
            raise CalibrationError(f"weights {weights!r}: use default or sensor")
        self.weights, self.w_h_opt, self.w_imu_opt = weights, w_h, w_imu
        self.bound, self.tol = float(bound), float(tol)
        self.preprocess = PreprocessConfig(n_max=int(n_max))

    @classmethod
    def benchmark_variants(cls) -> dict[str, dict]:
        return {"default": {"weights": "default"}, "sensor": {"weights": "sensor"}}

    def settings(self) -> dict:
        return {"weights": self.weights, "w_h": self.w_h_opt, "w_imu": self.w_imu_opt, "bound": self.bound,
                "n_max": self.preprocess.n_max}

    def _weights(self, recordings: list[Recording], kin: LegKinematics) -> tuple[float, float]:
        w_h, w_imu = 1000.0, 1000.0
        if self.weights == "sensor":
            s = noise_sigmas(recordings[0].sensor_model, kin.dims.leg_length)
            if s is not None:
                w_h, w_imu = 1.0 / s["height"], 1.0 / s["tilt"]
        return (self.w_h_opt or w_h), (self.w_imu_opt or w_imu)

    def calibrate(self, robot: LegMap, recordings: list[Recording]) -> CalibrationResult:
        t0 = time.perf_counter()
        kin = LegKinematics(robot)
        stances = [r for r in recordings if r.kind == "stance"]
        if not stances:
            raise CalibrationError("no stance recordings (kind 'stance') to calibrate from")
        # The same frame selection as the inter-foot calibrator (same data for both).
        Q, acc, reports = [], [], []
        for r in stances:
            segs, rep = select_frames(kin, r.name, r.time, r.q_enc, r.imu_acc, r.imu_gyro, self.preprocess)
            reports.append(rep.__dict__)
            for s in segs:
                Q.append(s.q_enc)
                acc.append(s.imu_acc)
        if not Q:
            raise CalibrationError("no usable frames in any stance after filtering")
        Q, acc = np.vstack(Q), np.vstack(acc)
        up = up_in_base(acc, kin.R_BI)
        w_h, w_imu = self._weights(stances, kin)
        n = len(Q)
        # Start each root orientation at the IMU's tilt: up = R^T e_z.
        roll0 = np.arctan2(up[:, 1], up[:, 2])
        pitch0 = np.arctan2(-up[:, 0], np.hypot(up[:, 1], up[:, 2]))
        corners = {s: kin.corners[s] for s in ("left", "right")}
        problem = _YamaneProblem(kin, Q, up, corners, w_h, w_imu)
        x0 = np.concatenate([np.zeros(12), np.column_stack([roll0, pitch0]).ravel()])
        lb = np.concatenate([-self.bound * np.ones(12), -np.inf * np.ones(2 * n)])
        ub = -lb
        t1 = time.perf_counter()
        sol = least_squares(problem.residual, x0, jac=problem.jacobian, bounds=(lb, ub), method="trf",
                            tr_solver="lsmr", x_scale=1.0, ftol=self.tol, xtol=self.tol, gtol=self.tol,
                            max_nfev=100)
        t_solve = time.perf_counter() - t1
        dq = sol.x[:12]
        w = np.linalg.eigvalsh(problem.information(sol.x))
        conditioning = {"kappa_H_data": float(w[-1] / w[0]) if w[0] > 0 else float("inf"),
                        "eigenvalues_H_data": w.tolist()}
        return CalibrationResult(
            calibrator=self.name, robot=robot.name,
            offsets_rad={nm: float(v) for nm, v in zip(robot.joint_names, dq)},
            pitch_sums_rad=pitch_sums(dq, kin.pitch_signs()),
            conditioning=conditioning,
            diagnostics={"frames_used": int(n), "w_h": w_h, "w_imu": w_imu, "filter": reports,
                         "cost": float(sol.cost), "nfev": int(sol.nfev), "status": int(sol.status)},
            timing_s={"preprocess": t1 - t0, "solve": t_solve, "total": time.perf_counter() - t0},
            settings=self.settings(),
        )


class _YamaneProblem:
    def __init__(self, kin, Q, up, corners, w_h, w_imu):
        self.kin, self.Q, self.up, self.w_h, self.w_imu = kin, Q, up, w_h, w_imu
        self.c = np.vstack([corners["left"], corners["right"]]).reshape(2, 4, 3)  # corners in the sole frames
        self.c_skew = np.array([[pin.skew(c) for c in side] for side in self.c])  # (2, 4, 3, 3)
        self._cache = None

    def _eval(self, x):
        if self._cache is not None and np.array_equal(self._cache[0], x):
            return self._cache[1]
        kin, n = self.kin, len(self.Q)
        dq, ang = x[:12], x[12:].reshape(n, 2)
        R, dR_roll, dR_pitch = _rot(ang[:, 0], ang[:, 1])
        fk = frame_kinematics(kin, self.Q + dq)
        Tr = np.stack([fk.R_L, fk.R_R], axis=1)  # (n, 2, 3, 3)
        Tt = np.stack([fk.p_L, fk.p_R], axis=1)
        Jl = np.stack([fk.J_L, fk.J_R], axis=1)
        P = (np.einsum("sic,nsac->nsia", self.c, Tr) + Tt[:, :, None, :]).reshape(n, 8, 3)
        # Corner velocity in the sole frame, v + w x c = J_v - [c]x J_w, then in the pelvis frame.
        local = Jl[:, :, None, :3, :] - np.einsum("sivw,nswc->nsivc", self.c_skew, Jl[:, :, 3:, :])
        world = np.einsum("nsab,nsibc->nsiac", Tr, local)
        Jp = np.zeros((n, 8, 3, 12))
        Jp[:, :4, :, :6], Jp[:, 4:, :, 6:] = world[:, 0], world[:, 1]
        z = np.einsum("nj,nvj->nv", R[:, 2, :], P)
        r_h = self.w_h * (z - z.mean(axis=1, keepdims=True))
        up_model = R[:, 2, :]  # R^T e_z, as rows
        r_i = self.w_imu * (up_model - self.up)
        out = (np.concatenate([np.column_stack([r_h, r_i]).ravel()]), R, dR_roll, dR_pitch, P, Jp)
        self._cache = (x.copy(), out)
        return out

    def residual(self, x):
        return self._eval(x)[0]

    def blocks(self, x):
        """Per-frame Jacobian blocks: (n, 11, 12) w.r.t. dq and (n, 11, 2) w.r.t. the
        frame's own roll and pitch (rows: 8 heights, then 3 IMU)."""
        _, R, dRr, dRp, P, Jp = self._eval(x)
        n = len(self.Q)
        Bq = np.zeros((n, 11, 12))
        Ba = np.zeros((n, 11, 2))
        # Heights: d z_kv = e_z^T (R_k dP + dR_k P), centred over the 8 vertices.
        Jz = np.einsum("nj,nvjc->nvc", R[:, 2, :], Jp)
        Bq[:, :8] = self.w_h * (Jz - Jz.mean(axis=1, keepdims=True))
        for j, dR in enumerate((dRr, dRp)):
            dz = np.einsum("nj,nvj->nv", dR[:, 2, :], P)
            Ba[:, :8, j] = self.w_h * (dz - dz.mean(axis=1, keepdims=True))
            # IMU rows: d(R^T e_z) = (dR)^T e_z, the third row of dR.
            Ba[:, 8:, j] = self.w_imu * dR[:, 2, :]
        return Bq, Ba

    def jacobian(self, x):
        Bq, Ba = self.blocks(x)
        n = len(self.Q)
        rows = np.arange(11 * n).reshape(n, 11)
        r = np.concatenate([np.repeat(rows, 12, axis=1).ravel(), np.repeat(rows, 2, axis=1).ravel()])
        c = np.concatenate([np.tile(np.arange(12), 11 * n),
                            (12 + 2 * np.arange(n)[:, None, None] + np.arange(2)[None, None, :]).repeat(11, 1).ravel()])
        v = np.concatenate([Bq.ravel(), Ba.ravel()])
        return csr_matrix((v, (r, c)), shape=(11 * n, 12 + 2 * n))

    def information(self, x) -> np.ndarray:
        """Information on dq with each frame's orientation eliminated (Schur complement)."""
        Bq, Ba = self.blocks(x)
        Hqq = np.einsum("nri,nrj->ij", Bq, Bq)
        Hqa = np.einsum("nri,nrj->nij", Bq, Ba)
        Haa = np.einsum("nri,nrj->nij", Ba, Ba)
        return Hqq - np.einsum("nij,njk,nlk->il", Hqa, np.linalg.inv(Haa), Hqa)
