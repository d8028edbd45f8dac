"""Compose a MuJoCo scene around any robot MJCF (dm_control's mjcf), per floor mode.

The robot file is loaded as it is; the scene only adds: the arena's floor, the leg map's frames
as sites (sole, corners, IMU, F/T) where the MJCF does not have them, our own IMU and
F/T sensors on those sites, joint equalities that hold non-leg joints, and in weld
mode a mocap anchor per foot with a stiff weld to the sole site. Kinematics are
untouched, so Pinocchio (which loads the plain robot file) sees the same robot.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco
import numpy as np
from dm_control import mjcf
from scipy.spatial.transform import Rotation

from legcal_bench.errors import ConfigError, LegMapError
from legcal_bench.geometry.poses import from_wxyz, wxyz
from legcal_bench.robots.frames import mjcf_element
from legcal_bench.robots.holds import JointHold, joint_holds
from legcal_bench.robots.transmission import EncoderMap, to_encoder_space, transmissions
from legcal_bench.robots.legmap import CORNER_NAMES, SIDES, FrameSpec, LegMap
from legcal_bench.sim.arena import FLOOR_SOLIMP, FLOOR_SOLREF, add_floor

MODES = ("kinematic", "weld", "contact")  # the static floors; "walking" is `legcal_bench.sim.walking`'s
# Servo-held feet: MuJoCo's default weld lets them drift by centimetres.
WELD_SOLREF = (0.004, 1.0)
WELD_SOLIMP = (0.99, 0.999, 0.001, 0.5, 2.0)
# Weight of the weld's angular residual (a length): at 1 the soles still tilt by
# hundredths of a degree under the closed-chain strain; servo-held feet do not.
WELD_TORQUESCALE = 10.0


@dataclass(frozen=True)
class ServoGains:
    """Servo gains for the leg joints (leg-map order) and where each came from."""

    kp: tuple[float, ...]  # N m/rad
    kd: tuple[float, ...]  # N m s/rad
    source: tuple[str, ...]  # "MJCF", "leg map", "default"
    note: str = ""  # why these (e.g. why the default replaced the MJCF's gains)

    def to_dict(self) -> dict:
        return {"kp": list(self.kp), "kd": list(self.kd), "source": list(self.source), "note": self.note}


@dataclass
class Scene:
    model: mujoco.MjModel
    legmap: LegMap
    mode: str
    qpos_adr: np.ndarray  # (n,) leg joints (`legmap.n_joints`)
    dof_adr: np.ndarray  # (n,)
    free_qpos_adr: int  # pelvis free joint (position 3 + quaternion wxyz 4)
    pelvis_body: int
    sole_site: dict[str, int]
    corner_sites: dict[str, list[int]]
    imu_site: int
    mocap: dict[str, int]  # mocap index per side (weld mode)
    sensor_adr: dict[str, int]  # name -> address in sensordata
    has_ft: bool
    # Per leg joint: position-actuator id (or -1), motor actuator id (or -1), gear.
    position_act: np.ndarray
    motor_act: np.ndarray
    motor_gear: np.ndarray
    servo_kp: np.ndarray
    servo_kd: np.ndarray
    servo_source: tuple[str, ...] = ()  # per leg joint: "MJCF", "leg map", "default" or "none"
    servo: tuple = ()  # (position ctrl index, target columns or None, motor PD arrays or None)
    holds: tuple = ()  # the held non-leg joints (`legcal_bench.robots.holds.JointHold`), as simulated
    hold_qpos_adr: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))  # (h,) their qpos addresses
    hold_angle: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (h,) what each is held at
    # Per leg joint, the joint its actuator turns (the leg joint, or its drive joint:
    # `legcal_bench.robots.transmission`; default the leg joints), and the drives' map
    # q_leg = c0 + c1 q_drive (None without drive joints).
    act_qpos_adr: np.ndarray | None = None
    act_dof_adr: np.ndarray | None = None
    drive: EncoderMap | None = None

    def __post_init__(self):
        self.act_qpos_adr = self.qpos_adr if self.act_qpos_adr is None else self.act_qpos_adr
        self.act_dof_adr = self.dof_adr if self.act_dof_adr is None else self.act_dof_adr
        self._layout()

    @property
    def drive_gain(self) -> np.ndarray | float:
        """A leg joint's gains in its actuated joint's space: kp_drive = kp c1^2 (power is conserved)."""
        return 1.0 if self.drive is None else self.drive.c1 ** 2

    def _layout(self) -> None:
        pa, ma = self.position_act >= 0, self.motor_act >= 0
        act, cols = self.position_act[pa], np.flatnonzero(pa)
        # Every leg joint on a position actuator, in order (the common case): ctrl[a:a + n] = target.
        n = len(self.position_act)
        contiguous = self.drive is None and pa.all() and np.array_equal(act, np.arange(act[0], act[0] + n))
        c2 = self.drive_gain
        self.servo = (
            slice(int(act[0]), int(act[0]) + n) if contiguous else act, None if contiguous else cols,
            (self.motor_act[ma], np.flatnonzero(ma), self.act_qpos_adr[ma], self.act_dof_adr[ma],
             (self.servo_kp * c2)[ma], (self.servo_kd * c2)[ma], self.motor_gear[ma]) if ma.any() else None,
            self.drive)


def _find(model: mjcf.RootElement, kind: str, name: str, where: str):
    el = model.find(kind, name)
    if el is None:
        raise LegMapError(f"{where}: no {kind} named '{name}' in the MJCF")
    return el


def _add_site(model: mjcf.RootElement, name: str, spec: FrameSpec, where: str, extra=None):
    """Site for a leg-map frame (optionally at `extra` = (pos) in that frame)."""
    if spec.site is not None:
        site = _find(model, "site", spec.site, where)
        body, pos, rot = site.parent, np.asarray(site.pos if site.pos is not None else np.zeros(3), float), (
            from_wxyz(site.quat) if site.quat is not None else Rotation.identity())
        if extra is None:
            return site.name
    else:
        body = _find(model, "body", spec.body, where)
        pos, rot = np.asarray(spec.pos, float), Rotation.from_euler("xyz", spec.rpy)
    if extra is not None:
        pos = pos + rot.apply(extra)
    body.add("site", name=name, pos=pos.tolist(), quat=wxyz(rot).tolist(), size=[0.006],
             rgba=[0.9, 0.3, 0.2, 1], group=3)
    return name


def build_scene(legmap: LegMap, mode: str, physics_dt: float = 0.001, floor: dict | None = None) -> Scene:
    """`floor`: the contact floor's parameters (`arena.floor_parameters`; default the table's)."""
    if mode not in MODES:
        raise ConfigError(f"mode {mode!r}: use one of {MODES}")
    m = mjcf_element(legmap.mjcf)
    m.option.timestep = physics_dt
    m.option.integrator = "implicitfast"
    return compose_robot(m, legmap, mode, floor, holds=joint_holds(legmap))


def compose_robot(m: mjcf.RootElement, legmap: LegMap, mode: str, floor: dict | None = None,
                  release: set | frozenset = frozenset(), holds: tuple[JointHold, ...] | None = None) -> Scene:
    """The scene around robot model `m` (its options already set): the arena's floor
    (`mode` "walking": colliding, with `floor`'s contact parameters), the leg map's
    frames and sensors, held joints (`holds`, default the leg map's `held_joints_rad`;
    except those in `release`: a whole-body policy drives them), weld anchors; compiled
    and indexed. In the static modes a held joint's own actuators are switched off (the
    hold replaces them); walking keeps them."""
    where = str(legmap.source or legmap.name)
    m.option.gravity = (0, 0, -9.81)
    vis_global = getattr(m.visual, "global")
    vis_global.offwidth, vis_global.offheight = 1280, 960
    pelvis = _find(m, "body", legmap.pelvis, f"{where}: pelvis")
    if pelvis.parent is not m.worldbody:
        raise LegMapError(f"{where}: pelvis body '{legmap.pelvis}' must be a child of <worldbody>")
    free = pelvis.freejoint or next((j for j in pelvis.joint if j.type == "free"), None)
    if free is None:
        free = pelvis.add("freejoint", name="legcal_root")
    # Only the floor's contacts matter here: in kinematic and weld modes, none at all.
    if mode == "walking":
        add_floor(m, contact=True, static_friction=False, **(floor or {}))
    else:
        add_floor(m, contact=mode == "contact", **(floor or {}))

    sole_site, corner_sites = {}, {}
    for side in SIDES:
        leg = legmap.legs[side]
        sole_site[side] = _add_site(m, f"legcal_{side}_sole", leg.sole, f"{where}: legs.{side}.sole")
        corner_sites[side] = [
            _add_site(m, f"legcal_{side}_corner_{c}", leg.sole, f"{where}: legs.{side}.sole", leg.corners[c])
            for c in CORNER_NAMES
        ]
    # Walking simulates the IMU its policy reads (`policy_imu`, else the leg map's), static modes the calibration's.
    walking_imu = mode == "walking" and legmap.policy_imu is not None
    imu_site = _add_site(m, "legcal_imu", legmap.policy_imu if walking_imu else legmap.imu,
                         f"{where}: {'policy_imu' if walking_imu else 'imu'}")
    m.sensor.add("accelerometer", name="legcal_imu_acc", site=imu_site)
    m.sensor.add("gyro", name="legcal_imu_gyro", site=imu_site)
    has_ft = all(legmap.legs[s].ft is not None for s in SIDES)
    if has_ft:
        for side in SIDES:
            ft = _add_site(m, f"legcal_{side}_ft", legmap.legs[side].ft, f"{where}: legs.{side}.ft")
            m.sensor.add("force", name=f"legcal_{side}_force", site=ft)
            m.sensor.add("torque", name=f"legcal_{side}_torque", site=ft)
    if holds is None:  # walking: the leg map's held joints, rigidly (a policy's spec drives or holds the rest)
        holds = tuple(JointHold(n, a, "leg map", "rigid") for n, a in legmap.held_joints_rad.items())
    holds = tuple(h for h in holds if h.joint not in release and h.how != "free")
    for h in holds:
        _find(m, "joint", h.joint, f"{where}: held joint")
        if h.how == "rigid":
            # MuJoCo's joint equality holds the angle from the joint's reference: angle - ref
            m.equality.add("joint", name=f"legcal_hold_{h.joint}", joint1=h.joint,
                           polycoef=[h.angle_rad - h.ref, 0, 0, 0, 0],
                           solref=list(FLOOR_SOLREF), solimp=list(FLOOR_SOLIMP))
        else:  # a PD servo toward the angle, no ctrl: force = kp (angle - q) - kd qdot
            m.actuator.add("general", name=f"legcal_servo_{h.joint}", joint=h.joint, gainprm=[0.0],
                           biastype="affine", biasprm=[h.kp * h.angle_rad, -h.kp, -h.kd], ctrllimited=False)
    if mode == "weld":
        for side in SIDES:
            anchor = m.worldbody.add("body", name=f"legcal_{side}_anchor", mocap=True)
            anchor.add("site", name=f"legcal_{side}_anchor_site", size=[0.004], group=3)
            m.equality.add("weld", name=f"legcal_{side}_weld", site1=sole_site[side], torquescale=WELD_TORQUESCALE,
                           site2=f"legcal_{side}_anchor_site", solref=list(WELD_SOLREF), solimp=list(WELD_SOLIMP))

    model = mujoco.MjModel.from_xml_string(m.to_xml_string(), m.get_assets())
    scene = _index(model, legmap, mode, free.full_identifier, sole_site, corner_sites, imu_site, has_ft, where)
    _index_holds(scene, holds, mute=mode != "walking")
    if mode != "walking":  # the leg map's (static) gains into the model; walking servos keep theirs
        set_servo_gains(scene, scene.servo_kp, scene.servo_kd, scene.servo_source)
    return scene


def _index(model, legmap, mode, free_name, sole_site, corner_sites, imu_site, has_ft, where) -> Scene:
    def jid(name):
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if i < 0:
            raise LegMapError(f"{where}: joint '{name}' is not in the MJCF")
        return i

    def sid(name):
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)

    joints = [jid(n) for n in legmap.joint_names]
    free = jid(free_name)
    sensor_adr = {}
    for i in range(model.nsensor):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_SENSOR, i)
        if name and name.startswith("legcal_"):
            sensor_adr[name[len("legcal_"):]] = int(model.sensor_adr[i])
    nj = legmap.n_joints
    # A leg joint turned by a drive joint (`legcal_bench.robots.transmission`): its actuator is the drive's.
    drive = {n: t for n, t in transmissions(legmap).items() if t.drive is not None}
    actuated = [jid(drive[n].drive) if n in drive else j for n, j in zip(legmap.joint_names, joints)]
    c0 = np.array([drive[n].c0 if n in drive else 0.0 for n in legmap.joint_names])
    c1 = np.array([drive[n].c1 if n in drive else 1.0 for n in legmap.joint_names])
    position_act = -np.ones(nj, dtype=int)
    motor_act = -np.ones(nj, dtype=int)
    gear = np.ones(nj)
    for a in range(model.nu):
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT or model.actuator_trnid[a, 0] not in actuated:
            continue
        k = actuated.index(int(model.actuator_trnid[a, 0]))
        g, b = model.actuator_gainprm[a], model.actuator_biasprm[a]
        is_position = g[0] > 0 and np.isclose(b[1], -g[0]) and model.actuator_gaintype[a] == 0
        is_motor = np.isclose(g[0], 1.0) and not np.any(b[:3]) and model.actuator_biastype[a] == 0
        if is_position:
            position_act[k] = a
        elif is_motor:
            motor_act[k], gear[k] = a, float(model.actuator_gear[a, 0])
    # Servo gains per leg joint: the leg map's servo_gains override the MJCF's position
    # actuators; a torque motor without leg-map gains has none yet (NaN, source "none":
    # `legcal_bench.protocol.servos` gives it the default).
    kp, kd = np.full(nj, np.nan), np.full(nj, np.nan)
    source = []
    for k, name in enumerate(legmap.joint_names):
        a = position_act[k]
        if a < 0 and motor_act[k] < 0:
            raise LegMapError(f"{where}: leg joint '{name}' has neither a position actuator nor a motor in the MJCF" + (
                f"; it is turned by its drive joint '{drive[name].drive}' (a joint equality in the model), which has "
                "no actuator either: give the drive a <position> actuator or a <motor>" if name in drive else
                ": give it a <position> actuator or a <motor> (with servo_gains in the leg map)"))
        if name in legmap.servo_gains and mode != "walking":
            kp[k], kd[k] = legmap.servo_gains[name]
            source.append("leg map")
        elif a >= 0:  # in the leg joint's angle: a drive's gains over c1^2
            kp[k], kd[k] = (model.actuator_gainprm[a, 0] / c1[k] ** 2,
                            (0.0 - model.actuator_biasprm[a, 2]) / c1[k] ** 2)  # no -0.0
            source.append("MJCF")
        else:
            source.append("none")
    mocap = {}
    if mode == "weld":
        for side in SIDES:
            b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"legcal_{side}_anchor")
            mocap[side] = int(model.body_mocapid[b])
    return Scene(
        model=model, legmap=legmap, mode=mode,
        qpos_adr=np.array([model.jnt_qposadr[j] for j in joints]),
        dof_adr=np.array([model.jnt_dofadr[j] for j in joints]),
        free_qpos_adr=int(model.jnt_qposadr[free]),
        pelvis_body=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, legmap.pelvis),
        sole_site={s: sid(n) for s, n in sole_site.items()},
        corner_sites={s: [sid(n) for n in names] for s, names in corner_sites.items()},
        imu_site=sid(imu_site), mocap=mocap, sensor_adr=sensor_adr, has_ft=has_ft,
        position_act=position_act, motor_act=motor_act, motor_gear=gear, servo_kp=kp, servo_kd=kd,
        servo_source=tuple(source),
        act_qpos_adr=np.array([model.jnt_qposadr[j] for j in actuated]),
        act_dof_adr=np.array([model.jnt_dofadr[j] for j in actuated]),
        drive=EncoderMap(c0, c1) if drive else None,
    )


def _index_holds(scene: Scene, holds: tuple[JointHold, ...], mute: bool) -> None:
    """Record the holds and their joints' addresses; with `mute`, switch off the model's
    own actuators on held joints (gain and bias 0: they would pull the joint elsewhere)."""
    m = scene.model
    ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, h.joint) for h in holds]
    scene.holds, scene.hold_qpos_adr = holds, np.array([m.jnt_qposadr[j] for j in ids], dtype=int)
    scene.hold_angle = np.array([h.angle_rad for h in holds], dtype=float)
    if not mute or not ids:
        return
    for a in range(m.nu):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) or ""
        if (m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and int(m.actuator_trnid[a, 0]) in ids
                and not name.startswith("legcal_servo_")):
            m.actuator_gainprm[a, :], m.actuator_biasprm[a, :] = 0.0, 0.0


def set_servo_gains(scene: Scene, kp: np.ndarray, kd: np.ndarray, source: tuple[str, ...]) -> None:
    """Use gains `kp`, `kd` (n,) on the n leg joints: written into the model's position
    actuators (gain kp, bias -kp q - kd qdot), kept for the torque motors' PD law. Joints
    with NaN gains keep none (a motor without gains cannot be driven: `apply_servos`
    refuses it)."""
    kp, kd = np.asarray(kp, dtype=float), np.asarray(kd, dtype=float)
    m = scene.model
    kpa, kda = kp * scene.drive_gain, kd * scene.drive_gain  # in the actuated joints' space
    for k, a in enumerate(scene.position_act):
        if a >= 0 and np.isfinite(kp[k]):
            m.actuator_gainprm[a, 0], m.actuator_biasprm[a, 1], m.actuator_biasprm[a, 2] = kpa[k], -kpa[k], -kda[k]
    scene.servo_kp, scene.servo_kd, scene.servo_source = kp.copy(), kd.copy(), tuple(source)
    scene._layout()


def apply_servos(scene: Scene, data: mujoco.MjData, target: np.ndarray) -> None:
    """Drive the leg joints toward `target` (joint space): position actuators take the
    target as ctrl; torque motors get the leg map's PD law. It runs before every physics
    step, with the index layout worked out once (`Scene.servo`)."""
    pos_act, pos_cols, motors, driven = scene.servo
    if driven is not None:  # targets of drive joints in their own angle: (q - c0) / c1
        target = to_encoder_space(target, driven)
    if pos_cols is None:
        data.ctrl[pos_act] = target
    elif len(pos_cols):
        data.ctrl[pos_act] = target[pos_cols]
    if motors is not None:
        act, cols, qadr, vadr, kp, kd, gear = motors
        tau = kp * (target[cols] - data.qpos[qadr]) - kd * data.qvel[vadr]
        data.ctrl[act] = tau / gear
