"""Static double support: both soles planted, the pelvis posture commanded.

The action is a posture command: the pelvis pose in the stance frame,
[x, y, z, roll, pitch, yaw] (m, rad). It is mapped through the nominal model's
closed-chain IK to joint targets, so every action keeps both feet planted; a posture
out of reach (or past a joint limit) is not applied, and `info["posture_reachable"]`
says so. Each step is one logged frame at `rate_hz`.

Physics modes:
  kinematic  exact closed-chain postures from IK on the simulated robot; encoders are
             derived from them. No dynamics: the ideal floor (each frame is a static
             posture, so the accelerometer reads gravity alone).
  weld       MuJoCo, each sole welded (stiffly) to its placement.
  contact    MuJoCo, frictional flat floor, no welds; the robot settles on its soles.
In weld and contact modes the servos track encoder-space targets from the nominal IK.
The encoders are offset, so in joint space the servo target is q_cmd + dq: nothing
reads the offsets, the offsets strain the closed chain as on a real robot.

The observation is what the robot logs: encoder angles, IMU specific force and
angular rate (and ankle force/torque in the dynamic modes, where the robot has them).
Ground truth (true angles, injected offsets, true sole and pelvis poses) is only in
`info`. The reward is the information gain of the new frame: the increase of
log det(H_data + eps I) of the segment's matched residuals (mm, mrad) linearised at the
logged data, eps = 1 (see `legcal_bench.observability.InformationGain`), so excitation
design can be learned; `info["log_det_information"]` is the running total
(`information_reward=False` skips it and returns 0, as the collector does).

Reset options: `stance` (I, II, III, IV or standing; default I), `jitter_m` and
`jitter_rad` (random re-placement of each sole, default 0.015 m and 0.05 rad). In the
`standing` stance the legs are straight (each true knee at the leg map's mechanical
straight angle plus `knee_straight_error_rad`) and the action is ignored.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
import pinocchio as pin
from gymnasium import spaces

from legcal_bench.kinematics import IKError, LegKinematics, se3, se3_to_pos_quat, solve_standing
from legcal_bench.observability import InformationGain
from legcal_bench.offsets import resolve_offsets
from legcal_bench.robots import load_robot
from legcal_bench.robots.legmap import SIDES, LegMap, LegMapError
from legcal_bench.sensors import SensorModel, sensor_model
from legcal_bench.sim.scene import MODES, Scene, apply_servos, build_scene
from legcal_bench.stances import ALL_STANCES, place, posture_pose

GRAVITY = np.array([0.0, 0.0, -9.81])


def _as_legmap(robot: str | LegMap, mjcf=None) -> LegMap:
    return robot if isinstance(robot, LegMap) else load_robot(robot, mjcf)


class StaticDoubleSupportEnv(gym.Env):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(
        self,
        robot: str | LegMap = "a3",
        mode: str = "kinematic",
        offsets: str | np.ndarray = "paper",
        sensors: str | SensorModel | dict = "realistic",
        sim_robot: str | LegMap | None = None,
        mjcf: str | None = None,
        rate_hz: float = 50.0,
        physics_dt: float = 0.001,
        offset_seed: int = 0,
        knee_straight_error_rad: float = 0.005,
        settle_s: float = 3.0,
        information_reward: bool = True,
        render_mode: str | None = None,
    ):
        if mode not in MODES:
            raise ValueError(f"mode {mode!r}: use one of {MODES}")
        self.legmap = _as_legmap(robot, mjcf)
        self.sim_legmap = self.legmap if sim_robot is None else _as_legmap(sim_robot)
        if self.sim_legmap.joint_names != self.legmap.joint_names:
            raise LegMapError("sim_robot: the simulated robot must have the same 12 leg joint names, in the same "
                              f"order, as the nominal robot ({self.legmap.joint_names})")
        self.mode = mode
        self.nominal = LegKinematics(self.legmap)
        self.true_kin = self.nominal if self.sim_legmap is self.legmap else LegKinematics(self.sim_legmap)
        self.offsets = resolve_offsets(offsets, self.legmap, np.random.default_rng(offset_seed))
        self.sensor = sensor_model(sensors)
        self.rate_hz = float(rate_hz)
        self.dt = 1.0 / self.rate_hz
        self.physics_dt = float(physics_dt)
        self.n_substeps = max(1, int(round(self.dt / self.physics_dt)))
        self.knee_straight_error_rad = float(knee_straight_error_rad)
        self.settle_s = float(settle_s)
        self.render_mode = render_mode
        self._scene: Scene | None = build_scene(self.sim_legmap, mode, physics_dt) if mode != "kinematic" else None
        self.data = mujoco.MjData(self._scene.model) if self._scene else None
        self._renderer = None
        self.has_ft = bool(self._scene and self._scene.has_ft)

        L = self.nominal.dims.leg_length
        self.action_space = spaces.Box(
            low=np.array([-0.25 * L, -0.25 * L, 0.6 * L, -0.4, -0.4, -0.4]),
            high=np.array([0.25 * L, 0.25 * L, 1.0 * L, 0.4, 0.4, 0.4]),
            dtype=np.float64,
        )
        obs = {
            "q_enc": spaces.Box(-np.inf, np.inf, (12,), np.float64),
            "imu_acc": spaces.Box(-np.inf, np.inf, (3,), np.float64),
            "imu_gyro": spaces.Box(-np.inf, np.inf, (3,), np.float64),
        }
        if self.has_ft:
            obs["ft"] = spaces.Box(-np.inf, np.inf, (2, 6), np.float64)
        self.observation_space = spaces.Dict(obs)
        self._placement = None
        # The reward costs ~0.3 ms a frame; a collector that only logs can switch it off.
        self._information = InformationGain(self.nominal) if information_reward else None

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        name = options.pop("stance", "I")
        if name not in ALL_STANCES:
            raise ValueError(f"reset option stance={name!r}: use one of {list(ALL_STANCES)}")
        jitter_m = float(options.pop("jitter_m", 0.015))
        jitter_rad = float(options.pop("jitter_rad", 0.05))
        if options:
            raise ValueError(f"unknown reset options {sorted(options)}; known: stance, jitter_m, jitter_rad")
        self._placement = place(ALL_STANCES[name], self.true_kin.dims, self.np_random, jitter_m, jitter_rad)
        self._standing = name == "standing"
        self._t = 0.0
        if self._standing:
            knee = self.sim_legmap.knee_straight_rad + self.knee_straight_error_rad
            posture, q_true = solve_standing(self.true_kin, self._placement.left, self._placement.right,
                                             self._placement.nominal, (knee, knee))
            self._posture, self._q_stand = posture, q_true
        else:
            self._posture = self._placement.nominal.copy()
            q_true = self._ik(self.true_kin, self._posture, self.true_kin.q_init())
        self._q_cmd = q_true - self.offsets if self._standing else self._ik(self.nominal, self._posture, q_true)
        self._q_true = q_true
        if self.mode == "kinematic":
            self._imu_hist = [self._imu_world(q_true, self._posture)] * 2
        else:
            self._reset_physics(q_true)
        self._sole_ref = self._sole_poses_world()
        self._reachable = True
        obs = self._observe()
        if self._information is not None:
            self._information.reset()
            self._information.add(obs["q_enc"], obs["imu_acc"])
        return obs, self._info()

    def step(self, action):
        action = np.asarray(action, dtype=np.float64).reshape(6)
        self._reachable = True
        if not self._standing:
            posture = np.clip(action, self.action_space.low, self.action_space.high)
            try:
                q_cmd = self._ik(self.nominal, posture, self._q_cmd)
                q_true = self._ik(self.true_kin, posture, self._q_true) if self.mode == "kinematic" else None
                self._posture, self._q_cmd = posture, q_cmd
                if q_true is not None:
                    self._q_true = q_true
            except IKError:
                self._reachable = False
        if self.mode == "kinematic":
            self._imu_hist = self._imu_hist[1:] + [self._imu_world(self._q_true, self._posture)]
        else:
            self._advance_physics()
        self._t += self.dt
        obs = self._observe()
        reward = self._information.add(obs["q_enc"], obs["imu_acc"]) if self._information is not None else 0.0
        return obs, reward, False, False, self._info()

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self._scene is None:
            self._scene = build_scene(self.sim_legmap, "kinematic", self.physics_dt)
            self.data = mujoco.MjData(self._scene.model)
        if self.mode == "kinematic":
            self._set_state(self._q_true, posture_pose(self._posture))
            mujoco.mj_forward(self._scene.model, self.data)
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self._scene.model, 480, 640)
        cam = mujoco.MjvCamera()
        cam.lookat[:] = self.data.xpos[self._scene.pelvis_body] * [1, 1, 0.6]
        cam.distance = 2.6 * self.nominal.dims.leg_length
        cam.azimuth, cam.elevation = 140.0, -15.0
        self._renderer.update_scene(self.data, cam)
        return self._renderer.render()

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # ------------------------------------------------------------ internals
    def _ik(self, kin: LegKinematics, posture: np.ndarray, q_init: np.ndarray) -> np.ndarray:
        T_WB = posture_pose(posture)
        return kin.solve(T_WB.actInv(self._placement.left), T_WB.actInv(self._placement.right), q_init)

    def _set_state(self, q_true: np.ndarray, T_WB: pin.SE3) -> None:
        sc, d = self._scene, self.data
        a = sc.free_qpos_adr
        d.qpos[a:a + 7] = se3_to_pos_quat(T_WB)
        d.qpos[sc.qpos_adr] = q_true
        for name, angle in self.sim_legmap.held_joints_rad.items():
            d.qpos[sc.model.jnt_qposadr[mujoco.mj_name2id(sc.model, mujoco.mjtObj.mjOBJ_JOINT, name)]] = angle

    def _servo_target(self) -> np.ndarray:
        # Standing is the one phase with a physically imposed posture (legs straightened
        # against the mechanism), so its servo target is the true straight-leg posture.
        return self._q_stand if self._standing else self._q_cmd + self.offsets

    def _reset_physics(self, q_true: np.ndarray) -> None:
        sc, d = self._scene, self.data
        mujoco.mj_resetData(sc.model, d)
        self._set_state(q_true, posture_pose(self._posture))
        if sc.mocap:
            for side, T in zip(SIDES, (self._placement.left, self._placement.right)):
                pq = se3_to_pos_quat(T)
                d.mocap_pos[sc.mocap[side]], d.mocap_quat[sc.mocap[side]] = pq[:3], pq[3:]
        mujoco.mj_forward(sc.model, d)
        # The servos start at the true posture and blend to their (strained) targets
        # over most of the settle time: a step would jolt the robot off its feet.
        self._target = self._servo_target()
        n = int(round(self.settle_s / self.physics_dt))
        for i in range(n):
            s = min(1.0, (i + 1) / max(1, int(0.7 * n)))
            apply_servos(sc, d, q_true + (s * s * (3 - 2 * s)) * (self._target - q_true))
            mujoco.mj_step(sc.model, d)

    def _advance_physics(self) -> None:
        sc, d = self._scene, self.data
        start, end = self._target, self._servo_target()
        for i in range(1, self.n_substeps + 1):
            apply_servos(sc, d, start + (end - start) * (i / self.n_substeps))
            mujoco.mj_step(sc.model, d)
        self._target = end
        self._q_true = d.qpos[sc.qpos_adr].copy()

    def _imu_world(self, q_true: np.ndarray, posture: np.ndarray) -> pin.SE3:
        return posture_pose(posture) * self.true_kin.imu_pose(q_true)

    def _true_imu(self) -> tuple[np.ndarray, np.ndarray]:
        """Specific force and angular rate in the IMU frame."""
        if self.mode != "kinematic":
            sd, adr = self.data.sensordata, self._scene.sensor_adr
            return sd[adr["imu_acc"]:adr["imu_acc"] + 3].copy(), sd[adr["imu_gyro"]:adr["imu_gyro"] + 3].copy()
        # Kinematic mode: each frame is a static posture (quasi-static), so the
        # accelerometer reads gravity alone; the rate is the backward difference.
        T1, T2 = self._imu_hist
        gyro = pin.log3(T1.rotation.T @ T2.rotation) / self.dt
        return T2.rotation.T @ (-GRAVITY), gyro

    def _observe(self) -> dict:
        acc, gyro = self._true_imu()
        acc, gyro = self.sensor.imu(acc, gyro, self.np_random)
        obs = {"q_enc": self.sensor.encoders(self._q_true - self.offsets, self.np_random),
               "imu_acc": acc, "imu_gyro": gyro}
        if self.has_ft:
            obs["ft"] = self.sensor.force_torque(self._wrenches(), self.np_random)
        return obs

    def _wrenches(self) -> np.ndarray:
        sd, adr = self.data.sensordata, self._scene.sensor_adr
        return np.array([np.concatenate([sd[adr[f"{s}_force"]:adr[f"{s}_force"] + 3],
                                         sd[adr[f"{s}_torque"]:adr[f"{s}_torque"] + 3]]) for s in SIDES])

    def _sole_poses_world(self) -> list[pin.SE3]:
        if self.mode == "kinematic":
            T_WB = posture_pose(self._posture)
            return [T_WB * T for T in self.true_kin.sole_poses(self._q_true)]
        d, sc = self.data, self._scene
        return [se3(d.site_xmat[sc.sole_site[s]].reshape(3, 3), d.site_xpos[sc.sole_site[s]]) for s in SIDES]

    def _pelvis_pose_world(self) -> pin.SE3:
        if self.mode == "kinematic":
            return posture_pose(self._posture)
        b = self._scene.pelvis_body
        return se3(self.data.xmat[b].reshape(3, 3), self.data.xpos[b])

    def _info(self) -> dict:
        soles = self._sole_poses_world()
        drift = [self._sole_ref[i].actInv(soles[i]) for i in range(2)]
        acc, gyro = self._true_imu()
        return {
            "time": self._t,
            "stance": self._placement.stance.name,
            "q_true": self._q_true.copy(),
            "offsets": self.offsets.copy(),
            "posture": self._posture.copy(),
            "posture_reachable": self._reachable,
            "sole_poses_world": np.array([se3_to_pos_quat(T) for T in soles]),
            "pelvis_pose_world": se3_to_pos_quat(self._pelvis_pose_world()),
            "sole_drift_m": np.array([np.linalg.norm(D.translation) for D in drift]),
            "sole_drift_rad": np.array([np.linalg.norm(pin.log3(D.rotation)) for D in drift]),
            "imu_true_acc": acc,
            "imu_true_gyro": gyro,
            "log_det_information": self._information.logdet if self._information is not None else None,
        }
