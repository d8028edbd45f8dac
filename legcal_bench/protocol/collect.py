"""Collect a session set: straight-leg standing, the stances, and held-out sessions.

The collector drives the static double-support simulator (the core the Gymnasium env
wraps) with the stance protocol's posture motion and writes one recording (plus its
ground truth) per segment, then a manifest. Every segment's randomness (placement,
motion phases, sensor noise) comes from one seed; a segment recorded here equals an
env episode reset with the same seed and stepped with the same postures.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
from tqdm import tqdm

from legcal_bench import inputs
from legcal_bench.data.recording import MANIFEST, Recording, Truth, is_session_dir, truth_path, write_manifest
from legcal_bench.errors import ConfigError, HoldError, IKError, SimulationError
from legcal_bench.files.atomic import replace_dir
from legcal_bench.files.scratch import scratch_dir
from legcal_bench.protocol.servos import servo_gains
from legcal_bench.geometry.lie import inverse
from legcal_bench.geometry.poses import posture_poses
from legcal_bench.protocol.stances import (ALL_STANCES, check_stance_names, commanded_soles,
                                          feasible_trajectory, fit_stance, load_protocol, posture_bounds,
                                          settled_placement, stances_for)
from legcal_bench.provenance import RESULTS_VERSION, stable_hash
from legcal_bench.robots.legmap import SIDES, LegMap
from legcal_bench.robots.transmission import to_joint_space
from legcal_bench.sim.arena import floor_parameters
from legcal_bench.robots import load_robot
from legcal_bench.sim.double_support import DoubleSupportSim, physics_timing
from legcal_bench.sim.effects import Reality, build_reality, floor_stances
from legcal_bench.sim.hold import RIGID_HOLD_LIMIT_RAD, HoldReport, held_joints_table
from legcal_bench.sim.offsets import paper_note, resolve_offsets
from legcal_bench.sim.scene import MODES
from legcal_bench.sim.sensors import sim_sensors
from legcal_bench.sim.standing import STANDING_CONTROLLERS

# The physics step the collector simulates with (s): each logged frame advances the
# physics by a whole number of these steps, one at least (`DoubleSupportSim.n_substeps`),
# so the logging rate is at most 1 / PHYSICS_DT (a faster rate would log frames the
# physics never stepped between, and run on).
PHYSICS_DT = 0.001
MIN_FRAMES = 2  # a segment's frames: two at least (a recording's rate needs two)
MAX_SEGMENT_S = 3600.0  # an hour of one posture: beyond, a typo (and memory) rather than a protocol
MAX_HELDOUT = 100
# The straight-leg phase's knees sit this close to mechanical straight at most: beyond,
# the leg is bent, not straight (the data check calls a knee 5 deg off straight "bent
# knees", `legcal_bench.estimation.checks.datacheck`).
MAX_KNEE_STRAIGHT_ERROR_RAD = math.radians(5.0)
STANDING = ("auto", *STANDING_CONTROLLERS)  # "auto": "cop" on a contact floor for a robot with ankle F/T sensors


@dataclass
class CollectConfig:
    robot: str = "a3"
    mjcf: str | None = None
    sim_robot: str | None = None  # simulate this robot; calibrators get `robot`
    sim_model: str | None = None  # simulate this MJCF (an edited copy of the robot's): the generic model gap
    # Reality effects (`legcal_bench.sim.effects`): specs like "compliance:joint=left_knee,k=1e4".
    effects: tuple[str, ...] = ()
    mode: str = "weld"
    stances: tuple[str, ...] = ("I", "II", "III", "IV")
    offsets: str | tuple[float, ...] = "paper"  # a preset, or 12 radians
    sensors: str = "realistic"
    seed: int = 0
    heldout: int = 3
    rate_hz: float = 50.0
    stance_s: float = 12.0
    heldout_s: float = 10.0
    standing_s: float = 5.0
    knee_straight_error_rad: float = 0.005
    # Placement jitter: the largest sole shift (m, for an A3-sized leg; scaled down for a
    # shorter one, `legcal_bench.protocol.stances.jitter_scale`) and yaw (rad).
    jitter_m: float = 0.015
    jitter_rad: float = 0.05
    heldout_jitter_m: float = 0.04
    heldout_jitter_rad: float = 0.1
    # The posture motion's periods x this: 2 = twice as slow, a quarter of the IMU's
    # motion acceleration (give twice the --stance-seconds to cover the same cycles).
    period_scale: float = 1.0
    # A protocol file (`legcal-bench design --out`): its stances replace `stances`.
    protocol: str | None = None
    # The standing controller (`legcal_bench.sim.standing`): "cop" centres each sole's
    # centre of pressure with the ankles, "none" holds the targets; "auto" is "cop" on a
    # contact floor for a robot with ankle force/torque sensors, else "none".
    standing: str = "auto"
    # The contact floor's parameters changed from the table's (docs/contact-floor.md):
    # "key=value,..." of `legcal_bench.sim.arena.FLOOR_KEYS`, for robustness studies.
    contact_floor: str = ""

    # The command-line option that sets each checked field (`legcal-bench collect`), named
    # with the field in every refusal.
    OPTIONS = {"mode": "--mode", "seed": "--seed", "heldout": "--heldout", "rate_hz": "--rate",
               "stance_s": "--stance-seconds", "heldout_s": "--heldout-seconds", "standing_s": "--standing-seconds",
               "knee_straight_error_rad": "--knee-error-deg", "period_scale": "--period-scale",
               "standing": "--standing", "stances": "--stances"}

    def __post_init__(self):
        check_config(self)


def _field(name: str) -> str:
    option = CollectConfig.OPTIONS.get(name)
    return f"{name} ({option})" if option else name


def check_config(cfg: CollectConfig) -> None:
    """The collection's values, checked before anything is simulated: the one place for
    them (the command line's options and the Python API alike); ConfigError naming the
    field, its option, the value and the fix. Values are checked, never converted (the
    config's dict is the session set's cache key)."""
    inputs.choice(_field("mode"), cfg.mode, MODES)
    if cfg.protocol is None:  # a protocol file's stances replace them (read when collecting)
        if isinstance(cfg.stances, str) or not cfg.stances:
            raise ConfigError(f"{_field('stances')} = {cfg.stances!r}: give a list of stance names, e.g. "
                              "('I', 'II', 'III', 'IV')")
        check_stance_names(cfg.stances, _field("stances"))
    inputs.seed(_field("seed"), cfg.seed)
    inputs.count(_field("heldout"), cfg.heldout, low=0, high=MAX_HELDOUT,
                 fix=f"held-out sessions to record: 0 to {MAX_HELDOUT}")
    rate, _, _ = physics_timing(cfg.rate_hz, PHYSICS_DT, _field("rate_hz"), "the physics step")
    for name, what, allow_zero in (("stance_s", "each stance", False), ("standing_s", "the straight-leg phase", True),
                                   ("heldout_s", "each held-out session", cfg.heldout == 0)):
        value = getattr(cfg, name)
        fix = (f"seconds of {what}" + (" (0: none)" if name == "standing_s" else "")
               + f", at most {MAX_SEGMENT_S:g}")
        seconds = (inputs.non_negative if allow_zero else inputs.positive)(_field(name), value, high=MAX_SEGMENT_S,
                                                                            fix=fix)
        if seconds > 0 and round(seconds * rate) < MIN_FRAMES:
            raise ConfigError(f"{_field(name)} = {value!r}: {round(seconds * rate)} frame(s) at {rate:g} Hz; give at "
                              f"least {MIN_FRAMES / rate:g} s ({MIN_FRAMES} frames) for {what}")
    knee = inputs.number(_field("knee_straight_error_rad"), cfg.knee_straight_error_rad)
    if abs(knee) > MAX_KNEE_STRAIGHT_ERROR_RAD:
        raise ConfigError(
            f"{_field('knee_straight_error_rad')} = {knee:g} rad ({math.degrees(knee):g} deg): the true knee's "
            f"distance from mechanical straight in the straight-leg phase must be within "
            f"{math.degrees(MAX_KNEE_STRAIGHT_ERROR_RAD):g} deg (a few tenths is typical; beyond, the leg is bent, not "
            "straight)")
    inputs.number(_field("period_scale"), cfg.period_scale, low=0.1, high=10,
                  fix="a factor on the posture motion's periods (2: twice as slow)")
    inputs.choice(_field("standing"), cfg.standing, STANDING)
    for name in ("jitter_m", "jitter_rad", "heldout_jitter_m", "heldout_jitter_rad"):
        inputs.non_negative(name, getattr(cfg, name), fix="the placement jitter's largest shift or yaw")


def session_id(cfg: CollectConfig, offsets, robot: str) -> str:
    """The session set's identity, written into every recording (field 'session') and
    its ground truth (meta 'session'): robot, floor and seed to read, and a hash of
    the whole config, the offsets injected and the results version, so that a truth
    file from another session set is told apart (`legcal_bench.data.recording.load_truth`)."""
    digest = stable_hash({"config": asdict(cfg), "offsets": [float(v) for v in offsets],
                          "results_version": RESULTS_VERSION})
    return f"{robot}-{cfg.mode}-seed{cfg.seed}-{digest[:10]}"


def stance_catalog(cfg: CollectConfig) -> tuple[dict, tuple[str, ...]]:
    """(every stance by name, the stances to record): the built-ins and `cfg.stances`,
    or with a protocol file its stances."""
    if cfg.protocol is None:
        return ALL_STANCES, tuple(cfg.stances)
    designed = load_protocol(cfg.protocol)
    return {**ALL_STANCES, **designed}, tuple(designed)


@dataclass
class SegmentSummary:
    name: str
    kind: str
    stance: str
    frames: int
    max_gyro: float
    joint_range_deg: list[float]
    max_sole_drift_mm: float
    max_sole_drift_deg: float
    unreachable: int
    stance_scale: float = 1.0  # the stance's placement and depth, shrunk to fit the robot (1: as designed)
    motion_scale: float = 1.0  # the posture motion's amplitude, shrunk to stay reachable and balanced
    hold: dict = field(default_factory=dict)  # the hold check's measurements (`HoldReport.to_dict`)


@dataclass
class CollectSummary:
    out_dir: str
    config: dict
    offsets_rad: list[float]
    joint_names: list[str]
    servo_gains: dict = field(default_factory=dict)  # in use, with their source (weld and contact modes)
    segments: list[SegmentSummary] = field(default_factory=list)
    wall_s: float = 0.0
    sim_s: float = 0.0
    # What the session set leaves out on this robot: a paper preset's roles it lacks
    # (`legcal_bench.sim.offsets.paper_note`), default stances its legs cannot stand in
    # (`legcal_bench.protocol.stances.stances_for`).
    notes: list[str] = field(default_factory=list)
    # Every held non-leg joint: at what, how, its largest departure over the segments
    # (`legcal_bench.sim.hold.held_joints_table`; weld and contact modes).
    held_joints: list[dict] = field(default_factory=list)


def _segments(cfg: CollectConfig, rng: np.random.Generator, catalog: dict, stances: tuple[str, ...]):
    if cfg.standing_s > 0:
        yield "standing", "standing", "standing", cfg.standing_s, 0.0, 0.0
    check_stance_names(stances, "stances", catalog)
    for s in stances:
        yield f"stance_{s}", "stance", s, cfg.stance_s, cfg.jitter_m, cfg.jitter_rad
    # Held-out sessions are drawn from the stances being recorded (a robot that cannot
    # hold a lunge is not asked for one in its held-out sessions either).
    for i in range(cfg.heldout):
        s = str(rng.choice(list(stances)))
        yield f"heldout_{i + 1}", "heldout", s, cfg.heldout_s, cfg.heldout_jitter_m, cfg.heldout_jitter_rad


PLACEMENT_TRIES = 5


class Segment(NamedTuple):
    obs: dict  # stacked observations (what the robot logs)
    truth: dict  # stacked ground truth
    stance_scale: float  # the stance's placement and depth, shrunk to fit the robot (1: as designed)
    motion_scale: float  # the posture motion's amplitude, shrunk to stay reachable and balanced


def is_collected(out_dir: str | Path, cfg: CollectConfig) -> bool:
    """True if `out_dir` holds a whole session set collected with `cfg` under the current
    `RESULTS_VERSION`: a cached set from other offsets, sensors or code is stale."""
    try:
        man = json.loads((Path(out_dir) / MANIFEST).read_text())
    except (OSError, ValueError):
        return False
    want = json.loads(json.dumps(asdict(cfg)))
    return isinstance(man, dict) and man.get("config") == want and man.get("results_version") == RESULTS_VERSION


def record_segment(sim: DoubleSupportSim, stance: str, duration: float, seed: int, jitter_m: float,
                   jitter_rad: float, progress=None, period_scale: float = 1.0, catalog: dict = ALL_STANCES,
                   stance_session: bool = False) -> Segment:
    """Run one segment of `stance` (fitted to the robot, `fit_stance`). The posture
    motion's IK is solved once, in one batch (`feasible_trajectory`), and handed to the
    simulator (`DoubleSupportSim.run`). `stance_session`: this is the stance's own
    (training) session, where a shim placed in that stance only sits."""
    rng = np.random.default_rng(seed)  # the stream Gymnasium's reset(seed=seed) gives the env
    fitted = fit_stance(catalog[stance], sim.nominal)
    for attempt in range(PLACEMENT_TRIES):
        # A jittered placement out of reach is drawn again (the built-ins never need to).
        placement = settled_placement(fitted.stance, sim.true_kin, rng, jitter_m, jitter_rad)
        try:
            sim.reset(placement.left, placement.right, placement.nominal, standing=stance == "standing",
                      stance=stance if stance_session else None)
            break
        except IKError as e:
            if attempt == PLACEMENT_TRIES - 1:
                fix = ("remove the shim or uneven floor (--effect) or give it as pitch, which the ankle takes"
                       if getattr(e, "unstandable", False) else "widen the joint's range in the MJCF if the real "
                       "robot allows it")
                raise IKError(f"stance {stance} ({catalog[stance].label}): its nominal posture is out of this "
                              f"robot's reach ({e}); record the other stances (--stances), or {fix}") from None
    sim.observe(rng)  # the reset observation (not logged; its noise draws keep the env's stream)
    n = int(round(duration * sim.rate_hz))
    low, high = posture_bounds(sim.nominal.dims)
    if stance == "standing":
        return Segment(*sim.run(np.clip(np.repeat(sim.posture[None], n, axis=0), low, high), rng,
                                progress=progress), 1.0, 1.0)
    motion = feasible_trajectory(sim.nominal, placement, duration, sim.rate_hz, np.random.default_rng(seed + 7919),
                                 return_q=True, period_scale=period_scale)
    clipped = np.clip(motion.postures, low, high)
    if any(fitted.stance.push):  # a load-varied stance: targets for soles displaced from where they are
        q_cmd = pushed_targets(sim.nominal, placement, clipped, motion.q[0], sim.rate_hz,
                               np.random.default_rng(seed + 104729))
    else:
        q_cmd = motion.q.copy()
        q_cmd[(clipped != motion.postures).any(axis=1)] = np.nan  # a clipped posture is solved by the simulator's step
    return Segment(*sim.run(clipped, rng, q_cmd=q_cmd, progress=progress), fitted.scale, motion.scale)


def pushed_targets(kin, placement, postures: np.ndarray, q_init: np.ndarray, rate_hz: float,
                   rng: np.random.Generator) -> np.ndarray:
    """(N, n) the servo targets (n leg joints) of a load-varied stance: each posture's IK with the soles
    displaced by the stance's push (`commanded_soles`); IKError naming the stance if a
    displaced sole is out of reach."""
    left, right = commanded_soles(placement, kin.dims, len(postures), rate_hz, rng)
    T_BW = inverse(posture_poses(postures))
    try:
        return kin.solve_batch(T_BW @ left, T_BW @ right, q_init)
    except IKError as e:
        raise IKError(f"stance {placement.stance.name} ({placement.stance.label}): its pushed soles are out of "
                      f"this robot's reach ({e}); give a smaller push in a protocol file (--protocol, field "
                      "'push') or leave the stance out") from None


G = 9.81
# A robot standing in double support has an IMU specific force of about 1 g (its motion
# adds a few per cent); a mean outside this band (in g) is a simulation shaking or
# diverging, not a posture.
STILL_G = (0.5, 2.0)


def check_simulation(sim: DoubleSupportSim, name: str, stance: str, truth: dict) -> None:
    """Raise SimulationError if the segment's simulation diverged (a state that is not
    finite) or shook (the IMU's true specific force far from 1 g), naming the body moving
    fastest at the segment's end and MuJoCo's own instability warning."""
    if sim.mode == "kinematic":
        return
    f = np.linalg.norm(np.asarray(truth["imu_true_acc"], dtype=float), axis=1)
    finite = all(np.isfinite(np.asarray(truth[k], dtype=float)).all()
                 for k in ("q_true", "imu_true_acc", "pelvis_pose_world"))
    if finite and STILL_G[0] * G <= f.mean() <= STILL_G[1] * G:
        return
    import mujoco

    model, data = sim.scene.model, sim.data
    speed = np.linalg.norm(data.cvel[:, 3:], axis=1)
    body = int(np.argmax(np.where(np.isfinite(speed), speed, np.inf))) if len(speed) else 0
    body_name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, body) or f"body {body}"
    bad_acc = int(data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)
    what = ("its state stopped being finite (NaN or infinite joint angles, pelvis pose or IMU)" if not finite else
            f"the IMU's true specific force averaged {f.mean():.3g} m/s^2 (peak {f.max():.3g}; a robot standing "
            f"still reads about {G:g})")
    raise SimulationError(
        f"segment {name}, stance {stance} ({sim.mode} mode): a simulation fault: the simulated robot did not stand "
        f"still: {what}; at the segment's end body '{body_name}' moved fastest ({speed[body]:.3g} m/s)"
        + (f"; MuJoCo reported unstable accelerations {bad_acc} time(s) (mjWARN_BADQACC)" if bad_acc else "")
        + ". Likely cause: servo gains too stiff for the simulation's time step (servo_gains in the leg map), or "
        "a held joint's servo too soft or too stiff for it (servo_gains naming a held joint), or a ball joint nothing "
        "holds; `legcal-bench info "
        "--robot <leg map>` lists the gains and the held joints")


def check_hold(sim: DoubleSupportSim, name: str, stance: str, truth: dict, gains_note: str = "",
               label: str | None = None) -> HoldReport:
    """The hold check of one recorded segment; raises HoldError naming the stance, what
    moved, the likely cause and the leg-map field that fixes it."""
    report = HoldReport.from_truth(truth, sim.true_kin.dims.leg_length)
    failures = report.failures()
    if sim.mode == "kinematic" or not failures:
        return report
    sc = sim.scene
    left = sim.sim_legmap.leg_slice("left")
    gains = ", ".join(f"{n} {kp:.0f}" for n, kp in zip(sim.sim_legmap.joint_names[left], sc.servo_kp[left]))
    fell = report.fell
    pelvis = not fell and report.pelvis_beyond_strain_m > report.pelvis_limit_m
    lacking = sim.sim_legmap.absent_roles
    twisted = not pelvis and not fell and report.soles_twisted
    cause = ("the posture with these offsets puts the robot off balance (the offsets move the centre of mass "
             "against the soles), or the servos cannot carry its weight" if fell else
             "the servos are too soft for the robot's weight (it sags or folds)" if pelvis else
             "the legs disagree (the offsets strain the closed chain) and twist a sole on the floor harder than "
             "friction holds it" if twisted else
             "the posture tips the robot onto a sole edge, or a sole slips" + (
                 (f"; legs without {', '.join(lacking)} cannot level a sole that the offsets of the joints above "
                  "it tilt (the hip roll's tilts it by as much), so on a contact floor it stands on an edge unless "
                  "the standing controller (--standing cop) levels it with the hip roll" if sim.regulator is None else
                  f"; legs without {', '.join(lacking)} level a sole with the hip roll, which moves it sideways too")
                 if lacking and sim.mode == "contact" else ""))
    fix = ("record this stance smaller (a protocol file with a smaller scale, --protocol) or leave it out "
           "(--stances); if the robot falls in every stance, give stiffer gains as servo_gains.<joint>: [kp, kd] "
           "in the leg map" if fell else
           "give stiffer gains as servo_gains.<joint>: [kp, kd] in the leg map (the default is k_role * m g L, "
           "see legcal_bench.protocol.servos)" if pelvis else
           ("stand with the standing controller (--standing cop), which yields the legs to the strain; it reads the "
            "ankle force/torque sensors (legs.<side>.ft in the leg map)" if sim.regulator is None else
            "record fewer stances (--stances)") if twisted else
           "check the sole frames and corners in the leg map (legs.<side>.sole, legs.<side>.corners), or record "
           "fewer stances (--stances)")
    raise HoldError(
        f"segment {name}, stance {stance} ({label or ALL_STANCES[stance].label}, {sim.mode} mode): the robot did not hold "
        f"the posture: {'; '.join(failures)}. Likely cause: {cause} (left-leg kp in use, N m/rad: {gains}; "
        f"sources {sorted(set(sc.servo_source))}{'; ' + gains_note if gains_note else ''}). Fix: {fix}.", report)


def collect(cfg: CollectConfig, out_dir: str | Path, progress: bool = True) -> CollectSummary:
    """Record the session set into `out_dir`, whole or not at all: the recordings are
    written to a temporary folder that replaces `out_dir` (a previous session set) only
    once every segment has passed the hold check. Raises HoldError if the robot does not
    hold a posture, IKError if a stance does not fit it."""
    check_config(cfg)  # again: a config's fields may have been changed since it was made
    out_dir = inputs.output_folder("out_dir", out_dir)
    with scratch_dir("reality") as workdir:
        legmap, reality = config_reality(cfg, workdir)
        return _collect(cfg, out_dir, progress, legmap, reality)


def config_reality(cfg: CollectConfig, workdir: str | Path) -> tuple[LegMap, Reality]:
    """The model's robot (leg map) and the simulated reality `cfg` records from: its
    simulated robot (`sim_robot`, `sim_model`; else the model's) with its effects applied,
    an edited model written under `workdir`. `collect`'s; the model-gap suite reads the
    same edited model to score against."""
    legmap = load_robot(cfg.robot, cfg.mjcf)
    sim_legmap = legmap
    if cfg.sim_robot is not None or cfg.sim_model is not None:
        sim_legmap = load_robot(cfg.sim_robot or cfg.robot, cfg.sim_model if cfg.sim_model else
                                (None if cfg.sim_robot else cfg.mjcf))
    return legmap, build_reality(legmap, sim_legmap, cfg.effects, sim_sensors(cfg.sensors), workdir, cfg.seed)


def standing_controller(cfg: CollectConfig, sim_legmap) -> str:
    """The standing controller `cfg.standing` asks for on `sim_legmap` ("auto" resolved)."""
    if cfg.standing != "auto":
        return cfg.standing
    has_ft = all(sim_legmap.legs[s].ft is not None for s in SIDES)
    return "cop" if cfg.mode == "contact" and has_ft else "none"


def _collect(cfg: CollectConfig, out_dir: Path, progress: bool, legmap, reality) -> CollectSummary:
    sim_legmap = reality.sim_legmap
    gains = servo_gains(sim_legmap) if cfg.mode != "kinematic" else None
    sim = DoubleSupportSim(
        legmap, cfg.mode, resolve_offsets(cfg.offsets, legmap, np.random.default_rng(cfg.seed)),
        reality.sensors, sim_legmap=sim_legmap if sim_legmap is not legmap else None, rate_hz=cfg.rate_hz,
        physics_dt=PHYSICS_DT,
        knee_straight_error_rad=cfg.knee_straight_error_rad, servo_gains=gains, floor=reality.floor,
        standing_controller=standing_controller(cfg, sim_legmap),
        contact_floor=floor_parameters(cfg.contact_floor) if cfg.contact_floor else None)
    catalog, stances = stance_catalog(cfg)
    left_out: list[str] = []
    if cfg.protocol is None and tuple(cfg.stances) == CollectConfig.stances:  # the default protocol
        catalog, stances, left_out = stances_for(sim.nominal, catalog, stances)
    unknown = sorted(floor_stances(reality.floor) - set(stances))
    if unknown:
        raise ConfigError(f"--effect shim:...,stance={unknown[0]}: stance {unknown[0]!r} is not recorded; "
                          f"use one of {list(stances)}")
    ss = np.random.SeedSequence(cfg.seed)
    plan = list(_segments(cfg, np.random.default_rng(ss.spawn(1)[0]), catalog, stances))
    seeds = [int(s.generate_state(1)[0]) for s in ss.spawn(len(plan) + 1)[1:]]
    total = sum(int(round(duration * cfg.rate_hz)) for _, _, _, duration, _, _ in plan)
    note = paper_note(cfg.offsets, legmap)
    summary = CollectSummary(str(out_dir), asdict(cfg), sim.offsets.tolist(), legmap.joint_names,
                             servo_gains=gains.to_dict() if gains else {}, notes=([note] if note else []) + left_out)
    session = session_id(cfg, sim.offsets, legmap.name)
    t0 = time.perf_counter()

    held_error = np.zeros(len(sim.scene.holds) if sim.scene is not None else 0)

    def write(folder: Path) -> None:
        files = []
        bar = tqdm(total=total, desc=f"collect {legmap.name} ({cfg.mode})", unit="frame", disable=not progress)
        for (name, kind, stance, duration, jm, jr), seed in zip(plan, seeds):
            bar.set_postfix_str(name)
            obs, tr, stance_scale, motion_scale = record_segment(sim, stance, duration, seed, jm, jr, bar,
                                                                 cfg.period_scale, catalog, kind == "stance")
            check_simulation(sim, name, stance, tr)
            hold = check_hold(sim, name, stance, tr, gains.note if gains else "", catalog[stance].label)
            if "held_joint_error_rad" in tr:
                np.maximum(held_error, np.abs(tr["held_joint_error_rad"]).max(axis=0, initial=0.0), out=held_error)
            rec = Recording(
                name=name, kind=kind, stance=stance, robot=legmap.name, joint_names=legmap.joint_names,
                time=tr["time"], q_enc=obs["q_enc"], imu_acc=obs["imu_acc"], imu_gyro=obs["imu_gyro"],
                sensor_model=sim.sensor.model, ft=obs.get("ft"), source=f"sim:{cfg.mode}", session=session,
                motion="static" if cfg.mode == "kinematic" else "continuous")
            path = rec.save(folder / f"{name}.npz")
            Truth(
                q_true=tr["q_true"], offsets=sim.offsets, sole_poses_world=tr["sole_poses_world"],
                pelvis_pose_world=tr["pelvis_pose_world"], posture=tr["posture"],
                posture_reachable=tr["posture_reachable"], imu_true_acc=tr["imu_true_acc"],
                imu_true_gyro=tr["imu_true_gyro"],
                q_enc_clean=clean_encoders(sim, tr["q_motor"], tr["time"]),
                meta={"session": session, "mode": cfg.mode, "sim_robot": sim.sim_legmap.name, "seed": seed,
                      "knee_straight_error_rad": cfg.knee_straight_error_rad if kind == "standing" else None,
                      "knee_straight_rad": sim.sim_legmap.knee_straight_rad, "offsets_spec": str(cfg.offsets),
                      "imu_errors": sim.sensor.errors.to_dict(), "reality": reality.describe(),
                      "encoder_scale": list(sim.sensor.encoder_scale)},
            ).save(truth_path(path))
            files.append(path.name)
            summary.segments.append(SegmentSummary(
                name=name, kind=kind, stance=stance, frames=rec.n_frames,
                max_gyro=float(np.abs(rec.imu_gyro).max()),
                joint_range_deg=np.rad2deg(np.ptp(tr["q_true"], axis=0)).round(2).tolist(),
                max_sole_drift_mm=float(tr["sole_drift_m"].max() * 1e3),
                max_sole_drift_deg=float(np.rad2deg(tr["sole_drift_rad"].max())),
                unreachable=int((~tr["posture_reachable"]).sum()), stance_scale=stance_scale,
                motion_scale=motion_scale, hold=hold.to_dict()))
        bar.close()
        if sim.scene is not None:
            summary.held_joints = held_joints_table(sim.scene.holds, held_error)
            loose = [h for h in summary.held_joints if h["how"] == "rigid" and not h["within_limit"]]
            if loose:
                summary.notes.append(
                    f"{len(loose)} rigidly held joint(s) moved more than {np.rad2deg(RIGID_HOLD_LIMIT_RAD):g} deg from "
                    "their hold angle: " + ", ".join(f"{h['joint']} {h['error_deg']:.3f} deg" for h in loose)
                    + " (the hold's equality yields under the joint's load; the calibration is unaffected, the "
                    "robot's mass distribution is not the model's)")
        write_manifest(folder, {"robot": legmap.name, "session": session, "mode": cfg.mode, "seed": cfg.seed,
                                "sensor_model": sim.sensor.model.to_dict(), "files": files, "config": asdict(cfg),
                                "results_version": RESULTS_VERSION,
                                "servo_gains": summary.servo_gains, "held_joints": summary.held_joints,
                                "stances": {g.name: {"stance": g.stance, "stance_scale": g.stance_scale,
                                                     "motion_scale": g.motion_scale, "hold": g.hold}
                                            for g in summary.segments}})

    replace_dir(out_dir, write, keep_if=is_session_dir)
    summary.wall_s = time.perf_counter() - t0
    summary.sim_s = total / cfg.rate_hz
    return summary


def clean_encoders(sim: DoubleSupportSim, q_motor: np.ndarray, time: np.ndarray | None = None) -> np.ndarray:
    """The encoders' noise-free readings (their scale error and reading laws included,
    `SimSensors.clean_readings`; `time` the series' timestamps) as the joints' angles."""
    return to_joint_space(sim.sensor.clean_readings(sim.encoder_input(q_motor), time), sim.encoder_map)


def format_summary(s: CollectSummary) -> str:
    lines = [
        f"wrote {len(s.segments)} recordings to {s.out_dir}  "
        f"({sum(g.frames for g in s.segments)} frames, {s.sim_s:.0f} s simulated in {s.wall_s:.1f} s wall, "
        f"{s.sim_s / max(s.wall_s, 1e-9):.1f}x real time)",
        "injected offsets (deg): " + ", ".join(
            f"{n.replace('_joint', '')} {np.rad2deg(v):+.3f}" for n, v in zip(s.joint_names, s.offsets_rad)),
        *s.notes,
    ]
    if s.servo_gains:
        g = s.servo_gains
        lines.append("servo gains kp (N m/rad): " + ", ".join(
            f"{n.replace('_joint', '')} {kp:.0f} ({src})"
            for n, kp, src in zip(s.joint_names[:len(s.joint_names) // 2], g["kp"], g["source"]))  # left leg first
            + f" (left leg; {g['note']})")
    if s.held_joints:
        rigid = [h for h in s.held_joints if h["how"] == "rigid"]
        servo = [h for h in s.held_joints if h["how"] == "servo"]
        worst = max(rigid, key=lambda h: h["error_deg"], default=None)
        lines.append("held joints (not in the leg map's legs): " + "; ".join(filter(None, [
            f"{len(rigid)} rigid (largest departure {worst['error_deg']:.4f} deg, {worst['joint']})" if rigid else "",
            (f"{len(servo)} on servos (sag, deg: "
             + ", ".join(f"{h['joint']} {h['sag_deg']:.3f}" for h in servo) + ")") if servo else ""])))
    lines.append(f"{'segment':<12} {'kind':<9} {'stance':<9} {'frames':>6} {'max|gyro|':>10} {'sole drift':>18} "
                 f"{'pelvis':>8} {'fit':>5} {'motion':>6} {f'joint range (deg, min..max over {len(s.joint_names)})':>36}")
    for g in s.segments:
        lines.append(
            f"{g.name:<12} {g.kind:<9} {g.stance:<9} {g.frames:>6} {g.max_gyro:>8.3f}/s "
            f"{g.max_sole_drift_mm:>8.4f} mm {g.max_sole_drift_deg:>6.4f}° "
            f"{g.hold.get('pelvis_mm', 0.0):>5.1f} mm {g.stance_scale:>5.2f} {g.motion_scale:>6.2f} "
            f"{min(g.joint_range_deg):>15.2f} .. {max(g.joint_range_deg):.2f}"
            + (f"  ({g.unreachable} unreachable postures held)" if g.unreachable else ""))
    shrunk = [g for g in s.segments if g.stance_scale < 1.0]
    if shrunk:
        lines.append("stances shrunk to fit this robot's joint limits (fit = placement and squat depth relative to "
                     "the protocol's): " + ", ".join(sorted({f"{g.stance} x{g.stance_scale:g}" for g in shrunk})))
    lines.append("pelvis: largest distance from the commanded pose; hold limits: pelvis 5 % of the leg length, "
                 "soles 2 mm and 1 deg (every segment passed)")
    return "\n".join(lines)
