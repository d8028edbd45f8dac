"""The model-based walker, the teacher of our walking policies (issue #14): footsteps,
a ZMP reference, the CoM from ZMP preview control, swing-foot arcs, joint targets by
closed-chain IK, and balance feedback on the IMU.

The gait: from a standing squat (`GaitParams.depth` below straight legs), the soles
`width` further apart than at zero (each side), steps of `step_length` every
`step_period`, the right foot first; each step begins with a double
support share in which the ZMP shifts to the stance foot, then the swing foot travels
on a cycloid (`lift` high). The CoM follows the ZMP through `zmp_preview.track` (height:
the pelvis's), the pelvis is the CoM less its offset at the starting pose, and the
joint targets come from one batch of closed-chain IK with both soles where the plan
puts them (`joint_targets`), computed once per walker.

`ZmpWalker` adds `Feedback`: the torso's roll and pitch from the IMU filter's gravity
direction (optionally less their slow mean) and the gyro's rate, turned into ankle
roll/pitch and hip roll/pitch corrections on each leg in proportion to its share of the
load (ankle force/torque where the robot has it, else the plan's stance). It reads only
the robot's sensors. `TeacherRecipe` (a `legcal-teacher/1` YAML file; the built-in
robots' are in policies/teachers/) holds a robot's gait, feedback and rates.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from legcal_bench.geometry.lie import inverse
from legcal_bench.geometry.poses import pose_xyz_rpy, posture_poses
from legcal_bench.policies.zmp_preview import preview_gains, track
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots.legmap import SIDES
from legcal_bench.sim.double_support import posture_ik


@dataclass(frozen=True)
class GaitParams:
    step_length: float = 0.12  # m
    step_period: float = 0.5  # s per step
    double_support: float = 0.2  # share of a step with both feet down
    lift: float = 0.04  # m, swing-foot height
    depth: float = 0.08  # squat depth, leg lengths
    start_s: float = 1.0  # standing before the first step
    end_s: float = 1.5  # standing after the last
    dt: float = 0.01  # s, the plan's (and the walker's control) period
    com_x_bias: float = 0.0  # m, the planned CoM ahead (+) or behind (-) of the ZMP reference
    width: float = 0.0  # m added to each sole's lateral distance from the midline (a wider stance)


@dataclass
class Gait:
    time: np.ndarray  # (n,)
    zmp: np.ndarray  # (n, 2) reference
    left: np.ndarray  # (n, 3) sole positions (flat soles)
    right: np.ndarray
    distance: float  # planned forward distance (m)


def plan_gait(kin: LegKinematics, n_steps: int, p: GaitParams = GaitParams()) -> Gait:
    """Footsteps and the ZMP reference for `n_steps` steps (the last one closes the feet)."""
    y0, dt = kin.dims.foot_y + p.width, p.dt
    n = int(round((p.start_s + n_steps * p.step_period + p.end_s) / dt))
    t = np.arange(n) * dt
    feet = {"left": np.zeros((n, 3)), "right": np.zeros((n, 3))}
    feet["left"][:, 1], feet["right"][:, 1] = y0, -y0
    zmp = np.zeros((n, 2))
    x = {"left": 0.0, "right": 0.0}
    for i in range(n_steps):
        swing = "right" if i % 2 == 0 else "left"
        stance = "left" if swing == "right" else "right"
        start = x[swing]
        target = max(x.values()) if i == n_steps - 1 else x[stance] + p.step_length
        t0 = p.start_s + i * p.step_period
        k0, k1 = int(round(t0 / dt)), int(round((t0 + p.step_period) / dt))
        s = (t[k0:k1] - t0) / p.step_period
        mid = np.array([(x["left"] + x["right"]) / 2, 0.0])
        foot = np.array([x[stance], y0 if stance == "left" else -y0])
        a = np.clip(s / p.double_support, 0, 1)[:, None]
        zmp[k0:k1] = mid + a * (foot - mid)
        b = np.clip((s - p.double_support) / (1 - p.double_support), 0, 1)
        feet[swing][k0:k1, 0] = start + (target - start) * (b - np.sin(2 * np.pi * b) / (2 * np.pi))
        feet[swing][k0:k1, 2] = p.lift * (1 - np.cos(2 * np.pi * b)) / 2
        x[swing] = target
        feet[swing][k1:, 0] = target
    end = int(round((p.start_s + n_steps * p.step_period) / dt))
    zmp[end:] = [(x["left"] + x["right"]) / 2, 0.0]
    return Gait(t, zmp, feet["left"], feet["right"], max(x.values()))


def joint_targets(kin: LegKinematics, gait: Gait, p: GaitParams = GaitParams()) -> np.ndarray:
    """(n, n_joints) joint targets: the CoM by preview control, the pelvis under it, IK."""
    z = kin.dims.leg_length * (1 - p.depth)
    g = preview_gains(z, p.dt)
    cx, _ = track(g, gait.zmp[:, 0])
    cy, _ = track(g, gait.zmp[:, 1])
    postures = np.zeros((len(gait.time), 6))
    postures[:, 2] = z
    q = posture_ik(kin, pose_xyz_rpy(gait.left[0], [0, 0, 0]), pose_xyz_rpy(gait.right[0], [0, 0, 0]), postures[:1])[0]
    com = kin.com(q)  # the CoM in the pelvis frame at the starting pose
    postures[:, 0], postures[:, 1] = cx[:, 0] + p.com_x_bias - com[0], cy[:, 0] - com[1]
    # One batch: every frame's (flat) soles in the pelvis frame, Newton from the starting pose.
    T_BW = inverse(posture_poses(postures))
    flat = np.zeros((len(gait.time), 3))
    T_left, T_right = (T_BW @ posture_poses(np.hstack([P, flat])) for P in (gait.left, gait.right))
    return kin.solve_batch(T_left, T_right, q)


FED_BACK = {"ankle_roll": 0, "hip_roll": 0, "ankle_pitch": 1, "hip_pitch": 1}  # role -> torso axis it corrects


@dataclass(frozen=True)
class Feedback:
    """The teacher's balance feedback: torso attitude (from the IMU's gravity direction
    and the gyro) turned into ankle and hip-roll corrections on the loaded leg(s)."""

    roll_p: float = 1.0  # rad of stance ankle roll per rad of torso roll
    roll_d: float = 0.05  # ... per rad/s of roll rate
    pitch_p: float = 0.5  # rad of stance ankle pitch per rad of torso pitch
    pitch_d: float = 0.02
    hip_roll_p: float = 0.0  # rad of stance hip roll per rad of torso roll
    hip_pitch_p: float = 0.0  # rad of stance hip pitch per rad of torso pitch
    tilt_tau: float = 0.0  # s; > 0: feed back the tilt minus its slow mean (time constant)


class ZmpWalker:
    """The model-based teacher: the gait plan's joint targets (`joint_targets`, computed
    once) plus `Feedback` on the IMU, applied to each leg in proportion to its share of
    the measured load (ankle force/torque where the robot has it, else the plan's
    stance). Same interface as `PolicyRunner`: `reset()`, `act(obs, info, time)`."""

    def __init__(self, legmap, seconds: float, gait: GaitParams = GaitParams(), feedback: Feedback = Feedback()):
        kin = LegKinematics(legmap)
        self.gait, self.feedback = gait, feedback
        n_steps = int(np.ceil(max(seconds - gait.start_s, 0.0) / gait.step_period)) + 2
        self.plan = plan_gait(kin, n_steps, gait)
        self.Q = joint_targets(kin, self.plan, gait)
        # Each fed-back joint of each leg: its column and the sign of its axis along the
        # torso axis it corrects (x for roll, y for pitch), so any robot's conventions work.
        roles, axes = list(legmap.joint_roles), kin.joint_axes(self.Q[0])
        # A role the robot lacks (no ankle roll) has no column and gets no correction.
        self.joints = [[(i, float(np.sign(axes[i, FED_BACK[roles[i]]]) or 1.0))
                        for i in range(legmap.n_joints)[legmap.leg_slice(side)] if roles[i] in FED_BACK]
                       for side in SIDES]
        self.roles = roles
        self.planned_load = np.stack([(self.plan.right[:, 2] > 1e-9) | (self.plan.left[:, 2] <= 1e-9),
                                      (self.plan.left[:, 2] > 1e-9) | (self.plan.right[:, 2] <= 1e-9)], 1).astype(float)
        self.default_q = self.Q[0]
        self.reset()

    privileged: list = []  # it reads only the robot's own sensors
    name = "zmp_teacher"

    def reset(self) -> None:
        self._slow = np.zeros(2)

    def act(self, obs: dict, info: dict, time: float) -> np.ndarray:
        p, f = self.gait, self.feedback
        k = min(int(round(time / p.dt)), len(self.Q) - 1)
        q = self.Q[k].copy()
        g, w = obs["gravity"], obs["ang_vel"]
        tilt = np.array([np.arctan2(-g[1], -g[2]), np.arcsin(np.clip(g[0], -1, 1))])
        if f.tilt_tau > 0:
            self._slow += (tilt - self._slow) * min(p.dt / f.tilt_tau, 1.0)
            tilt = tilt - self._slow
        if "ft" in obs:
            load = np.linalg.norm(obs["ft"][:, :3], axis=1)
        else:
            load = self.planned_load[k]
        share = load / max(load.sum(), 1e-9)
        correction = {"ankle_roll": f.roll_p * tilt[0] + f.roll_d * w[0],
                      "ankle_pitch": f.pitch_p * tilt[1] + f.pitch_d * w[1],
                      "hip_roll": f.hip_roll_p * tilt[0], "hip_pitch": f.hip_pitch_p * tilt[1]}
        for leg, joints in enumerate(self.joints):
            for i, sign in joints:
                q[i] += share[leg] * sign * correction[self.roles[i]]
        return q


TEACHER_FORMAT = "legcal-teacher/1"
TEACHERS_DIR = Path(__file__).resolve().parent / "teachers"  # the built-in robots' recipes


@dataclass(frozen=True)
class TeacherRecipe:
    """The teacher for one robot: its gait, its feedback and its rates (a YAML file,
    `format: legcal-teacher/1`, with sections `gait` (GaitParams fields), `feedback`
    (Feedback fields) and `rates` {physics_hz, control_hz}; `dt` follows control_hz)."""

    gait: GaitParams
    feedback: Feedback
    physics_hz: float = 500.0
    control_hz: float = 100.0
    path: str | None = None


def load_teacher_recipe(path) -> TeacherRecipe:
    """Read and check a teacher recipe; ConfigError naming the field and the fix."""
    import yaml

    from legcal_bench.errors import ConfigError

    from legcal_bench.files.packaged import packaged

    # A path from the working directory, else a built-in robot's recipe by its name (`a3`).
    path = packaged(path, {p.stem: p for p in TEACHERS_DIR.glob("*.yaml")})
    where = f"teacher recipe {path}"
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as e:
        raise ConfigError(f"{where}: not a readable YAML file ({e})") from None
    if not isinstance(doc, dict) or doc.get("format") != TEACHER_FORMAT:
        raise ConfigError(f"{where}: field 'format' must be {TEACHER_FORMAT!r} (see policies/teachers/)")
    unknown = set(doc) - {"format", "robot", "gait", "feedback", "rates", "notes"}
    if unknown:
        raise ConfigError(f"{where}: unknown fields {sorted(unknown)}; known: format, robot, gait, feedback, rates, "
                          "notes")
    rates = doc.get("rates") or {}
    try:
        physics_hz, control_hz = float(rates.get("physics_hz", 500.0)), float(rates.get("control_hz", 100.0))
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: rates.physics_hz and rates.control_hz must be numbers (Hz)") from None
    if control_hz <= 0 or physics_hz < control_hz or abs(physics_hz / control_hz - round(physics_hz / control_hz)) > 1e-9:
        raise ConfigError(f"{where}: rates: physics_hz must be a whole multiple of control_hz > 0")
    parts = {}
    for section, cls in (("gait", GaitParams), ("feedback", Feedback)):
        values = doc.get(section) or {}
        if not isinstance(values, dict):
            raise ConfigError(f"{where}: '{section}' must be a mapping of {cls.__name__} fields")
        bad = set(values) - set(cls.__dataclass_fields__) - ({"dt"} if section == "gait" else set())
        if bad:
            raise ConfigError(f"{where}: {section}: unknown fields {sorted(bad)}; known: "
                              f"{sorted(set(cls.__dataclass_fields__) - {'dt'})}")
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in values.values()):
            raise ConfigError(f"{where}: {section}: every value must be a finite number")
        parts[section] = cls(**{k: float(v) for k, v in values.items() if k != "dt"},
                             **({"dt": 1.0 / control_hz} if section == "gait" else {}))
    g = parts["gait"]
    if not (0 < g.double_support < 1 and g.step_period > 0 and g.step_length >= 0 and g.lift > 0 and 0 < g.depth < 1):
        raise ConfigError(f"{where}: gait: need step_period > 0, step_length >= 0, lift > 0, 0 < double_support < 1, "
                          "0 < depth < 1")
    return TeacherRecipe(parts["gait"], parts["feedback"], physics_hz, control_hz, str(path))
