"""The leg map: what legcal-bench needs to know about any robot beyond its MJCF or URDF.

A small YAML file names the leg joints (left leg then right, each from pelvis to foot:
six per leg, or five where a leg has no ankle roll and the leg map declares it absent)
with their roles, the sole frames and their four corner points, the pelvis and
the IMU placement, the angles at which any other joint is held, and servo gains when
the MJCF drives torque motors. See docs/leg-map.md for the schema.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from legcal_bench.errors import ConfigError, LegMapError, MissingModelError
from legcal_bench.inputs import known_keys, number, read_text, shown
from legcal_bench.robots.design import HIP_ROLES, LEG_ROLES

SCHEMA = "legcal-legmap/1"
SIDES = ("left", "right")
CORNER_NAMES = ("toe_left", "toe_right", "heel_left", "heel_right")
# Roles a leg map may declare absent (`absent_roles`): a 5-joint leg without ankle roll.
ABSENT_ALLOWED = ("ankle_roll",)
# The leg map's keys (a closed format: a misspelt key is refused, with the closest named).
TOP_FIELDS = ("schema", "name", "mjcf", "urdf", "pelvis", "imu", "legs", "knee_straight_rad", "held_joints_rad",
              "servo_gains", "absent_roles", "packages", "policy_imu")
LEG_FIELDS = ("joints", "sole", "corners", "ft", "linkage")
LINKAGE_MOTOR_FIELDS = ("pivot", "axis", "crank", "rod", "foot")
FRAME_FIELDS = ("site", "body", "pos", "rpy")


@dataclass(frozen=True)
class FrameSpec:
    """A frame on the robot: an MJCF site, or a pose relative to a body.

    `rpy` is roll-pitch-yaw in radians (fixed axes x, then y, then z).
    """

    site: str | None = None
    body: str | None = None
    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def to_dict(self) -> dict:
        if self.site is not None:
            return {"site": self.site}
        d: dict = {"body": self.body, "pos": list(self.pos)}
        if any(self.rpy):
            d["rpy"] = list(self.rpy)
        return d


@dataclass(frozen=True)
class Joint:
    name: str
    role: str
    # Motor turns per joint turn when the encoder sits on the motor behind a fixed gear
    # (`legcal_bench.robots.transmission`); 1: the encoder reads the joint.
    ratio: float = 1.0


@dataclass(frozen=True)
class LinkageMotor:
    """One motor of a parallel-linkage ankle (`legcal_bench.robots.linkage`): a crank on
    the shank turning about `axis` through `pivot`, its arm `crank` (from the pivot, at the
    encoder's zero; its length the crank's), a rod of length `rod` from the crank's tip to
    `foot` in the foot frame. Shank-frame vectors in the shank frame (m)."""

    pivot: tuple[float, float, float]
    axis: tuple[float, float, float]
    crank: tuple[float, float, float]
    rod: float
    foot: tuple[float, float, float]

    def to_dict(self) -> dict:
        return {"pivot": list(self.pivot), "axis": list(self.axis), "crank": list(self.crank), "rod": self.rod,
                "foot": list(self.foot)}


@dataclass(frozen=True)
class Leg:
    joints: tuple[Joint, ...]
    sole: FrameSpec
    corners: dict[str, tuple[float, float, float]]  # in the sole frame
    ft: FrameSpec | None = None
    # A two-motor parallel-linkage ankle: the motors whose encoders stand for the ankle's
    # two joints (the first ankle joint's column holds motor 0, the second's motor 1).
    linkage: tuple[LinkageMotor, LinkageMotor] | None = None

    @property
    def hip_order(self) -> tuple[str, str, str]:
        return tuple(j.role for j in self.joints[:3])  # type: ignore[return-value]


@dataclass(frozen=True)
class LegMap:
    name: str
    mjcf: Path
    pelvis: str
    legs: dict[str, Leg]
    imu: FrameSpec
    knee_straight_rad: float = 0.0
    held_joints_rad: dict[str, float] = field(default_factory=dict)
    # Only for MJCFs whose leg actuators are torque motors: joint -> (kp, kd).
    servo_gains: dict[str, tuple[float, float]] = field(default_factory=dict)
    source: Path | None = None
    # A robot described by a URDF: Pinocchio reads this; `mjcf` is then MuJoCo's
    # compilation of it (`legcal_bench.robots.urdf`).
    urdf: Path | None = None
    # The folders of the ROS packages the URDF's `package://` URIs name (beside the
    # environment's, `legcal_bench.robots.urdf.find_package`).
    packages: dict[str, Path] = field(default_factory=dict)
    # The calibration IMU's frame sits above these non-leg joints (`imu.through`: a torso
    # IMU above the waist), held in static collection; the IMU is carried to the pelvis
    # through them at their held angles (`legcal_bench.robots.kinematics`).
    imu_through: tuple[str, ...] = ()
    # The IMU a walking policy reads, when not the calibration's (`policy_imu`): walking
    # simulates it; static collection and calibration use `imu`.
    policy_imu: FrameSpec | None = None

    @property
    def model_file(self) -> Path:
        """The robot's own description: its URDF, else its MJCF."""
        return self.urdf if self.urdf is not None else self.mjcf

    @property
    def joint_names(self) -> list[str]:
        return [j.name for side in SIDES for j in self.legs[side].joints]

    @property
    def joint_roles(self) -> list[str]:
        return [j.role for side in SIDES for j in self.legs[side].joints]

    @property
    def hip_order(self) -> tuple[str, str, str]:
        return self.legs["left"].hip_order

    @property
    def leg_joints(self) -> int:
        """Joints per leg (both legs have the same roles): 6, or 5 without an ankle roll."""
        return len(self.legs["left"].joints)

    @property
    def n_joints(self) -> int:
        """Leg joints of both legs: the length of every joint vector (q, offsets)."""
        return 2 * self.leg_joints

    def leg_slice(self, side: str | int) -> slice:
        """The columns of one leg in a joint vector (leg-map order: left, then right)."""
        i = SIDES.index(side) if isinstance(side, str) else int(side)
        return slice(i * self.leg_joints, (i + 1) * self.leg_joints)

    def side_of(self, index: int) -> str:
        """The leg ('left'/'right') of joint `index` of a joint vector."""
        return SIDES[index // self.leg_joints]

    @property
    def absent_roles(self) -> tuple[str, ...]:
        """The leg roles this robot lacks (declared in the leg map's `absent_roles`)."""
        present = {j.role for j in self.legs["left"].joints}
        return tuple(r for r in LEG_ROLES if r not in present)

    def to_dict(self, mjcf_relative_to: Path | None = None) -> dict:
        key = "mjcf" if self.urdf is None else "urdf"
        model = self.model_file
        if mjcf_relative_to is not None:
            model = Path(_relpath(model, mjcf_relative_to))
        d: dict = {
            "schema": SCHEMA,
            "name": self.name,
            key: str(model),
            "pelvis": self.pelvis,
            "imu": {**self.imu.to_dict(), **({"through": list(self.imu_through)} if self.imu_through else {})},
            "knee_straight_rad": self.knee_straight_rad,
            "legs": {},
        }
        for side in SIDES:
            leg = self.legs[side]
            ld: dict = {
                "joints": [{"name": j.name, "role": j.role, **({"ratio": j.ratio} if j.ratio != 1.0 else {})}
                           for j in leg.joints],
                "sole": leg.sole.to_dict(),
                "corners": {k: list(v) for k, v in leg.corners.items()},
            }
            if leg.ft is not None:
                ld["ft"] = leg.ft.to_dict()
            if leg.linkage is not None:
                ld["linkage"] = {"motors": [mo.to_dict() for mo in leg.linkage]}
            d["legs"][side] = ld
        if self.absent_roles:
            d["absent_roles"] = list(self.absent_roles)
        if self.held_joints_rad:
            d["held_joints_rad"] = dict(self.held_joints_rad)
        if self.servo_gains:
            d["servo_gains"] = {k: list(v) for k, v in self.servo_gains.items()}
        if self.policy_imu is not None:
            d["policy_imu"] = self.policy_imu.to_dict()
        if self.packages:
            d["packages"] = {k: (_relpath(v, mjcf_relative_to) if mjcf_relative_to is not None else str(v))
                             for k, v in self.packages.items()}
        return d


def _relpath(target: Path, start: Path) -> str:
    import os

    return os.path.relpath(Path(target).resolve(), Path(start).resolve())


def _known(where: str, d: dict, allowed) -> None:
    """`inputs.known_keys` as a LegMapError: a misspelt key is named with the closest one."""
    try:
        known_keys(where, d, allowed, fix="see docs/leg-map.md")
    except ConfigError as e:
        raise LegMapError(str(e)) from None


def _name(value, where: str, what: str) -> str:
    """The name of an element of the model (a non-empty string)."""
    if not isinstance(value, str) or not value.strip():
        raise LegMapError(f"{where} is {shown(value)}: give {what} as a non-empty string")
    return value


def _number(value, where: str, fix: str, **limits) -> float:
    """One finite number (in `limits`, as `inputs.number` takes them); a string is refused
    (a quoted number in the file is a typo to fix, not a number)."""
    if isinstance(value, str):
        raise LegMapError(f"{where} = {shown(value)}: expected a number, not a string ({fix})")
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 1e308:
        raise LegMapError(f"{where} = {shown(value)}: expected a finite number ({fix})")
    try:
        return float(number(where, value, fix=fix, **limits))
    except ConfigError as e:
        raise LegMapError(str(e)) from None


def _vec(value, where: str, n: int = 3) -> tuple[float, ...]:
    """A list of `n` finite numbers."""
    out = None
    if isinstance(value, (list, tuple)) and len(value) == n and all(
            isinstance(x, numbers.Real) and not isinstance(x, bool) for x in value):
        try:
            out = tuple(float(x) for x in value)
        except OverflowError:
            out = None
    if out is None or not all(math.isfinite(x) for x in out):
        raise LegMapError(f"{where}: expected {n} finite numbers{' [x, y, z]' if n == 3 else ''}, got {shown(value)}")
    return out


def _frame(d, where: str) -> FrameSpec:
    if not isinstance(d, dict):
        raise LegMapError(f"{where} is {shown(d)}: expected a mapping {{site: NAME}} or {{body: NAME, pos: [x, y, z], "
                          "rpy: [r, p, y]}")
    _known(where, d, FRAME_FIELDS)
    if ("site" in d) == ("body" in d):
        raise LegMapError(f"{where}: give exactly one of 'site: NAME' or 'body: NAME' (with optional pos/rpy)")
    if "site" in d:
        if "pos" in d or "rpy" in d:
            raise LegMapError(f"{where}: 'pos'/'rpy' go with 'body', not with 'site'")
        return FrameSpec(site=_name(d["site"], f"{where}.site", "the name of a site in the MJCF"))
    return FrameSpec(
        body=_name(d["body"], f"{where}.body", "the name of a body (a link of a URDF)"),
        pos=_vec(d.get("pos", (0, 0, 0)), f"{where}.pos (metres)"),
        rpy=_vec(d.get("rpy", (0, 0, 0)), f"{where}.rpy (radians)"),
    )


def _model_path(data: dict, kind: str, base_dir: Path, where: str) -> Path:
    """The `mjcf` or `urdf` file, resolved against the leg map's folder; refused if it is
    not a path, is a folder or does not exist."""
    what = "MJCF" if kind == "mjcf" else "URDF"
    value = data[kind]
    if not isinstance(value, str) or not value.strip() or "\0" in value:
        raise LegMapError(f"{where}: field '{kind}' is {shown(value)}: give the path of the robot's {what} file, "
                          "relative to the leg map or absolute")
    model = Path(value).expanduser()
    if not model.is_absolute():
        model = (base_dir / model).resolve()
    if model.is_dir():
        raise LegMapError(f"{where}: field '{kind}' points to {model}, which is a folder; give the {what} file itself")
    if not model.is_file():
        from legcal_bench.files.packaged import EXTERNAL_HINT, from_examples

        raise MissingModelError(f"{where}: field '{kind}' points to {model}, which does not exist; "
                                + (EXTERNAL_HINT if from_examples(base_dir / "x") else
                                   "give a path relative to the leg map or an absolute path"))
    return model


def _leg(ld, side: str, where: str, expected_roles: tuple[str, ...]) -> Leg:
    lw = f"{where}: legs.{side}"
    if not isinstance(ld, dict):
        raise LegMapError(f"{lw} is {shown(ld)}: give the {side} leg as a mapping of joints (its joints from pelvis "
                          "to foot, each {name: ..., role: ...}), sole and corners (see docs/leg-map.md)")
    _known(lw, ld, LEG_FIELDS)
    for key in ("joints", "sole", "corners"):
        if key not in ld:
            raise LegMapError(f"{lw}: missing field '{key}'")
    joints_d = ld["joints"]
    if not isinstance(joints_d, list):
        raise LegMapError(f"{lw}.joints is {shown(joints_d)}: list the leg's joints from pelvis to foot, "
                          f"each as {{name: ..., role: ...}}")
    if len(joints_d) != len(expected_roles):
        raise LegMapError(
            f"{lw}.joints: {len(joints_d)} joints listed; this leg map describes legs of {len(expected_roles)} "
            f"joints ({', '.join(expected_roles)} from pelvis to foot, the three hip joints in any order)" + (
                "; a leg without one of these joints (e.g. no ankle roll) declares it with "
                "absent_roles: [ankle_roll]" if len(joints_d) < len(expected_roles)
                else "; list only the leg's own joints (hold the others with held_joints_rad)"))
    joints = []
    for i, jd in enumerate(joints_d):
        jw = f"{lw}.joints[{i}]"
        if not isinstance(jd, dict) or "name" not in jd or "role" not in jd:
            raise LegMapError(f"{jw}: expected {{name: ..., role: ...}}, got {shown(jd)}")
        _known(jw, jd, ("name", "role", "ratio"))
        role = jd["role"]
        if not isinstance(role, str) or role not in LEG_ROLES:
            raise LegMapError(f"{jw}.role: {shown(role)} is not one of {list(LEG_ROLES)}")
        ratio = _number(jd.get("ratio", 1.0), f"{jw}.ratio", "the motor's turns per turn of the joint (its encoder "
                        "on the motor behind a gear; negative if it turns the other way)")
        if ratio == 0.0:
            raise LegMapError(f"{jw}.ratio is 0: give the motor's turns per turn of the joint (e.g. 2.0), or leave "
                              "it out for an encoder on the joint")
        joints.append(Joint(_name(jd["name"], f"{jw}.name", "the joint's name in the model"), role, ratio))
    roles = [j.role for j in joints]
    ankles = [list(expected_roles[3:])]
    if len(ankles[0]) == 3:  # the ankle's two joints in either order
        ankles.append([ankles[0][0], ankles[0][2], ankles[0][1]])
    if sorted(roles[:3]) != sorted(HIP_ROLES) or roles[3:] not in ankles:
        raise LegMapError(
            f"{lw}.joints: roles must be the three hip joints (any order), then "
            f"{', '.join(expected_roles[3:])}" + (" (the two ankle joints in either order)" if len(ankles) > 1 else "")
            + f", from pelvis to foot; got {roles}")
    corners_d = ld["corners"]
    if not isinstance(corners_d, dict) or set(corners_d) != set(CORNER_NAMES):
        extra = sorted(map(str, set(corners_d) - set(CORNER_NAMES))) if isinstance(corners_d, dict) else []
        raise LegMapError(f"{lw}.corners: give the four sole corners {list(CORNER_NAMES)} "
                          "as [x, y, z] in the sole frame" + (f" (not {extra})" if extra else "")
                          + ("" if isinstance(corners_d, dict) else f"; got {shown(corners_d)}"))
    corners = {k: _vec(corners_d[k], f"{lw}.corners.{k}") for k in CORNER_NAMES}
    ft = _frame(ld["ft"], f"{lw}.ft") if ld.get("ft") is not None else None
    linkage = _linkage(ld["linkage"], f"{lw}.linkage", joints) if ld.get("linkage") is not None else None
    return Leg(tuple(joints), _frame(ld["sole"], f"{lw}.sole"), corners, ft, linkage)


def _linkage(d, where: str, joints: list[Joint]) -> tuple[LinkageMotor, LinkageMotor]:
    """A leg's parallel-linkage ankle: {motors: [two motors]}, each {pivot, axis, crank,
    rod, foot} (see `LinkageMotor`)."""
    if len(joints) != 6:
        raise LegMapError(f"{where}: a parallel-linkage ankle turns an ankle pitch and an ankle roll; this leg has "
                          f"no ankle roll: leave the linkage out")
    if any(j.ratio != 1.0 for j in joints[-2:]):
        raise LegMapError(f"{where}: the ankle joints also have a ratio: the linkage is their transmission; drop "
                          "the ratio")
    if not isinstance(d, dict) or set(d) != {"motors"} or not isinstance(d["motors"], list) or len(d["motors"]) != 2:
        raise LegMapError(f"{where}: expected {{motors: [two motors]}}, each {{pivot, axis, crank, rod, foot}} "
                          f"(docs/leg-map.md, 'Parallel-linkage ankles'); got {shown(d)}")
    motors = []
    for i, md in enumerate(d["motors"]):
        mw = f"{where}.motors[{i}]"
        if not isinstance(md, dict):
            raise LegMapError(f"{mw}: expected {{pivot, axis, crank, rod, foot}}, got {shown(md)}")
        _known(mw, md, LINKAGE_MOTOR_FIELDS)
        missing = [k for k in LINKAGE_MOTOR_FIELDS if k not in md]
        if missing:
            raise LegMapError(f"{mw}: missing {missing} (pivot, axis, crank: [x, y, z] in the shank frame; rod: the "
                              "rod's length, m; foot: [x, y, z], the rod's end in the foot frame)")
        axis = np.array(_vec(md["axis"], f"{mw}.axis"))
        crank = np.array(_vec(md["crank"], f"{mw}.crank"))
        if np.linalg.norm(axis) < 1e-9 or np.linalg.norm(crank) < 1e-6:
            raise LegMapError(f"{mw}: axis and crank must be non-zero (the motor's axis; the crank arm, pivot to "
                              "the rod's joint, m)")
        axis /= np.linalg.norm(axis)
        if abs(axis @ crank) > 1e-6 * np.linalg.norm(crank):
            raise LegMapError(f"{mw}.crank is not perpendicular to the motor's axis (crank . axis = "
                              f"{axis @ crank:.3g} m): give the crank arm from the pivot, in the plane the crank turns in")
        motors.append(LinkageMotor(_vec(md["pivot"], f"{mw}.pivot"), tuple(float(x) for x in axis),
                                   tuple(float(x) for x in crank),
                                   _number(md["rod"], f"{mw}.rod", "the rod's length, m", low=0.0, low_open=True),
                                   _vec(md["foot"], f"{mw}.foot")))
    return motors[0], motors[1]


def _optional_mapping(data: dict, key: str, where: str, meaning: str) -> dict:
    """An optional mapping field (absent or null: empty)."""
    v = data.get(key)
    if v is None:
        return {}
    if not isinstance(v, dict):
        raise LegMapError(f"{where}: field '{key}' is {shown(v)}: it must map {meaning}")
    return v


def parse_legmap(data: dict, base_dir: Path, source: Path | None = None) -> LegMap:
    """Validate a leg-map mapping; relative paths resolve against `base_dir`."""
    where = f"leg map {source}" if source else "leg map"
    if not isinstance(data, dict):
        raise LegMapError(f"{where}: expected a YAML mapping at the top level (schema, name, mjcf, pelvis, imu, "
                          f"legs: see docs/leg-map.md), got {shown(data)}")
    if data.get("schema") != SCHEMA:
        raise LegMapError(f"{where}: field 'schema' must be '{SCHEMA}' (got {shown(data.get('schema'))})")
    _known(where, data, TOP_FIELDS)
    for key in ("name", "pelvis", "imu", "legs"):
        if key not in data:
            raise LegMapError(f"{where}: missing field '{key}' (see docs/leg-map.md)")
    if ("mjcf" in data) == ("urdf" in data):
        raise LegMapError(f"{where}: give the robot's model in exactly one of the fields 'mjcf' (an MJCF file) "
                          "or 'urdf' (a URDF file)" + (", not both" if "mjcf" in data else ""))
    name = _name(data["name"], f"{where}: field 'name'", "the robot's name (recordings carry it)")
    pelvis = _name(data["pelvis"], f"{where}: field 'pelvis'", "the name of the floating-base body")
    kind = "mjcf" if "mjcf" in data else "urdf"
    model = _model_path(data, kind, base_dir, where)
    legs_d = data["legs"]
    if not isinstance(legs_d, dict) or set(legs_d) != set(SIDES):
        raise LegMapError(f"{where}: field 'legs' must have exactly the keys 'left' and 'right', got "
                          + (f"the keys {list(legs_d)}" if isinstance(legs_d, dict) else shown(legs_d)))
    absent = data.get("absent_roles") or []
    if not isinstance(absent, list) or not all(isinstance(r, str) and r in ABSENT_ALLOWED for r in absent):
        raise LegMapError(f"{where}: absent_roles: {shown(absent)}; the roles a leg may lack are {list(ABSENT_ALLOWED)} "
                          "(a leg needs three hip joints, a knee and an ankle pitch to stand and be calibrated)")
    expected_roles = tuple(r for r in LEG_ROLES if r not in absent)
    legs = {side: _leg(legs_d[side], side, where, expected_roles) for side in SIDES}
    if legs["left"].hip_order != legs["right"].hip_order:
        raise LegMapError(f"{where}: left and right legs have different hip orderings "
                          f"{legs['left'].hip_order} vs {legs['right'].hip_order}")
    if [j.role for j in legs["left"].joints] != [j.role for j in legs["right"].joints]:
        raise LegMapError(f"{where}: left and right legs have different ankle orders "
                          f"{[j.role for j in legs['left'].joints][3:]} vs {[j.role for j in legs['right'].joints][3:]}")
    names = [j.name for s in SIDES for j in legs[s].joints]
    if len(set(names)) != len(names):
        raise LegMapError(f"{where}: the {len(names)} leg joint names must be distinct; got {names}")
    imu_d = data["imu"]
    through: tuple[str, ...] = ()
    if isinstance(imu_d, dict) and "through" in imu_d:
        imu_d = dict(imu_d)
        t = imu_d.pop("through")
        if not isinstance(t, list) or not t:
            raise LegMapError(f"{where}: imu.through is {shown(t)}: give the non-leg joints between the pelvis and "
                              "the IMU as a list of names, e.g. [waist_yaw_joint, waist_roll_joint, waist_pitch_joint]")
        through = tuple(_name(j, f"{where}: imu.through entry", "a joint's name") for j in t)
        bad = [j for j in through if j in names]
        if bad or len(set(through)) != len(through):
            raise LegMapError(f"{where}: imu.through {list(through)}: " + (
                f"{bad[0]} is a leg joint; list only the joints between the pelvis and the IMU's body" if bad else
                "each joint once"))
    imu = _frame(imu_d, f"{where}: imu")
    policy_imu = _frame(data["policy_imu"], f"{where}: policy_imu") if data.get("policy_imu") is not None else None
    knee = _number(data.get("knee_straight_rad", 0.0), f"{where}: knee_straight_rad",
                   "the knee angle of a straight leg, in radians; 0 if the straight leg is at zero")
    held_d = _optional_mapping(data, "held_joints_rad", where, "joint names to angles in radians")
    held = {}
    for k, v in held_d.items():
        _name(k, f"{where}: held_joints_rad key", "the name of a non-leg joint of the model")
        if k in names:
            raise LegMapError(f"{where}: held_joints_rad.{k} is a leg joint; only non-leg joints are held")
        held[k] = _number(v, f"{where}: held_joints_rad.{k}", "the angle in radians at which the joint is held")
    # Leg joints by name; the held (non-leg) joints by name or pattern, checked against the
    # model's joints when they are held (`legcal_bench.robots.holds`).
    gains_d = _optional_mapping(data, "servo_gains", where, "joint names (or patterns of held joints) to [kp, kd]")
    gains = {}
    for k, v in gains_d.items():
        _name(k, f"{where}: servo_gains key", "a joint's name, or a pattern such as '*_wrist_*' for held joints")
        kp, kd = _vec(v, f"{where}: servo_gains.{k} ([kp, kd])", 2)
        if kp <= 0 or kd < 0:
            raise LegMapError(f"{where}: servo_gains.{k} = {shown(v)}: kp must be > 0 (N m/rad) and kd >= 0 "
                              "(N m s/rad); give the joint servo's PD gains [kp, kd], or leave the joint out to use "
                              "the MJCF's or the default gains")
        gains[k] = (kp, kd)
    packages = {}
    for k, v in _optional_mapping(data, "packages", where, "ROS package names to their folders").items():
        _name(k, f"{where}: packages key", "the name of a ROS package the URDF's package:// URIs name")
        if not isinstance(v, str) or not v.strip():
            raise LegMapError(f"{where}: packages.{k} is {shown(v)}: give the package's folder, relative to the leg "
                              "map or absolute")
        folder = Path(v).expanduser()
        folder = folder if folder.is_absolute() else (base_dir / folder).resolve()
        if not folder.is_dir():
            raise LegMapError(f"{where}: packages.{k} = {v!r}: {folder} is not a folder; give the folder of "
                              f"package '{k}' (the one holding its package.xml)")
        packages[k] = folder
    if packages and kind != "urdf":
        raise LegMapError(f"{where}: field 'packages' resolves a URDF's package:// URIs; this leg map names an MJCF")
    urdf = None
    if kind == "urdf":
        sites = [f for f, spec in [("imu", data["imu"]), ("policy_imu", data.get("policy_imu"))] + [(f"legs.{s}.{k}", legs_d[s].get(k)) for s in SIDES
                                                             for k in ("sole", "ft")]
                 if isinstance(spec, dict) and "site" in spec]
        if sites:
            raise LegMapError(f"{where}: {', '.join(sites)}: a URDF has no sites; give each frame as a pose relative "
                              "to a link, {body: <link>, pos: [x, y, z], rpy: [r, p, y]}")
        from legcal_bench.robots.urdf import mjcf_of_urdf

        urdf, model = model, mjcf_of_urdf(model, where, packages)
    return LegMap(
        name=name,
        mjcf=model,
        urdf=urdf,
        pelvis=pelvis,
        legs=legs,
        imu=imu,
        knee_straight_rad=knee,
        held_joints_rad=held,
        servo_gains=gains,
        source=source,
        packages=packages,
        imu_through=through,
        policy_imu=policy_imu,
    )


def load_legmap(path: str | Path) -> LegMap:
    path = Path(path).resolve()
    try:
        text = read_text("leg map", path, "leg map")
    except ConfigError as e:
        raise LegMapError(str(e) + ("; give the path of a leg-map YAML (see docs/leg-map.md)"
                                    if not path.exists() else "")) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise LegMapError(f"leg map {path}: not valid YAML: {e}") from None
    except RecursionError:
        raise LegMapError(f"leg map {path}: not valid YAML: nested too deeply") from None
    return parse_legmap(data, path.parent, source=path)
