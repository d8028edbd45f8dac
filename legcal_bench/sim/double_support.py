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

Reality effects (`legcal_bench.sim.effects`) enter as the simulated robot (an edited
MJCF), the sensors (encoder scale, IMU mount) and `floor`, a tilt of each sole's
placement that only the simulated robot feels (a shim): the nominal IK still plans on
the flat placements. A passive hinge `legcal_compliance_<joint>` in the simulated
model is a spring between that joint's motor (what the encoder reads and the servo
drives) and its link: the ground truth's q_true is the link angle, motor + spring.

In the straight-leg standing phase each true knee sits at the simulated robot's
mechanical straight angle plus `knee_straight_error_rad`, and postures are ignored.

Two ways to drive it, with the same physics and the same random-number stream:
`step` / `observe` / `truth` one frame at a time (the env), or `run` for a whole
posture sequence (the collector), which takes the sequence's IK solved in one batch
(`posture_ik`) and converts the ground truth once at the end. `truth` is `run`'s
conversion applied to one frame.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pinocchio as pin

from legcal_bench import inputs
from legcal_bench.errors import ConfigError, IKError, LegMapError
from legcal_bench.geometry.lie import Log, inverse
from legcal_bench.geometry.poses import homogeneous_to_pos_quat, posture_pose, posture_poses, se3_to_pos_quat
from legcal_bench.robots.kinematics import LegKinematics, holdable_postures, joint_frame_kinematics, solve_standing
from legcal_bench.robots.legmap import SIDES, LegMap
from legcal_bench.robots.transmission import encoder_map, to_encoder_space
from legcal_bench.sim.effects import COMPLIANCE_PREFIX, compliance_joints, floor_key
from legcal_bench.sim.scene import Scene, ServoGains, apply_servos, build_scene, set_servo_gains
from legcal_bench.sim.sensors import SimSensors
from legcal_bench.sim.standing import STANDING_CONTROLLERS, CopRegulator

GRAVITY = np.array([0.0, 0.0, -9.81])


def posture_ik(kin: LegKinematics, left: pin.SE3, right: pin.SE3, postures: np.ndarray,
               q_init: np.ndarray | None = None, with_postures: bool = False):
    """Closed-chain IK (within joint limits) of each posture (N, 6) with the soles at
    `left`/`right` (stance frame): (N, n), in one batch (`kin.solve_batch`). The first
    frame starts from `q_init` (default `kin.q_init()`), the others from its solution, as
    a sequence of `kin.solve` calls starts each from a nearby one. Legs of fewer than six
    joints cannot hold every pelvis pose with both soles flat: each posture is replaced
    by a nearby one they reach (`holdable_postures`) before the batch. With
    `with_postures`, returns (q, the postures solved for). Raises IKError with the
    failing frames in `.frames`."""
    postures = holdable_postures(kin, left, right, np.asarray(postures, dtype=float).reshape(-1, 6), q_init)
    T_BW = inverse(posture_poses(postures))
    T_left, T_right = T_BW @ left.homogeneous, T_BW @ right.homogeneous
    q0 = kin.solve_batch(T_left[:1], T_right[:1], q_init)[0]
    q = kin.solve_batch(T_left, T_right, q0)  # frame 0 is already solved: it stays q0
    return (q, postures) if with_postures else q


# The MuJoCo time step (s): from 10 us (a stiff model, resolved finely) to 10 ms (past
# it, the servos and the soles' contacts of these robots go unstable).
PHYSICS_DT_RANGE = (1e-5, 0.01)
# The logging (control) rate, Hz: at least one frame a second (`render_fps` is a whole
# number of frames a second); at most one frame per physics step (`physics_timing`).
MIN_RATE_HZ = 1.0
# A logging period is a whole number of physics steps to this relative tolerance (as a
# policy spec's physics_hz / control_hz, `legcal_bench.policies.spec`).
WHOLE_STEPS_TOL = 1e-6

def physics_timing(rate_hz, physics_dt, rate_field: str = "rate_hz",
                   dt_field: str = "physics_dt") -> tuple[float, float, int]:
    """(rate_hz, physics_dt, physics steps per logging period) checked: each a finite
    number in its range, and one logging period (1 / rate_hz) a whole, positive number
    of physics steps, as the simulator steps it (`DoubleSupportSim`: that many MuJoCo
    steps a frame, the clock advancing 1 / rate_hz) -- else the clock and the physics
    would disagree. ConfigError naming the arguments and a rate or step that fits."""
    physics_dt = inputs.number(dt_field, physics_dt, low=PHYSICS_DT_RANGE[0], high=PHYSICS_DT_RANGE[1],
                               fix="the MuJoCo time step in seconds, e.g. 0.001")
    rate_hz = inputs.number(rate_field, rate_hz, low=MIN_RATE_HZ, high=1.0 / physics_dt,
                            fix=f"the logging rate in Hz, e.g. 50; at most {1.0 / physics_dt:g}: one frame per "
                                f"{1e3 * physics_dt:g} ms physics step")
    steps = 1.0 / (rate_hz * physics_dt)
    k = round(steps)
    if abs(steps - k) > WHOLE_STEPS_TOL * k:
        up = math.ceil(steps)
        raise ConfigError(f"{rate_field} = {rate_hz:g} with {dt_field} = {physics_dt:g}: a logging period "
                          f"({1e3 / rate_hz:g} ms) must be a whole number of physics steps, and is {steps:.6g}; give "
                          f"physics_dt = 1 / ({up} x rate_hz) = {1.0 / (up * rate_hz):.6g}, or a rate_hz that "
                          f"1 / physics_dt divides (e.g. {1.0 / (physics_dt * max(1, math.floor(steps))):g})")
    return rate_hz, physics_dt, k


class DoubleSupportSim:
    """One robot in static double support; `reset` places it, `step` moves its pelvis.

    `legmap` is the nominal robot (what the robot's software believes: IK targets come
    from it); `sim_legmap` the simulated one (default the same)."""

    def __init__(self, legmap: LegMap, mode: str, offsets: np.ndarray, sensor: SimSensors,
                 sim_legmap: LegMap | None = None, rate_hz: float = 50.0, physics_dt: float = 0.001,
                 knee_straight_error_rad: float = 0.005, settle_s: float = 3.0,
                 servo_gains: ServoGains | None = None, floor: dict | None = None,
                 standing_controller: str = "none", contact_floor: dict | None = None):
        self.legmap = legmap
        self.sim_legmap = legmap if sim_legmap is None else sim_legmap
        if self.sim_legmap.joint_names != legmap.joint_names:
            raise LegMapError(f"sim_robot: the simulated robot must have the same {legmap.n_joints} leg joint names, "
                              f"in the same order, as the nominal robot ({legmap.joint_names})")
        self.mode = mode
        self.nominal = LegKinematics(legmap)
        # A distinct simulated model whenever the simulated robot differs (a shim included):
        # `_ik` tells the two apart by identity.
        self.true_kin = self.nominal if self.sim_legmap is legmap and not floor else LegKinematics(self.sim_legmap)
        self.offsets = np.asarray(offsets, dtype=float)
        self.sensor = sensor
        self.rate_hz, self.physics_dt, self.n_substeps = physics_timing(rate_hz, physics_dt)
        self.dt = 1.0 / self.rate_hz
        self.knee_straight_error_rad = float(knee_straight_error_rad)
        self.settle_s = float(settle_s)
        self.scene: Scene | None = (build_scene(self.sim_legmap, mode, physics_dt, contact_floor)
                                    if mode != "kinematic" else None)
        if self.scene is not None:
            if servo_gains is not None:
                set_servo_gains(self.scene, np.array(servo_gains.kp), np.array(servo_gains.kd), servo_gains.source)
            missing = [n for n, s in zip(self.sim_legmap.joint_names, self.scene.servo_source) if s == "none"]
            if missing:
                raise LegMapError(
                    f"{self.sim_legmap.source or self.sim_legmap.name}: leg joints {missing} are torque motors with no "
                    "servo gains: give servo_gains.<joint>: [kp, kd] in the leg map (or collect through "
                    "legcal_bench.protocol, which uses the documented default)")
        self.data = mujoco.MjData(self.scene.model) if self.scene else None
        self.floor = {s: np.asarray(T, dtype=float) for s, T in (floor or {}).items()}
        springs = compliance_joints(self.scene.model, self.sim_legmap.joint_names) if self.scene else []
        if mode == "kinematic" and any(n.startswith(COMPLIANCE_PREFIX) for n in self._model_joint_names()):
            raise ConfigError("a series spring (compliance, joints legcal_compliance_*) needs physics: it settles "
                              "under load; use --mode weld or contact")
        if mode == "contact" and self.floor:
            raise ConfigError("a shim or a slope is applied to the sole placements, which contact mode does not "
                              "use: use --mode weld or kinematic")
        self._spring_cols = np.array([i for i, _ in springs], dtype=int)
        self._spring_adr = np.array([a for _, a in springs], dtype=int)
        self.has_ft = bool(self.scene and self.scene.has_ft)
        if self.scene is not None:
            sc, adr = self.scene, self.scene.sensor_adr
            self._substep_frac = (np.arange(1, self.n_substeps + 1) / self.n_substeps)[:, None]
            self._imu_adr = np.r_[adr["imu_acc"]:adr["imu_acc"] + 3, adr["imu_gyro"]:adr["imu_gyro"] + 3]
            self._ft_adr = (np.array([np.r_[adr[f"{s}_force"]:adr[f"{s}_force"] + 3,
                                            adr[f"{s}_torque"]:adr[f"{s}_torque"] + 3] for s in SIDES])
                            if self.has_ft else None)
            self._sole_sites = np.array([sc.sole_site[s] for s in SIDES])
        self.regulator = None
        if standing_controller not in STANDING_CONTROLLERS:
            raise ConfigError(f"standing_controller {standing_controller!r}: use one of {list(STANDING_CONTROLLERS)}")
        if standing_controller == "cop" and self.scene is not None:
            if not self.has_ft:
                raise ConfigError(f"standing_controller 'cop' regulates each sole's centre of pressure from its ankle "
                                  f"force/torque sensor, and {self.sim_legmap.name} has none: give legs.left.ft and "
                                  "legs.right.ft in the leg map, or use standing_controller 'none'")
            self.regulator = CopRegulator(self.scene.model, self.scene, LegKinematics(self.sim_legmap),
                                          self.physics_dt)
            self._plan_data = mujoco.MjData(self.scene.model)  # where the plan puts the centre of mass
        self._R_BI = self.true_kin.T_BI[:3, :3]  # the simulated IMU in the pelvis frame (kinematic mode)
        self.encoder_map = encoder_map(self.sim_legmap)  # encoders behind transmissions (None: none)
        self.left = self.right = None
        self.standing = False

    def _model_joint_names(self) -> list[str]:
        return [self.true_kin.model.names[j] for j in range(1, self.true_kin.model.njoints)]

    def _placed(self, side: str, T: pin.SE3, stance: str | None = None) -> pin.SE3:
        """Where the simulated sole really sits: the placement on the sloped floor (if
        any, about the stance frame's origin), with its shims (if any, about the sole:
        the one in every session, then the one in `stance`'s session only)."""
        for F in (self.floor.get(side), None if stance is None else self.floor.get(floor_key(side, stance))):
            T = T if F is None else T * pin.SE3(F[:3, :3], F[:3, 3])
        S = self.floor.get("slope")
        return T if S is None else pin.SE3(S[:3, :3], S[:3, 3]) * T

    # ------------------------------------------------------------------ public
    @property
    def q_true(self) -> np.ndarray:
        return self._q_true.copy()

    @property
    def posture(self) -> np.ndarray:
        return self._posture.copy()

    def reset(self, left: pin.SE3, right: pin.SE3, posture: np.ndarray, standing: bool = False,
              stance: str | None = None) -> None:
        """Plant the soles at `left`/`right` (stance frame) with the pelvis at `posture`
        (standing: the straight-leg posture is solved instead), then let the servos settle.
        `stance` names the session's stance for a shim placed in it only (`floor`)."""
        self.left, self.right, self.standing = left, right, standing
        self.true_left, self.true_right = self._placed("left", left, stance), self._placed("right", right, stance)
        self.time = 0.0
        if standing:
            knee = self.sim_legmap.knee_straight_rad + self.knee_straight_error_rad
            posture, q_true = solve_standing(self.true_kin, self.true_left, self.true_right, posture, (knee, knee))
            self._posture, self._q_stand = posture, q_true
        else:
            q_true, self._posture = self._ik(self.true_kin, np.array(posture, dtype=float), self.true_kin.q_init())
        self._q_cmd = self._command_of(q_true) if standing else self._ik(self.nominal, self._posture, q_true)[0]
        self._q_true = q_true
        if self.mode == "kinematic":
            self._R_WB = posture_pose(self._posture).rotation
            R_WI = self._R_WB @ self._R_BI
            self._imu_R = (R_WI, R_WI)
            self._imu_true = self._kinematic_imu()
        else:
            self._reset_physics(q_true)
        self.reachable = True
        self._sole_ref = self._world_poses(self._snapshot(1))[0][0]  # sole drift is measured from here

    def step(self, posture: np.ndarray, q_cmd: np.ndarray | None = None, q_true: np.ndarray | None = None) -> bool:
        """Move to `posture` over one logging period; False if it was out of reach (the
        previous posture is held). `q_cmd` is the posture's nominal IK solution and (in
        kinematic mode) `q_true` the simulated robot's, if already known (`posture_ik`);
        otherwise `step` solves them, starting from the current ones."""
        return self._step(np.array(posture, dtype=float), q_cmd, q_true, None)

    def observe(self, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """What the robot logs now: encoder angles, IMU specific force and rate (and
        ankle force/torque where the scene has them), with the sensor model's errors.
        Random draws, in order: IMU, encoders, force/torque."""
        return {k: v[0] for k, v in self._sense(self._snapshot(1), rng).items()}

    def truth(self) -> dict:
        """The ground truth now (never given to calibrators)."""
        buf = self._snapshot(1)
        tr = {k: v[0] for k, v in self._truth(buf).items()}
        tr["time"], tr["posture_reachable"] = float(tr["time"]), bool(tr["posture_reachable"])
        return tr

    def solve_postures(self, postures: np.ndarray, kin: LegKinematics | None = None) -> np.ndarray:
        """`posture_ik` for the current soles with `kin` (default the nominal model),
        starting from the current solution: (N, n), a row of NaN for each posture out of
        reach or past a joint limit (which `step` then reports as unreachable)."""
        kin = self.nominal if kin is None else kin
        postures = np.asarray(postures, dtype=float).reshape(-1, 6)
        q = np.full((len(postures), self.legmap.n_joints), np.nan)
        todo = np.arange(len(postures))
        true = kin is self.true_kin
        start = self._q_true if true else self._q_cmd
        left, right = self._soles(kin)
        while todo.size:
            try:
                q[todo] = posture_ik(kin, left, right, postures[todo], start)
                break
            except IKError as e:
                todo = np.delete(todo, e.frames)
        return q

    def run(self, postures: np.ndarray, rng: np.random.Generator, q_cmd: np.ndarray | None = None,
            q_true: np.ndarray | None = None, progress=None) -> tuple[dict, dict]:
        """`step` through `postures` (N, 6), observing after each: (observations, ground
        truth), each stacked over the N frames: what `step`, `observe` and `truth` give
        frame by frame, with the same random draws (equal to rounding: batched and
        sequential IK agree to ~1e-13). `q_cmd` (N, n) is the postures' nominal IK
        (`posture_ik`; rows of NaN are solved by `step`); in kinematic mode the simulated
        robot's IK is solved here in one batch (or taken from `q_cmd` when the simulated
        robot is the nominal one). Legs of fewer than six joints hold nearby
        reachable postures (`holdable_postures`; the simulated robot's in kinematic mode,
        the commanded ones otherwise), which are what is recorded."""
        postures = np.asarray(postures, dtype=float).reshape(-1, 6)
        n = len(postures)
        kinematic = self.mode == "kinematic"
        if not self.standing:
            held = self.true_kin if kinematic else self.nominal
            postures = holdable_postures(held, *self._soles(held), postures,
                                         self._q_true if kinematic else self._q_cmd)
        R_WB = posture_poses(postures)[:, :3, :3] if kinematic else None
        if kinematic and q_true is None and not self.standing:
            q_true = q_cmd if q_cmd is not None and self.true_kin is self.nominal else \
                self.solve_postures(postures, self.true_kin)
        has_cmd = None if q_cmd is None else ~np.isnan(q_cmd).any(axis=1)
        has_true = None if q_true is None else ~np.isnan(q_true).any(axis=1)
        buf = self._buffers(n)
        for i in range(n):
            self._step(postures[i].copy(), q_cmd[i] if has_cmd is not None and has_cmd[i] else None,
                       q_true[i] if has_true is not None and has_true[i] else None,
                       R_WB[i] if kinematic else None)
            self._record(buf, i)
            if progress is not None:
                progress.update(1)
        return self._sense(buf, rng), self._truth(buf)

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
    def _soles(self, kin: LegKinematics) -> tuple[pin.SE3, pin.SE3]:
        """Where `kin`'s soles are: the simulated robot's (placed) or the nominal ones."""
        return (self.true_left, self.true_right) if kin is self.true_kin else (self.left, self.right)

    def _ik(self, kin: LegKinematics, posture: np.ndarray, q_init: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(q, posture): `kin`'s joint angles holding `posture` with its soles, and the
        posture held (`holdable_postures`: the one given, for legs of six joints)."""
        left, right = self._soles(kin)
        posture = holdable_postures(kin, left, right, posture, q_init)
        T_WB = posture_pose(posture)
        return kin.solve(T_WB.actInv(left), T_WB.actInv(right), q_init), posture

    def _step(self, posture: np.ndarray, q_cmd, q_true, R_WB) -> bool:
        """`step` (posture already a fresh float array); `R_WB`, the posture's rotation
        if known (kinematic mode)."""
        self.reachable = True
        kinematic = self.mode == "kinematic"
        if not self.standing:
            try:
                if q_cmd is None:
                    q_cmd, posture = self._ik(self.nominal, posture, self._q_cmd)
                if kinematic and q_true is None:
                    q_true, posture = self._ik(self.true_kin, posture, self._q_true)
                self._posture, self._q_cmd = posture, np.array(q_cmd, dtype=float)
                if kinematic:
                    self._q_true = np.array(q_true, dtype=float)
                    self._R_WB = posture_pose(posture).rotation if R_WB is None else R_WB
            except IKError:
                self.reachable = False
        if kinematic:
            self._imu_R = (self._imu_R[1], self._R_WB @ self._R_BI)
            self._imu_true = self._kinematic_imu()
        else:
            self._advance_physics()
        self.time += self.dt
        return self.reachable

    def _set_state(self, q_true: np.ndarray, T_WB: pin.SE3, data: mujoco.MjData | None = None) -> None:
        sc, d = self.scene, self.data if data is None else data
        a = sc.free_qpos_adr
        d.qpos[a:a + 7] = se3_to_pos_quat(T_WB)
        d.qpos[sc.qpos_adr] = q_true
        if sc.drive is not None:  # drive joints where their couplings put them: (q - c0) / c1
            d.qpos[sc.act_qpos_adr] = to_encoder_space(q_true, sc.drive)
        d.qpos[sc.hold_qpos_adr] = sc.hold_angle

    def _planned_com(self) -> tuple[float, float]:
        """Where the plan puts the centre of mass on the floor (world x, y): the robot's
        model with the pelvis at the posture and the commanded (nominal) joint angles,
        as a real robot's controller computes it from its model."""
        sc, d = self.scene, self._plan_data
        self._set_state(self._q_cmd, posture_pose(self._posture), d)
        mujoco.mj_kinematics(sc.model, d)
        mujoco.mj_comPos(sc.model, d)
        return float(d.subtree_com[0, 0]), float(d.subtree_com[0, 1])

    def _servo_target(self) -> np.ndarray:
        # Standing is the one phase with a physically imposed posture (legs straightened
        # against the mechanism), so its servo target is the true straight-leg posture.
        return self._q_stand if self.standing else self._true_of(self._q_cmd)

    # The offsets are in the calibration's coordinates: the joints' angles, but a linkage
    # ankle's two columns its motors' (`legcal_bench.robots.linkage`). The robot's software
    # turns a joint command into motor targets through the nominal linkage; the motors
    # reach them off by the offsets, and the true linkage turns the joints.
    def _true_of(self, q_cmd: np.ndarray) -> np.ndarray:
        """The joints' true angles where the servos hold the command `q_cmd` (n,)."""
        q = q_cmd + self.offsets
        for nom, true in zip(self.nominal.linkages, self.true_kin.linkages):
            c = list(nom.cols)
            q[c] = true.joints(nom.motors(q_cmd[c][None]) + self.offsets[c])[0][0]
        return q

    def _command_of(self, q_true: np.ndarray) -> np.ndarray:
        """`_true_of`'s inverse: the command that holds the joints at `q_true` (n,)."""
        q = q_true - self.offsets
        for nom, true in zip(self.nominal.linkages, self.true_kin.linkages):
            c = list(nom.cols)
            q[c] = nom.joints(true.motors(q_true[c][None]) - self.offsets[c])[0][0]
        return q

    def _drive(self, targets: np.ndarray) -> None:
        """One physics step per row of `targets` (joint-space servo targets)."""
        sc, d, mj_step = self.scene, self.data, mujoco.mj_step
        m = sc.model
        pos_act, pos_cols, motors, _ = sc.servo
        if self.regulator is not None:  # the standing controller's corrections, tick by tick
            reg = self.regulator
            for target in targets:
                apply_servos(sc, d, target + reg.step(d))
                mj_step(m, d)
            return
        if pos_cols is None and motors is None:  # every leg joint on a position actuator, in order
            ctrl = d.ctrl  # `apply_servos` of this layout, its lookups made once
            for target in targets:
                ctrl[pos_act] = target
                mj_step(m, d)
            return
        for target in targets:
            apply_servos(sc, d, target)
            mj_step(m, d)

    def _reset_physics(self, q_true: np.ndarray) -> None:
        sc, d = self.scene, self.data
        mujoco.mj_resetData(sc.model, d)
        self._set_state(q_true, posture_pose(self._posture))
        if sc.mocap:
            for side, T in zip(SIDES, (self.true_left, self.true_right)):
                pq = se3_to_pos_quat(T)
                d.mocap_pos[sc.mocap[side]], d.mocap_quat[sc.mocap[side]] = pq[:3], pq[3:]
        mujoco.mj_forward(sc.model, d)
        # The servos start at the true posture and blend to their (strained) targets
        # over most of the settle time (smoothstep): a step would jolt the robot off its feet.
        self._target = self._servo_target()
        if self.regulator is not None:
            # The straight-leg phase's targets are the true posture (`_servo_target`):
            # no offset moves its centre of mass, so none is held.
            self.regulator.hold_com = not self.standing
            self.regulator.com_ref = self._planned_com()
            self.regulator.reset(q_true, d.site_xmat[self._sole_sites].reshape(2, 3, 3))
        n = int(round(self.settle_s / self.physics_dt))
        s = np.minimum(1.0, np.arange(1, n + 1) / max(1, int(0.7 * n)))[:, None]
        self._drive(q_true + (s * s * (3 - 2 * s)) * (self._target - q_true))
        if self.regulator is not None:  # the centre of mass is held while the targets blend in, then left
            self.regulator.hold_com = False

    def _advance_physics(self) -> None:
        sc, d = self.scene, self.data
        start, end = self._target, self._servo_target()
        self._drive(start + (end - start) * self._substep_frac)  # linear over the logging period
        self._target = end
        self._q_true = d.qpos[sc.qpos_adr]
        if self._spring_cols.size:  # the link angle: motor + series spring
            self._q_true = self._q_true.copy()
            self._q_true[self._spring_cols] += d.qpos[self._spring_adr]

    def _q_motor(self) -> np.ndarray:
        """What the encoders measure: the motor side of any series spring."""
        if not self._spring_cols.size:
            return self._q_true
        return self.data.qpos[self.scene.qpos_adr]

    def _kinematic_imu(self) -> tuple[np.ndarray, np.ndarray]:
        # Each frame is a static posture (quasi-static), so the accelerometer reads
        # gravity alone; the rate is the backward difference.
        R1, R2 = self._imu_R
        return R2.T @ (-GRAVITY), pin.log3(R1.T @ R2) / self.dt

    def _true_imu(self) -> tuple[np.ndarray, np.ndarray]:
        """Specific force and angular rate in the IMU frame."""
        if self.mode == "kinematic":
            return self._imu_true[0].copy(), self._imu_true[1].copy()
        imu = self.data.sensordata[self._imu_adr]
        return imu[:3], imu[3:]

    def encoder_input(self, q_motor: np.ndarray) -> np.ndarray:
        """What the encoders see before their own errors: the joint angle less the offset,
        behind a transmission the motor's angle, (q - dq - c0) / c1 (its offset dq / c1),
        and a linkage ankle's motors' angles less their offsets."""
        e = to_encoder_space(q_motor - self.offsets, self.encoder_map)
        for lk in self.true_kin.linkages:
            c = list(lk.cols)
            e[..., c] = lk.motors(np.atleast_2d(q_motor[..., c])).reshape(e[..., c].shape) - self.offsets[c]
        return e

    def _sense(self, buf: dict[str, np.ndarray], rng: np.random.Generator) -> dict[str, np.ndarray]:
        """`observe` of every frame recorded in `buf` (`_record`), in one pass: the
        random draws of all frames at once, each frame's in `observe`'s order (IMU 3 + 3,
        encoders one per leg joint, force/torque 2 x 6), so the same numbers as frame by frame."""
        n, sen = len(buf["time"]), self.sensor
        enc = slice(6, 6 + self.legmap.n_joints)  # after the IMU's 3 + 3
        noise = rng.standard_normal((n, enc.stop + (12 if self.has_ft else 0)))
        imu = sen.imu_samples(np.stack([buf["imu_true_acc"], buf["imu_true_gyro"]], axis=1), noise[:, :6])
        obs = {"q_enc": sen.encoders(self.encoder_input(buf["q_motor"]), rng, noise[:, enc], buf["time"]),
               "imu_acc": np.ascontiguousarray(imu[:, 0]), "imu_gyro": np.ascontiguousarray(imu[:, 1])}
        if self.has_ft:
            obs["ft"] = sen.force_torque(buf["ft"], rng, noise[:, enc.stop:].reshape(n, 2, 6))
        return obs

    # ------------------------------------------------------------ ground truth
    # A frame's raw state goes into preallocated arrays (`_record`); `_truth` converts
    # any number of frames at once (poses to [x y z qw qx qy qz], sole drift).
    def _buffers(self, n: int) -> dict[str, np.ndarray]:
        nj = self.legmap.n_joints
        buf = {"time": np.empty(n), "q_true": np.empty((n, nj)), "q_motor": np.empty((n, nj)),
               "posture": np.empty((n, 6)),
               "posture_reachable": np.empty(n, dtype=bool), "imu_true_acc": np.empty((n, 3)),
               "imu_true_gyro": np.empty((n, 3))}
        if self.mode != "kinematic":
            buf.update(sole_pos=np.empty((n, 2, 3)), sole_rot=np.empty((n, 2, 9)),
                       pelvis_pos=np.empty((n, 3)), pelvis_rot=np.empty((n, 9)), q_target=np.empty((n, nj)),
                       held_q=np.empty((n, len(self.scene.holds))))
        if self.has_ft:
            buf["ft"] = np.empty((n, 2, 6))  # the ankle sensors' true wrenches
        return buf

    def _record(self, buf: dict[str, np.ndarray], i: int) -> None:
        buf["time"][i] = self.time
        buf["q_true"][i] = self._q_true
        buf["q_motor"][i] = self._q_motor() if self.scene is not None else self._q_true
        buf["posture"][i] = self._posture
        buf["posture_reachable"][i] = self.reachable
        buf["imu_true_acc"][i], buf["imu_true_gyro"][i] = self._true_imu()
        if self.mode != "kinematic":
            d, b = self.data, self.scene.pelvis_body
            buf["sole_pos"][i] = d.site_xpos[self._sole_sites]
            buf["sole_rot"][i] = d.site_xmat[self._sole_sites]
            buf["pelvis_pos"][i] = d.xpos[b]
            buf["pelvis_rot"][i] = d.xmat[b]
            # What the servos are told: the planned target and the standing controller's corrections.
            buf["q_target"][i] = self._target if self.regulator is None else self._target + self.regulator.u
            if self.scene.holds:
                buf["held_q"][i] = d.qpos[self.scene.hold_qpos_adr]
        if self.has_ft:
            buf["ft"][i] = self.data.sensordata[self._ft_adr]

    def _snapshot(self, n: int) -> dict[str, np.ndarray]:
        buf = self._buffers(n)
        self._record(buf, 0)
        return buf

    def _world_poses(self, buf: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """(sole poses (N, 2, 4, 4), pelvis poses (N, 4, 4)) in the world (stance) frame."""
        if self.mode == "kinematic":
            T_WB = posture_poses(buf["posture"])
            T_left, T_right = self.true_kin.sole_poses_batch(buf["q_true"])
            return T_WB[:, None] @ np.stack([T_left, T_right], axis=1), T_WB
        n = len(buf["time"])
        soles, pelvis = np.zeros((n, 2, 4, 4)), np.zeros((n, 4, 4))
        soles[..., :3, :3], soles[..., :3, 3], soles[..., 3, 3] = buf["sole_rot"].reshape(n, 2, 3, 3), buf["sole_pos"], 1
        pelvis[:, :3, :3], pelvis[:, :3, 3], pelvis[:, 3, 3] = buf["pelvis_rot"].reshape(n, 3, 3), buf["pelvis_pos"], 1
        return soles, pelvis

    def _truth(self, buf: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        soles, pelvis = self._world_poses(buf)
        drift = inverse(self._sole_ref) @ soles  # each sole relative to its pose at reset
        rotation = Log(drift)[..., 3:]
        n = len(buf["time"])
        return {
            "time": buf["time"],
            "q_true": buf["q_true"],
            "q_motor": buf["q_motor"],  # what the encoders measure (the motor side of any series spring)
            "offsets": np.tile(self.offsets, (n, 1)),
            "posture": buf["posture"],
            "posture_reachable": buf["posture_reachable"],
            "sole_poses_world": homogeneous_to_pos_quat(soles),
            "pelvis_pose_world": homogeneous_to_pos_quat(pelvis),
            "sole_drift_m": np.linalg.norm(drift[..., :3, 3], axis=-1),
            "sole_drift_rad": np.linalg.norm(rotation, axis=-1),
            "sole_turn_rad": np.abs(rotation[..., 2]),  # of that, about the sole's normal (a twist on the floor)
            "imu_true_acc": buf["imu_true_acc"],
            "imu_true_gyro": buf["imu_true_gyro"],
            # (N, h) each held non-leg joint's angle minus its hold angle (`Scene.holds`; physics modes)
            **({"held_joint_error_rad": buf["held_q"] - self.scene.hold_angle} if "held_q" in buf else {}),
            **dict(zip(("pelvis_hold_error_m", "pelvis_strain_m", "pelvis_beyond_strain_m"),
                       self._pelvis_hold_error(buf, soles, pelvis))),
        }

    def _pelvis_hold_error(self, buf, soles: np.ndarray, pelvis: np.ndarray) -> tuple[np.ndarray, ...]:
        """((N,) x 3, m): the pelvis's distance from its commanded pose, where the servo
        targets put it on the simulated robot's kinematics from each sole's actual pose
        (the midpoint of the two legs' predictions); how far the offsets' strain moves
        that pose (to the closed chain's compromise: the joint angles nearest the targets,
        weighed by the servos' stiffness, that put both soles where they are: one
        Gauss-Newton step of the constrained least squares); and the pelvis's distance
        from that compromise (what sag, folding or tipping add). Zeros in kinematic mode."""
        n = len(buf["time"])
        if "q_target" not in buf:
            return np.zeros(n), np.zeros(n), np.zeros(n)
        q_t = buf["q_target"]
        T_left, T_right = self.true_kin.sole_poses_batch(q_t)
        by_left, by_right = (soles[:, 0] @ inverse(T_left))[:, :3, 3], (soles[:, 1] @ inverse(T_right))[:, :3, 3]
        predicted = (by_left + by_right) / 2
        # The compromise: min (q - q_t)' K (q - q_t) with C(q) = the soles' actual transform.
        fk = joint_frame_kinematics(self.true_kin, q_t)
        r = Log(inverse(fk.C) @ (inverse(soles[:, 0]) @ soles[:, 1]))
        Kinv_Gt = np.swapaxes(fk.G, 1, 2) / self.scene.servo_kp[None, :, None]
        # pinv, not solve: the 6x6 is singular where the legs' joints cannot move the soles'
        # transform every way (a leg of five joints at a straight-knee posture: issue #60).
        dq = (Kinv_Gt @ (np.linalg.pinv(fk.G @ Kinv_Gt, hermitian=True) @ r[..., None]))[..., 0]
        T_left_c = self.true_kin.sole_poses_batch(q_t + dq)[0]
        compromise = (soles[:, 0] @ inverse(T_left_c))[:, :3, 3]
        return (np.linalg.norm(pelvis[:, :3, 3] - predicted, axis=-1),
                np.linalg.norm(compromise - predicted, axis=-1),
                np.linalg.norm(pelvis[:, :3, 3] - compromise, axis=-1))
