"""A simulated long robot log (issue 39): standing, the four stances, walking and
stepping in place, with transitions, on one clock, for testing log import and the
automatic detection of static double-support segments.

`simulate_long_log(robot)` returns a `LongLog`: what a robot logs (encoders, pelvis IMU,
ankle force/torque) at one rate, a label per frame, and the injected offsets. In order:

  standing    straight legs, static                            physically simulated
  transition                                                   joined kinematically
  stance_I    ... stance_IV, a transition between each         physically simulated
  transition
  walking     forward, the frozen walking policy               physically simulated
  transition
  stepping    in place, the model-based teacher                physically simulated
  transition
  standing    straight legs again                              physically simulated

What is simulated, and how:

- standing and stances: the static double-support simulator in contact mode (a
  frictional floor, no welds), one segment each, exactly as `legcal-bench collect
  --mode contact` records them (`legcal_bench.protocol.collect.record_segment`: the
  stance fitted to the robot, a jittered placement, the posture motion, the standing
  controller `collect` would use), each passed through the collector's hold check. A
  stance the robot cannot stand in (`stances_for`) is left out.
- walking: the robot's frozen walking policy (`policies/walkers/<robot>`) in the
  walking env (`WalkingEnv`, its sensors read each control step through
  `WalkingSim.observe`). The policy stands still for about a second after its reset
  (its start-up clock); that start-up is simulated but not logged: the log takes
  `walk_s` from 0.1 s before the first foot lifts off, ending at the last frame with
  both feet loaded (within its last second).
- stepping in place: the frozen policy has no velocity command (it always walks at its
  trained speed), so stepping is the policy's teacher (`policies/zmp_walker.py`, the
  robot's recipe in `policies/teachers/`) with its step length replaced: the feet
  lift alternately on the teacher's cycloids. With a zero step length the teacher
  creeps forward (~2.5 cm/s on the A3-like robot, feet shuffling); two pilot walks (as
  long, step length 0 and 2 cm backward) measure the creep, and the logged stepping
  uses the step length that cancels it by linear interpolation (about 2 cm backward
  per step on the plan, which the shuffle cancels: the pelvis stays within ~2 cm
  forward; it still drifts a few cm sideways over 6 s). Its start-up is trimmed as the
  walk's.
- each part's ankle force/torque are the leg map's sensors (the same MuJoCo force and
  torque sensors at `legs.<side>.ft` in the static and the walking scenes, so one frame
  and sign convention: [fx fy fz tx ty tz], left then right; a loaded foot reads fz < 0
  on the built-ins). A robot without them logs NaN there.

The parts are separate simulations stitched on one clock: the world pose is not
continuous between parts (each has its own world frame), which a robot's log never
shows anyway. Every part has the same injected offsets (`offsets`, the `collect`
preset) and the same sensors (`sensors`, a `SENSOR_PRESETS` name: the encoders read
q_true - offsets plus noise, quantized; the IMU has the same realized bias and mounting
tilt), at the same rate (`rate_hz`; the walking parts run at their control rate, which
must be a whole multiple of it, and are logged every k-th control step).

Transitions (`transition_s`, 1.5 s) are not simulated: they join the last frame of one
part to the first of the next as a repositioning step would look, kinematically:

- joint angles: a cosine blend of the true angles, read by the same encoders. The
  inter-foot transform from forward kinematics changes along the blend, as it does
  when a foot is lifted and put down elsewhere (no lift of the foot is added);
- ankle force/torque: each foot's reading blends between the two ends; one foot (the
  left, then the right, alternately) is unloaded over the first quarter, stays
  unloaded (reading noise only: its own weight below the sensor is left out) through
  the middle half, and takes its load back over the last quarter; its vertical load
  goes to the other foot, added along that sensor's z axis;
- IMU: the accelerometer's gravity direction and magnitude blend between the two
  ends, with the pelvis swaying over the stance foot (5 cm sideways and 0.03 rad of
  roll, sin^4 profiles, so ~0.6 m/s^2 of lateral acceleration), the gyro reading the
  blend's rotation and the sway's roll rate. The ends' readings (means of what was
  logged, over 0.3 s for the IMU, which averages a walk's footfall shakes out, and 3
  frames for the force/torque, double support at every end) already carry the IMU's
  bias and mounting tilt; the sensor model's noise is added.

So a transition is neither static (the gyro and joints move) nor double support (one
foot unloaded in the middle half), which is what the detection must see. The ground
truth that a robot does not log (true angles, each part's pelvis pose in its own world
frame) is in `LongLog.truth`, NaN in the transitions' pelvis.

On the A3-like robot with the defaults the whole log (70.5 s, 3525 frames at 50 Hz)
takes 13-16 s on one core (the six static parts about 1.3 s each, loading the walking
policy about 3 s, the walk 0.5 s, the three stepping walks 1.5 s).
"""

from __future__ import annotations

import dataclasses
import time as _time
from dataclasses import dataclass, field

import numpy as np

from legcal_bench.errors import ConfigError, HoldError
from legcal_bench.robots.legmap import SIDES

LABELS = ("standing", "stance_I", "stance_II", "stance_III", "stance_IV", "walking", "stepping", "transition")
TRANSITION_S = 1.5  # s, each kinematic join
SWAY_M, SWAY_ROLL_RAD = 0.05, 0.03  # the pelvis's sway over the stance foot in a transition
END_MEAN_S = 0.3  # s, the IMU's reading at a part's end: its mean over this long (a walk's shakes averaged out)
WALK_LEAD_S = 0.1  # a walk is logged from this long before its first liftoff
PILOT_STEP_M = -0.02  # the second pilot walk's step length (stepping in place)
LOADED_FRACTION = 0.2  # of the weight on each foot: double support (where a walk's log ends)
WALK_TRIES = 3  # walks started again (another seed) if the robot falls


@dataclass
class LongLog:
    robot: str  # leg map name
    joint_names: list[str]  # the leg map's leg joints (left leg then right), = columns of q_enc
    time: np.ndarray  # (N,) s, from 0, one clock at rate_hz
    q_enc: np.ndarray  # (N, n) rad, encoder readings (true angles minus the injected offsets, plus sensor noise)
    imu_acc: np.ndarray  # (N, 3) m/s^2 pelvis IMU specific force, IMU frame
    imu_gyro: np.ndarray  # (N, 3) rad/s
    # (N, 2, 6) ankle force/torque [fx fy fz tx ty tz], left then right (NaN without sensors; None from `without_ft`)
    ft: np.ndarray
    labels: np.ndarray  # (N,) str: "standing", "stance_I".."stance_IV", "walking", "stepping", "transition"
    offsets: np.ndarray  # (n,) rad injected offsets (q_enc = q_true - offsets + noise)
    rate_hz: float
    # Ground truth a robot does not log: "q_true" (N, n), "pelvis_pose" (N, 7) [x y z qw qx
    # qy qz] in each part's own world frame (NaN in transitions), "part" (N,) the part's
    # index in `segments()`.
    truth: dict = field(default_factory=dict)
    sensors: str = "realistic"
    wall_s: float = 0.0  # time taken to simulate it

    @property
    def n_frames(self) -> int:
        return len(self.time)

    def segments(self) -> list[tuple[str, int, int]]:
        """The labels' runs in order: (label, first frame, stop frame)."""
        change = np.flatnonzero(self.labels[1:] != self.labels[:-1]) + 1
        starts, stops = np.r_[0, change], np.r_[change, len(self.labels)]
        return [(str(self.labels[a]), int(a), int(b)) for a, b in zip(starts, stops)]

    def without_ft(self) -> "LongLog":
        """The same log as a robot without ankle force/torque sensors logs it (ft None)."""
        return dataclasses.replace(self, ft=None)


@dataclass
class _Part:
    label: str
    q_true: np.ndarray  # (n, nj)
    q_enc: np.ndarray
    acc: np.ndarray
    gyro: np.ndarray
    ft: np.ndarray  # (n, 2, 6), NaN without sensors
    pelvis: np.ndarray  # (n, 7)


def simulate_long_log(robot: str = "a3", seed: int = 0, sensors: str = "realistic", rate_hz: float = 50.0,
                      stance_s: float = 8.0, walk_s: float = 6.0, progress: bool = False, *,
                      offsets: str = "paper", transition_s: float = TRANSITION_S) -> LongLog:
    """Simulate the long log (module docstring) of `robot` (a built-in with a frozen
    walker and a teacher recipe, or a leg map path whose name has them). `stance_s` is
    each standing and stance part's length, `walk_s` the walking's and the stepping's;
    `offsets` the injected offsets (a `collect` preset)."""
    from tqdm import tqdm

    from legcal_bench.protocol.collect import CollectConfig
    from legcal_bench.robots import load_robot

    if min(stance_s, walk_s) < 2.0 or transition_s < 0.5 or rate_hz <= 0:
        raise ConfigError(f"stance_s {stance_s}, walk_s {walk_s}, transition_s {transition_s}, rate_hz {rate_hz}: "
                          "need parts of at least 2 s, transitions of at least 0.5 s and a rate > 0")
    t0 = _time.perf_counter()
    legmap = load_robot(robot)
    cfg = CollectConfig(robot=robot, mode="contact", sensors=sensors, seed=seed, rate_hz=rate_hz, offsets=offsets)
    static = _StaticParts(cfg, legmap)
    plan = ["standing", *static.stances, "walking", "stepping", "standing"]
    # One seed per part and one for the transitions' noise.
    seeds = [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(len(plan) + 1)]
    parts: list[_Part] = []
    bar = tqdm(plan, desc=f"long log {legmap.name}", unit="part", disable=not progress)
    for k, name in enumerate(bar):
        bar.set_postfix_str(name)
        if name == "walking":
            parts.append(_walking_part(legmap, static.sim.offsets, sensors, rate_hz, walk_s, seeds[k]))
        elif name == "stepping":
            parts.append(_stepping_part(legmap, static.sim.offsets, sensors, rate_hz, walk_s, seeds[k]))
        else:
            parts.append(static.record(name, stance_s, seeds[k]))
    bar.close()
    rng = np.random.default_rng(seeds[-1])
    kin_R_BI = static.sim.nominal.R_BI
    n_tr = max(2, int(round(transition_s * rate_hz)))
    pieces: list[_Part] = []
    for k, p in enumerate(parts):
        if k:
            pieces.append(_transition(parts[k - 1], p, n_tr, SIDES[(k + 1) % 2], 1.0 / rate_hz, kin_R_BI,
                                      static.sim.sensor, static.sim.offsets, rng))
        pieces.append(p)
    cat = {f: np.concatenate([getattr(p, f) for p in pieces]) for f in ("q_true", "q_enc", "acc", "gyro", "ft",
                                                                         "pelvis")}
    labels = np.concatenate([np.full(len(p.q_enc), p.label) for p in pieces]).astype(str)
    part = np.concatenate([np.full(len(p.q_enc), i) for i, p in enumerate(pieces)])
    n = len(labels)
    return LongLog(robot=legmap.name, joint_names=list(legmap.joint_names), time=np.arange(n) / rate_hz,
                   q_enc=cat["q_enc"], imu_acc=cat["acc"], imu_gyro=cat["gyro"], ft=cat["ft"], labels=labels,
                   offsets=static.sim.offsets.copy(), rate_hz=float(rate_hz),
                   truth={"q_true": cat["q_true"], "pelvis_pose": cat["pelvis"], "part": part}, sensors=sensors,
                   wall_s=_time.perf_counter() - t0)


# ---------------------------------------------------------------- static parts
class _StaticParts:
    """The static double-support simulator as `collect` sets it up (contact mode)."""

    def __init__(self, cfg, legmap):
        from legcal_bench.protocol.collect import stance_catalog, standing_controller
        from legcal_bench.protocol.servos import servo_gains
        from legcal_bench.protocol.stances import stances_for
        from legcal_bench.sim.double_support import DoubleSupportSim
        from legcal_bench.sim.offsets import resolve_offsets
        from legcal_bench.errors import ConfigError
        from legcal_bench.robots.transmission import transmissions
        from legcal_bench.sim.sensors import sim_sensors

        from legcal_bench.robots.linkage import linked_joints

        moved = sorted(transmissions(legmap)) + linked_joints(legmap)
        if moved:  # its walking parts would log joint angles beside the static parts' motors'
            raise ConfigError(f"{legmap.source or legmap.name}: leg joints {moved} read "
                              "their encoders through a transmission or a linkage: simulate-log does not simulate them yet; "
                              "collect static sets (`collect`) instead")
        self.cfg = cfg
        self.gains = servo_gains(legmap)
        offsets = resolve_offsets(cfg.offsets, legmap, np.random.default_rng(cfg.seed))
        self.sim = DoubleSupportSim(legmap, "contact", offsets, sim_sensors(cfg.sensors), rate_hz=cfg.rate_hz,
                                    servo_gains=self.gains, standing_controller=standing_controller(cfg, legmap))
        catalog, stances = stance_catalog(cfg)
        self.catalog, self.stances, _ = stances_for(self.sim.nominal, catalog, stances)

    def record(self, stance: str, seconds: float, seed: int) -> _Part:
        from legcal_bench.protocol.collect import check_hold, record_segment

        cfg, sim = self.cfg, self.sim
        standing = stance == "standing"
        obs, tr, _, _ = record_segment(sim, stance, seconds, seed, 0.0 if standing else cfg.jitter_m,
                                       0.0 if standing else cfg.jitter_rad, catalog=self.catalog,
                                       stance_session=not standing)
        label = "standing" if standing else f"stance_{stance}"
        check_hold(sim, label, stance, tr, self.gains.note, self.catalog[stance].label)
        n = len(obs["q_enc"])
        ft = obs["ft"] if "ft" in obs else np.full((n, 2, 6), np.nan)
        return _Part(label, tr["q_true"], obs["q_enc"], obs["imu_acc"], obs["imu_gyro"], ft, tr["pelvis_pose_world"])


# --------------------------------------------------------------- walking parts
def _walking_part(legmap, offsets, sensors, rate_hz, seconds, seed) -> _Part:
    """The frozen walking policy, forward."""
    from legcal_bench.envs.walking import WalkingEnv
    from legcal_bench.policies.runner import PolicyRunner

    try:
        env = WalkingEnv(robot=legmap, policy=legmap.name, sensors=sensors)
    except ConfigError as e:
        raise ConfigError(f"robot {legmap.name}: the long log walks with its frozen walking policy "
                          f"(policies/walkers/{legmap.name}), which could not be loaded: {e}") from None
    runner = PolicyRunner(env.policy_spec, env.legmap)
    return _walk(env, runner, offsets, rate_hz, seconds, seed, "walking")


def _stepping_part(legmap, offsets, sensors, rate_hz, seconds, seed) -> _Part:
    """The teacher stepping in place: the step length that cancels its creep, from two pilots."""
    from legcal_bench.envs.walking import WalkingEnv, teacher_walking_config
    from legcal_bench.policies.zmp_walker import TEACHERS_DIR, ZmpWalker, load_teacher_recipe

    path = TEACHERS_DIR / f"{legmap.name}.yaml"
    if not path.is_file():
        raise ConfigError(f"robot {legmap.name}: the long log steps in place with the walking policy's teacher, "
                          f"and there is no recipe {path}")
    recipe = load_teacher_recipe(path)
    plan_s = seconds + recipe.gait.start_s + 3.0  # the logged window stays inside the stepping

    def walk(step_length: float) -> tuple[_Part, float]:
        gait = dataclasses.replace(recipe.gait, step_length=step_length)
        teacher = ZmpWalker(legmap, plan_s, gait, recipe.feedback)
        env = WalkingEnv(robot=legmap, sensors=sensors, walking=teacher_walking_config(legmap, recipe, teacher))
        part = _walk(env, teacher, offsets, rate_hz, seconds, seed, "stepping")
        # The creep: the pelvis's travel along its heading at the start.
        p = part.pelvis
        heading = _heading(p[0, 3:])
        return part, float(np.dot(p[-1, :2] - p[0, :2], heading))

    part0, d0 = walk(0.0)
    _, d1 = walk(PILOT_STEP_M)
    if abs(d1 - d0) < 1e-4:
        return part0
    length = float(np.clip(-d0 * PILOT_STEP_M / (d1 - d0), 3 * PILOT_STEP_M, -3 * PILOT_STEP_M))
    return walk(length)[0]


def _heading(quat: np.ndarray) -> np.ndarray:
    w, x, y, z = quat
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.array([np.cos(yaw), np.sin(yaw)])


def _walk(env, runner, offsets, rate_hz, seconds, seed, label) -> _Part:
    """One walk logged every k-th control step: from `WALK_LEAD_S` before the first
    liftoff, `seconds` long, ending at the last frame with both feet loaded. Started
    again with another seed if the robot falls (HoldError after `WALK_TRIES`)."""
    u = env.unwrapped
    every = u.dt * rate_hz
    k = int(round(1.0 / every)) if every > 0 else 0
    if k < 1 or abs(1.0 / every - k) > 1e-6:
        raise ConfigError(f"rate_hz {rate_hz:g}: the walking env's control rate ({1 / u.dt:g} Hz) must be a whole "
                          "multiple of the log's rate")
    for attempt in range(WALK_TRIES):
        out = _walk_once(env, runner, offsets, k, seconds, seed + 7919 * attempt, label)
        if out is not None:
            return out
    raise HoldError(f"the {label} part of the long log: {u.legmap.name} fell (or never lifted a foot) in "
                    f"{WALK_TRIES} walks with these offsets; use smaller offsets")


def _walk_once(env, runner, offsets, k, seconds, seed, label) -> _Part | None:
    from legcal_bench.sim.walking import LIFTOFF_FRACTION

    u = env.unwrapped
    sim = u.sim
    sc, d = sim.scene, sim.data
    obs, _ = env.reset(seed=seed, options={"offsets": np.asarray(offsets), "correction": None})
    runner.reset()
    lead = int(round(WALK_LEAD_S / u.dt))
    steps = int(round(seconds / u.dt))
    startup_max = int(round(4.0 / u.dt))
    rows = []
    liftoff = None
    settled = False  # both feet loaded once (the reset drops the robot onto its soles)
    i = 0
    while liftoff is None or i < liftoff - lead + steps:
        obs = u.advance(runner.act(obs, None, sim.time))
        if sim.fallen_at is not None or (liftoff is None and i > startup_max):
            return None
        both = bool(sim.loads.min() > LOADED_FRACTION * sim.weight)
        settled = settled or both
        if liftoff is None and settled and sim.loads.min() < LIFTOFF_FRACTION * sim.weight:
            liftoff = i
        rows.append((obs["q_enc"], obs["imu_acc"], obs["imu_gyro"], obs.get("ft"), d.qpos[sc.qpos_adr].copy(),
                     sim.pelvis_pose(), both))
        i += 1
    first = max(0, liftoff - lead)
    rows = rows[first:]
    # End on double support: the last such step of the final step period, else the last.
    both = np.flatnonzero([r[6] for r in rows])
    period = int(round(1.0 / u.dt))
    end = both[-1] + 1 if both.size and both[-1] >= len(rows) - period else len(rows)
    rows = rows[:end][::-1][::k][::-1]  # every k-th control step, ending on the last
    n = len(rows)
    ft = (np.stack([r[3] for r in rows]) if rows[0][3] is not None else np.full((n, 2, 6), np.nan))
    return _Part(label, np.stack([r[4] for r in rows]), np.stack([r[0] for r in rows]),
                 np.stack([r[1] for r in rows]), np.stack([r[2] for r in rows]), ft,
                 np.stack([r[5] for r in rows]))


# ----------------------------------------------------------------- transitions
def _transition(a: _Part, b: _Part, n: int, swing: str, dt: float, R_BI: np.ndarray, sensor, offsets,
                rng: np.random.Generator) -> _Part:
    """`n` frames joining part `a`'s end to part `b`'s start kinematically (module
    docstring): blended joints, a foot unloaded in the middle half, a sway on the IMU."""
    from scipy.spatial.transform import Rotation

    s = np.arange(1, n + 1) / (n + 1)
    T = (n + 1) * dt
    c = ((1 - np.cos(np.pi * s)) / 2)[:, None]
    q_true = (1 - c) * a.q_true[-1] + c * b.q_true[0]
    q_enc = sensor.encoders(q_true - offsets, rng)
    m = sensor.model

    w = max(3, int(round(END_MEAN_S / dt)))

    def ends(x: _Part, first: bool) -> np.ndarray:
        return np.stack([v[:w] if first else v[-w:] for v in (x.acc, x.gyro)]).mean(axis=1)

    (acc_a, gyro_a), (acc_b, gyro_b) = ends(a, False), ends(b, True)
    # Gravity's direction and magnitude blended; the pelvis rolls and sways over the stance foot.
    sign = 1.0 if swing == "right" else -1.0  # the stance foot's side (+y left)
    u = (1 - c) * acc_a / np.linalg.norm(acc_a) + c * acc_b / np.linalg.norm(acc_b)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    g = (1 - c) * np.linalg.norm(acc_a) + c * np.linalg.norm(acc_b)
    sn, cs = np.sin(np.pi * s), np.cos(np.pi * s)
    bump = sn ** 4  # sway profile: zero with its two derivatives' ends at both ends
    bump_dd = 4 * np.pi ** 2 * sn ** 2 * (3 * cs ** 2 - sn ** 2) / T ** 2
    bump_d = 4 * np.pi * sn ** 3 * cs / T
    x_I, y_I = R_BI.T[:, 0], R_BI.T[:, 1]  # the pelvis's forward and left axes in the IMU frame
    roll = Rotation.from_rotvec(-(sign * SWAY_ROLL_RAD * bump)[:, None] * x_I)
    acc = roll.apply(g * u) + (sign * SWAY_M * bump_dd)[:, None] * y_I
    du = np.gradient(u, dt, axis=0)
    gyro = (1 - c) * gyro_a + c * gyro_b + np.cross(du, u) + (sign * SWAY_ROLL_RAD * bump_d)[:, None] * x_I
    acc = acc + m.accel_noise_std * rng.standard_normal(acc.shape)
    gyro = gyro + m.gyro_noise_std * rng.standard_normal(gyro.shape)
    # Force/torque: each foot's blend; the swing foot's load handed to the stance foot.
    base = (1 - c[:, :, None]) * a.ft[-3:].mean(axis=0) + c[:, :, None] * b.ft[:3].mean(axis=0)  # NaN stays NaN
    w = np.where(s < 0.25, 1 - _smoothstep(s / 0.25), np.where(s > 0.75, _smoothstep((s - 0.75) / 0.25), 0.0))
    i_sw, i_st = SIDES.index(swing), 1 - SIDES.index(swing)
    ft = base.copy()
    ft[:, i_sw] *= w[:, None]
    ft[:, i_st, 2] += (1 - w) * base[:, i_sw, 2]
    ft = ft + m.ft_std * rng.standard_normal(ft.shape)
    return _Part("transition", q_true, q_enc, acc, gyro, ft, np.full((n, 7), np.nan))


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)
