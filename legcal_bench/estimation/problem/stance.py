"""The contact-constrained problem of static double support, as the framework fits it.

Per contact segment (a stretch of one stance recording where the feet stayed put) an
inter-foot term (the left-to-right foot transform from forward kinematics against the
segment's Fréchet mean) and a flat-ground term (both soles level in the IMU's
vertical), over one shared offsets block; optionally a Tikhonov and a knee-prior term,
and the blocks of model-gap effects. Any calibrator's offsets can start it; the
framework's model gap, contact check and generalized least squares run on it.

- `InterFootWeights`: the rows' weights (per residual type, or 1/sigma per row);
  `MATCHED` unit weights, `sensor_weights` the declared noise's;
- `Segment`, `segments_of`: the frames a fit uses, with their IMU vertical;
- `FitOptions`: solver, Jacobian, tolerance, bound (and the wider one gross offsets are
  solved for within), trimming;
- `Prepared`, `prepare`: the training recordings ready to fit;
- `StanceProblem`: the weighted objective, solved by variable projection (the segment
  means re-estimated inside the residual) or by the paper's alternation.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import least_squares

from legcal_bench import paper
from legcal_bench.data.recording import Recording
from legcal_bench.errors import CalibrationError
from legcal_bench.estimation.imu.levelling import levelling_rotations, up_in_base
from legcal_bench.estimation.information.noise import noise_sigmas
from legcal_bench.estimation.information.uncertainty import BOUND_FRACTION, at_bound_mask
from legcal_bench.estimation.modelgap.effects import EffectModel, EffectSegment, SegmentData
from legcal_bench.estimation.problem.preprocess import PreprocessConfig, filter_warnings, select_frames
from legcal_bench.estimation.problem.problem import Block, Problem
from legcal_bench.estimation.problem.smoothing import smooth_wrenches
from legcal_bench.estimation.problem.terms import (OFFSETS, FlatGroundTerm, HeldParametersTerm, InterFootTerm,
                                                   KneePriorTerm, SegmentKinematics, TikhonovTerm)
from legcal_bench.estimation.verdict import HARMLESS, LIMITS, Finding
from legcal_bench.robots.design import HIP_ROLES, LEG_ROLES
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots.legmap import LegMap

SENSOR = "sensor"  # the setting whose rows are whitened by the declared noise (then the GLS)
SOLVERS = ("projected", "alternating")
JACOBIANS = ("analytic", "2-point")
# Gross offsets (a re-mounted joint, a multi-turn encoder that lost a count): offsets the
# data push against the bound are solved for at GROSS_BOUND_RAD (`StanceProblem.solve_gross`);
# the result states the first doubling (x GROW_FACTOR) of the bound that holds them.
GROSS_BOUND_RAD = float(np.deg2rad(30.0))
GROW_FACTOR = 2.0
# "grow": the solve at the widest bound from the same start (with the projected solver,
# run first: its answer inside the first bound is that bound's own); "double": the bound
# doubled and solved again until no offset sits at it; "coarse": the solve at the widest
# bound started from a global stage on every COARSE_STRIDE-th frame from zero; "off": the
# bound stays. "double" and "coarse" were measured against "grow" and are slower.
GROSS_STAGES = ("grow", "double", "coarse", "off")
COARSE_STRIDE = 8


@dataclass(frozen=True)
class InterFootWeights:
    lambda_f: float
    lambda_g: float
    lambda_q: float
    lambda_knee: float
    # Per leg, in the platform's joint order (its three hips, knee, ankle pitch, ankle roll;
    # left leg, mirrored to the right): read by role (`joint_weights`).
    w_q: tuple[float, ...]
    unit_scale: float = 1.0  # residual units: 1 = metres and radians, 1000 = mm and mrad
    # Per-row 1/sigma instead of unit_scale (the "sensor" setting): feet translation,
    # feet rotation, flat height, flat normal.
    row_sigmas: tuple[float, float, float, float] | None = None


# Both residual types at unit weight in mm and mrad, no priors.
MATCHED = InterFootWeights(1.0, 1.0, 0.0, 0.0, (1,) * len(LEG_ROLES), unit_scale=paper.MATCHED_UNIT_SCALE)


def joint_weights(w_q, legmap: LegMap) -> np.ndarray:
    """(n,) the per-leg weights `w_q` (the platform's joint order: its hips in the leg
    map's hip order, then knee, ankle pitch, ankle roll) on each leg joint, by role; a
    role the robot lacks has no joint and its weight goes unused."""
    order = legmap.hip_order + tuple(r for r in LEG_ROLES if r not in HIP_ROLES)
    by_role = dict(zip(order, w_q))
    missing = [r for r in dict.fromkeys(legmap.joint_roles) if r not in by_role]
    if missing:
        raise CalibrationError(f"w_q {tuple(w_q)}: no weight for the roles {missing} (give one per leg joint, "
                               f"in the order {', '.join(order)})")
    return np.array([by_role[r] for r in legmap.joint_roles], dtype=float)


def noise_weights(sig: dict) -> InterFootWeights:
    """Each row divided by its declared noise level (`noise_sigmas`), no priors."""
    return InterFootWeights(1.0, 1.0, 0.0, 0.0, MATCHED.w_q, row_sigmas=(
        sig["feet_translation"], sig["feet_rotation"], sig["flat_height"], sig["flat_normal"]))


def sensor_weights(legmap: LegMap, recordings: list[Recording], **overrides) -> tuple[str, InterFootWeights]:
    """("sensor", the declared noise's weights), or ("matched", `MATCHED`) for recordings
    that declare no noise (noise-free data: any weighting reaches the same optimum)."""
    sig = (noise_sigmas(recordings[0].sensor_model, LegKinematics(legmap).dims.leg_length, legmap.leg_joints)
           if recordings else None)
    if sig is None:
        return "matched", replace(MATCHED, **overrides)
    return SENSOR, replace(noise_weights(sig), **overrides)


def gross_report(stage: str, first: float, bound: float, dq: np.ndarray, names: list[str], solves: int) -> dict:
    """What a gross stage did: the `stage`, the `first` bound and the `bound` the solve
    ended with, the first doubling (x `GROW_FACTOR`) of the first bound that holds the
    offsets `dq`, the joints at or beyond the first bound, the extra solves."""
    holds, top = first, float(np.abs(dq).max())
    while top >= BOUND_FRACTION * holds and holds < bound:
        holds = min(GROW_FACTOR * holds, bound)
    return {"stage": stage, "first_bound_rad": first, "bound_rad": bound, "holds_rad": holds,
            "beyond_first_bound": [n for n, hit in zip(names, at_bound_mask(dq, first)) if hit],
            "solves": solves}


def bound_diagnostics(first: float, final: float, gross: dict | None) -> dict:
    """A result's record of its bound: the first, the final, and what the gross stage did
    (`gross_report`; none: stage None)."""
    keys = ("stage", "holds_rad", "beyond_first_bound", "solves")
    return {"first_rad": first, "final_rad": final,
            **({"stage": None, "holds_rad": first, "beyond_first_bound": [], "solves": 0} if gross is None else
               {k: gross[k] for k in keys})}


def at_bound(dq: np.ndarray, bound: float) -> bool:
    """Does an offset sit at `bound` (within `BOUND_FRACTION` of it)?"""
    return bool(at_bound_mask(dq, bound).any())


def gross_warnings(gross: dict | None, dq: np.ndarray, bound: float, names: list[str]) -> list[str]:
    """Information (not an alarm) when the gross stage ran (`StanceProblem.gross`) and the
    offsets ended inside its `bound`: which joints were at or beyond the first bound, by
    how much, and the likely cause. Offsets still at `bound` are the bound warning's
    (`bound_warnings`)."""
    if gross is None or at_bound(dq[:len(names)], bound):
        return []
    first = gross["first_bound_rad"]
    beyond = ", ".join(f"{n} {np.rad2deg(v):+.2f}°" for n, v, hit in zip(names, dq, at_bound_mask(dq[:len(names)], first))
                       if hit)
    first_name = "the paper's bound" if first == paper.OFFSET_BOUND_RAD else "the bound"
    holds = (f"; ±{np.rad2deg(gross['holds_rad']):.2f}° would hold them" if gross["holds_rad"] < bound else "")
    return [Finding(f"gross offsets: {beyond} at or beyond {first_name} ±{np.rad2deg(first):.2f}°: solved within "
                    f"±{np.rad2deg(bound):.2f}° ({gross['stage']} stage{holds}); estimates, not clipped, the same "
                    "as a solve given that bound by hand. "
                    "Offsets this large are most likely a re-mounted joint or a multi-turn encoder that lost a "
                    "count: check those joints' mounting and encoder zero", HARMLESS)]


@dataclass(frozen=True)
class FitOptions:
    """How the problem is solved: `solver` "projected" (variable projection, reaches the
    optimum) or "alternating" (the paper's: means, then a bounded inner solve with them
    held); the Jacobian analytic or forward differences; |offset| <= `bound`, offsets
    that sit at it solved for within `bound_max` by the `gross` stage
    (`StanceProblem.solve_gross`); after the first solve the `trim_fraction` of each segment's frames with the largest
    residual is dropped and the problem solved again."""

    solver: str = "projected"
    jacobian: str = "analytic"
    tol: float = 1e-10
    bound: float = paper.OFFSET_BOUND_RAD
    max_outer: int = paper.OUTER_MAX_ITERATIONS
    trim_fraction: float = paper.TRIM_FRACTION
    bound_max: float = GROSS_BOUND_RAD
    gross: str = "grow"


@dataclass
class Segment:
    """One contact segment's frames: encoder angles, the IMU's up vector in the pelvis
    frame and the levelling rotations, the frames' sample indices, the ankle wrenches
    (N, 2, 6) if recorded, the stance recording it comes from and the frames' timestamps
    (s, increasing; the frames the selection kept, so not always consecutive samples)."""

    name: str
    q_enc: np.ndarray
    up_B: np.ndarray
    R_WB: np.ndarray
    frames: np.ndarray
    ft: np.ndarray | None = None
    recording: str = ""
    time: np.ndarray | None = None

    def subset(self, keep: np.ndarray) -> "Segment":
        return Segment(self.name, self.q_enc[keep], self.up_B[keep], self.R_WB[keep], self.frames[keep],
                       None if self.ft is None else self.ft[keep], self.recording,
                       None if self.time is None else self.time[keep])


def segments_of(kin: LegKinematics, recordings: list[Recording],
                preprocess: PreprocessConfig) -> tuple[list[Segment], list]:
    """Each recording's contact segments after the frame selection (`select_frames`)
    with its IMU vertical; (segments, filter reports)."""
    segments, reports = [], []
    for r in recordings:
        segs, rep = select_frames(kin, r.name, r.time, r.q_enc, r.imu_acc, r.imu_gyro, preprocess, r.motion)
        reports.append(rep)
        for s in segs:
            up = up_in_base(s.imu_acc, kin.R_BI)
            ft = None
            if r.ft is not None:  # smoothed over the segment's span: noisy loads bias a compliance low
                a, b = int(s.frames.min()), int(s.frames.max()) + 1
                ft = smooth_wrenches(r.time[a:b], r.ft[a:b])[s.frames - a]
            segments.append(Segment(s.name, s.q_enc, up, levelling_rotations(up), s.frames, ft, r.name,
                                    np.asarray(r.time, dtype=float)[s.frames]))
    return segments, reports


@dataclass
class Prepared:
    """Training recordings ready to fit: the stances' segments, the weights and the
    setting they came from, the knee prior (or None), the filter reports, the warnings
    so far and the solve options."""

    robot: LegMap
    kin: LegKinematics
    stances: list[Recording]
    segments: list[Segment]
    w: InterFootWeights
    setting_name: str
    prior: np.ndarray | None
    knees: list[int]
    reports: list
    warnings: list[str]
    options: FitOptions = field(default_factory=FitOptions)

    @property
    def whitens(self) -> bool:
        """Does a fit end with the generalized least squares (rows weighed by the
        declared noise)?"""
        return self.setting_name == SENSOR


def prepare(robot: LegMap, recordings: list[Recording], w: InterFootWeights, setting_name: str,
            preprocess: PreprocessConfig | None = None, options: FitOptions | None = None,
            knee_prior_shift_rad: float = 0.0) -> Prepared:
    """The stance recordings' segments with weights `w`; the knee prior (when
    `w.lambda_knee` > 0) from the straight-leg standing recordings."""
    preprocess = preprocess or PreprocessConfig()
    kin = LegKinematics(robot)
    warnings: list[str] = []
    for r in recordings:
        if r.joint_names != robot.joint_names:
            raise CalibrationError(f"recording {r.name}: joint names do not match robot {robot.name}")
    stances = [r for r in recordings if r.kind == "stance"]
    if not stances:
        raise CalibrationError("no stance recordings (kind 'stance'): record at least one static "
                               "double-support stance, better four (I-IV)")
    segments, reports = segments_of(kin, stances, preprocess)
    warnings += filter_warnings(reports)
    if not segments:
        raise CalibrationError("no usable frames in any stance after filtering: "
                               + "; ".join(f"{r.name}: {r.text()}" for r in reports))
    knees = [i for i, role in enumerate(robot.joint_roles) if role == "knee"]
    prior = None
    standing = [r for r in recordings if r.kind == "standing"]
    if w.lambda_knee > 0:
        if standing:
            q_knee = np.concatenate([r.q_enc[:, knees] for r in standing]).mean(axis=0)
            prior = robot.knee_straight_rad - q_knee + knee_prior_shift_rad
        else:
            warnings.append(Finding("no straight-leg standing recording: knee prior disabled (lambda_knee -> 0)",
                                    LIMITS))
            w = replace(w, lambda_knee=0.0)
    return Prepared(robot, kin, stances, segments, w, setting_name, prior, knees, reports, warnings,
                    options or FitOptions())


def prepare_sensor(robot: LegMap, recordings: list[Recording], preprocess: PreprocessConfig | None = None,
                   options: FitOptions | None = None) -> Prepared:
    """`prepare` with the declared noise's weights (`sensor_weights`): the framework's
    own fit, whatever calibrator made the offsets it starts from."""
    name, w = sensor_weights(robot, recordings)
    return prepare(robot, recordings, w, name, preprocess, options)


class StanceProblem:
    """The weighted objective as terms over the offsets block, per contact segment an
    inter-foot term and a flat-ground term (rows in that order), then the priors. With
    an `EffectModel`, every segment's kinematics carries the effects (their blocks
    follow the offsets; `q_ref` are the offsets at which effects evaluate loads) and
    `held` parameters are pinned at zero."""

    def __init__(self, kin: LegKinematics, segments: list[Segment], w: InterFootWeights, prior=None, knees=(),
                 bound: float = paper.OFFSET_BOUND_RAD, model: EffectModel | None = None,
                 q_ref: np.ndarray | None = None, held: tuple[int, ...] = ()):
        self.kin, self.w, self.prior, self.knees, self.bound = kin, w, prior, list(knees), bound
        self.model, self.q_ref, self.held = model, q_ref, tuple(held)
        self.gross: dict | None = None  # what the gross stage did, if it ran (`solve_gross`)
        self.n_offsets = kin.legmap.n_joints
        self.n = self.n_offsets if model is None else model.n
        if w.row_sigmas is None:
            self.sf = np.sqrt(w.lambda_f) * w.unit_scale * np.ones(6)
            self.sg = np.sqrt(w.lambda_g) * w.unit_scale * np.ones(5)
        else:
            st, sr, sh, sn = w.row_sigmas
            self.sf = np.sqrt(w.lambda_f) * np.array([1 / st] * 3 + [1 / sr] * 3)
            self.sg = np.sqrt(w.lambda_g) * np.array([1 / sh] + [1 / sn] * 4)
        # Prior rows share the residual units (rad, or mrad in the matched setting).
        self.wq = np.sqrt(w.lambda_q) * w.unit_scale * joint_weights(w.w_q, kin.legmap)
        self.sk = np.sqrt(w.lambda_knee) * w.unit_scale
        self.build(segments)

    @classmethod
    def of(cls, prep: Prepared, segments: list[Segment] | None = None, **kw) -> "StanceProblem":
        """The problem of `prep` (its weights, prior and bound) over `segments`."""
        return cls(prep.kin, prep.segments if segments is None else segments, prep.w, prep.prior, prep.knees,
                   prep.options.bound, **kw)

    def build(self, segments: list[Segment]) -> None:
        self.segments = segments
        self.feet, terms = [], []
        for seg in segments:
            if self.model is None:
                sk = SegmentKinematics(self.kin, seg.q_enc)
            else:
                sk = EffectSegment(self.model, SegmentData(seg.q_enc, seg.ft, seg.up_B,
                                                           q_ref=seg.q_enc + self.q_ref, time=seg.time))
            feet = InterFootTerm(f"{seg.name}/feet", sk, self.sf)
            self.feet.append(feet)
            terms += [feet, FlatGroundTerm(f"{seg.name}/flat", sk, seg.up_B, seg.R_WB, self.sg)]
        if self.w.lambda_q > 0:
            terms.append(TikhonovTerm(self.wq))
        if self.prior is not None and self.w.lambda_knee > 0:
            terms.append(KneePriorTerm(self.knees, self.prior, self.sk))
        blocks = [Block(OFFSETS, self.n_offsets, bound=self.bound)]
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
        values = self.problem.unpack(x) if len(x) > self.n_offsets else x
        return [t.update_mean(values) for t in self.feet]

    def evaluate(self, dq: np.ndarray, mode: str):
        """Stacked residual and Jacobian with the segment means re-estimated
        ("projected") or held at their last values ("fixed")."""
        for t in self.feet:
            t.mode = mode
        return self.problem.evaluate(dq)

    def evaluate_both(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(r, J_fixed, J_projected) at `x`, the segment means re-estimated at `x`: the
        two `evaluate` modes from one pass of the kinematics (the projected feet columns
        from the fixed ones, `project_mean`)."""
        self.means_at(x)
        for t in self.feet:
            t.mode = "both"
        r, J_fixed = self.problem.evaluate(x)
        J_proj = J_fixed.copy()
        pos = 0
        for seg, t in zip(self.segments, self.feet):
            rows = 6 * len(seg.frames)
            J_proj[pos:pos + rows] = self.problem.dense(t.projected, rows)
            t.projected, t.mode = None, "projected"
            pos += 11 * len(seg.frames)
        return r, J_fixed, J_proj

    def solve(self, dq0: np.ndarray, opts: FitOptions) -> tuple[np.ndarray, list]:
        lb, ub = -opts.bound * np.ones(self.n_offsets), opts.bound * np.ones(self.n_offsets)
        x0 = np.array(dq0, dtype=float)
        x0[:self.n_offsets] = np.clip(x0[:self.n_offsets], lb + 1e-12, ub - 1e-12)
        history = []
        if opts.solver == "projected":
            for t in self.feet:
                t.mode = "projected"
            # MINPACK's Levenberg-Marquardt is fastest here; the bounds are honoured by
            # re-solving with the bounded trust-region method if they would be active.
            sol = self.problem.solve(x0, method="lm", tol=opts.tol, jac=opts.jacobian,
                                     max_nfev=100 if opts.jacobian == "analytic" else 2000,
                                     on_jacobian=lambda x: history.append(x.tolist()))
            history.append(sol.x.tolist())
            return sol.x, history
        # The paper's alternation: means from the current dq, then a bounded inner solve.
        x = x0
        for _ in range(opts.max_outer):
            self.means_at(x)
            for t in self.feet:
                t.mode = "fixed"
            self.problem.reset_cache()
            fun, jac = self.problem.functions()
            sol = least_squares(fun, x, jac=jac if opts.jacobian == "analytic" else "2-point", bounds=(lb, ub),
                                method="trf", ftol=paper.INNER_FTOL, max_nfev=paper.INNER_MAX_ITERATIONS)
            moved = np.abs(sol.x - x).max()
            x = sol.x
            history.append(x.tolist())
            if moved < 1e-14:
                break
        self.means_at(x)
        for t in self.feet:
            t.mode = "projected"
        self.problem.reset_cache()  # its last residual is the fixed-mean one, not this mode's
        return x, history

    def trim(self, dq: np.ndarray, fraction: float) -> None:
        """Drop the `fraction` of frames with the largest weighted residual, per segment."""
        r = self.problem.cached_residual(dq) if all(t.mode == "projected" for t in self.feet) else None
        if r is None:
            r, _ = self.evaluate(dq, "projected")
        pos = 0
        kept = []
        for seg in self.segments:
            n = len(seg.frames)
            feet = r[pos:pos + 6 * n].reshape(n, 6)
            flat = r[pos + 6 * n:pos + 11 * n].reshape(n, 5)
            pos += 11 * n
            score = (feet**2).sum(1) + (flat**2).sum(1)
            kept.append(seg.subset(np.sort(np.argsort(score)[: n - int(round(fraction * n))])))
        self.build(kept)

    def set_bound(self, bound: float) -> None:
        """|offset| <= `bound` from now on (the terms, and their segment means, kept)."""
        self.bound = bound
        p = self.problem
        self.problem = Problem([replace(b, bound=bound) if b.name == OFFSETS else b for b in p.blocks.values()],
                               p.terms)
        self.problem._cache, self.problem._patterns = p._cache, p._patterns  # the same rows: still valid

    def solve_gross(self, dq0: np.ndarray, opts: FitOptions) -> tuple[np.ndarray, list]:
        """`solve` at the problem's bound, and if offsets sit at it (gross offsets) the
        solve at `opts.bound_max` that a hand-given bound would run, the bound kept there
        for every later step; offsets still at `bound_max` are the bound warning's.

        The gross stage (`opts.gross`): "grow" (default) solves at `bound_max` from `dq0`
        (the hand-bounded solve itself, the same minimum bit for bit); with the projected
        solver it is the first solve too: its Levenberg-Marquardt steps are unbounded and
        the bound is honoured by a bounded re-solve only when they leave it, so an answer
        inside the first bound is the first bound's own (the same steps, bit for bit),
        and the bounded re-solve at the first bound, the slow part, is skipped where it
        would be discarded. "double" (measured, slower): the bound doubled (x
        `GROW_FACTOR`) and solved again from the bounded answer until no offset sits at
        it. "coarse" (measured, slower) starts the solve at `bound_max` from a global
        stage instead: every `COARSE_STRIDE`-th frame solved at `bound_max` from zero.
        "off": the first bound stays. What ran is in `self.gross` (the stage, the first bound,
        the bound the solve ended with, the first doubling of the first bound that holds
        the offsets, the joints at or beyond the first bound, the extra solves)."""
        first = self.bound
        if opts.gross == "off" or first >= opts.bound_max:
            return self.solve(dq0, replace(opts, bound=first))
        early = opts.gross == "grow" and opts.solver == "projected"
        if early:
            self.set_bound(opts.bound_max)
        dq, history = self.solve(dq0, replace(opts, bound=self.bound))
        if not at_bound(dq[:self.n_offsets], first):
            self.set_bound(first)
            return dq, history
        solves = 0
        while opts.gross == "double" and at_bound(dq[:self.n_offsets], self.bound) and self.bound < opts.bound_max:
            self.set_bound(min(GROW_FACTOR * self.bound, opts.bound_max))
            dq, more = self.solve(dq, replace(opts, bound=self.bound))
            history += more
            solves += 1
        if not early and opts.gross != "double":
            x0 = dq0
            if opts.gross == "coarse":
                coarse = StanceProblem(self.kin, [s.subset(np.arange(0, len(s.frames), COARSE_STRIDE))
                                                  for s in self.segments], self.w, self.prior, self.knees,
                                       opts.bound_max, self.model, self.q_ref, self.held)
                x0, _ = coarse.solve(np.zeros_like(dq), replace(opts, bound=opts.bound_max))
                solves += 1
            self.set_bound(opts.bound_max)
            dq, more = self.solve(x0, replace(opts, bound=self.bound))
            history += more
            solves += 1
        self.gross = gross_report(opts.gross, first, self.bound, dq[:self.n_offsets], self.kin.legmap.joint_names,
                                  solves)
        return dq, history

    def solve_trimmed(self, dq0: np.ndarray, opts: FitOptions) -> tuple[np.ndarray, list, list]:
        """Solve (the bound grown for gross offsets, `solve_gross`), drop the largest
        residual frames (`opts.trim_fraction`), solve again from there at the bound the
        first solve ended with; (offsets, first solve's history, second's)."""
        dq, hist1 = self.solve_gross(dq0, opts)
        hist2: list = []
        if opts.trim_fraction > 0:
            self.trim(dq, opts.trim_fraction)
            dq, hist2 = self.solve_gross(dq, opts)
        return dq, hist1, hist2
