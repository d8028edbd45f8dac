"""The paper's inter-foot dispersion calibrator.

Objective over all contact segments sharing one offset vector dq:

  sum_s sum_k [ l_f ||r_feet||^2 + l_g ||r_flat||^2 ] + l_q ||W_q . dq||^2
        + l_knee ||dq_knee - dq_knee_prior||^2

on the framework's stance problem (`legcal_bench.estimation.problem.stance`: one
inter-foot and one flat-ground term per contact segment, a Tikhonov and a knee-prior
term), bounded to |dq| <= 0.08 rad from dq = 0. Offsets the data push against that
bound (gross ones: a re-mounted joint, a multi-turn encoder that lost a count) are
solved for within ±30° (`bound_max`; the same minimum as that bound given by hand;
`gross`: the stage, `StanceProblem.solve_gross`), the bound and the stage in the
result's diagnostics ("bound") and a warning naming the joints. What this method owns:
its settings (the rows' weights and priors), its solver choice, and the order of the steps;
the machinery (generalized least squares, the contact check, the posterior, the model
gap's effects fit) is the framework's (`legcal_bench.estimation`).

Settings: "sensor" (default): each row divided by its declared noise level, then the
generalized least squares where that noise holds; on noise-free data (nothing
declared) the matched weights, which reach the same optimum. "matched": both residual
types at unit weight in mm and mrad. "operating": the paper's weights and priors
(A3's for a hip-pitch-first leg, A2's otherwise); biased on perfect data by its
priors, kept by name for the paper's rows.
Solvers: "projected" (default): C*_s re-estimated inside the residual (variable
projection), with the analytic Jacobian that includes dC*_s/d dq; reaches the optimum.
"alternating": the paper's scheme, C*_s recomputed, then a bounded solve with C*_s
held fixed (inner: <= 200 iterations, ftol 1e-8; outer: <= 15).
Both run the same preprocessing, solve, drop the largest 10 % residual frames per
segment, and solve again from there.
"""

from __future__ import annotations

import time
from dataclasses import asdict, replace

import numpy as np

from legcal_bench import paper
from legcal_bench.calibrators.base import CalibrationResult, Calibrator, number_option, preprocess_options
from legcal_bench.data.recording import Recording
from legcal_bench.errors import CalibrationError
from legcal_bench.estimation.checks.contact import CONTACT_CHECKS, contact_check
from legcal_bench.estimation.checks.datacheck import data_warnings
from legcal_bench.estimation.imu.imu_motion import IMU_WINDOW_S
from legcal_bench.estimation.information.observability import analyze, observability_warnings
from legcal_bench.estimation.information.uncertainty import (NO_NOISE, bound_warnings, imu_tilt_warnings, posterior,
                                                             uncertainty_warnings)
from legcal_bench.estimation.modelgap.effects import load_effects
from legcal_bench.estimation.problem.fit import (GLS_MAX_CHI2_PER_DOF, fit_effects, frame_whitening, noise_posterior,
                                                 offsets_fit, refine, tilt_response)
from legcal_bench.estimation.problem.stance import (GROSS_BOUND_RAD, GROSS_STAGES, JACOBIANS, MATCHED, SENSOR,
                                                    SOLVERS, FitOptions, InterFootWeights, Prepared, StanceProblem,
                                                    bound_diagnostics, gross_warnings, prepare, sensor_weights)
from legcal_bench.estimation.verdict import DOUBTS, HARMLESS, LIMITS, Finding
from legcal_bench.robots.kinematics import pitch_sums
from legcal_bench.robots.legmap import LegMap

# The paper's settings. W_q follows each platform's own joint order.
SETTINGS = {
    "a3_operating": InterFootWeights(**paper.A3_OPERATING),
    "a2_operating": InterFootWeights(**paper.A2_OPERATING),
    "matched": MATCHED,
}
SETTING_NAMES = (SENSOR, "operating", *SETTINGS)


def operating_setting(legmap: LegMap) -> str:
    """A3's operating weights for a hip-pitch-first ordering (geometric decoupling
    possible), A2's for orderings where hip pitch follows roll and yaw."""
    return "a3_operating" if legmap.hip_order[0] == "hip_pitch" else "a2_operating"


class InterFootCalibrator(Calibrator):
    name = "interfoot"

    def __init__(self, setting: str = SENSOR, solver: str = "projected", jacobian: str = "analytic",
                 lambda_f: float | None = None, lambda_g: float | None = None, lambda_q: float | None = None,
                 lambda_knee: float | None = None, knee_prior_shift_rad: float = 0.0,
                 trim_fraction: float = paper.TRIM_FRACTION, bound: float = paper.OFFSET_BOUND_RAD,
                 max_outer: int = paper.OUTER_MAX_ITERATIONS, n_max: int = paper.N_MAX_PER_STANCE, tol: float = 1e-10,
                 imu: str = "compensated", imu_window_s: float = IMU_WINDOW_S, effects: str = "",
                 contact_check: str = "flag", bound_max: float = GROSS_BOUND_RAD, gross: str = "grow"):
        if setting not in SETTING_NAMES:
            raise CalibrationError(f"setting {setting!r}: use one of {', '.join(SETTING_NAMES)}")
        if solver not in SOLVERS:
            raise CalibrationError(f"solver {solver!r}: use projected (default) or alternating (the paper's)")
        if jacobian not in JACOBIANS:
            raise CalibrationError(f"jacobian {jacobian!r}: use analytic or 2-point (forward differences)")
        if contact_check not in CONTACT_CHECKS:
            raise CalibrationError(f"contact_check {contact_check!r}: use flag (default: warn about a stance whose "
                                   "soles were not on one plane), drop (also refit without it) or off")
        if gross not in GROSS_STAGES:
            raise CalibrationError(f"gross {gross!r}: use grow (default: offsets at the bound solved for within "
                                   "bound_max), double (the bound doubled while offsets sit at it), coarse (from a "
                                   "global stage on a subsample) or off")
        self.setting, self.contact_check = setting, contact_check
        self.overrides = {k: number_option(k, v, 0.0) for k, v in dict(
            lambda_f=lambda_f, lambda_g=lambda_g, lambda_q=lambda_q, lambda_knee=lambda_knee).items() if v is not None}
        self.knee_prior_shift_rad = number_option("knee_prior_shift_rad", knee_prior_shift_rad, -0.5, 0.5)
        self.options = FitOptions(
            solver=solver, jacobian=jacobian, tol=number_option("tol", tol, 0.0, 1.0, low_open=True),
            bound=number_option("bound", bound, 0.0, np.pi, low_open=True),
            max_outer=number_option("max_outer", max_outer, 1, integer=True),
            trim_fraction=number_option("trim_fraction", trim_fraction, 0.0, 0.5),
            bound_max=number_option("bound_max", bound_max, 0.0, np.pi, low_open=True), gross=gross)
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
        o = self.options
        return {"setting": self.setting, "solver": o.solver, "jacobian": o.jacobian, **self.overrides,
                "knee_prior_shift_rad": self.knee_prior_shift_rad, "trim_fraction": o.trim_fraction,
                "bound": o.bound, "bound_max": o.bound_max, "gross": o.gross, "max_outer": o.max_outer,
                "preprocess": asdict(self.preprocess),
                "effects": list(self.effect_names), "contact_check": self.contact_check}

    def weights_for(self, legmap: LegMap, recordings: list[Recording] | None = None) -> tuple[str, InterFootWeights]:
        if self.setting == SENSOR:
            return sensor_weights(legmap, recordings or [], **self.overrides)
        name = operating_setting(legmap) if self.setting == "operating" else self.setting
        return name, replace(SETTINGS[name], **self.overrides)

    def prepare(self, robot: LegMap, recordings: list[Recording]) -> Prepared:
        """The preprocessed stance segments, weights and solve options a fit runs on."""
        setting_name, w = self.weights_for(robot, recordings)
        return prepare(robot, recordings, w, setting_name, self.preprocess, self.options, self.knee_prior_shift_rad)

    def calibrate(self, robot: LegMap, recordings: list[Recording]) -> CalibrationResult:
        t0 = time.perf_counter()
        prep = self.prepare(robot, recordings)
        kin, w, stances, prior = prep.kin, prep.w, prep.stances, prep.prior
        setting_name, reports, warnings = prep.setting_name, prep.reports, list(prep.warnings)
        problem = StanceProblem.of(prep)
        t_pre = time.perf_counter() - t0

        # First solve, trim the largest residual frames, solve again.
        t1 = time.perf_counter()
        dq, hist1, hist2 = problem.solve_trimmed(np.zeros(robot.n_joints), self.options)
        # The bound the solve ended with (bound_max for gross offsets) holds for every later step.
        opts = replace(self.options, bound=problem.bound)
        prep = replace(prep, options=opts)
        t_solve = time.perf_counter() - t1
        t_contact = time.perf_counter()
        contacts, dropped = None, []
        # The offsets-only fit's frames whitened at the declared noise, read by the contact
        # check and the generalized least squares' first step alike: computed once.
        start = (frame_whitening(prep, offsets_fit(prep, dq, problem.segments))
                 if prep.whitens and self.contact_check != "off" else None)
        if self.contact_check != "off":
            contacts = contact_check(prep, problem.segments, dq, solved=True, start=start)
            flagged = [c for c in contacts or [] if c.flagged]
            warnings += [Finding(c.text(), DOUBTS) for c in flagged]
            kept = [s for s in problem.segments if s.recording not in {c.recording for c in flagged}]
            if flagged and self.contact_check == "drop" and len({s.recording for s in kept}) < 2:
                warnings.append(Finding(f"contact_check=drop: not dropped: fewer than two stances would be left of "
                                        f"{len(contacts)}; these data do not fit soles on one flat floor (re-record)",
                                        DOUBTS))
            elif flagged and self.contact_check == "drop":
                dropped = [c.recording for c in flagged]
                start = None  # of the stances before the drop
                problem.build(kept)
                dq, hist3 = problem.solve_gross(dq, opts)
                hist2 += hist3
                opts = replace(opts, bound=problem.bound)
                # A fit with effects starts from the same stances.
                prep = replace(prep, segments=[s for s in prep.segments if s.recording not in dropped], options=opts)
                warnings.append(Finding(f"contact_check=drop: fitted without {', '.join(dropped)}", LIMITS))
            elif flagged:
                warnings.append(Finding("contact_check: rerun with --option contact_check=drop to fit without "
                                        f"{', '.join(c.recording for c in flagged)}, or re-record on a flat floor",
                                        HARMLESS))  # advice on the doubt the flagged stance already carries
        t_contact = time.perf_counter() - t_contact
        t_gls = time.perf_counter()
        gls, gls_report = None, None
        if prep.whitens:  # generalized least squares from the row-weighted solution
            gls = refine(prep, offsets_fit(prep, dq, problem.segments), start)
            gls_report = {"steps": gls.steps, "converged": gls.converged, "chi2_per_dof": gls.chi2_per_dof,
                          "used": gls.holds}
            if not gls.holds:
                warnings.append(Finding(
                    f"generalized least squares: not used: the declared sensor noise explains the residual poorly "
                    f"(whitened chi2/dof {gls.chi2_per_dof:.2f} > {GLS_MAX_CHI2_PER_DOF}; soles rocking on a real "
                    "floor, or an effect the model lacks: `legcal-bench diagnose` traces it); the row-weighted fit "
                    "is kept, its posterior from the row weights", DOUBTS))
                gls = None
            else:
                dq = gls.fit.x
                if not gls.converged:
                    warnings.append(Finding(f"generalized least squares: not converged in {gls.steps} Gauss-Newton "
                                            "steps; the offsets are the last step's (the data may be far from the "
                                            "model: see diagnose)", DOUBTS))
        t_gls = time.perf_counter() - t_gls

        t2 = time.perf_counter()
        r_final, J_fixed, J_proj = problem.evaluate_both(dq)
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
            Jq = gls.Jw[:, :robot.n_joints]
            post = posterior(Jq.T @ Jq, robot.joint_names, robot.joint_roles, signs)
        else:
            post = noise_posterior(prep, problem, dq, signs)
        if post is not None:
            warnings += uncertainty_warnings(post)
        tilt = tilt_response(prep, problem, dq, gls)
        warnings += imu_tilt_warnings(tilt, stances[0].sensor_model.tilt_bound, signs)
        warnings += bound_warnings(dq, opts.bound, robot.joint_names)
        warnings += gross_warnings(problem.gross, dq, opts.bound, robot.joint_names)
        warnings += data_warnings(kin, recordings, dq)
        t_obs = time.perf_counter() - t2
        effects_report = None
        if self.effect_names:
            t3 = time.perf_counter()
            effects_report, dq_eff, eff_warnings = fit_effects(prep, self.effect_names, dq)
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
                "bound": bound_diagnostics(self.options.bound, opts.bound, problem.gross),
                "pitch_signs": signs.tolist(),
                "posterior": post if post is not None else {"note": NO_NOISE},
                "imu_tilt_response": tilt.tolist(),
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
