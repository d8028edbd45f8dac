"""Static double support: both soles planted, the pelvis posture commanded.

## Description
A humanoid stands with both soles fixed on a flat floor (a stance) and moves its
pelvis; it logs what a real robot logs: encoder angles (offset by the injected
encoder offsets), IMU specific force and angular rate, and ankle force/torque in
the dynamic modes. Ground truth (true angles, offsets, sole and pelvis poses) is only
in `info`. The physics is `legcal_bench.sim.double_support.DoubleSupportSim`, the same
core the session collector records with.

## Action space
`Box(6)`: the pelvis posture in the stance frame, [x, y, z, roll, pitch, yaw] (m, rad),
bounded to ±0.25 leg lengths in x and y, 0.6-1.0 leg lengths in z and ±0.4 rad (a finite
action past the bounds is clipped to them; a NaN or infinite entry, or a length other
than 6, is refused with `ConfigError`). It is mapped through the nominal model's
closed-chain IK to joint targets, so every action keeps both feet planted; a posture
out of reach (or past a joint limit) is not applied and `info["posture_reachable"]`
is False. In the `standing` stance the legs are straight and the action is ignored.

## Observation space
`Dict`: `q_enc` (n,) rad in leg-map order (n = the robot's leg joints, `legmap.n_joints`:
12 for six-joint legs, 10 without ankle roll), `imu_acc` (3,) m/s², `imu_gyro` (3,)
rad/s, and `ft` (2, 6) [force N, torque N m] per ankle in weld and contact modes.

## Rewards
The information gain of the new frame about the n offsets (one per leg joint): the increase of
log det(H_data + εI) of the stance's matched residuals (mm, mrad) linearised at the
logged data, ε = 1 (`legcal_bench.estimation.information.gain.InformationGain`). An
episode's return is therefore the log-determinant of the information its motion
gathered (D-optimal design; less the reset frame's, `info["log_det_information"]`), the objective a learned excitation policy maximizes
without knowing the calibration; `legcal-bench excite` learns a small one
(`legcal_bench.evaluation.excitation`), and `env.unwrapped.information_matrix` gives
H_data itself. `information_reward=False` returns 0 (the collector's setting; it
saves ~0.3 ms a frame).

## Starting state
`reset(seed=..., options={"stance": "I", "jitter_m": 0.015, "jitter_rad": 0.05})`
places the soles for the stance (I normal squat, II left lunge, III right lunge, IV
wide squat, or `standing`; each shrunk to fit the robot's joint limits as the collector
does, `legcal_bench.protocol.stances.fit_stance`), each jittered uniformly, puts the
pelvis at the stance's nominal posture and lets the servos settle (`settle_s`, dynamic
modes; servo gains as the collector chooses them, `legcal_bench.protocol.servos`).
`info` carries the ground truth, including `pelvis_hold_error_m` and the soles' drift
that the collector's hold check (`legcal_bench.sim.hold`) limits.

## Episode end
Never terminates; registered ids truncate after 1000 steps.

## Arguments
`robot` (built-in name or leg-map path; required for the `-Path-` id), `mode`
(`kinematic`, `weld`, `contact`), `offsets` (`none`, `paper`, `random:<deg>`, or one
radian per leg joint), `sensors` (`zero`, `realistic` or a sensor-model dict), `sim_robot` (simulate
another model with the same joints), `mjcf`, `rate_hz` (logging rate, also
`render_fps`), `physics_dt`, `offset_seed`, `knee_straight_error_rad`, `settle_s`,
`information_reward`, `render_mode` (`rgb_array`), `standing` (the standing controller,
as `collect --standing`: `auto`, the default, runs `cop` on a contact floor for a robot
with ankle force/torque sensors; docs/contact-floor.md). Each is checked at construction
(`gym.make` too) and a bad one raises `ConfigError` naming it and the fix: `rate_hz` in
[1, 1e5] Hz and `physics_dt` in [1e-5, 0.01] s, one logging period a whole number of
physics steps (`legcal_bench.sim.double_support.physics_timing`); `offset_seed` a 32-bit unsigned
integer; `knee_straight_error_rad` within ±0.1; `settle_s` in [0, 60]; a misspelt
argument is named with the closest one. An action of the wrong length, not numbers
or not finite is refused at `step` the same way.

## Version History
* v0: the first version (static double support with kinematic, weld and contact floors).
  At results version 9 (issue #38) its contact floor's parameters are the floor's own and
  a contact floor runs the standing controller unless `standing="none"`: contact-mode
  episodes differ from earlier ones of the same id (kinematic and weld do not).
"""

from __future__ import annotations

from functools import cached_property
from typing import Any

import numpy as np
from gymnasium import spaces

from legcal_bench import inputs
from legcal_bench.envs.base import MujocoEnv, named
from legcal_bench.errors import ConfigError, LegMapError
from legcal_bench.estimation.information.gain import InformationGain
from legcal_bench.protocol.servos import servo_gains
from legcal_bench.protocol.collect import CollectConfig, standing_controller
from legcal_bench.protocol.stances import ALL_STANCES, Placement, fit_stance, posture_bounds, settled_placement
from legcal_bench.robots import load_robot
from legcal_bench.robots.holds import joint_holds
from legcal_bench.robots.legmap import LegMap
from legcal_bench.robots.transmission import encoder_map, to_joint_space
from legcal_bench.sim.double_support import DoubleSupportSim, physics_timing
from legcal_bench.sim.offsets import resolve_offsets
from legcal_bench.sim.scene import MODES
from legcal_bench.sim.sensors import SensorModel, SimSensors, sim_sensors
from legcal_bench.sim.standing import STANDING_CONTROLLERS

RESET_OPTIONS = ("stance", "jitter_m", "jitter_rad")
KNEE_ERROR_MAX_RAD = 0.1  # the standing knee's error from straight, either way (a few mrad is realistic)
SETTLE_MAX_S = 60.0  # a reset's settling time: every reset simulates it
JITTER_MAX_M, JITTER_MAX_RAD = 0.1, 0.5  # a placement jitter beyond these does not keep a stance


def _as_legmap(robot: str | LegMap, mjcf=None) -> LegMap:
    return robot if isinstance(robot, LegMap) else load_robot(robot, mjcf)


class StaticDoubleSupportEnv(MujocoEnv):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}
    action_doc = "the pelvis posture [x, y, z, roll, pitch, yaw] in the stance frame (m, rad)"

    def __init__(
        self,
        robot: str | LegMap | None = None,
        mode: str = "kinematic",
        offsets: str | np.ndarray = "paper",
        sensors: str | SimSensors | SensorModel | dict = "realistic",
        sim_robot: str | LegMap | None = None,
        mjcf: str | None = None,
        rate_hz: float = 50.0,
        physics_dt: float = 0.001,
        offset_seed: int = 0,
        knee_straight_error_rad: float = 0.005,
        settle_s: float = 3.0,
        information_reward: bool = True,
        render_mode: str | None = None,
        standing: str = "auto",
        **unknown,
    ):
        self._refuse_unknown(unknown)
        if robot is None:
            raise LegMapError("robot: give a built-in name or the path of a leg map, e.g. "
                              "gym.make('legcal/StaticDoubleSupport-Path-v0', robot='path/to/robot.legmap.yaml')")
        mode = inputs.choice("mode", mode, MODES)
        rate_hz, physics_dt, _ = physics_timing(rate_hz, physics_dt)
        offset_seed = inputs.seed("offset_seed", offset_seed)
        knee_straight_error_rad = inputs.number(
            "knee_straight_error_rad", knee_straight_error_rad, low=-KNEE_ERROR_MAX_RAD, high=KNEE_ERROR_MAX_RAD,
            fix="the true straight knee's angle past the leg map's knee_straight, in radians, e.g. 0.005")
        settle_s = inputs.non_negative("settle_s", settle_s, high=SETTLE_MAX_S,
                                       fix="seconds the servos settle after a reset, e.g. 3")
        if not isinstance(information_reward, (bool, np.bool_)):
            raise ConfigError(f"information_reward = {information_reward!r}: give True (the reward is the frame's "
                              "information gain) or False (0)")
        standing = inputs.choice("standing", standing, ("auto", *STANDING_CONTROLLERS))
        legmap = _as_legmap(robot, mjcf)
        sim_legmap = legmap if sim_robot is None else named("sim_robot", _as_legmap, sim_robot)
        offsets = named("offsets", resolve_offsets, offsets, legmap, np.random.default_rng(offset_seed))
        self.sim = DoubleSupportSim(
            legmap, mode, offsets, named("sensors", sim_sensors, sensors),
            sim_legmap=sim_legmap, rate_hz=rate_hz, physics_dt=physics_dt,
            knee_straight_error_rad=knee_straight_error_rad, settle_s=settle_s,
            servo_gains=servo_gains(sim_legmap) if mode != "kinematic" else None,
            standing_controller=standing_controller(CollectConfig(mode=mode, standing=standing), sim_legmap))
        super().__init__(physics_dt, self.sim.n_substeps, render_mode)
        self.legmap, self.mode = legmap, mode
        self._encoder_map = encoder_map(legmap)  # the software's reading of encoders behind transmissions
        low, high = posture_bounds(self.sim.nominal.dims)
        self.action_space = spaces.Box(low=low, high=high, dtype=np.float64)
        obs = {
            "q_enc": spaces.Box(-np.inf, np.inf, (legmap.n_joints,), np.float64),
            "imu_acc": spaces.Box(-np.inf, np.inf, (3,), np.float64),
            "imu_gyro": spaces.Box(-np.inf, np.inf, (3,), np.float64),
        }
        if self.sim.has_ft:
            obs["ft"] = spaces.Box(-np.inf, np.inf, (2, 6), np.float64)
        self.observation_space = spaces.Dict(obs)
        self.placement: Placement | None = None
        self._information = InformationGain(self.sim.nominal) if information_reward else None

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = self._reset_options(options, RESET_OPTIONS)
        name = inputs.choice("reset option stance", options.get("stance", "I"), ALL_STANCES)
        jitter_m = inputs.non_negative("reset option jitter_m", options.get("jitter_m", 0.015), high=JITTER_MAX_M,
                                       fix="the largest random shift of each sole, metres")
        jitter_rad = inputs.non_negative("reset option jitter_rad", options.get("jitter_rad", 0.05),
                                         high=JITTER_MAX_RAD, fix="the largest random yaw of each sole, radians")
        self.placement = settled_placement(fit_stance(ALL_STANCES[name], self.sim.nominal).stance, self.sim.true_kin,
                                           self.np_random, jitter_m, jitter_rad)
        self.sim.reset(self.placement.left, self.placement.right, self.placement.nominal, standing=name == "standing")
        obs = self.sim.observe(self.np_random)
        if self._information is not None:
            self._information.reset()
            self._information.add(to_joint_space(obs["q_enc"], self._encoder_map), obs["imu_acc"])
        return obs, self._info()

    def step(self, action):
        """ConfigError for an action of the wrong length, not numbers or not finite; a
        finite one outside the action space is clipped to it."""
        posture = np.clip(self._action(action), self.action_space.low, self.action_space.high)
        self.sim.step(posture)
        obs = self.sim.observe(self.np_random)
        # the information of joint angles (an encoder behind a transmission reads its motor: converted)
        reward = (self._information.add(to_joint_space(obs["q_enc"], self._encoder_map), obs["imu_acc"])
                  if self._information is not None else 0.0)
        return obs, reward, False, False, self._info()

    @property
    def information_matrix(self) -> np.ndarray:
        """H_data of the episode so far (n, n) over the n leg joints' offsets, mm and mrad units (the reward's; zeros
        with `information_reward=False`)."""
        return self._information.H if self._information is not None else np.zeros((self.legmap.n_joints,) * 2)

    @property
    def offsets(self) -> np.ndarray:
        """The injected offsets (ground truth)."""
        return self.sim.offsets.copy()

    @cached_property
    def _held_joints(self) -> list[dict]:
        """Every non-leg joint: held at what, how (`legcal_bench.robots.holds`)."""
        return [h.to_dict() for h in joint_holds(self.sim.sim_legmap)]

    def _info(self) -> dict:
        return {**self.sim.truth(), "stance": self.placement.stance.name, "held_joints": self._held_joints,
                "log_det_information": self._information.logdet if self._information is not None else None}

    def _render_scene(self):
        model, data, pelvis = self.sim.render_scene(self.physics_dt)
        return model, data, pelvis * [1, 1, 0.6], 2.6 * self.sim.nominal.dims.leg_length
