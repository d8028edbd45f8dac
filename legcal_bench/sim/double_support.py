"""The static double-support simulator: both soles planted, the pelvis posture commanded.

This is the physics and sensing core that the Gymnasium env (`legcal_bench.envs`) and
the session collector share, so an env episode and a recording are the same thing.

A posture is the pelvis pose in the stance frame, [x, y, z, roll, pitch, yaw] (m,
rad). It is mapped through the nominal model's closed-chain IK to joint targets, so
every posture keeps both feet planted; a posture out of reach (or past a joint limit)
is not applied and `step` returns False.

Physics modes:
  kinematic  exact closed-chain postures from IK on the simulated robot; encoders are
             derived from them. No dynamics: the ideal floor (each frame is a static
             posture, so the accelerometer reads gravity alone).
  weld       MuJoCo, each sole welded (stiffly) to its placement.
  contact    MuJoCo, frictional flat floor, no welds; the robot settles on its soles.
In weld and contact modes the servos track encoder-space targets from the nominal IK.
The encoders are offset, so in joint space the servo target is q_cmd + dq: nothing
reads the offsets, the offsets strain the closed chain as on a real robot.

In the straight-leg standing phase each true knee sits at the simulated robot's
mechanical straight angle plus `knee_straight_error_rad`, and postures are ignored.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin

from legcal_bench.errors import IKError, LegMapError
from legcal_bench.geometry.poses import posture_pose, se3, se3_to_pos_quat
from legcal_bench.robots.kinematics import LegKinematics, solve_standing
from legcal_bench.robots.legmap import SIDES, LegMap
from legcal_bench.sim.scene import Scene, apply_servos, build_scene
from legcal_bench.sim.sensors import SensorModel

GRAVITY = np.array([0.0, 0.0, -9.81])


class DoubleSupportSim:
    """One robot in static double support; `reset` places it, `step` moves its pelvis.

    `legmap` is the nominal robot (what the robot's software believes: IK targets come
    from it); `sim_legmap` the simulated one (default the same)."""

    def __init__(self, legmap: LegMap, mode: str, offsets: np.ndarray, sensor: SensorModel,
                 sim_legmap: LegMap | None = None, rate_hz: float = 50.0, physics_dt: float = 0.001,
                 knee_straight_error_rad: float = 0.005, settle_s: float = 3.0):
        self.legmap = legmap
        self.sim_legmap = legmap if sim_legmap is None else sim_legmap
        if self.sim_legmap.joint_names != legmap.joint_names:
            raise LegMapError("sim_robot: the simulated robot must have the same 12 leg joint names, in the same "
                              f"order, as the nominal robot ({legmap.joint_names})")
        self.mode = mode
        self.nominal = LegKinematics(legmap)
        self.true_kin = self.nominal if self.sim_legmap is legmap else LegKinematics(self.sim_legmap)
        self.offsets = np.asarray(offsets, dtype=float)
        self.sensor = sensor
        self.rate_hz = float(rate_hz)
        self.dt = 1.0 / self.rate_hz
        self.physics_dt = float(physics_dt)
        self.n_substeps = max(1, int(round(self.dt / self.physics_dt)))
        self.knee_straight_error_rad = float(knee_straight_error_rad)
        self.settle_s = float(settle_s)
        self.scene: Scene | None = build_scene(self.sim_legmap, mode, physics_dt) if mode != "kinematic" else None
        self.data = mujoco.MjData(self.scene.model) if self.scene else None
        self.has_ft = bool(self.scene and self.scene.has_ft)
        self.left = self.right = None
        self.standing = False

    # ------------------------------------------------------------------ public
    @property
    def q_true(self) -> np.ndarray:
        return self._q_true.copy()

    @property
    def posture(self) -> np.ndarray:
        return self._posture.copy()

    def reset(self, left: pin.SE3, right: pin.SE3, posture: np.ndarray, standing: bool = False) -> None:
        """Plant the soles at `left`/`right` (stance frame) with the pelvis at `posture`
        (standing: the straight-leg posture is solved instead), then let the servos settle."""
        self.left, self.right, self.standing = left, right, standing
        self.time = 0.0
        if standing:
            knee = self.sim_legmap.knee_straight_rad + self.knee_straight_error_rad
            posture, q_true = solve_standing(self.true_kin, left, right, posture, (knee, knee))
            self._posture, self._q_stand = posture, q_true
        else:
            self._posture = np.array(posture, dtype=float)
            q_true = self._ik(self.true_kin, self._posture, self.true_kin.q_init())
        self._q_cmd = q_true - self.offsets if standing else self._ik(self.nominal, self._posture, q_true)
        self._q_true = q_true
        if self.mode == "kinematic":
            self._imu_hist = [self._imu_world(q_true, self._posture)] * 2
        else:
            self._reset_physics(q_true)
        self._sole_ref = self._sole_poses_world()
        self.reachable = True

    def step(self, posture: np.ndarray) -> bool:
        """Move to `posture` over one logging period; False if it was out of reach (the
        previous posture is held)."""
        self.reachable = True
        if not self.standing:
            try:
                q_cmd = self._ik(self.nominal, posture, self._q_cmd)
                q_true = self._ik(self.true_kin, posture, self._q_true) if self.mode == "kinematic" else None
                self._posture, self._q_cmd = np.array(posture, dtype=float), q_cmd
                if q_true is not None:
                    self._q_true = q_true
            except IKError:
                self.reachable = False
        if self.mode == "kinematic":
            self._imu_hist = self._imu_hist[1:] + [self._imu_world(self._q_true, self._posture)]
        else:
            self._advance_physics()
        self.time += self.dt
        return self.reachable

    def observe(self, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """What the robot logs now: encoder angles, IMU specific force and rate (and
        ankle force/torque where the scene has them), with the sensor model's errors."""
        acc, gyro = self._true_imu()
        acc, gyro = self.sensor.imu(acc, gyro, rng)
        obs = {"q_enc": self.sensor.encoders(self._q_true - self.offsets, rng), "imu_acc": acc, "imu_gyro": gyro}
        if self.has_ft:
            obs["ft"] = self.sensor.force_torque(self._wrenches(), rng)
        return obs

    def truth(self) -> dict:
        """The ground truth now (never given to calibrators)."""
        soles = self._sole_poses_world()
        drift = [self._sole_ref[i].actInv(soles[i]) for i in range(2)]
        acc, gyro = self._true_imu()
        return {
            "time": self.time,
            "q_true": self._q_true.copy(),
            "offsets": self.offsets.copy(),
            "posture": self._posture.copy(),
            "posture_reachable": self.reachable,
            "sole_poses_world": np.array([se3_to_pos_quat(T) for T in soles]),
            "pelvis_pose_world": se3_to_pos_quat(self._pelvis_pose_world()),
            "sole_drift_m": np.array([np.linalg.norm(D.translation) for D in drift]),
            "sole_drift_rad": np.array([np.linalg.norm(pin.log3(D.rotation)) for D in drift]),
            "imu_true_acc": acc,
            "imu_true_gyro": gyro,
        }

    def render_scene(self, physics_dt: float) -> tuple[mujoco.MjModel, mujoco.MjData, np.ndarray]:
        """(model, data, pelvis position) posed for rendering; kinematic mode builds a
        scene on first use and poses it from the kinematic state."""
        if self.scene is None:
            self.scene = build_scene(self.sim_legmap, "kinematic", physics_dt)
            self.data = mujoco.MjData(self.scene.model)
        if self.mode == "kinematic":
            self._set_state(self._q_true, posture_pose(self._posture))
            mujoco.mj_forward(self.scene.model, self.data)
        return self.scene.model, self.data, self.data.xpos[self.scene.pelvis_body].copy()

    # ---------------------------------------------------------------- internals
    def _ik(self, kin: LegKinematics, posture: np.ndarray, q_init: np.ndarray) -> np.ndarray:
        T_WB = posture_pose(posture)
        return kin.solve(T_WB.actInv(self.left), T_WB.actInv(self.right), q_init)

    def _set_state(self, q_true: np.ndarray, T_WB: pin.SE3) -> None:
        sc, d = self.scene, self.data
        a = sc.free_qpos_adr
        d.qpos[a:a + 7] = se3_to_pos_quat(T_WB)
        d.qpos[sc.qpos_adr] = q_true
        for name, angle in self.sim_legmap.held_joints_rad.items():
            d.qpos[sc.model.jnt_qposadr[mujoco.mj_name2id(sc.model, mujoco.mjtObj.mjOBJ_JOINT, name)]] = angle

    def _servo_target(self) -> np.ndarray:
        # Standing is the one phase with a physically imposed posture (legs straightened
        # against the mechanism), so its servo target is the true straight-leg posture.
        return self._q_stand if self.standing else self._q_cmd + self.offsets

    def _reset_physics(self, q_true: np.ndarray) -> None:
        sc, d = self.scene, self.data
        mujoco.mj_resetData(sc.model, d)
        self._set_state(q_true, posture_pose(self._posture))
        if sc.mocap:
            for side, T in zip(SIDES, (self.left, self.right)):
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
        sc, d = self.scene, self.data
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
            sd, adr = self.data.sensordata, self.scene.sensor_adr
            return sd[adr["imu_acc"]:adr["imu_acc"] + 3].copy(), sd[adr["imu_gyro"]:adr["imu_gyro"] + 3].copy()
        # Kinematic mode: each frame is a static posture (quasi-static), so the
        # accelerometer reads gravity alone; the rate is the backward difference.
        T1, T2 = self._imu_hist
        gyro = pin.log3(T1.rotation.T @ T2.rotation) / self.dt
        return T2.rotation.T @ (-GRAVITY), gyro

    def _wrenches(self) -> np.ndarray:
        sd, adr = self.data.sensordata, self.scene.sensor_adr
        return np.array([np.concatenate([sd[adr[f"{s}_force"]:adr[f"{s}_force"] + 3],
                                         sd[adr[f"{s}_torque"]:adr[f"{s}_torque"] + 3]]) for s in SIDES])

    def _sole_poses_world(self) -> list[pin.SE3]:
        if self.mode == "kinematic":
            T_WB = posture_pose(self._posture)
            return [T_WB * T for T in self.true_kin.sole_poses(self._q_true)]
        d, sc = self.data, self.scene
        return [se3(d.site_xmat[sc.sole_site[s]].reshape(3, 3), d.site_xpos[sc.sole_site[s]]) for s in SIDES]

    def _pelvis_pose_world(self) -> pin.SE3:
        if self.mode == "kinematic":
            return posture_pose(self._posture)
        b = self.scene.pelvis_body
        return se3(self.data.xmat[b].reshape(3, 3), self.data.xpos[b])
