"""Every joint of the model that the leg map does not list: held, at what angle, how.

A static calibration posture is the legs'; every other joint of the robot (a waist, the
arms, a head, the fingers of a vendor's URDF) is held still while the legs move, as a
robot team holds them on the real robot. For each hinge or slide joint of the model
that is not a leg joint (the pelvis's free joint aside) this module says

  at what  the leg map's `held_joints_rad` angle, else the model's first keyframe's
           (`<keyframe><key qpos=...>`: a vendor's standing pose), else the model's
           reference angle (`qpos0`: 0 unless the joint gives `ref`);
  how      `rigid`: a stiff joint equality (the simulator's hold for such joints since
           the first release; its own actuators switched off, or they would pull it
           elsewhere), or `servo`: a PD servo toward the angle with the leg map's
           `servo_gains` for that joint (a name, or a pattern such as `"*_wrist_*"`),
           under which the joint sags by what gravity asks of those gains (measured
           per segment and reported by the collector).

Joints named `legcal_...` are legcal-bench's own (a reality effect's series spring,
`legcal_bench.sim.effects`): they belong to the effect and are not held. Ball joints cannot be held by a joint equality; they are listed as `free`. The table
comes from MuJoCo's own reading of the robot file (`mujoco.MjSpec`, includes and frames
resolved; meshes left out, so that it compiles in milliseconds), kept per file.
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from legcal_bench.errors import LegMapError
from legcal_bench.robots.legmap import LegMap

OWN_PREFIX = "legcal_"  # joints legcal-bench adds to a model (a series spring): the effect's, not held
PATTERN_CHARS = "*?["
RANGE_SLACK_RAD = 1e-9  # a hold at a limit is inside it


@dataclass(frozen=True)
class JointHold:
    """One non-leg joint's hold."""

    joint: str
    angle_rad: float
    source: str  # "leg map", "keyframe '<name>'", "model's reference (qpos0)"
    how: str  # "rigid", "servo" or "free" (not held: a ball joint, or one without a name)
    kp: float | None = None  # servo holds: N m/rad (or N/m for a slide joint)
    kd: float | None = None
    ref: float = 0.0  # the joint's reference (qpos0): MuJoCo's joint equality holds angle - ref

    def to_dict(self) -> dict:
        d = {"joint": self.joint, "angle_deg": float(np.rad2deg(self.angle_rad)), "from": self.source,
             "how": self.how}
        if self.how == "servo":
            d.update(kp=self.kp, kd=self.kd)
        return d


@dataclass(frozen=True)
class ModelJoint:
    name: str
    kind: str  # "hinge", "slide", "ball", "free"
    qpos0: float  # hinge and slide joints: the reference; others 0
    keyframe: float | None  # the first keyframe's value, None without keyframes
    range: tuple[float, float] | None = None  # the joint's limits, None for an unlimited joint


@dataclass(frozen=True)
class Coupling:
    """A joint equality of the model between two joints: joint = c0 + c1 drive (+ ...)."""

    joint: str
    drive: str
    polycoef: tuple[float, ...]  # MuJoCo's five coefficients, of the angles from each joint's reference:
    refs: tuple[float, float] = (0.0, 0.0)  # joint - ref_joint = poly(drive - ref_drive) (the joints' qpos0)

    @property
    def linear(self) -> tuple[float, float] | None:
        """(c0, c1) of joint = c0 + c1 drive, or None for a coupling of higher degree."""
        a = self.polycoef
        if any(a[2:]) or a[1] == 0.0:
            return None
        return self.refs[0] + a[0] - a[1] * self.refs[1], a[1]


def is_pattern(key: str) -> bool:
    return any(c in key for c in PATTERN_CHARS)


@lru_cache(maxsize=32)
def _model_joints(path: str, _stamp: tuple[int, int]) -> tuple[tuple[ModelJoint, ...], str | None,
                                                                 tuple[Coupling, ...]]:
    import mujoco

    try:
        spec = mujoco.MjSpec.from_file(path)
        for geom in spec.geoms:  # the table needs no meshes: the compile takes ms, not seconds
            if geom.type == mujoco.mjtGeom.mjGEOM_MESH:
                geom.type, geom.meshname = mujoco.mjtGeom.mjGEOM_SPHERE, ""
                geom.size = [0.01, 0.0, 0.0]
        for mesh in list(spec.meshes):
            spec.delete(mesh)
        model = spec.compile()
    except Exception as e:  # MuJoCo's own words; the scene's compile says the same with the fix
        raise LegMapError(f"{path}: MuJoCo could not read the robot's joints: {e}") from e
    kinds = {0: "free", 1: "ball", 2: "slide", 3: "hinge"}
    key_name = (mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_KEY, 0) or "0") if model.nkey else None
    out = []
    for j in range(model.njnt):
        adr, kind = int(model.jnt_qposadr[j]), kinds[int(model.jnt_type[j])]
        scalar = kind in ("hinge", "slide")
        out.append(ModelJoint(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or "", kind,
                              float(model.qpos0[adr]) if scalar else 0.0,
                              float(model.key_qpos[0, adr]) if scalar and model.nkey else None,
                              tuple(float(x) for x in model.jnt_range[j]) if model.jnt_limited[j] else None))
    couplings = tuple(
        Coupling(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, int(model.eq_obj1id[e])),
                 mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, int(model.eq_obj2id[e])),
                 tuple(float(c) for c in model.eq_data[e, :5]),
                 (float(model.qpos0[model.jnt_qposadr[model.eq_obj1id[e]]]),
                  float(model.qpos0[model.jnt_qposadr[model.eq_obj2id[e]]])))
        for e in range(model.neq)
        if model.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT and model.eq_obj2id[e] >= 0 and model.eq_active0[e])
    return tuple(out), key_name, couplings


def model_joints(mjcf: Path) -> tuple[tuple[ModelJoint, ...], str | None]:
    """(every joint of the robot file, in MuJoCo's order; the first keyframe's name or None)."""
    return _model_table(mjcf)[:2]


def joint_couplings(mjcf: Path) -> tuple[Coupling, ...]:
    """The model's active joint equalities between two joints (an MJCF `<equality><joint
    joint1= joint2=>`, a URDF `<mimic>` as MuJoCo compiles it): a joint driven through
    another (a gear or a drive joint) is one of them."""
    return _model_table(mjcf)[2]


def _model_table(mjcf: Path):
    p = Path(mjcf).resolve()
    st = p.stat()
    return _model_joints(str(p), (st.st_mtime_ns, st.st_size))


def joint_holds(legmap: LegMap) -> tuple[JointHold, ...]:
    """The hold of every non-leg joint of `legmap`'s robot, in the model's order.
    Raises LegMapError for a `held_joints_rad` or `servo_gains` entry that names no
    joint of the model, or a pattern that matches none."""
    joints, key_name = model_joints(legmap.mjcf)
    where = str(legmap.source or legmap.name)
    names = {j.name for j in joints}
    legs = set(legmap.joint_names)
    for name in legmap.held_joints_rad:
        if name not in names:
            raise LegMapError(f"{where}: held_joints_rad.{name}: no joint of that name in {legmap.model_file}; "
                              f"its non-leg joints are {_listing(joints, legs)}")
    couplings = joint_couplings(legmap.mjcf)
    # A leg joint's drive moves with the leg (holding it would lock the leg), and a joint
    # the model couples to another (`joint1` of an equality: a follower, a mimic) moves
    # with that one: neither is held.
    moving = {c.drive for c in couplings if c.joint in legs} | {c.joint for c in couplings}
    held = [j for j in joints if j.kind != "free" and j.name not in legs and not j.name.startswith(OWN_PREFIX)
            and j.name not in moving]
    for key in legmap.servo_gains:
        if key in legs:
            continue
        if is_pattern(key):
            if not any(fnmatch.fnmatchcase(j.name, key) for j in held):
                raise LegMapError(f"{where}: servo_gains.{key!r} matches no non-leg joint of {legmap.model_file} "
                                  f"(they are {_listing(joints, legs)}); fix the pattern or remove it")
        elif key not in names:
            raise LegMapError(f"{where}: servo_gains.{key}: no joint of that name in {legmap.model_file}; give a "
                              f"leg joint or one of its non-leg joints ({_listing(joints, legs)}), or a pattern")
    out = []
    for j in held:
        if j.name in legmap.held_joints_rad:
            angle, source = legmap.held_joints_rad[j.name], "leg map"
        elif j.keyframe is not None:
            angle, source = j.keyframe, f"keyframe '{key_name}'"
        else:
            angle, source = j.qpos0, "model's reference (qpos0)"
        if j.kind == "ball" or not j.name:  # a ball joint, or one without a name: nothing can hold it
            out.append(JointHold(j.name or "(unnamed)", 0.0, "model", "free"))
            continue
        if j.range is not None and not j.range[0] - RANGE_SLACK_RAD <= angle <= j.range[1] + RANGE_SLACK_RAD:
            field = f"held_joints_rad.{j.name}" if source == "leg map" else f"{j.name}'s hold ({source})"
            raise LegMapError(f"{where}: {field} = {angle:+.4f} is outside the joint's range [{j.range[0]:+.4f}, "
                              f"{j.range[1]:+.4f}]: its limit would fight the hold; give held_joints_rad.{j.name} "
                              "an angle inside it")
        gains = servo_gains_of(legmap, j.name)
        out.append(JointHold(j.name, float(angle), source, "servo", *gains, ref=j.qpos0) if gains is not None
                   else JointHold(j.name, float(angle), source, "rigid", ref=j.qpos0))
    return tuple(out)


def servo_gains_of(legmap: LegMap, joint: str) -> tuple[float, float] | None:
    """The leg map's servo gains for a non-leg joint: by its name, else by the first
    pattern (in the leg map's order) that matches it; None for a rigid hold."""
    if joint in legmap.servo_gains:
        return legmap.servo_gains[joint]
    for key, gains in legmap.servo_gains.items():
        if is_pattern(key) and fnmatch.fnmatchcase(joint, key):
            return gains
    return None


def hold_angles(legmap: LegMap) -> dict[str, float]:
    """Joint name -> the angle it is held at (rigid and servo holds)."""
    return {h.joint: h.angle_rad for h in joint_holds(legmap) if h.how != "free"}


def _listing(joints, legs) -> str:
    names = [j.name for j in joints if j.kind != "free" and j.name not in legs]
    return ", ".join(names[:12]) + (f" and {len(names) - 12} more" if len(names) > 12 else "") if names else "none"
