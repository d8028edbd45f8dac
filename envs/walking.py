"""Free-standing walking on a frictional floor, with offset encoders.

## Description
A humanoid stands on a flat floor and walks under joint-position targets. Its encoders
read q_enc = q_true - dq (the injected offsets, plus noise); a correction dq_hat (a
calibration's estimate) is applied as a robot applies it, q_enc + dq_hat, before both
the observation and the servo loop, so uncorrected offsets bend the real posture. The
physics is `legcal_bench.sim.walking.WalkingSim` (PD servos at physics rate inside
MuJoCo's step, the walking-only model additions of `WalkingConfig`).

## Action space
`Box(n)`: joint position targets, one per leg joint (n = `legmap.n_joints`: 12 for
six-joint legs, 10 without ankle roll; rad, leg-map order, encoder space: what the
robot's software commands), within the joints' ranges widened by 0.5 rad. With a
whole-body policy's spec, the leg joints are followed by the policy's other joints
(waist, arms) and the joints its spec holds (`WalkingConfig.extra_joints`).

## Observation space
`Dict`, what the robot's software reads, in leg-map order and the base frame through
the nominal IMU mount: `q_enc` (n,) corrected encoder angles (rad), `dq_enc` (n,)
joint velocities (rad/s), `ang_vel` (3,) the gyro's rate (rad/s), `gravity` (3,) the
unit gravity direction from an orientation filter on the IMU (its noise, bias and
mounting tilt included), `imu_acc`, `imu_gyro` (3,) raw IMU readings (IMU frame),
`ft` (2, 6) ankle force/torque where the leg map has them, and with a whole-body policy
`q_extra`, `dq_extra`: its other joints' encoders (no offsets) and velocities.

## Rewards
None (0): the env evaluates fixed policies; what a run did is in `info`.

## Starting state
`reset(seed=..., options={"offsets": ..., "correction": ...})` stands the robot at the
default pose (the policy spec's `default_q`, or for a robot without a spec stance I's
squat) with the servos holding it, its lowest sole corner on the floor, with a seeded
jitter of +-0.01 rad per joint and +-0.02 rad of heading. The seed also drives the
sensor noise. Options override the constructor's `offsets` (a preset: `none`,
`paper`, `paper@<deg>`, `random:<deg>`, or one radian per leg joint) and `correction` (one radian per leg
joint, or None).

## Episode end
Terminates when the robot falls: the pelvis below 60 % of its starting height or
tilted more than 1 rad (`legcal_bench.sim.walking`). Registered ids truncate after
1000 steps (20 s at 50 Hz).

## Info
The truth: `time`, `pelvis_pose` [x y z qw qx qy qz], `base_lin_vel` (base frame;
privileged), `q_true`, `torque` (n, N m), `power` (W, sum |tau qdot|), `foot_loads`
(N, left/right), `new_strikes` (this step's touchdowns: (side, time, [x, y, z])),
`strike_counts`, `fallen`, `fallen_at`, `offsets`, `correction`, `sensors` (the MJCF
sensors a spec's privileged `sensor` terms name) and `gravity_true` (the IMU frame's
true gravity direction; privileged). Every touchdown so far: `env.unwrapped.sim.strikes`.

## Arguments
`robot` (built-in name or leg-map path; required for the `-Path-` id), `policy` (a
policy spec: its gains, default pose and rates configure the servos; the policy itself
is run by `legcal_bench.evaluation.walk`), `offsets`, `correction`, `sensors` (`zero`,
`realistic`, `calibrated-imu` or a sensor-model dict), `offset_seed` (for `random:`),
`mjcf`, `walking` (a `WalkingConfig`, overriding the spec's), `render_mode`
(`rgb_array`), `width`, `height`. A bad argument raises `ConfigError` naming it and the
fix at construction (`gym.make` too), and an action of the wrong length, not numbers
or not finite at `step`; finite targets past the action space go to the servos as given.

## Version History
* v0: the first version.
"""

from __future__ import annotations

from os import PathLike
from typing import Any

import numpy as np
from gymnasium import spaces

from legcal_bench import inputs
from legcal_bench.envs.base import MujocoEnv, named
from legcal_bench.sim.double_support import PHYSICS_DT_RANGE
from legcal_bench.errors import ConfigError, LegMapError
from legcal_bench.policies.runner import walking_config
from legcal_bench.policies.spec import PolicySpec, load_policy_spec
from legcal_bench.protocol.servos import servo_gains
from legcal_bench.protocol.stances import STANCES, fit_stance, place
from legcal_bench.robots import load_robot
from legcal_bench.robots.legmap import LegMap
from legcal_bench.sim.double_support import posture_ik
from legcal_bench.sim.offsets import resolve_offsets
from legcal_bench.sim.sensors import SensorModel, SimSensors, sim_sensors
from legcal_bench.sim.walking import WalkingConfig, WalkingSim

RESET_OPTIONS = ("offsets", "correction")


def default_walking_config(legmap: LegMap) -> WalkingConfig:
    """For a robot without a policy spec: the servo gains `collect` uses and stance I's
    nominal squat as the default pose."""
    from legcal_bench.robots.kinematics import LegKinematics

    kin = LegKinematics(legmap)
    p = place(fit_stance(STANCES["I"], kin).stance, kin.dims)
    q = posture_ik(kin, p.left, p.right, p.nominal[None])[0]
    g = servo_gains(legmap)
    return WalkingConfig(kp=tuple(g.kp), kd=tuple(g.kd), default_q=tuple(q.tolist()), integrator="implicitfast")


def teacher_walking_config(legmap: LegMap, recipe, walker) -> WalkingConfig:
    """For the model-based teacher (`legcal_bench.policies.zmp_walker`): the `collect`
    servo gains, its plan's first pose, its recipe's rates."""
    from dataclasses import replace

    return replace(default_walking_config(legmap), default_q=tuple(float(v) for v in walker.default_q),
                   physics_dt=1.0 / recipe.physics_hz, decimation=int(round(recipe.physics_hz / recipe.control_hz)))


def _correction(value, where: str, legmap: LegMap) -> np.ndarray:
    n = legmap.n_joints
    if value is None:
        return np.zeros(n)
    try:
        c = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        c = np.full(0, np.nan)
    if c.shape != (n,) or not np.isfinite(c).all():
        raise ConfigError(f"{where}: give {n} finite radians, one per leg joint of {legmap.name} in leg-map order "
                          "(a calibration's offsets), or None")
    return c


def _policy(policy) -> PolicySpec | None:
    if policy is None or isinstance(policy, PolicySpec):
        return policy
    if not isinstance(policy, (str, PathLike)):
        raise ConfigError(f"policy = {policy!r}: give a policy spec YAML's path, one of our policies (a2, a3), a "
                          "PolicySpec, or None (the servos hold the default pose)")
    return named("policy", load_policy_spec, policy)


def _walking(walking) -> WalkingConfig:
    """A WalkingConfig whose physics step is in range (its own checks did the rest)."""
    if not isinstance(walking, WalkingConfig):
        raise ConfigError(f"walking = {walking!r}: give a legcal_bench.sim.walking.WalkingConfig, or None (the "
                          "policy spec's, or for a robot without one the collect servo gains)")
    inputs.number("walking.physics_dt", walking.physics_dt, low=PHYSICS_DT_RANGE[0], high=PHYSICS_DT_RANGE[1],
                  fix="the MuJoCo time step in seconds, e.g. 0.002")
    inputs.count("walking.decimation", walking.decimation, fix="physics steps per control step, e.g. 10")
    return walking


class WalkingEnv(MujocoEnv):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}
    action_doc = "joint position targets (rad, encoder space), the leg joints in leg-map order, then a whole-body " \
                 "policy's other joints"

    def __init__(
        self,
        robot: str | LegMap | None = None,
        policy: str | PolicySpec | None = None,
        offsets: str | np.ndarray = "none",
        correction: np.ndarray | None = None,
        sensors: str | SimSensors | SensorModel | dict = "realistic",
        offset_seed: int = 0,
        mjcf: str | None = None,
        walking: WalkingConfig | None = None,
        render_mode: str | None = None,
        width: int = 640,
        height: int = 480,
        **unknown,
    ):
        self._refuse_unknown(unknown)
        if robot is None:
            raise LegMapError("robot: give a built-in name or the path of a leg map, e.g. "
                              "gym.make('legcal/Walking-Path-v0', robot='robot.legmap.yaml', policy='policy.yaml')")
        offset_seed = inputs.seed("offset_seed", offset_seed)
        self.legmap = robot if isinstance(robot, LegMap) else load_robot(robot, mjcf)
        self.policy_spec = _policy(policy)
        if walking is None:
            walking = (walking_config(self.policy_spec, self.legmap) if self.policy_spec is not None
                       else default_walking_config(self.legmap))
        walking = _walking(walking)
        self.offsets = named("offsets", resolve_offsets, offsets, self.legmap, np.random.default_rng(offset_seed))
        self.correction = _correction(correction, "correction", self.legmap)
        self.sim = WalkingSim(self.legmap, walking, named("sensors", sim_sensors, sensors))
        super().__init__(walking.physics_dt, walking.decimation, render_mode, width, height)
        self._offset_seed = offset_seed
        self.offsets_spec = offsets
        m, sc = self.sim.model, self.sim.scene
        g = m.vis.global_
        if render_mode is not None and (self.width > g.offwidth or self.height > g.offheight):
            raise ConfigError(f"width, height = {self.width}, {self.height}: larger than the model's offscreen "
                              f"buffer ({g.offwidth} x {g.offheight}); give at most that")
        jnt = m.dof_jntid[self.sim.body_dof]  # the leg joints, then a whole-body policy's others
        low = np.where(m.jnt_limited[jnt], m.jnt_range[jnt, 0] - 0.5, -np.pi)
        high = np.where(m.jnt_limited[jnt], m.jnt_range[jnt, 1] + 0.5, np.pi)
        self.action_space = spaces.Box(low=low, high=high, dtype=np.float64)
        box = lambda *shape: spaces.Box(-np.inf, np.inf, shape, np.float64)  # noqa: E731
        n = self.legmap.n_joints
        obs = {"q_enc": box(n), "dq_enc": box(n), "ang_vel": box(3), "gravity": box(3), "imu_acc": box(3),
               "imu_gyro": box(3)}
        if sc.has_ft:
            obs["ft"] = box(2, 6)
        if walking.extra_joints:
            obs["q_extra"] = box(len(walking.extra_joints))
            obs["dq_extra"] = box(len(walking.extra_joints))
        self.observation_space = spaces.Dict(obs)
        self._counts = {"left": 0, "right": 0}

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = self._reset_options(options, RESET_OPTIONS)
        if "offsets" in options:
            self.offsets = named("reset option offsets", resolve_offsets, options["offsets"], self.legmap,
                                 np.random.default_rng(self._offset_seed))
        if "correction" in options:
            self.correction = _correction(options["correction"], "reset option correction", self.legmap)
        self.sim.reset(self.offsets, self.correction, self.np_random)
        self._counts = {"left": 0, "right": 0}
        return self._observe(), self._info()

    def step(self, action):
        """ConfigError for an action of the wrong length, not numbers or not finite."""
        obs = self.advance(action)
        return obs, 0.0, self.sim.fallen_at is not None, False, self._info()

    def advance(self, action) -> dict:
        """`step` without its info dict (the truth, from `sim`, when asked): the
        observation. For a caller that reads the truth itself (`evaluation.walk`)."""
        self.sim.step(self._action(action))
        return self._observe()

    def _observe(self) -> dict:
        o = self.sim.observe(self.np_random)
        o["ang_vel"] = self.sim.R_BI @ o["imu_gyro"]
        return {k: o[k] for k in self.observation_space.spaces}

    def _info(self) -> dict:
        sim = self.sim
        t = sim.truth()
        new = []
        for side in ("left", "right"):
            times = sim.strikes.time[side]
            for k in range(self._counts[side], len(times)):
                new.append((side, times[k], sim.strikes.position[side][k]))
            self._counts[side] = len(times)
        t.update(base_lin_vel=sim.base_lin_vel(), foot_loads=sim.loads.copy(), new_strikes=new,
                 strike_counts=dict(self._counts), sensors=sim.sensor_readings(),
                 gravity_true=sim.imu_site_gravity())
        return t

    def _render_scene(self):
        m, d = self.sim.model, self.sim.data
        return m, d, self.sim.pelvis_pose()[:3] * [1, 1, 0.6], 2.5 * self.sim.kin.dims.leg_length
