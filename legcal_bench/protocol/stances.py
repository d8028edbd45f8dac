"""The stance protocol: the paper's four stances, foot placements and posture motion.

A stance fixes both soles on the floor; within it the pelvis moves continuously
(squat depth, fore-aft and lateral sway, roll, pitch and yaw), which excites every
leg joint including hip roll and hip yaw. Everything scales with the robot's own
dimensions (`RobotDims`), so the same protocol fits any robot.

Frames: the stance frame S has its origin on the floor midway between the nominal
sole centres, x forward, z up; it is the world frame of a recording. A posture is the
pelvis pose in S as [x, y, z, roll, pitch, yaw] (m, rad; fixed-axis roll-pitch-yaw).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
import pinocchio as pin
from scipy.spatial import ConvexHull

from legcal_bench.errors import IKError
from legcal_bench.inputs import is_finite_number, shown
from legcal_bench.geometry.lie import Exp, inverse
from legcal_bench.geometry.poses import pose_xyz_rpy, posture_poses
from legcal_bench.robots.kinematics import (
    LegKinematics, RobotDims, reachable_postures, reached_as_commanded,
)
from legcal_bench.robots.legmap import SIDES


@dataclass(frozen=True)
class Stance:
    name: str
    label: str
    left_x: float = 0.0  # fore-aft sole position, in leg lengths
    right_x: float = 0.0
    extra_width: float = 0.0  # added to each sole's lateral position, in leg lengths
    toe_out: float = 0.0  # sole yaw, rad (left +, right -)
    depth: float = 0.08  # squat depth below straight legs, in leg lengths
    # Sinusoid amplitudes of the posture components (x, y in leg lengths; z in leg
    # lengths; roll, pitch, yaw in rad).
    amplitude: tuple[float, float, float, float, float, float] = (0.02, 0.03, 0.03, 0.05, 0.08, 0.10)
    # A load-varied stance: sinusoid amplitudes (period PUSH_PERIOD_S) of a scissor
    # displacement of the servo targets' soles (fore-aft, lateral and vertical in leg
    # lengths, pitch in rad; +half on the left sole, -half on the right): the soles stay
    # where they are, so the legs push them apart and together, shift the weight from one
    # to the other and pitch them against the floor, and the ankle F/T sensors measure
    # the loads. The loads then vary apart from the posture, which tells a joint's
    # compliance from its encoder scale.
    push: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)


STANCES: dict[str, Stance] = {
    s.name: s
    for s in (
        Stance("I", "normal squat"),
        # Lunges sway less sideways: their support polygon is a skewed parallelogram,
        # and a strained chain (offsets) rolls narrow feet onto their edges.
        Stance("II", "left lunge", left_x=0.12, right_x=-0.10, depth=0.10,
               amplitude=(0.015, 0.012, 0.025, 0.025, 0.06, 0.06)),
        Stance("III", "right lunge", left_x=-0.10, right_x=0.12, depth=0.10,
               amplitude=(0.015, 0.012, 0.025, 0.025, 0.06, 0.06)),
        Stance("IV", "wide squat", extra_width=0.10, toe_out=0.15, depth=0.12,
               amplitude=(0.015, 0.03, 0.025, 0.04, 0.06, 0.08)),
    )
}
# The optional load-varied protocol (not in the default set): stance I's squat with
# the soles pushed apart and together while the weight shifts ("push"), or scissored
# fore-aft and pitched against the floor ("press"); record them with the others
# (--stances I II III IV push press). Amplitudes chosen on the A3-like robot and the G1
# (stance I plus each candidate, seed 0, the knee compliance/encoder-scale cosine):
# larger vertical pushes failed the hold check.
LOAD_STANCES: dict[str, Stance] = {
    s.name: s
    for s in (
        Stance("push", "normal squat, feet pushing apart and together, weight shifting between them",
               push=(0.0, 0.03, 0.01, 0.0)),
        Stance("press", "normal squat, feet scissoring fore-aft and pitching against the floor",
               push=(0.03, 0.0, 0.0, 0.1)),
    )
}
# The optional range stance (not in the default set): the legs nearly straight while the
# pelvis sways, so each pitch joint works far from the squats' angles (the knee ~0.2 rad
# instead of ~1). In the squats a pitch joint's angle moves little about its mean, so its
# encoder scale looks like its offset; with this stance the scale's price on the offsets'
# posterior falls from 1.5-1.7x to 1.2-1.3x (A3-like, A2-like, G1: the effects table with
# and without it; record --stances I II III IV tall). No vertical sway: straight legs cannot lengthen.
RANGE_STANCES: dict[str, Stance] = {
    s.name: s
    for s in (
        Stance("tall", "near-straight legs, the pelvis swaying", depth=0.005,
               amplitude=(0.02, 0.03, 0.0, 0.05, 0.08, 0.10)),
    )
}
STANDING = Stance("standing", "straight-leg standing", depth=0.0, amplitude=(0.0,) * 6)
ALL_STANCES = {**STANCES, **LOAD_STANCES, **RANGE_STANCES, "standing": STANDING}


def check_stance_names(names, where: str = "--stances", catalog: dict | None = None) -> None:
    """ConfigError naming the stances of `names` that are not recordable stances of
    `catalog` (default: the built-ins; "standing" is recorded on its own), and the choices."""
    from legcal_bench.errors import ConfigError

    catalog = ALL_STANCES if catalog is None else catalog
    if isinstance(names, str) or not isinstance(names, (list, tuple)):
        raise ConfigError(f"{where} = {names!r}: give the stances as a list of names, e.g. ['I', 'II']")
    bad = [s for s in names if s not in catalog or s == "standing"]
    if bad:
        raise ConfigError(f"{where}: {', '.join(f'stance {b!r}' for b in bad)} not known; use stances from {list(STANCES)}, the load-varied {list(LOAD_STANCES)}, "
                          f"the range stance {list(RANGE_STANCES)}, or a protocol file (collect --protocol)")

# Incommensurate periods (s) so no posture repeats within a stance.
PERIODS = (11.0, 9.0, 7.0, 5.5, 8.5, 6.5)
PUSH_PERIOD_S = 4.5  # the load-varied stances' push, faster than any posture component


def posture_bounds(dims: RobotDims) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) of a commanded posture: +-0.25 leg lengths in x and y, 0.6-1.0 leg
    lengths in z, +-0.4 rad in roll, pitch and yaw."""
    L = dims.leg_length
    return (np.array([-0.25 * L, -0.25 * L, 0.6 * L, -0.4, -0.4, -0.4]),
            np.array([0.25 * L, 0.25 * L, 1.0 * L, 0.4, 0.4, 0.4]))


# A stance's nominal posture must keep every joint this far inside its limits, so the
# placement jitter and the posture motion around it have room.
FIT_MARGIN_RAD = 0.05
FIT_SCALES = tuple(np.round(np.arange(1.0, 0.19, -0.05), 2))  # tried in turn, largest first
MIN_DEPTH = 0.02  # leg lengths: a shallower squat puts the knees near their singularity


class FittedStance(NamedTuple):
    stance: Stance
    scale: float  # 1: the protocol's stance; less: its placement and squat depth shrunk to fit


def fit_stance(stance: Stance, kin: LegKinematics, margin_rad: float = FIT_MARGIN_RAD) -> FittedStance:
    """`stance` shrunk until its nominal posture fits this robot: the lunge or widening
    of the feet, the toe-out and the squat depth scaled together (by 1, 0.95, ..., 0.2)
    until the nominal posture's IK keeps every joint `margin_rad` inside its limits.
    Raises IKError naming the stance, the joints in the way and the fix."""
    if stance.name == STANDING.name:
        return FittedStance(stance, 1.0)
    # Kept with the robot's kinematics (one fit per stance and robot, freed with it).
    cache = kin.__dict__.setdefault("_fitted_stances", {})
    key = (stance, float(margin_rad))
    if key not in cache:
        cache[key] = _fit(stance, kin, float(margin_rad))
    return cache[key]


def _scaled(stance: Stance, s: float) -> Stance:
    """`stance` with its lunge, widening, toe-out and squat depth scaled by `s`."""
    return stance if s == 1.0 else replace(
        stance, left_x=stance.left_x * s, right_x=stance.right_x * s, extra_width=stance.extra_width * s,
        toe_out=stance.toe_out * s, depth=max(stance.depth * s, min(MIN_DEPTH, stance.depth)))


def _fit(stance: Stance, kin: LegKinematics, margin: float) -> FittedStance:
    lower, upper = kin.q_lower + margin, kin.q_upper - margin
    worst: list[str] = []
    scales = FIT_SCALES
    if not kin.reaches_any_sole_pose:
        # The slide a placement needs to stand flat on legs that do not reach every sole
        # pose grows with its size: one that needs too much at the smallest size needs too
        # much at every size (the A3-like wide squat's extra width: 28 settles saved).
        try:
            settle(place(_scaled(stance, FIT_SCALES[-1]), kin.dims), kin)
        except IKError:
            scales = ()
    for s in scales:
        fitted = _scaled(stance, s)
        pl = place(fitted, kin.dims)  # settled below for legs that need it
        # A stance fits a robot whose legs hold its nominal posture as placed (legs of
        # fewer than six joints do not hold every one: `reached_as_commanded`).
        if kin.reaches_any_sole_pose:
            T_BW = inverse(posture_poses(pl.nominal))
            try:
                q = kin.solve_batch(T_BW @ pl.left.homogeneous, T_BW @ pl.right.homogeneous, check_limits=False)[0]
            except IKError:
                continue
        else:  # where the legs stand flat near this placement (`settle`), if they do
            try:
                pl = settle(pl, kin)
            except IKError:
                continue
            reached, Q = reached_as_commanded(kin, pl.left, pl.right, pl.nominal)
            if not reached[0]:
                continue
            q = Q[0]
        outside = (q < lower) | (q > upper)
        if not outside.any():
            return FittedStance(fitted, float(s))
        worst = [kin.legmap.joint_names[i] for i in np.flatnonzero(outside)]
    lacking = kin.legmap.absent_roles if not worst else ()
    err = IKError(f"stance {stance.name} ({stance.label}) does not fit this robot even shrunk to "
                  f"{FIT_SCALES[-1]:g} of its size" + (f" (joints at their limits: {worst})" if worst else "")
                  + (f"; its legs have no {', '.join(lacking)} (absent_roles), and no pelvis posture puts both "
                     "soles flat at this stance's placement" if lacking else "")
                  + "; record the other stances (--stances), or widen the joints' ranges in the MJCF if the real "
                  "robot allows it")
    err.lacking_roles = lacking  # what the stance needs that the robot lacks (empty: joint limits)
    raise err


def stances_for(kin: LegKinematics, catalog: dict,
                names: tuple[str, ...]) -> tuple[dict, tuple[str, ...], list[str]]:
    """(the catalog, the stances of `names` the robot stands in, a note per change): a
    stance the robot's legs lack what it needs for (a wide squat needs ankle roll to keep
    the soles flat: `absent_roles`) is replaced by its variant with the soles under the
    hips (no extra width or toe-out; named `<name>u`, added to the catalog) where that
    fits, so the protocol keeps its number of stances, and left out otherwise; a stance
    that does not fit for joint limits raises IKError as `fit_stance` does."""
    catalog = dict(catalog)
    kept, notes = [], []
    for name in names:
        try:
            if name != "standing":
                fit_stance(catalog[name], kin)
            kept.append(name)
            continue
        except IKError as e:
            if not getattr(e, "lacking_roles", ()):
                raise
            lacking = ", ".join(e.lacking_roles)
        st = catalog[name]
        # The toe-out is kept where the legs stand flat with it (it turns the hips' yaw and
        # roll, which the other stances leave still), else dropped.
        for toe_out in dict.fromkeys((st.toe_out, 0.0)):
            under = replace(st, name=f"{name}u", label=f"{st.label}, soles under the hips" + (
                ", toes out" if toe_out else ""), extra_width=0.0, toe_out=toe_out)
            try:
                fit_stance(under, kin)
                break
            except IKError:
                under = None
        if under is None:
            notes.append(f"stance {name} ({st.label}) left out: legs without {lacking} cannot keep both soles flat "
                         "in it")
            continue
        catalog[under.name] = under
        kept.append(under.name)
        notes.append(f"stance {name} ({st.label}) recorded as {under.name} ({under.label}): legs without {lacking} "
                     "cannot keep both soles flat at its width" + ("" if under.toe_out else " and toe-out"))
    return catalog, tuple(kept), notes


@dataclass(frozen=True)
class Placement:
    """Where the soles are (in the stance/world frame) and the nominal pelvis posture."""

    stance: Stance
    left: pin.SE3
    right: pin.SE3
    nominal: np.ndarray  # posture [x, y, z, roll, pitch, yaw]


def settle(placement: "Placement", kin: LegKinematics) -> "Placement":
    """`placement` where the robot can stand on it with both soles flat: as placed for
    legs of six joints. A leg without ankle roll stands flat only with its sole under its
    hip, at the leg's own yaw: for shorter legs the soles keep their fore-aft jitter,
    lose the sideways and yaw jitter, and the right sole is then slid in the floor plane
    by the least amount that lets both legs reach (`reachable_postures` with `slide`;
    none for the built-in stances), with the nominal posture the robot holds."""
    if kin.reaches_any_sole_pose:
        return placement
    st, L = placement.stance, kin.dims.leg_length
    fore_aft = [placement.left.translation[0] - st.left_x * L, placement.right.translation[0] - st.right_x * L]
    placement = _placement(st, kin.dims, [np.array([dx, 0.0, 0.0]) for dx in fore_aft])
    if reached_as_commanded(kin, placement.left, placement.right, placement.nominal[None])[0][0]:
        return placement
    postures, _, right = reachable_postures(kin, placement.left, placement.right, placement.nominal[None], slide=True)
    moved = pin.log6(placement.right.actInv(pin.SE3(right[0][:3, :3], right[0][:3, 3]))).vector
    if np.abs(moved[:3]).max() > SETTLE_MAX_SLIDE * L or np.abs(moved[3:]).max() > SETTLE_MAX_SLIDE:
        raise IKError(f"stance {st.name} ({st.label}): legs without {', '.join(kin.legmap.absent_roles)} stand flat "
                      f"on this placement only with the right sole slid {np.abs(moved[:3]).max() * 1e3:.0f} mm and "
                      f"turned {np.degrees(np.abs(moved[3:]).max()):.1f} deg (at most {SETTLE_MAX_SLIDE:.0%} of the "
                      "leg's length and 1 deg: another stance, not this one)")
    return replace(placement, right=pin.SE3(right[0][:3, :3], right[0][:3, 3]), nominal=postures[0])


def settled_placement(stance: Stance, kin: LegKinematics, rng: np.random.Generator | None = None,
                      jitter_m: float = 0.0, jitter_rad: float = 0.0) -> "Placement":
    """`place` then `settle`: where this robot stands in `stance` (jittered with `rng`)."""
    return settle(place(stance, kin.dims, rng, jitter_m, jitter_rad), kin)


# `settle`: the right sole slides at most this far (leg lengths; rad) to where legs without
# ankle roll stand flat (a toe-out of 0.15 rad with the soles under the hips of the A3-like
# robot without ankle roll: 6.6 mm); farther is another stance.
SETTLE_MAX_SLIDE = 0.02


# A commanded step along one posture axis (leg lengths, rad) for `followable_axes`, and the
# share of it the held posture may miss along that axis or move along another one (in leg
# lengths and rad, relative to the step): a squat with toes out moves the pelvis 1 mm
# fore-aft per 10 mm of height on the A3-like robot without ankle roll.
FOLLOW_PROBE = 0.02
FOLLOW_SLACK = 0.2


def followable_axes(kin: LegKinematics, placement: "Placement") -> np.ndarray:
    """(6,) bool: the posture axes [x, y, z, roll, pitch, yaw] along which the pelvis can
    move with the soles where `placement` puts them. All of them for legs of six joints.
    For shorter legs, measured: a step of FOLLOW_PROBE (leg lengths, rad) along each axis
    from the nominal posture, and the axes along which both legs reach it as commanded
    (`reached_as_commanded`) or hold a posture that follows it within FOLLOW_SLACK
    (`holdable_postures`). On the A3-like robot without ankle roll: fore-aft, height and
    pitch with the soles under the hips and parallel (not sideways, roll or yaw, which
    their soles follow only in part); height with the toes out."""
    if kin.reaches_any_sole_pose:
        return np.ones(6, dtype=bool)
    step = FOLLOW_PROBE * np.r_[np.full(3, kin.dims.leg_length), np.ones(3)]
    probes = placement.nominal + np.diag(step)
    follows, q = reached_as_commanded(kin, placement.left, placement.right, probes)
    rest = np.flatnonzero(~follows)  # followed with the other axes moving a little?
    if rest.size:
        try:
            held = reachable_postures(kin, placement.left, placement.right, probes[rest], q[rest])[0]
        except IKError:  # some probe has no reachable posture at all: each on its own
            held = np.array([_held_or_nan(kin, placement, probes[a], q[a]) for a in rest])
        moved = (held - placement.nominal) / step
        for a, m in zip(rest, moved):
            follows[a] = m[a] > 1 - FOLLOW_SLACK and np.abs(np.delete(m, a)).max() < FOLLOW_SLACK
    return follows


def _held_or_nan(kin: LegKinematics, placement: "Placement", posture: np.ndarray, q: np.ndarray) -> np.ndarray:
    try:
        return reachable_postures(kin, placement.left, placement.right, posture[None], q[None])[0][0]
    except IKError:
        return np.full(6, np.nan)


# Placement jitter in metres (`CollectConfig.jitter_m`, `heldout_jitter_m`) is written for
# a leg as long as the A3-like robot's (this, its `RobotDims.leg_length`); a shorter leg gets
# it scaled by its length (a 0.3 m leg a third of it), a longer one as written (the
# built-ins are all at least this long: their data do not change).
JITTER_REFERENCE_LEG_M = 0.935


def jitter_scale(dims: RobotDims) -> float:
    """The factor on a placement jitter in metres for a robot of `dims`."""
    return min(1.0, dims.leg_length / JITTER_REFERENCE_LEG_M)


def place(stance: Stance, dims: RobotDims, rng: np.random.Generator | None = None,
          jitter_m: float = 0.0, jitter_rad: float = 0.0) -> Placement:
    """Sole poses for `stance`, each perturbed uniformly by up to the jitter (`jitter_m`
    for an A3-sized leg, `jitter_scale`)."""
    jitter_m = jitter_m * jitter_scale(dims)
    d = [np.zeros(3) if rng is None else rng.uniform(-1, 1, 3) * [jitter_m, jitter_m, jitter_rad] for _ in SIDES]
    return _placement(stance, dims, d)


def _placement(stance: Stance, dims: RobotDims, jitter: list[np.ndarray]) -> Placement:
    """`place` with each sole moved by its jitter (dx, dy, dyaw)."""
    L = dims.leg_length
    y = dims.foot_y + stance.extra_width * L
    feet = [pose_xyz_rpy([sx * L + d[0], sy + d[1], 0.0], [0.0, 0.0, yaw + d[2]])
            for (sx, sy, yaw), d in zip(((stance.left_x, y, stance.toe_out), (stance.right_x, -y, -stance.toe_out)),
                                        jitter)]
    mid = (feet[0].translation + feet[1].translation) / 2
    nominal = np.array([mid[0] - dims.foot_x, mid[1], L * (1 - stance.depth), 0, 0, 0])
    return Placement(stance, feet[0], feet[1], nominal)


def posture_trajectory(placement: Placement, dims: RobotDims, duration: float, rate_hz: float,
                       rng: np.random.Generator, ramp_s: float = 3.0, period_scale: float = 1.0,
                       axes: np.ndarray | None = None) -> np.ndarray:
    """(N, 6) postures at `rate_hz`: the nominal posture plus slow sinusoids with random
    phases (periods `PERIODS` x `period_scale`: twice as slow, a quarter of the
    accelerations), faded in (smoothstep) over `ramp_s` so motion starts from rest;
    along the posture `axes` given only (`followable_axes`; default all)."""
    n = int(round(duration * rate_hz))
    t = np.arange(n) / rate_hz
    amp = np.array(placement.stance.amplitude) * [dims.leg_length, dims.leg_length, dims.leg_length, 1, 1, 1]
    phase = rng.uniform(0, 2 * np.pi, 6)
    if axes is not None:
        amp = np.where(axes, amp, 0.0)
    wave = amp * np.sin(2 * np.pi * t[:, None] / (period_scale * np.array(PERIODS)) + phase)
    return placement.nominal + fade_in(t, ramp_s)[:, None] * wave


def fade_in(t: np.ndarray, ramp_s: float) -> np.ndarray:
    """(N,) a smoothstep from 0 at t = 0 to 1 at `ramp_s` (all ones without a ramp): motion
    starts from rest."""
    fade = np.clip(t / ramp_s, 0, 1) if ramp_s > 0 else np.ones(len(t))
    return fade * fade * (3 - 2 * fade)


def commanded_soles(placement: Placement, dims: RobotDims, n: int, rate_hz: float, rng: np.random.Generator,
                    ramp_s: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """(left, right) (N, 4, 4): the soles the servo targets are solved for, frame by frame:
    the placement's, displaced by the stance's `push` (a sinusoid of period
    PUSH_PERIOD_S with a random phase, faded in like the posture motion), +half on the
    left sole and -half on the right, in the stance frame: the left sole forward, out
    (+y), down and toe down while the right one goes back, out (-y), up and toe up."""
    t = np.arange(n) / rate_hz
    wave = fade_in(t, ramp_s) * np.sin(2 * np.pi * t / PUSH_PERIOD_S + rng.uniform(0, 2 * np.pi))
    fx, fy, fz, pitch = placement.stance.push
    out = []
    for sign, T in ((1.0, placement.left), (-1.0, placement.right)):
        d = 0.5 * sign * wave  # the left sole is at +y: +d moves it forward and outward, the right one back and out
        M = np.broadcast_to(T.homogeneous, (n, 4, 4)).copy()
        M[:, 0, 3] += d * fx * dims.leg_length
        M[:, 1, 3] += d * fy * dims.leg_length
        M[:, 2, 3] -= d * fz * dims.leg_length  # the left sole's target below the floor: it takes more weight
        M[:, :3, :3] = M[:, :3, :3] @ Exp(np.outer(d * pitch, [0, 0, 0, 0, 1.0, 0]))[:, :3, :3]  # about the sole's y
        out.append(M)
    return out[0], out[1]


def support_margin(kin: LegKinematics, placement: Placement, posture: np.ndarray,
                   q: np.ndarray) -> float | np.ndarray:
    """Distance (m) of the CoM's ground projection inside the convex hull of the eight
    sole corners; negative outside. `posture` (6,) and `q` (n,) (the n leg joints) give a
    float; postures (N, 6) and their joint angles (N, n) give the (N,) margins."""
    corners = np.vstack([(T.rotation @ kin.corners[s].T).T + T.translation
                         for s, T in (("left", placement.left), ("right", placement.right))])
    hull = ConvexHull(corners[:, :2])
    T_WB = posture_poses(posture)
    qs = np.reshape(q, (-1, kin.legmap.n_joints))
    com = np.einsum("nij,nj->ni", T_WB[:, :2, :3], np.array([kin.com(qk) for qk in qs]))
    com += T_WB[:, :2, 3]
    margins = -(com @ hull.equations[:, :2].T + hull.equations[:, 2]).max(axis=1)
    return float(margins[0]) if np.ndim(posture) == 1 else margins


class Motion(NamedTuple):
    postures: np.ndarray  # (N, 6)
    q: np.ndarray  # (N, n) their joint angles (n leg joints)
    scale: float  # the motion's amplitude relative to the stance's


def feasible_trajectory(kin: LegKinematics, placement: Placement, duration: float, rate_hz: float,
                        rng: np.random.Generator, shrink: float = 0.8, tries: int = 10, return_q: bool = False,
                        period_scale: float = 1.0):
    """`posture_trajectory` with its motion shrunk (x `shrink` per try) until every frame
    is reachable within the joint limits of `kin` and statically balanced (the CoM at
    least a quarter sole width inside the support polygon, checked every fifth frame),
    so any robot gets a stance it can hold on a real floor. Returns the postures (N, 6)
    (those the robot holds: `posture_ik`, for legs of fewer than six joints the nearest
    reachable ones),
    with `return_q` a `Motion`: also their joint angles (N, n) on `kin` (the whole
    trajectory's IK is solved in one batch, `posture_ik`) and the amplitude scale used."""
    # Here, not at the top: the stances' table is read by the data checks of every
    # calibration, and the simulator's module loads dm_control (~0.2 s of a first call).
    from legcal_bench.sim.double_support import posture_ik

    margin = 0.25 * kin.dims.sole_width
    base = posture_trajectory(placement, kin.dims, duration, rate_hz, rng, period_scale=period_scale,
                              axes=None if kin.reaches_any_sole_pose else followable_axes(kin, placement))
    for k in range(tries):
        traj = placement.nominal + (shrink ** k) * (base - placement.nominal)
        try:
            q, traj = posture_ik(kin, placement.left, placement.right, traj, with_postures=True)
        except IKError:
            continue
        if (support_margin(kin, placement, traj[::5], q[::5]) < margin).any():
            continue
        return Motion(traj, q, shrink ** k) if return_q else traj
    raise IKError(f"stance {placement.stance.name}: no reachable, balanced posture motion for this robot "
                  f"(the nominal posture itself may be out of reach or off balance)")


# ----------------------------------------------------------------- protocol files
PROTOCOL_FORMAT = "legcal-protocol"
_STANCE_FIELDS = ("left_x", "right_x", "extra_width", "toe_out", "depth")
MAX_PUSH = 0.1  # leg lengths (fore-aft, lateral, vertical) and rad (pitch): a protocol file's push amplitudes


def write_protocol(path, stances: list[Stance], meta: dict | None = None):
    """A stance protocol as a YAML file a robot team can take to their robot: each
    stance's placement (leg lengths, rad), squat depth and posture-motion amplitudes."""
    import yaml

    from legcal_bench.files.atomic import atomic_write_text

    doc = {"format": PROTOCOL_FORMAT, "version": 1, **(meta or {}),
           "stances": [{"name": st.name, "label": st.label, **{k: float(getattr(st, k)) for k in _STANCE_FIELDS},
                        "amplitude": [float(a) for a in st.amplitude],
                        **({"push": [float(a) for a in st.push]} if any(st.push) else {})} for st in stances]}
    return atomic_write_text(path, yaml.safe_dump(doc, sort_keys=False))


# A protocol file's keys (closed: a misspelt key is refused, naming the closest): the
# stances, and the metadata `legcal-bench design --out` writes beside them.
PROTOCOL_KEYS = ("format", "version", "stances", "robot", "frames", "stance_s", "made_by", "code", "predicted",
                 "hold_screen")
STANCE_KEYS = ("name", "label", *_STANCE_FIELDS, "amplitude", "push")


def _amplitudes(d: dict, field: str, default: tuple, high: float, where: str, meaning: str) -> tuple:
    """A protocol entry's `field`: len(default) numbers in [0, high] (default if absent);
    ConfigError naming the field otherwise."""
    from legcal_bench.errors import ConfigError

    v = d.get(field, list(default))
    if (not isinstance(v, list) or len(v) != len(default)
            or not all(is_finite_number(a) and 0 <= a <= high for a in v)):
        raise ConfigError(f"{where}: field '{field}' must be {len(default)} numbers in [0, {high}] ({meaning}), "
                          f"got {shown(v)}")
    return tuple(float(a) for a in v)


def load_protocol(path) -> dict[str, Stance]:
    """The stances of a protocol file, by name; ConfigError naming the field and the fix."""
    from pathlib import Path

    import yaml

    from legcal_bench.errors import ConfigError
    from legcal_bench.inputs import known_keys, read_text

    from legcal_bench.files.packaged import packaged

    fix = "write one with legcal-bench design --out"
    path = packaged(path)  # the one rule for a file a user names
    try:
        text = read_text("protocol", path, "protocol file")
    except ConfigError as e:
        raise ConfigError(f"{e} ({fix})" if not Path(path).exists() else str(e)) from None
    try:
        doc = yaml.safe_load(text)
    except (yaml.YAMLError, RecursionError) as e:
        reason = e if isinstance(e, yaml.YAMLError) else "nested too deeply"
        raise ConfigError(f"protocol {path}: not a readable YAML file ({reason})") from None
    if not isinstance(doc, dict) or doc.get("format") != PROTOCOL_FORMAT:
        got = shown(doc.get("format")) if isinstance(doc, dict) else f"{shown(doc)} (the file is not a YAML mapping)"
        raise ConfigError(f"protocol {path}: field 'format' must be {PROTOCOL_FORMAT!r}, got {got} ({fix})")
    known_keys(f"protocol {path}", doc, PROTOCOL_KEYS, fix=f"the stances go under 'stances'; {fix}")
    version = doc.get("version", 1)
    if isinstance(version, bool) or version != 1:
        raise ConfigError(f"protocol {path}: field 'version' is {shown(version)}: this legcal-bench reads version 1 "
                          f"({fix})")
    items = doc.get("stances")
    if not isinstance(items, list) or not items:
        raise ConfigError(f"protocol {path}: field 'stances' must list at least one stance, got {shown(items)}")
    out: dict[str, Stance] = {}
    for i, d in enumerate(items):
        where = f"protocol {path}: stances[{i}]"
        if not isinstance(d, dict) or not isinstance(d.get("name"), str) or not d["name"].strip():
            got = shown(d.get("name")) if isinstance(d, dict) else f"the entry {shown(d)}"
            raise ConfigError(f"{where}: needs a 'name' (a string), got {got}")
        known_keys(where, d, STANCE_KEYS, fix="the fields of a stance: see write_protocol")
        name = d["name"]
        if name in ALL_STANCES or name in out:
            raise ConfigError(f"{where}: name {name!r} is taken (built-in stances and earlier entries); rename it")
        vals = {}
        for k in _STANCE_FIELDS:
            v = d.get(k, getattr(Stance, k))
            low = 0.0 if k == "depth" else -1.0  # a negative depth would put the pelvis above straight legs
            if not is_finite_number(v) or not low <= v <= 1.0:
                raise ConfigError(f"{where}: field '{k}' must be a finite number within [{low:g}, 1] (leg lengths or "
                                  f"rad), got {shown(v)}")
            vals[k] = float(v)
        label = d.get("label", "protocol")
        if not isinstance(label, str):
            raise ConfigError(f"{where}: field 'label' is {shown(label)}: give a short description (a string)")
        amp = _amplitudes(d, "amplitude", Stance.amplitude, 0.5, where,
                          "x, y, z in leg lengths; roll, pitch, yaw in rad")
        push = _amplitudes(d, "push", Stance.push, MAX_PUSH, where,
                           "the load-varied scissor: fore-aft, lateral and vertical in leg lengths, pitch in rad")
        out[name] = Stance(name, label, amplitude=amp, push=push, **vals)
    return out
