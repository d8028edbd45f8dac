"""Free-standing walking: the robot on a frictional floor, servos at physics rate
tracking encoder-space targets, and what its software reads.

The scene is the robot's own MJCF on the arena's walking floor (`legcal_bench.sim.scene`,
mode "walking"): the leg joints' actuators become position servos with the walking
gains (PD at physics rate, inside MuJoCo's step), and the walking-only additions of
`WalkingConfig` (integrator, armature, floor friction) live here, never in the robot
file, so the static results do not move.

Encoders and corrections, as on a robot: the encoders read q_enc = q_true - dq (+ noise,
quantized); the software applies a correction dq_hat as q_corr = q_enc + dq_hat before
both the policy and the servo loop. A servo tracking target u on q_corr drives the true
joint to u + dq - dq_hat: with no correction the offsets bend the real posture, with the
true one (dq_hat = dq) they vanish. The servo loop reads the encoders without their
noise (a motor driver's loop at physics rate; the noise is 1e-4 rad against kp of
~100 N m/rad, 0.01 N m).

What the software sees each control step (`observe`): the corrected encoder angles,
joint velocities (the true ones plus the noise of a difference of two encoder readings
one physics step apart, as a motor driver differentiates), the gyro and accelerometer (`SimSensors`: noise, bias and the
realized mounting tilt), the gravity direction from an orientation filter on them
(`GravityFilter`, in the base frame through the nominal IMU mount: a mounting tilt is
seen as a tilt of the robot), and the ankle force/torque where the leg map has them.

A whole-body policy (`WalkingConfig.extra_joints`) drives the robot's other joints too
(waist, arms; no offsets on them), with PD servos or, with `model_actuators`, the MJCF's
own actuators; joints a leg map holds (`held_joints_rad`) are released when driven.
A spec's training settings enter here: the floor's friction (`floor_friction_exact`: the
floor geom's priority makes it the contacts'), the MJCF keyframe to start from, and the
MJCF sensors its privileged terms read (`sensor_readings`).

Ground truth (`truth`): pelvis pose, joint torques and mechanical power, each foot's
vertical contact load, foot strikes (a touchdown is the load of a foot rising above
`TOUCHDOWN_FRACTION` of the robot's weight after it was below `LIFTOFF_FRACTION`; its
position is the sole frame's at that step) and falls (`FALL_HEIGHT_FRACTION`,
`FALL_TILT_RAD`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import mujoco
import numpy as np
import pinocchio as pin

from dm_control import mjcf

from legcal_bench.errors import ConfigError
from legcal_bench.robots.frames import mjcf_element
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots.legmap import SIDES, LegMap
from legcal_bench.robots.linkage import linked_joints
from legcal_bench.robots.transmission import transmissions
from legcal_bench.sim.orientation import GravityFilter
from legcal_bench.sim.scene import Scene, compose_robot
from legcal_bench.sim.sensors import SimSensors

FALL_HEIGHT_FRACTION = 0.6  # fallen: the pelvis below this fraction of its starting height ...
FALL_TILT_RAD = 1.0  # ... or its z axis more than this from vertical (57 deg)
TOUCHDOWN_FRACTION = 0.15  # of the robot's weight on a foot: touchdown (after liftoff)
LIFTOFF_FRACTION = 0.03  # of the robot's weight: the foot is off the floor
_COS_FALL_TILT = float(np.cos(FALL_TILT_RAD))


@dataclass(frozen=True)
class WalkingConfig:
    """How the robot walks: servo gains and pose (leg-map order), rates, and the
    walking-only model additions."""

    kp: tuple[float, ...]  # N m/rad
    kd: tuple[float, ...]  # N m s/rad
    default_q: tuple[float, ...]  # rad, the pose the robot starts in (encoder space)
    physics_dt: float = 0.002
    decimation: int = 10  # physics steps per control step
    torque_limit: tuple[float, ...] | None = None  # N m per joint; None: the MJCF's
    integrator: str | None = None  # None: the MJCF's own
    armature: float | None = None  # kg m^2 on leg joints whose MJCF gives none
    # The walking floor's contact: MuJoCo's defaults (the static floor is stiffer and
    # has torsional friction, for soles that must not creep).
    floor_friction: tuple[float, float, float] = (1.0, 0.005, 0.0001)
    # True: the floor's friction is the contact's (MuJoCo's geom priority), e.g. the friction
    # a policy was trained on; False: MuJoCo's mix with the feet's (the larger).
    floor_friction_exact: bool = False
    floor_solref: tuple[float, float] = (0.02, 1.0)
    floor_solimp: tuple[float, ...] = (0.9, 0.95, 0.001, 0.5, 2.0)
    jitter_q_rad: float = 0.01  # initial joint angles, uniform +-
    jitter_yaw_rad: float = 0.02  # initial heading, uniform +-
    # A whole-body policy: the robot's other joints it drives, or that its spec holds
    # (waist, arms), after the leg joints in every joint vector (targets, observations).
    # They carry no offsets. Their gains (pd servos) and default pose, in this order.
    extra_joints: tuple[str, ...] = ()
    extra_kp: tuple[float, ...] = ()
    extra_kd: tuple[float, ...] = ()
    extra_default_q: tuple[float, ...] = ()
    # True: every driven joint keeps the MJCF's own actuator (e.g. position actuators with
    # their gains and ranges; kp, kd then unused); False: PD servos with kp, kd.
    model_actuators: bool = False
    keyframe: str | int | None = None  # the MJCF keyframe the robot starts from (joints not driven too)
    sensors: tuple[str, ...] = ()  # MJCF sensors read into the truth (privileged observation terms)

    def __post_init__(self):
        n = np.shape(self.default_q)[0] if np.ndim(self.default_q) == 1 else None  # the robot's leg joints
        for name in ("kp", "kd", "default_q"):
            v = np.asarray(getattr(self, name), dtype=float)
            if n is None or v.shape != (n,) or not n or not np.isfinite(v).all():
                raise ConfigError(f"walking config: '{name}' must be finite numbers, one per leg joint (leg-map "
                                  f"order) as default_q gives, got {v.shape}")
        k = len(self.extra_joints)
        for name in ("extra_kp", "extra_kd", "extra_default_q"):
            v = np.asarray(getattr(self, name), dtype=float)
            if v.shape != (k,) or not np.isfinite(v).all():
                raise ConfigError(f"walking config: '{name}' must be finite numbers, one per extra joint ({k}), "
                                  f"got {v.shape}")
        if self.physics_dt <= 0 or self.decimation < 1:
            raise ConfigError("walking config: physics_dt must be > 0 and decimation >= 1")

    @property
    def body_joints(self) -> int:
        """Entries of a target or default pose vector: the leg joints, then the extra ones."""
        return len(self.default_q) + len(self.extra_joints)

    @property
    def control_dt(self) -> float:
        return self.physics_dt * self.decimation


def build_walking_scene(legmap: LegMap, cfg: WalkingConfig) -> Scene:
    """The robot's MJCF on the walking floor, its leg actuators replaced by position
    servos (gain kp, bias -kp q - kd qdot: PD at physics rate inside MuJoCo's step) with
    the robot's torque limits (or `cfg.torque_limit`), and `cfg`'s model additions."""
    if len(cfg.default_q) != legmap.n_joints:
        raise ConfigError(f"walking config: {len(cfg.default_q)} joint values (kp, kd, default_q) but robot "
                          f"{legmap.name} has {legmap.n_joints} leg joints")
    driven = sorted(n for n, t in transmissions(legmap).items() if t.drive is not None)
    if driven:
        raise ConfigError(f"{legmap.source or legmap.name}: leg joints {driven} are turned by drive joints (joint "
                          "equalities in the model): walking does not simulate drive joints yet (static collection "
                          "does); walk a model whose leg joints carry their actuators")
    if linked_joints(legmap):
        raise ConfigError(f"{legmap.source or legmap.name}: ankle joints {linked_joints(legmap)} are turned by a "
                          "linkage (legs.<side>.linkage): walking does not simulate linkage ankles yet (static "
                          "collection does); walk the model without the leg map's linkage")
    m = mjcf_element(legmap.mjcf)
    m.option.timestep = cfg.physics_dt
    if cfg.integrator is not None:
        m.option.integrator = cfg.integrator
    body = list(legmap.joint_names) + list(cfg.extra_joints)
    where = str(legmap.source or legmap.name)
    for name in cfg.extra_joints:
        if m.find("joint", name) is None:
            raise ConfigError(f"walking config: joint '{name}' (a whole-body policy's) is not in {legmap.mjcf}")
    actuated = [_actuated_joint(a) for a in m.actuator.all_children()]
    loose = [j for j in actuated if j is not None and j not in body and j not in legmap.held_joints_rad]
    if cfg.extra_joints and loose:  # a whole-body run: every actuated joint driven or held, or it sags
        raise ConfigError(f"{where}: actuated joints {loose} are neither driven by the policy nor held: list them "
                          "in the spec's 'joints' or 'hold' (or the leg map's held_joints_rad)")
    if cfg.model_actuators:
        missing = [j for j in body if j not in actuated]
        if missing:
            raise ConfigError(f"walking config: model_actuators, but joints {missing} have no actuator in "
                              f"{legmap.mjcf}: use PD servos (the spec's `actuators: pd`) or add them")
    else:
        limits = np.full(len(body), np.inf)
        for act in list(m.actuator.all_children()):
            name = _actuated_joint(act)
            if name in body:
                rng = act.forcerange if act.forcelimited in (True, "true") else (
                    act.ctrlrange * (act.gear[0] if act.gear is not None else 1.0)
                    if act.tag == "motor" and act.ctrllimited in (True, "true") and act.ctrlrange is not None else None)
                if rng is not None:
                    limits[body.index(name)] = float(np.max(np.abs(rng)))
                act.remove()
        if cfg.torque_limit is not None:
            limits[:legmap.n_joints] = np.asarray(cfg.torque_limit, dtype=float)
        kp, kd = list(cfg.kp) + list(cfg.extra_kp), list(cfg.kd) + list(cfg.extra_kd)
        for k, name in enumerate(body):
            extra = {} if not np.isfinite(limits[k]) else dict(forcelimited=True, forcerange=[-limits[k], limits[k]])
            m.actuator.add("general", name=f"legcal_servo_{name}", joint=name, gaintype="fixed", biastype="affine",
                           gainprm=[kp[k]], biasprm=[0.0, -kp[k], -kd[k]], **extra)
    floor = dict(friction=cfg.floor_friction, solref=cfg.floor_solref, solimp=cfg.floor_solimp)
    if cfg.floor_friction_exact:
        floor["priority"] = True
    scene = compose_robot(m, legmap, "walking", floor=floor, release=set(body))
    if cfg.armature is not None:
        dofs = scene.dof_adr[scene.model.dof_armature[scene.dof_adr] == 0]
        scene.model.dof_armature[dofs] = cfg.armature
    return scene


def _actuated_joint(act) -> str | None:
    """The joint an MJCF actuator drives (by name), or None."""
    joint = getattr(act, "joint", None)
    return joint if isinstance(joint, str) or joint is None else getattr(joint, "name", None)


def _body_actuators(model: mujoco.MjModel, body_qpos: np.ndarray) -> np.ndarray:
    """Per driven joint (legs, then extra), the actuator that drives it (by its qpos address)."""
    out = -np.ones(len(body_qpos), dtype=int)
    for a in range(model.nu):
        if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT:
            hit = np.flatnonzero(body_qpos == model.jnt_qposadr[model.actuator_trnid[a, 0]])
            if hit.size:
                out[hit[0]] = a
    return out


@dataclass
class FootStrikes:
    """Touchdowns per foot: times (s) and sole positions (m, world)."""

    time: dict = field(default_factory=lambda: {s: [] for s in SIDES})
    position: dict = field(default_factory=lambda: {s: [] for s in SIDES})

    def to_dict(self) -> dict:
        return {s: {"time": list(self.time[s]), "position": [list(p) for p in self.position[s]]} for s in SIDES}


class WalkingSim:
    """One robot walking freely; `reset` stands it on the floor, `step` applies one
    control step's targets (encoder space, leg-map order)."""

    def __init__(self, legmap: LegMap, config: WalkingConfig, sensor: SimSensors):
        self.legmap, self.config, self.sensor = legmap, config, sensor
        self.scene = build_walking_scene(legmap, config)
        self.model = self.scene.model
        self.data = mujoco.MjData(self.model)
        # The nominal mount of the IMU the policy reads (`policy_imu`, else the leg map's IMU)
        self.kin = LegKinematics(replace(legmap, imu=legmap.policy_imu, imu_through=())
                                 if legmap.policy_imu is not None else legmap)
        self.R_BI = self.kin.R_BI  # nominal IMU mount in the base frame
        self.filter = GravityFilter()
        sc, m = self.scene, self.model
        self.weight = float(sum(m.body_mass)) * 9.81
        self._foot_bodies = {s: self._subtree(m.site_bodyid[sc.sole_site[s]]) for s in SIDES}
        self._imu_adr = np.r_[sc.sensor_adr["imu_acc"]:sc.sensor_adr["imu_acc"] + 3,
                              sc.sensor_adr["imu_gyro"]:sc.sensor_adr["imu_gyro"] + 3]
        self._ft_adr = (np.concatenate([np.r_[sc.sensor_adr[f"{s}_{k}"]:sc.sensor_adr[f"{s}_{k}"] + 3]
                                        for s in SIDES for k in ("force", "torque")]) if sc.has_ft else None)
        free = int(np.flatnonzero(m.jnt_qposadr == sc.free_qpos_adr)[0])
        self._free_dof = int(m.jnt_dofadr[free])
        # Driven joints: the leg joints (scene order), then a whole-body policy's others.
        extra = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in config.extra_joints]
        self.body_qpos = np.r_[sc.qpos_adr, [m.jnt_qposadr[j] for j in extra]].astype(int)
        self.body_dof = np.r_[sc.dof_adr, [m.jnt_dofadr[j] for j in extra]].astype(int)
        self._n_extra = len(extra)
        self.body_act = _body_actuators(m, self.body_qpos) if (config.model_actuators or extra) else None
        self._ctrl_idx = sc.servo[0] if self.body_act is None else self.body_act  # the driven joints' ctrl
        if self.body_act is not None and (self.body_act < 0).any():
            raise ConfigError(f"walking config: joints {[n for n, a in zip(legmap.joint_names + list(config.extra_joints), self.body_act) if a < 0]} have no actuator")
        self._sensor_adr = {}
        for name in config.sensors:
            i = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, name)
            if i < 0:
                raise ConfigError(f"walking config: sensor '{name}' is not in {legmap.mjcf} (its sensors: "
                                  f"{[mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_SENSOR, k) for k in range(m.nsensor)]})")
            self._sensor_adr[name] = slice(int(m.sensor_adr[i]), int(m.sensor_adr[i] + m.sensor_dim[i]))
        self._keyframe = None
        if config.keyframe is not None:
            k = (config.keyframe if isinstance(config.keyframe, int)
                 else mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, config.keyframe))
            if not 0 <= k < m.nkey:
                raise ConfigError(f"walking config: keyframe {config.keyframe!r} is not in {legmap.mjcf} "
                                  f"({m.nkey} keyframes)")
            self._keyframe = k
        # Worked out once, used every control step: which geoms belong to a foot (side x
        # geom), the differentiated encoders' noise, gravity's specific force.
        self._foot_geom_lists = tuple(self._foot_bodies[s].tolist() for s in SIDES)
        self._dq_sigma = np.sqrt(2) * sensor.model.encoder_noise_std / config.physics_dt
        self._up_g = np.array([0.0, 0.0, 9.81])
        # Standard normal draws per `observe`: encoders and joint velocities (one per leg
        # joint each), the IMU (3 + 3, twice), force/torque (2 x 6).
        nj = legmap.n_joints
        self._noise_at = {"q_enc": slice(0, nj), "dq_enc": slice(nj, 2 * nj), "imu": slice(2 * nj, 2 * nj + 12)}
        self._n_noise = 2 * nj + 12 + (12 if sc.has_ft else 0)
        # A whole-body policy's other joints: their encoders and velocities, drawn after the rest.
        ne = self._n_extra
        self._noise_at["extra"] = slice(self._n_noise, self._n_noise + 2 * ne)
        self._n_noise += 2 * ne
        self._imu4 = np.empty((4, 3))  # the IMU's two samples per `observe`: [acc, gyro] now, over the step
        self.offsets = np.zeros(nj)
        self.correction = np.zeros(nj)

    def _subtree(self, body: int) -> np.ndarray:
        m = self.model
        bodies = {body}
        for b in range(m.nbody):
            p = b
            while p > 0 and p not in bodies:
                p = m.body_parentid[p]
            if p in bodies:
                bodies.add(b)
        return np.isin(m.geom_bodyid, sorted(bodies))

    # ------------------------------------------------------------------ control
    def reset(self, offsets: np.ndarray, correction: np.ndarray, rng: np.random.Generator) -> None:
        """Stand the robot on the floor at the default pose (servo targets held), its
        soles' lowest corner touching the floor, with a small seeded jitter."""
        sc, m, d, cfg = self.scene, self.model, self.data, self.config
        self.offsets = np.asarray(offsets, dtype=float).copy()
        self.correction = np.asarray(correction, dtype=float).copy()
        if self._keyframe is None:
            mujoco.mj_resetData(m, d)
        else:
            mujoco.mj_resetDataKeyframe(m, d, self._keyframe)
        target = np.r_[cfg.default_q, cfg.extra_default_q]
        d.qpos[self.body_qpos] = self._true_target(target) + rng.uniform(-1, 1, len(target)) * cfg.jitter_q_rad
        yaw = rng.uniform(-1, 1) * cfg.jitter_yaw_rad
        f = sc.free_qpos_adr
        d.qpos[f:f + 3] = 0.0
        d.qpos[f + 3:f + 7] = [np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]
        mujoco.mj_kinematics(m, d)
        corners = np.concatenate([sc.corner_sites[s] for s in SIDES])
        d.qpos[f + 2] = -d.site_xpos[corners, 2].min() + 0.002
        mujoco.mj_forward(m, d)
        self._ctrl(target)
        self.start_height = float(d.qpos[f + 2])
        self.time = 0.0
        self.fallen_at: float | None = None
        self.strikes = FootStrikes()
        self._airborne = {s: False for s in SIDES}
        self.loads = self.foot_loads()
        # The filter has settled on the robot standing still before the run: the
        # accelerometer's static reading (gravity, through the mount tilt and bias).
        R_WI = d.site_xmat[sc.imu_site].reshape(3, 3)
        self.filter.reset(self.sensor.imu(R_WI.T @ np.array([0.0, 0.0, 9.81]), np.zeros(3), rng)[0])
        self._imu_state = self._imu_kinematics()
        self._imu_mean = (R_WI.T @ np.array([0.0, 0.0, 9.81]), np.zeros(3))

    def _true_target(self, target: np.ndarray) -> np.ndarray:
        # q_corr = q_true - dq + dq_hat tracks target  <=>  q_true tracks target + dq - dq_hat.
        # A whole-body policy's other joints (after the legs) carry no offsets.
        if self._n_extra:
            out = np.array(target, dtype=float)
            out[:len(self.offsets)] += self.offsets - self.correction
            return out
        return target + self.offsets - self.correction

    def _ctrl(self, target: np.ndarray) -> None:
        self.data.ctrl[self._ctrl_idx] = self._true_target(target)

    def step(self, target: np.ndarray) -> None:
        """Hold `target` (encoder space, corrected; the leg joints, then a whole-body
        policy's others) for one control step."""
        m, d, cfg = self.model, self.data, self.config
        d.ctrl[self._ctrl_idx] = self._true_target(target)
        mujoco.mj_step(m, d, nstep=cfg.decimation)
        self.time += cfg.control_dt
        # The IMU's rate and specific force averaged over the step (a high-rate filter's input).
        (R0, v0), (R1, v1) = self._imu_state, self._imu_kinematics()
        T = cfg.control_dt
        self._imu_mean = (R1.T @ ((v1 - v0) / T + self._up_g), pin.log3(R0.T @ R1) / T)
        self._imu_state = (R1, v1)
        self._events()

    # ----------------------------------------------------------------- sensing
    def _imu_kinematics(self) -> tuple[np.ndarray, np.ndarray]:
        """The IMU site's orientation (world) and linear velocity (world)."""
        v = np.empty(6)
        mujoco.mj_objectVelocity(self.model, self.data, mujoco.mjtObj.mjOBJ_SITE, self.scene.imu_site, v, 0)
        return self.data.site_xmat[self.scene.imu_site].reshape(3, 3).copy(), v[3:]

    def _true_imu(self) -> tuple[np.ndarray, np.ndarray]:
        s = self.data.sensordata[self._imu_adr]
        return s[:3], s[3:]

    def observe(self, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """What the robot's software reads now (corrected encoders). Random draws, in
        order: encoders (one per leg joint), joint velocities (one per leg joint), the IMU
        now (accelerometer 3, gyro 3), the filter's IMU sample over the step (3 + 3),
        force/torque (2 x 6); drawn at
        once (the same numbers), the IMU's two samples read in one call."""
        sc, d, sen = self.scene, self.data, self.sensor
        noise = rng.standard_normal(self._n_noise)
        at = self._noise_at
        q_enc = sen.encoders(d.qpos[sc.qpos_adr] - self.offsets, rng, noise[at["q_enc"]])
        dq = d.qvel[sc.dof_adr] + self._dq_sigma * noise[at["dq_enc"]]
        imu = self._imu4
        imu[:2] = d.sensordata[self._imu_adr].reshape(2, 3)  # `_true_imu`
        imu[2], imu[3] = self._imu_mean
        acc, gyro, acc_mean, gyro_mean = sen.imu_samples(imu, noise[at["imu"]])
        down_I = self.filter.update(acc_mean, gyro_mean, self.config.control_dt)
        obs = {"q_enc": q_enc + self.correction, "dq_enc": dq, "imu_acc": acc, "imu_gyro": gyro,
               "gravity": self.R_BI @ down_I}
        if self._ft_adr is not None:
            obs["ft"] = sen.force_torque(d.sensordata[self._ft_adr].reshape(2, 6), rng,
                                         noise[at["imu"].stop:at["imu"].stop + 12].reshape(2, 6))
        if self._n_extra:  # a whole-body policy's other joints: encoders without offsets
            ne, ex = self._n_extra, noise[at["extra"]]
            obs["q_extra"] = sen.encoders(d.qpos[self.body_qpos[-ne:]], rng, ex[:ne])
            obs["dq_extra"] = d.qvel[self.body_dof[-ne:]] + self._dq_sigma * ex[ne:]
        return obs

    def sensor_readings(self) -> dict[str, np.ndarray]:
        """The MJCF sensors `config.sensors` names, as the simulator computes them (the
        truth: a privileged observation)."""
        return {k: self.data.sensordata[a].copy() for k, a in self._sensor_adr.items()}

    def imu_site_gravity(self) -> np.ndarray:
        """The unit gravity direction in the IMU site's frame from its true orientation (privileged)."""
        R = self.data.site_xmat[self.scene.imu_site].reshape(3, 3)
        return R.T @ np.array([0.0, 0.0, -1.0])

    # ------------------------------------------------------------ ground truth
    def foot_loads(self) -> np.ndarray:
        """Vertical contact force on each foot (N): left, right."""
        m, d = self.model, self.data
        loads = np.zeros(2)
        n = d.ncon
        if not n:
            return loads
        con, (left, right) = d.contact, self._foot_geom_lists
        g1, g2, nz = con.geom1.tolist(), con.geom2.tolist(), con.frame[:, 2]
        f6 = np.zeros(6)
        for i in range(n):
            a, b = g1[i], g2[i]
            on = (left[a] or left[b], right[a] or right[b])
            if on[0] or on[1]:
                mujoco.mj_contactForce(m, d, i, f6)
                f = abs(f6[0] * nz[i])  # normal force times the normal's z
                for k in (0, 1):
                    if on[k]:
                        loads[k] += f
        return loads

    def _events(self) -> None:
        self.loads = self.foot_loads()
        loads = (self.loads / self.weight).tolist()
        d, sc = self.data, self.scene
        for k, s in enumerate(SIDES):
            if loads[k] < LIFTOFF_FRACTION:
                self._airborne[s] = True
            elif self._airborne[s] and loads[k] > TOUCHDOWN_FRACTION:
                self._airborne[s] = False
                self.strikes.time[s].append(self.time)
                self.strikes.position[s].append(d.site_xpos[sc.sole_site[s]].tolist())
        if self.fallen_at is None and self.fallen():
            self.fallen_at = self.time

    def pelvis_pose(self) -> np.ndarray:
        """[x y z qw qx qy qz] of the pelvis (world)."""
        f = self.scene.free_qpos_adr
        return self.data.qpos[f:f + 7].copy()

    def base_lin_vel(self) -> np.ndarray:
        """Pelvis linear velocity in its own frame (m/s; the free joint's is in the world)."""
        f, v = self.scene.free_qpos_adr, self.data.qvel[self._free_dof:self._free_dof + 3]
        R = np.empty(9)
        mujoco.mju_quat2Mat(R, self.data.qpos[f + 3:f + 7])
        return R.reshape(3, 3).T @ v

    def fallen(self) -> bool:
        f = self.scene.free_qpos_adr
        z, w, x, y, _ = self.data.qpos[f + 2:f + 7].tolist()
        cos_tilt = 1 - 2 * (x * x + y * y)  # z axis of the pelvis against vertical
        return z < FALL_HEIGHT_FRACTION * self.start_height or cos_tilt < _COS_FALL_TILT

    def torques(self) -> np.ndarray:
        """The leg joints' actuator torques (N m)."""
        act = self.scene.servo[0] if self.body_act is None else self.body_act[:len(self.offsets)]
        return self.data.actuator_force[act].copy()

    def power(self, torques: np.ndarray | None = None) -> float:
        """Mechanical power of the leg servos (W): sum |tau * qdot| (`servo_power`)."""
        tau = self.torques() if torques is None else torques
        return float(servo_power(tau, self.data.qvel[self.scene.dof_adr]))

    def truth(self) -> dict:
        tau = self.torques()
        return {"time": self.time, "pelvis_pose": self.pelvis_pose(), "q_true": self.data.qpos[self.scene.qpos_adr],
                "torque": tau, "power": self.power(tau), "fallen": self.fallen_at is not None,
                "fallen_at": self.fallen_at, "offsets": self.offsets.copy(), "correction": self.correction.copy()}


def servo_power(tau: np.ndarray, qvel: np.ndarray) -> np.ndarray:
    """Mechanical power of the leg servos (W), sum |tau * qdot| over the last axis: one
    step's (n_joints,) or many steps' (n, n_joints) at once."""
    return np.abs(tau * qvel).sum(axis=-1)
