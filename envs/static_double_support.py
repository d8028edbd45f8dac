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
bounded to ±0.25 leg lengths in x and y, 0.6-1.0 leg lengths in z and ±0.4 rad. It is
mapped through the nominal model's closed-chain IK to joint targets, so every action
keeps both feet planted; a posture out of reach (or past a joint limit) is not
applied and `info["posture_reachable"]` is False. In the `standing` stance the legs
are straight and the action is ignored.

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
with ankle force/torque sensors; docs/contact-floor.md).

## Version History
* v0: the first version (static double support with kinematic, weld and contact floors).
  At results version 9 (issue #38) its contact floor's parameters are the floor's own and
  a contact floor runs the standing controller unless `standing="none"`: contact-mode
  episodes differ from earlier ones of the same id (kinematic and weld do not).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from legcal_bench.envs.base import MujocoEnv
from legcal_bench.errors import ConfigError, LegMapError
from legcal_bench.estimation.information.gain import InformationGain
from legcal_bench.protocol.servos import servo_gains
from legcal_bench.protocol.collect import CollectConfig, standing_controller
from legcal_bench.protocol.stances import ALL_STANCES, Placement, fit_stance, posture_bounds, settled_placement
from legcal_bench.robots import load_robot
from legcal_bench.robots.legmap import LegMap
from legcal_bench.sim.double_support import DoubleSupportSim
from legcal_bench.sim.offsets import resolve_offsets
from legcal_bench.sim.scene import MODES
from legcal_bench.sim.sensors import SensorModel, SimSensors, sim_sensors

RESET_OPTIONS = ("stance", "jitter_m", "jitter_rad")


def _as_legmap(robot: str | LegMap, mjcf=None) -> LegMap:
    return robot if isinstance(robot, LegMap) else load_robot(robot, mjcf)


class StaticDoubleSupportEnv(MujocoEnv):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}

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
    ):
        if robot is None:
            raise LegMapError("robot: give a built-in name or the path of a leg map, e.g. "
                              "gym.make('legcal/StaticDoubleSupport-Path-v0', robot='path/to/robot.legmap.yaml')")
        if mode not in MODES:
            raise ConfigError(f"mode {mode!r}: use one of {MODES}")
        legmap = _as_legmap(robot, mjcf)
        sim_legmap = legmap if sim_robot is None else _as_legmap(sim_robot)
        self.sim = DoubleSupportSim(
            legmap, mode, resolve_offsets(offsets, legmap, np.random.default_rng(offset_seed)), sim_sensors(sensors),
            sim_legmap=sim_legmap, rate_hz=rate_hz, physics_dt=physics_dt,
            knee_straight_error_rad=knee_straight_error_rad, settle_s=settle_s,
            servo_gains=servo_gains(sim_legmap) if mode != "kinematic" else None,
            standing_controller=standing_controller(CollectConfig(mode=mode, standing=standing), sim_legmap))
        super().__init__(physics_dt, self.sim.n_substeps, render_mode)
        self.legmap, self.mode = legmap, mode
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
        name = options.get("stance", "I")
        if name not in ALL_STANCES:
            raise ConfigError(f"reset option stance={name!r}: use one of {list(ALL_STANCES)}")
        self.placement = settled_placement(fit_stance(ALL_STANCES[name], self.sim.nominal).stance, self.sim.true_kin,
                                           self.np_random, float(options.get("jitter_m", 0.015)),
                                           float(options.get("jitter_rad", 0.05)))
        self.sim.reset(self.placement.left, self.placement.right, self.placement.nominal, standing=name == "standing")
        obs = self.sim.observe(self.np_random)
        if self._information is not None:
            self._information.reset()
            self._information.add(obs["q_enc"], obs["imu_acc"])
        return obs, self._info()

    def step(self, action):
        posture = np.clip(np.asarray(action, dtype=np.float64).reshape(6), self.action_space.low,
                          self.action_space.high)
        self.sim.step(posture)
        obs = self.sim.observe(self.np_random)
        reward = self._information.add(obs["q_enc"], obs["imu_acc"]) if self._information is not None else 0.0
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

    def _info(self) -> dict:
        return {**self.sim.truth(), "stance": self.placement.stance.name,
                "log_det_information": self._information.logdet if self._information is not None else None}

    def _render_scene(self):
        model, data, pelvis = self.sim.render_scene(self.physics_dt)
        return model, data, pelvis * [1, 1, 0.6], 2.6 * self.sim.nominal.dims.leg_length
