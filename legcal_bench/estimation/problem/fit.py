"""The framework's fits on the stance problem (`legcal_bench.estimation.problem.stance`):
the offsets with or without model-gap effects, the generalized least squares, each
frame's residual and Jacobians, the posterior and the IMU-tilt response. Every
calibrator's result goes through the same: the model gap starts from its offsets, the
contact check and the posterior judge them with the same noise model."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from legcal_bench.errors import CalibrationError
from legcal_bench.estimation.information.noise import noise_sigmas
from legcal_bench.estimation.information.uncertainty import posterior
from legcal_bench.estimation.information.whitening import frame_covariances, whitened_system, whitening
from legcal_bench.estimation.modelgap.confounds import confound_lines, confound_report
from legcal_bench.estimation.modelgap.effects import EffectModel, load_effects
from legcal_bench.estimation.problem.stance import (MATCHED, InterFootWeights, Prepared, Segment, StanceProblem,
                                                    noise_weights)
from legcal_bench.estimation.verdict import LIMITS, classed
from legcal_bench.robots.kinematics import LegKinematics

NOISE_TILT = "imu_tilt"  # the effect whose columns carry the IMU's noise


def effect_model(kin: LegKinematics, names, segments: list[Segment]) -> EffectModel:
    """The offsets and the effects `names`; refused when an effect needs ankle wrenches
    the segments lack."""
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


def offsets_fit(prep: Prepared, dq: np.ndarray, segments: list[Segment] | None = None) -> ModelFit:
    """Offsets `dq` as a fit without effects over `segments` (default: `prep`'s)."""
    segments = prep.segments if segments is None else segments
    dq = np.asarray(dq, dtype=float)
    return ModelFit((), effect_model(prep.kin, (), segments), dq, dq, (), None, segments)


def fit_model(prep: Prepared, effects=(), segments: list[Segment] | None = None, dq0: np.ndarray | None = None,
              start: np.ndarray | None = None) -> ModelFit:
    """Fit the offsets with `effects` (names; none: the offsets-only fit) to `segments`
    (default: all of `prep`'s): solve, trim, solve; with effects, from the offsets-only
    estimate `dq0` (fitted here if not given), the confound report at the start
    (parameters the data cannot separate held at zero), loads re-evaluated at the new
    offsets once. The offsets-only solve starts from `start` (any calibrator's offsets;
    default zero)."""
    segments = prep.segments if segments is None else segments
    opts = prep.options
    trimmed = segments
    if dq0 is None:
        problem = StanceProblem.of(prep, segments)
        dq0, _, _ = problem.solve_trimmed(np.zeros(problem.n_offsets) if start is None else np.asarray(start, float),
                                          opts)
        trimmed = problem.segments
    model = effect_model(prep.kin, effects, segments)
    if not effects:
        dq0 = np.asarray(dq0, dtype=float)
        return _finish(prep, ModelFit((), model, dq0, dq0, (), None, trimmed))
    x = np.r_[dq0, np.zeros(model.n - model.n_offsets)]
    confounds = start_confounds(prep, model, dq0, segments)
    held = tuple(model.names.index(h) for h in confounds["held"])
    q_ref = dq0
    # Loads at the offsets-only estimate, then at the effects fit's: only an effect that
    # reads loads (the ankle wrenches through the chain, `needs_ft`) sees `q_ref`; for the
    # others a second pass would solve the same problem again from its own optimum.
    for _ in range(2 if any(e.needs_ft for e in model.effects) else 1):
        problem = StanceProblem.of(prep, segments, model=model, q_ref=q_ref, held=held)
        x, _, _ = problem.solve_trimmed(x, opts)
        q_ref = x[:model.n_offsets]
    return _finish(prep, ModelFit(tuple(effects), model, x, q_ref, tuple(confounds["held"]), confounds,
                                  problem.segments))


def _finish(prep: Prepared, fit: ModelFit) -> ModelFit:
    """The "sensor" setting's fit ends with the generalized least squares (`refine`)
    where the declared noise holds (`Refined.holds`); the others are their weighted
    least squares as they stand."""
    if not prep.whitens:
        return fit
    gls = refine(prep, fit)
    return gls.fit if gls.holds else fit


def start_confounds(prep: Prepared, model, dq0: np.ndarray, segments: list[Segment] | None = None) -> dict:
    """The confound report of `model` (an `EffectModel`, or effect names) at the
    offsets-only estimate `dq0`, effects at zero: what these data cannot separate, before
    any fit with the effects."""
    segments = prep.segments if segments is None else segments
    if not hasattr(model, "slices"):
        model = effect_model(prep.kin, tuple(model), segments)
    x = np.r_[np.asarray(dq0, dtype=float), np.zeros(model.n - model.n_offsets)]
    start = ModelFit(tuple(e.name for e in model.effects), model, x, np.asarray(dq0, dtype=float), (), None, segments)
    _, J, _ = whitened_rows(prep, start)
    return confound_report(J, model, prep.robot.joint_names)


def fit_effects(prep: Prepared, effects, dq0: np.ndarray):
    """The fit with model-gap `effects` from the offsets-only estimate `dq0`
    (`fit_model`), then the posterior of every parameter from the noise-whitened data
    rows and the confound report at the solution. Returns (report, offsets, warnings)."""
    robot = prep.robot
    fit = fit_model(prep, effects, dq0=dq0)
    model, x = fit.model, fit.x
    _, J, _ = whitened_rows(prep, fit)
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
    n_q = model.n_offsets
    for i in range(n_q, model.n):
        params[model.names[i]] = {"value": float(x[i]), "std": float(std[i]), "unit": model.units[i],
                                  "held": i in held}
    report = {
        "effects": [e.name for e in model.effects],
        "parameters": params,
        "offsets_only_rad": {n: float(v) for n, v in zip(robot.joint_names, dq0)},
        "offsets_rad": {n: float(v) for n, v in zip(robot.joint_names, x[:n_q])},
        "offsets_std_rad": {n: float(v) for n, v in zip(robot.joint_names, std[:n_q])},
        "confounds": confounds, "confounds_at_start": fit.confounds,
        "frames_used": int(sum(len(s.frames) for s in fit.segments)),
    }
    warnings = classed([f"effects: {line}" for line in confound_lines(confounds)], LIMITS)
    return report, x[:n_q], warnings


@dataclass
class FrameResiduals:
    """Per frame of a set of segments, at a fit: the raw residual rows r (N, 11) (6
    inter-foot, 5 flat-ground; metres and radians), their Jacobians over `model`'s
    columns with the segment means re-estimated, J (N, 11, n), and held, J_fixed; the
    Jacobian G (N, 11, n) w.r.t. the n joint angles and H (N, 11, 2) w.r.t. the IMU's
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
        return self.J_fixed[:, :, :self.model.n_offsets]

    @property
    def H(self) -> np.ndarray:
        return self.J_fixed[:, :, self.model.slices[NOISE_TILT]][:, :, :2]


def frame_residuals(prep: Prepared, fit: ModelFit, segments: list[Segment], extra=()) -> FrameResiduals:
    """The residuals of `segments` at `fit` and their Jacobians, with the columns of the
    `extra` effects (instances, at zero) appended for score tests."""
    kin = prep.kin
    effects = list(fit.model.effects) + list(extra)
    if NOISE_TILT not in fit.effects:
        effects += load_effects([NOISE_TILT])
    model = EffectModel(kin, effects)
    x = np.r_[fit.x, np.zeros(model.n - fit.model.n)]
    unit = InterFootWeights(1.0, 1.0, 0.0, 0.0, MATCHED.w_q)
    problem = StanceProblem(kin, segments, unit, None, [], prep.options.bound, model, fit.q_ref)
    r, J_fix, J = problem.evaluate_both(x)
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
    sig = noise_sigmas(prep.stances[0].sensor_model, prep.kin.dims.leg_length, prep.robot.leg_joints)
    if sig is None:
        raise CalibrationError("the recordings declare no sensor noise (sensor_model.encoder_noise_std, "
                               f"accel_noise_std): {needed_by}")
    return sig


def whitened_rows(prep: Prepared, fit: ModelFit) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(z, Jw, rank): the residual rows of the fit's segments at `fit` and their Jacobian
    over every column of `fit.model` (held ones too, segment means eliminated), each
    frame whitened by its declared covariance (`whitening`)."""
    z, Jw, rank = _whitened(prep, fit)
    return z, Jw[:, :fit.model.n], rank


@dataclass(frozen=True)
class FrameWhitening:
    """A fit's frame residuals at its estimate and each frame's whitening at the declared
    noise (`frame_whitening`): the offsets-only fit's are read by the contact check and by
    the generalized least squares' first step alike, so a calibration computes them once."""

    frames: FrameResiduals
    W: np.ndarray  # (N, 11, 11)
    rank: np.ndarray  # (N,)


def frame_whitening(prep: Prepared, fit: ModelFit) -> FrameWhitening:
    """The frame residuals of `fit`'s segments at `fit` and their whitening by the
    declared covariance (`whitening` of `frame_covariances`)."""
    sig = declared_noise(prep)
    fr = frame_residuals(prep, fit, fit.segments)
    W, rank = whitening(frame_covariances(fr.G, fr.H, sig["encoder"], sig["tilt"]))
    return FrameWhitening(fr, W, rank)


def _whitened(prep: Prepared, fit: ModelFit, at: FrameWhitening | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`whitened_rows` with the IMU tilt's two columns last (`NOISE_TILT`, segment means
    eliminated): how the rows move with a fixed error of the IMU's vertical. `at`: the
    fit's `frame_whitening`, if in hand."""
    fw = frame_whitening(prep, fit) if at is None else at
    fr = fw.frames
    tilt = fr.J[:, :, fr.model.slices[NOISE_TILT]][:, :, :2]
    z, Jw = whitened_system(fr.r, np.concatenate([fr.J[:, :, :fit.model.n], tilt], axis=2), fw.W)
    return z, Jw, fw.rank


REFINE_MAX_STEPS = 6
REFINE_TOL = 1e-3  # converged when every step is below this fraction of its parameter's posterior std
# The generalized least squares weighs every frame by its declared covariance, which is
# right only while that noise model holds. When the data reject it by far (chi-square
# per degree of freedom above this at the solution: the declared noise explains less
# than 2/3 of the residual's variance), the row-weighted fit is kept: the frames the
# whitening trusts most are those an unmodelled error spoils most. Measured on the full
# suite's datasets (`reports/gls/gls_holds.md`, seeds 0-5, three robots): chi2/dof
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
    tilt: np.ndarray | None = None  # (rows, 2) the whitened rows' change per rad of IMU tilt (x, y)

    @property
    def holds(self) -> bool:
        """Does the declared noise explain the residual well enough to weigh the frames by
        it (`GLS_MAX_CHI2_PER_DOF`)?"""
        return self.chi2_per_dof <= GLS_MAX_CHI2_PER_DOF


def refine(prep: Prepared, fit: ModelFit, start: FrameWhitening | None = None) -> Refined:
    """Generalized least squares from `fit`: Gauss-Newton steps of the problem whose
    every frame is whitened by its declared covariance (encoder noise through the chain,
    IMU tilt noise; the rows' correlations included) over the fit's free columns, loads
    re-evaluated at each step's offsets. The row-weighted fit that starts it divides each
    row type by one constant sigma, which ignores how the encoder noise's share moves
    with the posture and correlates a frame's rows: unbiased, but (A3-like, clean sets)
    two to three times the offsets error of this fit, which the whitened posterior
    matches. The problem is nearly linear about the start: one step, then a check.
    `start`: `fit`'s own `frame_whitening`, if in hand (the first step's)."""
    held = {fit.model.names.index(h) for h in fit.held}
    free = [i for i in range(fit.model.n) if i not in held]
    x = np.array(fit.x, dtype=float)
    n_q = fit.model.n_offsets
    converged = False
    for n_steps in range(1, REFINE_MAX_STEPS + 1):
        z, Jw_all, rank = _whitened(prep, replace(fit, x=x.copy(), q_ref=x[:n_q].copy()),
                                    start if n_steps == 1 else None)
        Jw = Jw_all[:, :fit.model.n]
        A = Jw[:, free]
        step = np.linalg.lstsq(A, z, rcond=None)[0]
        std = np.sqrt(np.diag(np.linalg.pinv(A.T @ A, hermitian=True)))
        x[free] -= step
        if np.all(np.abs(step) <= REFINE_TOL * std):
            converged = True
            break
    r = z - A @ step
    dof = int(rank.sum()) - 6 * len(fit.segments) - len(free)
    bound = prep.options.bound
    x[:n_q] = np.clip(x[:n_q], -bound, bound)
    return Refined(replace(fit, x=x, q_ref=x[:n_q].copy()), Jw, n_steps, converged, float(r @ r / max(dof, 1)),
                   Jw_all[:, fit.model.n:])


def noise_posterior(prep: Prepared, problem: StanceProblem, dq: np.ndarray, signs: np.ndarray) -> dict | None:
    """Posterior standard deviations: `problem`'s frames' data rows, each divided by its
    declared noise level, C*_s eliminated (the projected Jacobian) at `dq`; None when
    the recordings declare no noise."""
    sig = noise_sigmas(prep.stances[0].sensor_model, prep.kin.dims.leg_length, prep.robot.leg_joints)
    if sig is None:
        return None
    whitened = StanceProblem(prep.kin, problem.segments, noise_weights(sig), None, [], problem.bound)
    whitened.means_at(dq)
    _, J = whitened.evaluate(dq, "projected")
    J = J[:whitened.n_data_rows]
    return posterior(J.T @ J, prep.robot.joint_names, prep.robot.joint_roles, signs)


def tilt_response(prep: Prepared, problem: StanceProblem, dq: np.ndarray, gls: Refined | None = None) -> np.ndarray:
    """(n, 2) how the estimate moves per rad of a fixed error of the IMU's vertical
    about the pelvis x and y axes (every up vector rotated alike): to first order, the
    Gauss-Newton step of the fit's own problem against the rows' change with the tilt,
    -(J^T J)^-1 J^T T, T the `imu_tilt` effect's columns at zero (segment means
    eliminated). With `gls` (the generalized least squares) its whitened rows; else
    `problem`'s row-weighted ones at `dq`, priors included. The response is linear at the
    sizes it is used for (a declared tilt bound of a few mrad).

    The effect's columns turn the vertical about the IMU's own x and y axes (a mounting
    tilt); the response is returned per rad about the pelvis's, `to_pelvis` (an IMU
    yawed on its mount, or turned by a waist above it, has the two apart: without the
    turn, tests/estimation/test_imu_yaw.py's 0.5 rad yaw scored 0.0345 deg IMU-removed
    against 0.0016 deg aligned)."""
    # A tilt b about the pelvis x, y is phi = R_BI^T [b, 0] about the IMU's axes (its z
    # part turns about the IMU's near-vertical z: no change of the vertical to first order).
    to_pelvis = prep.kin.R_BI.T[:2, :2]
    if gls is not None:
        held = {gls.fit.model.names.index(h) for h in gls.fit.held}
        free = [i for i in range(gls.fit.model.n) if i not in held]
        step = np.linalg.lstsq(gls.Jw[:, free], gls.tilt, rcond=None)[0]
        return -step[:gls.fit.model.n_offsets] @ to_pelvis
    model = effect_model(prep.kin, [NOISE_TILT], problem.segments)
    with_tilt = StanceProblem(prep.kin, problem.segments, problem.w, problem.prior, problem.knees, problem.bound,
                              model, np.asarray(dq, dtype=float))
    x = np.r_[dq, np.zeros(model.n - model.n_offsets)]
    with_tilt.means_at(x)
    _, J = with_tilt.evaluate(x, "projected")
    tilt = J[:, model.slices[NOISE_TILT]][:, :2]
    return -np.linalg.lstsq(J[:, :model.n_offsets], tilt, rcond=None)[0] @ to_pelvis
