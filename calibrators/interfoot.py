"""The paper's inter-foot dispersion calibrator.

Objective over all contact segments sharing one offset vector dq:

  sum_s sum_k [ l_f ||r_feet||^2 + l_g ||r_flat||^2 ] + l_q ||W_q . dq||^2
        + l_knee ||dq_knee - dq_knee_prior||^2

assembled from residual terms (`legcal_bench.estimation.terms`: one inter-foot and one
flat-ground term per contact segment, a Tikhonov and a knee-prior term) into one
`legcal_bench.estimation.problem.Problem`, bounded to |dq| <= 0.08 rad from dq = 0.
Two solvers:
  "projected" (default): C*_s re-estimated inside the residual (variable projection),
      with the analytic Jacobian that includes dC*_s/d dq; reaches the optimum.
  "alternating": the paper's scheme, C*_s recomputed, then a bounded solve with C*_s
      held fixed (inner: <= 200 iterations, ftol 1e-8; outer: <= 15).
Both run the same preprocessing, solve, drop the largest 10 % residual frames per
segment, and solve again from there.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from legcal_bench import paper
from legcal_bench.calibrators.base import CalibrationResult, Calibrator, number_option, preprocess_options
from legcal_bench.data.recording import Recording
from legcal_bench.errors import CalibrationError
from legcal_bench.estimation.confounds import confound_lines, confound_report
from legcal_bench.estimation.coplanarity import StanceContact, check_stances
from legcal_bench.estimation.datacheck import data_warnings
from legcal_bench.estimation.effects import EffectModel, EffectSegment, SegmentData, load_effects
from legcal_bench.estimation.levelling import levelling_rotations, tilted, up_in_base
from legcal_bench.estimation.noise import noise_sigmas
from legcal_bench.estimation.observability import analyze, observability_warnings
from legcal_bench.estimation.whitening import frame_covariances, whitened_system, whitening
from legcal_bench.estimation.imu_motion import IMU_WINDOW_S
from legcal_bench.estimation.preprocess import filter_warnings, select_frames
from legcal_bench.estimation.smoothing import smooth_wrenches
from legcal_bench.estimation.problem import Block, Problem
from legcal_bench.estimation.uncertainty import (NO_NOISE, bound_warnings, imu_tilt_warnings, posterior,
                                                 uncertainty_warnings)
from legcal_bench.estimation.terms import (OFFSETS, FlatGroundTerm, HeldParametersTerm, InterFootTerm, KneePriorTerm,
                                           SegmentKinematics, TikhonovTerm)
from legcal_bench.robots.kinematics import LegKinematics, pitch_sums
from legcal_bench.robots.legmap import LegMap


@dataclass(frozen=True)
class InterFootWeights:
    lambda_f: float
    lambda_g: float
    lambda_q: float
    lambda_knee: float
    w_q: tuple[float, ...]  # per leg, in the platform's joint order (left leg; mirrored to the right)
    unit_scale: float = 1.0  # residual units: 1 = metres and radians, 1000 = mm and mrad
    # Per-row 1/sigma instead of unit_scale (the "sensor" setting): feet translation,
    # feet rotation, flat height, flat normal.
    row_sigmas: tuple[float, float, float, float] | None = None


# The paper's settings. W_q follows each platform's own joint order.
SETTINGS = {
    "a3_operating": InterFootWeights(**paper.A3_OPERATING),
    "a2_operating": InterFootWeights(**paper.A2_OPERATING),
    "matched": InterFootWeights(1.0, 1.0, 0.0, 0.0, (1, 1, 1, 1, 1, 1), unit_scale=paper.MATCHED_UNIT_SCALE),
}
# "sensor": the matched setting with each row divided by its noise level from the
# recordings' declared sensor model (falls back to "matched" for noise-free data).
SETTING_NAMES = ("operating", "sensor", *SETTINGS)


def operating_setting(legmap: LegMap) -> str:
    """A3's operating weights for a hip-pitch-first ordering (geometric decoupling
    possible), A2's for orderings where hip pitch follows roll and yaw."""
    return "a3_operating" if legmap.hip_order[0] == "hip_pitch" else "a2_operating"


@dataclass
class _Prepared:
    name: str
    q_enc: np.ndarray
    up_B: np.ndarray
    R_WB: np.ndarray
    frames: np.ndarray
    ft: np.ndarray | None = None  # (N, 2, 6) ankle wrenches of these frames, if recorded
    recording: str = ""  # the stance recording the segment comes from


@dataclass
class Prepared:
    """Sessions ready to fit (`InterFootCalibrator.prepare`)."""

    robot: LegMap
    kin: LegKinematics
    stances: list[Recording]
    segments: list[_Prepared]
    w: "InterFootWeights"
    setting_name: str
    prior: np.ndarray | None
    knees: list[int]
    reports: list
    warnings: list[str]


class InterFootCalibrator(Calibrator):
    name = "interfoot"

    def __init__(self, setting: str = "operating", solver: str = "projected", jacobian: str = "analytic",
                 lambda_f: float | None = None, lambda_g: float | None = None, lambda_q: float | None = None,
                 lambda_knee: float | None = None, knee_prior_shift_rad: float = 0.0,
                 trim_fraction: float = paper.TRIM_FRACTION, bound: float = paper.OFFSET_BOUND_RAD,
                 max_outer: int = paper.OUTER_MAX_ITERATIONS, n_max: int = paper.N_MAX_PER_STANCE, tol: float = 1e-10,
                 imu: str = "compensated", imu_window_s: float = IMU_WINDOW_S, effects: str = "",
                 contact_check: str = "flag"):
        if setting not in SETTING_NAMES:
            raise CalibrationError(f"setting {setting!r}: use one of {', '.join(SETTING_NAMES)}")
        if solver not in ("projected", "alternating"):
            raise CalibrationError(f"solver {solver!r}: use projected (default) or alternating (the paper's)")
        if jacobian not in ("analytic", "2-point"):
            raise CalibrationError(f"jacobian {jacobian!r}: use analytic or 2-point (forward differences)")
        if contact_check not in CONTACT_CHECKS:
            raise CalibrationError(f"contact_check {contact_check!r}: use flag (default: warn about a stance whose "
                                   "soles were not on one plane), drop (also refit without it) or off")
        self.setting, self.solver, self.jacobian = setting, solver, jacobian
        self.contact_check = contact_check
        self.overrides = {k: number_option(k, v, 0.0) for k, v in dict(
            lambda_f=lambda_f, lambda_g=lambda_g, lambda_q=lambda_q, lambda_knee=lambda_knee).items() if v is not None}
        self.knee_prior_shift_rad = number_option("knee_prior_shift_rad", knee_prior_shift_rad, -0.5, 0.5)
        self.trim_fraction = number_option("trim_fraction", trim_fraction, 0.0, 0.5)
        self.bound = number_option("bound", bound, 0.0, np.pi, low_open=True)
        self.max_outer = number_option("max_outer", max_outer, 1, integer=True)
        self.tol = number_option("tol", tol, 0.0, 1.0, low_open=True)
        self.preprocess = preprocess_options(n_max, imu, imu_window_s)
        self.effect_names = tuple(n for n in (str(effects).replace(",", " ").split()) if n)
        if self.effect_names:
            load_effects(self.effect_names)  # a bad name fails before any data is read
            if solver != "projected":
                raise CalibrationError("effects: fits with model-gap effects use the projected solver")

    @classmethod
    def benchmark_variants(cls) -> dict[str, dict]:
        return {"operating": {"setting": "operating"}, "matched": {"setting": "matched"},
                "sensor": {"setting": "sensor"}}

    def settings(self) -> dict:
        return {"setting": self.setting, "solver": self.solver, "jacobian": self.jacobian, **self.overrides,
                "knee_prior_shift_rad": self.knee_prior_shift_rad, "trim_fraction": self.trim_fraction,
                "bound": self.bound, "max_outer": self.max_outer, "preprocess": asdict(self.preprocess),
                "effects": list(self.effect_names), "contact_check": self.contact_check}

    @staticmethod
    def _posterior(kin: LegKinematics, robot: LegMap, stances: list[Recording], problem, dq: np.ndarray,
                   signs: np.ndarray) -> dict | None:
        """Posterior standard deviations: the same frames' data rows, each divided by its
        declared noise level, C*_s eliminated (the projected Jacobian) at the solution."""
        sig = noise_sigmas(stances[0].sensor_model, kin.dims.leg_length)
        if sig is None:
            return None
        w = InterFootWeights(1.0, 1.0, 0.0, 0.0, (1,) * 6, row_sigmas=(
            sig["feet_translation"], sig["feet_rotation"], sig["flat_height"], sig["flat_normal"]))
        whitened = _InterFootProblem(kin, problem.segments, w, None, [], problem.bound)
        whitened.means_at(dq)
        _, J = whitened.evaluate(dq, "projected")
        J = J[:whitened.n_data_rows]
        return posterior(J.T @ J, robot.joint_names, robot.joint_roles, signs)

    def _tilt_response(self, problem: "_InterFootProblem", dq: np.ndarray, finish=None,
                       eps: float = 1e-3) -> np.ndarray:
        """(12, 2) how the estimate moves per rad of a fixed error of the IMU's vertical
        about the pelvis x and y axes: the same problem re-solved, from `dq`, with every
        up vector tilted by `eps` (the response is linear at this size); with `finish`
        (segments, x -> x: the generalized least squares) that instead of the row-weighted
        solve."""
        base = problem.segments
        V = np.zeros((12, 2))
        for axis in range(2):
            segs = []
            for s in base:
                up = tilted(s.up_B, axis, eps)
                segs.append(replace(s, up_B=up, R_WB=levelling_rotations(up)))
            if finish is not None:
                moved = finish(segs, dq)
            else:
                problem.build(segs)
                moved, _ = problem.solve(dq, self)
            V[:, axis] = (moved - dq) / eps
        problem.build(base)
        problem.means_at(dq)
        return V

    # ------------------------------------------------------------------ setup
    def weights_for(self, legmap: LegMap, recordings: list[Recording] | None = None) -> tuple[str, InterFootWeights]:
        if self.setting == "sensor":
            sig = noise_sigmas(recordings[0].sensor_model, LegKinematics(legmap).dims.leg_length) if recordings else None
            if sig is None:
                return "matched", replace(SETTINGS["matched"], **self.overrides)
            rows = (sig["feet_translation"], sig["feet_rotation"], sig["flat_height"], sig["flat_normal"])
            return "sensor", replace(SETTINGS["matched"], unit_scale=1.0, row_sigmas=rows, **self.overrides)
        name = operating_setting(legmap) if self.setting == "operating" else self.setting
        return name, replace(SETTINGS[name], **self.overrides)

    def prepare(self, robot: LegMap, recordings: list[Recording]) -> "Prepared":
        """The preprocessed stance segments and the weights a fit runs on (the first half
        of `calibrate`; the model-gap diagnosis fits several models to the same)."""
        kin = LegKinematics(robot)
        setting_name, w = self.weights_for(robot, recordings)
        warnings: list[str] = []
        for r in recordings:
            if r.joint_names != robot.joint_names:
                raise CalibrationError(f"recording {r.name}: joint names do not match robot {robot.name}")
        stances = [r for r in recordings if r.kind == "stance"]
        if not stances:
            raise CalibrationError("no stance recordings (kind 'stance'): record at least one static "
                                   "double-support stance, better four (I-IV)")
        # Preprocessing on the raw encoders.
        segments, reports = self.segments_of(kin, stances)
        warnings += filter_warnings(reports)
        if not segments:
            raise CalibrationError("no usable frames in any stance after filtering: "
                                   + "; ".join(f"{r.name}: {r.text()}" for r in reports))
        # Knee prior from the straight-leg standing phase.
        knees = [i for i, role in enumerate(robot.joint_roles) if role == "knee"]
        prior = None
        standing = [r for r in recordings if r.kind == "standing"]
        if w.lambda_knee > 0:
            if standing:
                q_knee = np.concatenate([r.q_enc[:, knees] for r in standing]).mean(axis=0)
                prior = robot.knee_straight_rad - q_knee + self.knee_prior_shift_rad
            else:
                warnings.append("no straight-leg standing recording: knee prior disabled (lambda_knee -> 0)")
                w = replace(w, lambda_knee=0.0)
        return Prepared(robot, kin, stances, segments, w, setting_name, prior, knees, reports, warnings)

    def segments_of(self, kin: LegKinematics, recordings: list[Recording]) -> tuple[list["_Prepared"], list]:
        """Each recording's contact segments after the frame selection (`select_frames`)
        with its IMU vertical; (segments, filter reports)."""
        segments, reports = [], []
        for r in recordings:
            segs, rep = select_frames(kin, r.name, r.time, r.q_enc, r.imu_acc, r.imu_gyro, self.preprocess,
                                      r.motion)
            reports.append(rep)
            for s in segs:
                up = up_in_base(s.imu_acc, kin.R_BI)
                ft = None
                if r.ft is not None:  # smoothed over the segment's span: noisy loads bias a compliance low
                    a, b = int(s.frames.min()), int(s.frames.max()) + 1
                    ft = smooth_wrenches(r.time[a:b], r.ft[a:b])[s.frames - a]
                segments.append(_Prepared(s.name, s.q_enc, up, levelling_rotations(up), s.frames, ft, r.name))
        return segments, reports

    def calibrate(self, robot: LegMap, recordings: list[Recording]) -> CalibrationResult:
        t0 = time.perf_counter()
        prep = self.prepare(robot, recordings)
        kin, w, stances, segments = prep.kin, prep.w, prep.stances, prep.segments
        setting_name, reports, warnings = prep.setting_name, prep.reports, list(prep.warnings)
        prior, knees = prep.prior, prep.knees
        problem = _InterFootProblem(kin, segments, w, prior, knees, self.bound)
        t_pre = time.perf_counter() - t0

        # First solve, trim the largest residual frames, solve again.
        t1 = time.perf_counter()
        dq, hist1 = problem.solve(np.zeros(12), self)
        if self.trim_fraction > 0:
            problem.trim(dq, self.trim_fraction)
            dq, hist2 = problem.solve(dq, self)
        else:
            hist2 = []
        t_solve = time.perf_counter() - t1
        t_contact = time.perf_counter()
        contacts, dropped = None, []
        if self.contact_check != "off":
            contacts = contact_check(self, prep, problem.segments, dq)
            flagged = [c for c in contacts or [] if c.flagged]
            warnings += [c.text() for c in flagged]
            kept = [s for s in problem.segments if s.recording not in {c.recording for c in flagged}]
            if flagged and self.contact_check == "drop" and len({s.recording for s in kept}) < 2:
                warnings.append(f"contact_check=drop: not dropped: fewer than two stances would be left of "
                                f"{len(contacts)}; these data do not fit soles on one flat floor (re-record)")
            elif flagged and self.contact_check == "drop":
                dropped = [c.recording for c in flagged]
                problem.build(kept)
                dq, hist3 = problem.solve(dq, self)
                hist2 += hist3
                # A fit with effects starts from the same stances.
                prep = replace(prep, segments=[s for s in prep.segments if s.recording not in dropped])
                warnings.append(f"contact_check=drop: fitted without {', '.join(dropped)}")
            elif flagged:
                warnings.append("contact_check: rerun with --option contact_check=drop to fit without "
                                f"{', '.join(c.recording for c in flagged)}, or re-record on a flat floor")
        t_contact = time.perf_counter() - t_contact
        t_gls = time.perf_counter()
        gls, gls_report = None, None
        if whitens(prep):  # generalized least squares from the row-weighted solution
            gls = refine(self, prep, ModelFit((), _effect_model(kin, (), problem.segments), dq, dq, (), None,
                                              problem.segments))
            gls_report = {"steps": gls.steps, "converged": gls.converged, "chi2_per_dof": gls.chi2_per_dof,
                          "used": gls.holds}
            if not gls.holds:
                warnings.append(
                    f"generalized least squares: not used: the declared sensor noise explains the residual poorly "
                    f"(whitened chi2/dof {gls.chi2_per_dof:.2f} > {GLS_MAX_CHI2_PER_DOF}; soles rocking on a real "
                    "floor, or an effect the model lacks: `legcal-bench diagnose` traces it); the row-weighted fit "
                    "is kept, its posterior from the row weights")
                gls = None
            else:
                dq = gls.fit.x
                if not gls.converged:
                    warnings.append(f"generalized least squares: not converged in {gls.steps} Gauss-Newton steps; "
                                    "the offsets are the last step's (the data may be far from the model: see "
                                    "diagnose)")
        t_gls = time.perf_counter() - t_gls

        t2 = time.perf_counter()
        problem.means_at(dq)
        _, J_fixed = problem.evaluate(dq, "fixed")
        _, J_proj = problem.evaluate(dq, "projected")
        n_data = problem.n_data_rows
        obs = analyze(J_fixed[:n_data], problem.prior_hessian(), robot.joint_names, robot.joint_roles,
                      J_data_projected=J_proj[:n_data])
        warnings += observability_warnings(obs)
        if obs["unobservable_reg"]:
            raise CalibrationError(
                "the offsets are not determined by the data or any prior: " + "; ".join(obs["unobservable_reg"])
                + ". Record several stances with varied postures (hip roll and yaw excitation).")
        signs = kin.pitch_signs()
        if gls is not None:
            post = posterior(gls.Jw[:, :12].T @ gls.Jw[:, :12], robot.joint_names, robot.joint_roles, signs)
        else:
            post = self._posterior(kin, robot, stances, problem, dq, signs)
        if post is not None:
            warnings += uncertainty_warnings(post)
        tilt_response = self._tilt_response(problem, dq, None if gls is None else
                                            lambda segs, x: refine(self, prep, replace(gls.fit, x=x, q_ref=x,
                                                                                       segments=segs)).fit.x)
        warnings += imu_tilt_warnings(tilt_response, stances[0].sensor_model.tilt_bound, signs)
        warnings += bound_warnings(dq, self.bound, robot.joint_names)
        warnings += data_warnings(kin, recordings, dq)
        t_obs = time.perf_counter() - t2
        r_final, _ = problem.evaluate(dq, "projected")
        effects_report = None
        if self.effect_names:
            t3 = time.perf_counter()
            effects_report, dq_eff, eff_warnings = fit_effects(self, prep, dq)
            warnings += eff_warnings
            effects_report["seconds"] = time.perf_counter() - t3
        return CalibrationResult(
            calibrator=self.name, robot=robot.name,
            offsets_rad={n: float(v) for n, v in zip(robot.joint_names, dq if effects_report is None else dq_eff)},
            pitch_sums_rad=pitch_sums(dq if effects_report is None else dq_eff, signs),
            conditioning=obs,
            diagnostics={
                "setting": setting_name, "weights": asdict(w),
                "knee_prior_rad": None if prior is None else prior.tolist(),
                "filter": [asdict(r) for r in reports],
                "segments": {s.name: len(s.frames) for s in problem.segments},
                "frames_used": int(sum(len(s.frames) for s in problem.segments)),
                "cost": float(0.5 * r_final @ r_final),
                "generalized_least_squares": gls_report,
                "history_first_solve": hist1, "history_after_trim": hist2,
                "pitch_signs": signs.tolist(),
                "posterior": post if post is not None else {"note": NO_NOISE},
                "imu_tilt_response": tilt_response.tolist(),
                "contact_check": None if contacts is None else {"stances": [c.to_dict() for c in contacts],
                                                                "dropped": dropped},
                **({"effects": effects_report} if effects_report is not None else {}),
            },
            timing_s={"preprocess": t_pre, "solve": t_solve, "contact_check": t_contact, "gls": t_gls,
                      "observability": t_obs,
                      "total": time.perf_counter() - t0},
            settings=self.settings(),
            warnings=warnings,
        )


class _InterFootProblem:
    """The weighted objective as terms over the offsets block, per contact segment an
    inter-foot term and a flat-ground term (rows in that order), then the priors. With
    an `EffectModel`, every segment's kinematics carries the effects (their blocks
    follow the offsets; `q_ref` are the offsets at which effects evaluate loads) and
    `held` parameters are pinned at zero."""

    def __init__(self, kin: LegKinematics, segments: list[_Prepared], w: InterFootWeights, prior, knees,
                 bound: float, model: EffectModel | None = None, q_ref: np.ndarray | None = None,
                 held: tuple[int, ...] = ()):
        self.kin, self.w, self.prior, self.knees, self.bound = kin, w, prior, knees, bound
        self.model, self.q_ref, self.held = model, q_ref, tuple(held)
        self.n = 12 if model is None else model.n
        if w.row_sigmas is None:
            self.sf = np.sqrt(w.lambda_f) * w.unit_scale * np.ones(6)
            self.sg = np.sqrt(w.lambda_g) * w.unit_scale * np.ones(5)
        else:
            st, sr, sh, sn = w.row_sigmas
            self.sf = np.sqrt(w.lambda_f) * np.array([1 / st] * 3 + [1 / sr] * 3)
            self.sg = np.sqrt(w.lambda_g) * np.array([1 / sh] + [1 / sn] * 4)
        # Prior rows share the residual units (rad, or mrad in the matched setting).
        self.wq = np.sqrt(w.lambda_q) * w.unit_scale * np.array(list(w.w_q) * 2, dtype=float)
        self.sk = np.sqrt(w.lambda_knee) * w.unit_scale
        self.build(segments)

    def build(self, segments: list[_Prepared]) -> None:
        self.segments = segments
        self.feet, terms = [], []
        for seg in segments:
            if self.model is None:
                sk = SegmentKinematics(self.kin, seg.q_enc)
            else:
                sk = EffectSegment(self.model, SegmentData(seg.q_enc, seg.ft, seg.up_B,
                                                           q_ref=seg.q_enc + self.q_ref))
            feet = InterFootTerm(f"{seg.name}/feet", sk, self.sf)
            self.feet.append(feet)
            terms += [feet, FlatGroundTerm(f"{seg.name}/flat", sk, seg.up_B, seg.R_WB, self.sg)]
        if self.w.lambda_q > 0:
            terms.append(TikhonovTerm(self.wq))
        if self.prior is not None and self.w.lambda_knee > 0:
            terms.append(KneePriorTerm(self.knees, self.prior, self.sk))
        blocks = [Block(OFFSETS, 12, bound=self.bound)]
        if self.model is not None:
            blocks += [Block(name, size) for name, size in self.model.blocks]
            if self.held:
                terms.append(HeldParametersTerm(self.model, self.held))
        self.problem = Problem(blocks, terms)

    @property
    def n_data_rows(self) -> int:
        return 11 * sum(len(s.frames) for s in self.segments)

    def prior_hessian(self) -> np.ndarray:
        H = np.diag(self.wq**2)
        if self.prior is not None and self.w.lambda_knee > 0:
            H[self.knees, self.knees] += self.sk**2
        return H

    def means_at(self, x: np.ndarray) -> list:
        values = self.problem.unpack(x) if len(x) > 12 else x
        return [t.update_mean(values) for t in self.feet]

    def evaluate(self, dq: np.ndarray, mode: str):
        """Stacked residual and Jacobian with the segment means re-estimated
        ("projected") or held at their last values ("fixed")."""
        for t in self.feet:
            t.mode = mode
        return self.problem.evaluate(dq)

    def solve(self, dq0: np.ndarray, cal: InterFootCalibrator) -> tuple[np.ndarray, list]:
        lb, ub = -cal.bound * np.ones(12), cal.bound * np.ones(12)
        x0 = np.array(dq0, dtype=float)
        x0[:12] = np.clip(x0[:12], lb + 1e-12, ub - 1e-12)
        history = []
        if cal.solver == "projected":
            for t in self.feet:
                t.mode = "projected"
            # MINPACK's Levenberg-Marquardt is fastest here; the bounds are honoured by
            # re-solving with the bounded trust-region method if they would be active.
            sol = self.problem.solve(x0, method="lm", tol=cal.tol, jac=cal.jacobian,
                                     max_nfev=100 if cal.jacobian == "analytic" else 2000,
                                     on_jacobian=lambda x: history.append(x.tolist()))
            history.append(sol.x.tolist())
            return sol.x, history
        # The paper's alternation: means from the current dq, then a bounded inner solve.
        x = x0
        for _ in range(cal.max_outer):
            self.means_at(x)
            for t in self.feet:
                t.mode = "fixed"
            self.problem.reset_cache()
            fun, jac = self.problem.functions()
            sol = least_squares(fun, x, jac=jac if cal.jacobian == "analytic" else "2-point", bounds=(lb, ub),
                                method="trf", ftol=paper.INNER_FTOL, max_nfev=paper.INNER_MAX_ITERATIONS)
            moved = np.abs(sol.x - x).max()
            x = sol.x
            history.append(x.tolist())
            if moved < 1e-14:
                break
        self.means_at(x)
        for t in self.feet:
            t.mode = "projected"
        return x, history

    def trim(self, dq: np.ndarray, fraction: float) -> None:
        """Drop the `fraction` of frames with the largest weighted residual, per segment."""
        r, _ = self.evaluate(dq, "projected")
        pos = 0
        kept = []
        for seg in self.segments:
            n = len(seg.frames)
            feet = r[pos:pos + 6 * n].reshape(n, 6)
            flat = r[pos + 6 * n:pos + 11 * n].reshape(n, 5)
            pos += 11 * n
            score = (feet**2).sum(1) + (flat**2).sum(1)
            keep = np.sort(np.argsort(score)[: n - int(round(fraction * n))])
            kept.append(_Prepared(seg.name, seg.q_enc[keep], seg.up_B[keep], seg.R_WB[keep], seg.frames[keep],
                                  None if seg.ft is None else seg.ft[keep], seg.recording))
        self.build(kept)


def _noise_weights(prep: Prepared) -> InterFootWeights:
    """Row weights 1/sigma from the recordings' declared noise (the contact check's
    scaling); raises when the recordings declare none."""
    sig = declared_noise(prep)
    return InterFootWeights(1.0, 1.0, 0.0, 0.0, (1,) * 6, row_sigmas=(
        sig["feet_translation"], sig["feet_rotation"], sig["flat_height"], sig["flat_normal"]))


def _effect_model(kin: LegKinematics, names, segments: list[_Prepared]) -> EffectModel:
    model = EffectModel(kin, load_effects(names))
    if any(e.needs_ft for e in model.effects) and any(s.ft is None for s in segments):
        raise CalibrationError(f"effects {[e.name for e in model.effects if e.needs_ft]}: the stance recordings "
                               "have no ankle force/torque wrenches (ft)")
    return model


@dataclass
class ModelFit:
    """A fit of the offsets and a set of effects (`fit_model`): the packed solution `x`
    over `model`'s columns (offsets only: `model` has no effects), the offsets loads are
    evaluated at, the parameters held at zero (confounded), the confound report at the
    start and the segments left after trimming."""

    effects: tuple[str, ...]
    model: EffectModel
    x: np.ndarray
    q_ref: np.ndarray
    held: tuple[str, ...]
    confounds: dict | None
    segments: list


def fit_model(cal: InterFootCalibrator, prep: Prepared, effects=(), segments: list[_Prepared] | None = None,
              dq0: np.ndarray | None = None) -> ModelFit:
    """Fit the offsets with `effects` (names; none: the offsets-only fit) to `segments`
    (default: all of `prep`'s), as `calibrate` does: solve, trim, solve; with effects,
    from the offsets-only estimate `dq0` (fitted here if not given), the confound report
    at the start (parameters the data cannot separate held at zero), loads re-evaluated
    at the new offsets once."""
    segments = prep.segments if segments is None else segments
    kin = prep.kin
    trimmed = segments
    if dq0 is None:
        problem = _InterFootProblem(kin, segments, prep.w, prep.prior, prep.knees, cal.bound)
        dq0, _ = problem.solve(np.zeros(12), cal)
        if cal.trim_fraction > 0:
            problem.trim(dq0, cal.trim_fraction)
            dq0, _ = problem.solve(dq0, cal)
        trimmed = problem.segments
    model = _effect_model(kin, effects, segments)
    if not effects:
        dq0 = np.asarray(dq0, dtype=float)
        return _finish(cal, prep, ModelFit((), model, dq0, dq0, (), None, trimmed))
    x = np.r_[dq0, np.zeros(model.n - 12)]
    confounds = start_confounds(cal, prep, model, dq0, segments)
    held = tuple(model.names.index(h) for h in confounds["held"])
    q_ref = dq0
    for _ in range(2):  # loads at the offsets-only estimate, then at the effects fit's
        problem = _InterFootProblem(kin, segments, prep.w, prep.prior, prep.knees, cal.bound, model, q_ref, held)
        x, _ = problem.solve(x, cal)
        if cal.trim_fraction > 0:
            problem.trim(x, cal.trim_fraction)
            x, _ = problem.solve(x, cal)
        q_ref = x[:12]
    return _finish(cal, prep, ModelFit(tuple(effects), model, x, q_ref, tuple(confounds["held"]), confounds,
                                       problem.segments))


def _finish(cal: InterFootCalibrator, prep: Prepared, fit: ModelFit) -> ModelFit:
    """The "sensor" setting's fit ends with the generalized least squares (`refine`)
    where the declared noise holds (`Refined.holds`); the others are their weighted
    least squares as they stand."""
    if not whitens(prep):
        return fit
    gls = refine(cal, prep, fit)
    return gls.fit if gls.holds else fit


def start_confounds(cal: InterFootCalibrator, prep: Prepared, model, dq0: np.ndarray,
                    segments: list[_Prepared] | None = None) -> dict:
    """The confound report of `model` (an `EffectModel`, or effect names) at the
    offsets-only estimate `dq0`, effects at zero: what these data cannot separate, before
    any fit with the effects."""
    segments = prep.segments if segments is None else segments
    if not hasattr(model, "slices"):
        model = _effect_model(prep.kin, tuple(model), segments)
    x = np.r_[np.asarray(dq0, dtype=float), np.zeros(model.n - 12)]
    start = ModelFit(tuple(e.name for e in model.effects), model, x, np.asarray(dq0, dtype=float), (), None, segments)
    _, J, _ = whitened_rows(cal, prep, start)
    return confound_report(J, model, prep.robot.joint_names)


def fit_effects(cal: InterFootCalibrator, prep: Prepared, dq0: np.ndarray):
    """The fit with the calibrator's model-gap effects (`--with-effects`) from the
    offsets-only estimate `dq0` (`fit_model`), then the posterior of every parameter
    from the noise-whitened data rows and the confound report at the solution.
    Returns (report, offsets, warnings)."""
    robot = prep.robot
    fit = fit_model(cal, prep, cal.effect_names, dq0=dq0)
    model, x = fit.model, fit.x
    _, J, _ = whitened_rows(cal, prep, fit)
    confounds = confound_report(J, model, robot.joint_names)
    held = [model.names.index(h) for h in fit.held]
    free = [i for i in range(model.n) if i not in held]
    H = J[:, free].T @ J[:, free]
    cov = np.full((model.n, model.n), np.nan)
    try:
        cov[np.ix_(free, free)] = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        pass
    std = np.sqrt(np.diag(cov))
    params = {}
    for i in range(12, model.n):
        params[model.names[i]] = {"value": float(x[i]), "std": float(std[i]), "unit": model.units[i],
                                  "held": i in held}
    report = {
        "effects": [e.name for e in model.effects],
        "parameters": params,
        "offsets_only_rad": {n: float(v) for n, v in zip(robot.joint_names, dq0)},
        "offsets_rad": {n: float(v) for n, v in zip(robot.joint_names, x[:12])},
        "offsets_std_rad": {n: float(v) for n, v in zip(robot.joint_names, std[:12])},
        "confounds": confounds, "confounds_at_start": fit.confounds,
        "frames_used": int(sum(len(s.frames) for s in fit.segments)),
    }
    warnings = [f"effects: {line}" for line in confound_lines(confounds)]
    return report, x[:12], warnings


NOISE_TILT = "imu_tilt"  # the effect whose columns carry the IMU's noise


@dataclass
class FrameResiduals:
    """Per frame of a set of segments, at a fit: the raw residual rows r (N, 11) (6
    inter-foot, 5 flat-ground; metres and radians), their Jacobians over `model`'s
    columns with the segment means re-estimated, J (N, 11, n), and held, J_fixed; the
    Jacobian G (N, 11, 12) w.r.t. the joint angles and H (N, 11, 2) w.r.t. the IMU's
    roll and pitch (means held: the noise propagation), and each frame's segment,
    recording, encoder angles and sample index in its recording."""

    model: EffectModel
    r: np.ndarray
    J: np.ndarray
    J_fixed: np.ndarray
    segment: np.ndarray
    recording: np.ndarray
    q_enc: np.ndarray
    time_index: np.ndarray

    @property
    def G(self) -> np.ndarray:
        return self.J_fixed[:, :, :12]

    @property
    def H(self) -> np.ndarray:
        return self.J_fixed[:, :, self.model.slices[NOISE_TILT]][:, :, :2]


def frame_residuals(cal: InterFootCalibrator, prep: Prepared, fit: ModelFit, segments: list[_Prepared],
                    extra=()) -> FrameResiduals:
    """The residuals of `segments` at `fit` and their Jacobians, with the columns of the
    `extra` effects (instances, at zero) appended for score tests."""
    kin = prep.kin
    names = list(fit.effects)
    effects = list(fit.model.effects) + list(extra)
    if NOISE_TILT not in names:
        effects += load_effects([NOISE_TILT])
    model = EffectModel(kin, effects)
    x = np.r_[fit.x, np.zeros(model.n - fit.model.n)]
    unit = InterFootWeights(1.0, 1.0, 0.0, 0.0, (1,) * 6)
    problem = _InterFootProblem(kin, segments, unit, None, [], cal.bound, model, fit.q_ref)
    problem.means_at(x)
    _, J_fix = problem.evaluate(x, "fixed")
    r, J = problem.evaluate(x, "projected")
    rows, Js, Jfs, seg_idx, rec, q, tix = [], [], [], [], [], [], []
    pos = 0
    for i, seg in enumerate(segments):
        n = len(seg.frames)

        def per_frame(a):
            feet = a[pos:pos + 6 * n].reshape(n, 6, *a.shape[1:])
            flat = a[pos + 6 * n:pos + 11 * n].reshape(n, 5, *a.shape[1:])
            return np.concatenate([feet, flat], axis=1)

        rows.append(per_frame(r))
        Jfs.append(per_frame(J_fix))
        Js.append(per_frame(J))
        seg_idx.append(np.full(n, i))
        rec.append(np.array([seg.recording] * n, dtype=object))
        q.append(seg.q_enc)
        tix.append(seg.frames)
        pos += 11 * n
    return FrameResiduals(model, np.concatenate(rows), np.concatenate(Js), np.concatenate(Jfs),
                          np.concatenate(seg_idx), np.concatenate(rec), np.concatenate(q), np.concatenate(tix))


def declared_noise(prep: Prepared,
                   needed_by: str = "the generalized least squares, the posterior and the confound report need it"
                   ) -> dict:
    """The recordings' declared noise (`noise_sigmas`); raises when they declare none,
    saying what `needed_by` it."""
    sig = noise_sigmas(prep.stances[0].sensor_model, prep.kin.dims.leg_length)
    if sig is None:
        raise CalibrationError("the recordings declare no sensor noise (sensor_model.encoder_noise_std, "
                               f"accel_noise_std): {needed_by}")
    return sig


def whitens(prep: Prepared) -> bool:
    """Does this fit end with the generalized least squares (the "sensor" setting on
    recordings that declare their noise)?"""
    return prep.setting_name == "sensor"


def whitened_rows(cal: InterFootCalibrator, prep: Prepared, fit: ModelFit) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(z, Jw, rank): the residual rows of the fit's segments at `fit` and their Jacobian
    over every column of `fit.model` (held ones too, segment means eliminated), each
    frame whitened by its declared covariance (`whitening`)."""
    sig = declared_noise(prep)
    fr = frame_residuals(cal, prep, fit, fit.segments)
    W, rank = whitening(frame_covariances(fr.G, fr.H, sig["encoder"], sig["tilt"]))
    z, Jw = whitened_system(fr.r, fr.J[:, :, :fit.model.n], W)
    return z, Jw, rank


REFINE_MAX_STEPS = 6
REFINE_TOL = 1e-3  # converged when every step is below this fraction of its parameter's posterior std
# The generalized least squares weighs every frame by its declared covariance, which is
# right only while that noise model holds. When the data reject it by far (chi-square
# per degree of freedom above this at the solution: the declared noise explains less
# than 2/3 of the residual's variance), the row-weighted fit is kept: the frames the
# whitening trusts most are those an unmodelled error spoils most. Measured on the full
# suite's datasets (`reports/gls/gls_holds.py`, seeds 0-5, three robots): chi2/dof
# 0.92-1.19 on every weld set, where the row-weighted fit's offsets error is 0.93-1.6x
# the whitened fit's (A2-like 1.1-1.6x); 2.2-129 on every contact set (soles rocking and
# sinking under load), where the whitened fit's is 1.0-2.7x the row-weighted's. A
# variance component shaped like the row weights, its scale fitted to chi2/dof = 1, was
# tried (scratch) and did not close the gap: the contact error is systematic with the
# posture, not noise.
GLS_MAX_CHI2_PER_DOF = 1.5


@dataclass
class Refined:
    """The generalized least-squares fit (`refine`): the fit, the whitened Jacobian over
    every column at it (the posterior's information), the Gauss-Newton steps taken,
    whether they converged and the whitened chi-square per degree of freedom left."""

    fit: ModelFit
    Jw: np.ndarray
    steps: int
    converged: bool
    chi2_per_dof: float

    @property
    def holds(self) -> bool:
        """Does the declared noise explain the residual well enough to weigh the frames by
        it (`GLS_MAX_CHI2_PER_DOF`)?"""
        return self.chi2_per_dof <= GLS_MAX_CHI2_PER_DOF


def refine(cal: InterFootCalibrator, prep: Prepared, fit: ModelFit) -> Refined:
    """Generalized least squares from `fit`: Gauss-Newton steps of the problem whose
    every frame is whitened by its declared covariance (encoder noise through the chain,
    IMU tilt noise; the rows' correlations included) over the fit's free columns, loads
    re-evaluated at each step's offsets. The row-weighted fit that starts it divides each
    row type by one constant sigma, which ignores how the encoder noise's share moves
    with the posture and correlates a frame's rows: unbiased, but (A3-like, clean sets)
    two to three times the offsets error of this fit, which the whitened posterior
    matches. The problem is nearly linear about the start: one step, then a check."""
    held = {fit.model.names.index(h) for h in fit.held}
    free = [i for i in range(fit.model.n) if i not in held]
    x = np.array(fit.x, dtype=float)
    converged = False
    for n_steps in range(1, REFINE_MAX_STEPS + 1):
        z, Jw, rank = whitened_rows(cal, prep, replace(fit, x=x.copy(), q_ref=x[:12].copy()))
        A = Jw[:, free]
        step = np.linalg.lstsq(A, z, rcond=None)[0]
        std = np.sqrt(np.diag(np.linalg.pinv(A.T @ A, hermitian=True)))
        x[free] -= step
        if np.all(np.abs(step) <= REFINE_TOL * std):
            converged = True
            break
    r = z - A @ step
    dof = int(rank.sum()) - 6 * len(fit.segments) - len(free)
    x[:12] = np.clip(x[:12], -cal.bound, cal.bound)
    return Refined(replace(fit, x=x, q_ref=x[:12].copy()), Jw, n_steps, converged, float(r @ r / max(dof, 1)))


CONTACT_CHECKS = ("flag", "drop", "off")


def contact_check(cal: InterFootCalibrator, prep: Prepared, segments: list[_Prepared],
                  dq0: np.ndarray) -> list[StanceContact] | None:
    """The per-stance coplanarity check (`legcal_bench.estimation.coplanarity`) of
    `segments` (a fit's, after trimming), from offsets `dq0`: on the noise-weighted
    problem without priors whatever the calibrator's setting (a prior's pull would show
    as a departure), stances tested against the others; the worst flagged stance is set
    aside and the rest tested again without it, while three or more remain (one bad
    stance would otherwise spoil the others' predictions). None when the recordings
    declare no noise to judge it against or have a single stance."""
    sig = noise_sigmas(prep.stances[0].sensor_model, prep.kin.dims.leg_length)
    if sig is None or len({s.recording for s in segments}) < 2:
        return None
    problem = _InterFootProblem(prep.kin, segments, _noise_weights(prep), None, [], cal.bound)
    dq, _ = problem.solve(dq0, cal)
    final: dict[str, StanceContact] = {}
    while True:
        results = _stance_contacts(cal, prep, problem, dq, sig)
        bad = [c for c in results if c.flagged]
        if not bad or len(results) <= 2:
            final.update({c.recording: c for c in results})
            break
        worst = max(bad, key=lambda c: c.chi2)
        final[worst.recording] = worst
        problem.build([s for s in problem.segments if s.recording != worst.recording])
        dq, _ = problem.solve(dq, cal)
    return [final[n] for n in dict.fromkeys(s.recording for s in segments)]


def _stance_contacts(cal, prep, problem, dq, sig) -> list[StanceContact]:
    segs = problem.segments
    names = list(dict.fromkeys(s.recording for s in segs))
    fit = ModelFit((), _effect_model(prep.kin, (), segs), dq, dq, (), None, segs)
    fr = frame_residuals(cal, prep, fit, segs)
    W, _ = whitening(frame_covariances(fr.G, fr.H, sig["encoder"], sig["tilt"]))
    Jw = W @ fr.J[:, :, :12]
    info = {n: np.einsum("kri,krj->ij", Jw[fr.recording == n], Jw[fr.recording == n]) for n in names}
    total = sum(info.values())
    means = problem.means_at(dq)
    r, J = problem.evaluate(dq, "projected")
    owner = np.concatenate([[s.recording] * 11 * len(s.frames) for s in segs])
    # The offsets' change without each stance: one Gauss-Newton step on the other rows.
    delta = {n: -np.linalg.lstsq(J[owner != n], r[owner != n], rcond=None)[0] for n in names}
    items = []
    for i, s in enumerate(segs):
        m = fr.segment == i
        items.append({"recording": s.recording, "M": means[i], "G": fr.J_fixed[m, :6, :12],
                      "delta": delta[s.recording],
                      "cov": np.linalg.pinv(total - info[s.recording], hermitian=True),
                      "left_tilt": fr.r[m, 7:9].mean(axis=0)})
    return check_stances(items, sig["encoder"])
