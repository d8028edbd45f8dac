"""The leg map: what legcal-bench needs to know about any robot beyond its MJCF or URDF.

A small YAML file names the leg joints (left leg then right, each from pelvis to foot:
six per leg, or five where a leg has no ankle roll and the leg map declares it absent)
with their roles, the sole frames and their four corner points, the pelvis and
the IMU placement, the angles at which any other joint is held, and servo gains when
the MJCF drives torque motors. See docs/leg-map.md for the schema.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from legcal_bench.errors import LegMapError, MissingModelError
from legcal_bench.robots.design import HIP_ROLES, LEG_ROLES

SCHEMA = "legcal-legmap/1"
SIDES = ("left", "right")
CORNER_NAMES = ("toe_left", "toe_right", "heel_left", "heel_right")
# Roles a leg map may declare absent (`absent_roles`): a 5-joint leg without ankle roll.
ABSENT_ALLOWED = ("ankle_roll",)


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


@dataclass(frozen=True)
class Leg:
    joints: tuple[Joint, ...]
    sole: FrameSpec
    corners: dict[str, tuple[float, float, float]]  # in the sole frame
    ft: FrameSpec | None = None

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
            "imu": self.imu.to_dict(),
            "knee_straight_rad": self.knee_straight_rad,
            "legs": {},
        }
        for side in SIDES:
            leg = self.legs[side]
            ld: dict = {
                "joints": [{"name": j.name, "role": j.role} for j in leg.joints],
                "sole": leg.sole.to_dict(),
                "corners": {k: list(v) for k, v in leg.corners.items()},
            }
            if leg.ft is not None:
                ld["ft"] = leg.ft.to_dict()
            d["legs"][side] = ld
        if self.absent_roles:
            d["absent_roles"] = list(self.absent_roles)
        if self.held_joints_rad:
            d["held_joints_rad"] = dict(self.held_joints_rad)
        if self.servo_gains:
            d["servo_gains"] = {k: list(v) for k, v in self.servo_gains.items()}
        return d


def _relpath(target: Path, start: Path) -> str:
    import os

    return os.path.relpath(Path(target).resolve(), Path(start).resolve())


def _vec(value, where: str, n: int = 3) -> tuple[float, ...]:
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise LegMapError(f"{where}: expected {n} numbers, got {value!r}") from None
    if arr.size != n or not np.all(np.isfinite(arr)):
        raise LegMapError(f"{where}: expected {n} finite numbers, got {value!r}")
    return tuple(float(x) for x in arr)


def _frame(d, where: str) -> FrameSpec:
    if not isinstance(d, dict):
        raise LegMapError(f"{where}: expected a mapping with 'site' or 'body' (+ 'pos', 'rpy'), got {d!r}")
    unknown = set(d) - {"site", "body", "pos", "rpy"}
    if unknown:
        raise LegMapError(f"{where}: unknown keys {sorted(unknown)}; allowed: site, body, pos, rpy")
    if ("site" in d) == ("body" in d):
        raise LegMapError(f"{where}: give exactly one of 'site: NAME' or 'body: NAME' (with optional pos/rpy)")
    if "site" in d:
        if "pos" in d or "rpy" in d:
            raise LegMapError(f"{where}: 'pos'/'rpy' go with 'body', not with 'site'")
        return FrameSpec(site=str(d["site"]))
    return FrameSpec(
        body=str(d["body"]),
        pos=_vec(d.get("pos", (0, 0, 0)), f"{where}.pos"),
        rpy=_vec(d.get("rpy", (0, 0, 0)), f"{where}.rpy (radians)"),
    )


def parse_legmap(data: dict, base_dir: Path, source: Path | None = None) -> LegMap:
    """Validate a leg-map mapping; relative paths resolve against `base_dir`."""
    where = str(source) if source else "leg map"
    if not isinstance(data, dict):
        raise LegMapError(f"{where}: expected a YAML mapping at the top level")
    if data.get("schema") != SCHEMA:
        raise LegMapError(f"{where}: field 'schema' must be '{SCHEMA}' (got {data.get('schema')!r})")
    for key in ("name", "pelvis", "imu", "legs"):
        if key not in data:
            raise LegMapError(f"{where}: missing field '{key}' (see docs/leg-map.md)")
    if ("mjcf" in data) == ("urdf" in data):
        raise LegMapError(f"{where}: give the robot's model in exactly one of the fields 'mjcf' (an MJCF file) "
                          "or 'urdf' (a URDF file)" + (", not both" if "mjcf" in data else ""))
    unknown = set(data) - {
        "schema", "name", "mjcf", "urdf", "pelvis", "imu", "legs", "knee_straight_rad",
        "held_joints_rad", "servo_gains", "absent_roles",
    }
    if unknown:
        raise LegMapError(f"{where}: unknown fields {sorted(unknown)} (see docs/leg-map.md)")
    kind = "mjcf" if "mjcf" in data else "urdf"
    model = Path(data[kind])
    if not model.is_absolute():
        model = (base_dir / model).resolve()
    if not model.is_file():
        raise MissingModelError(f"{where}: field '{kind}' points to {model}, which does not exist; "
                                "give a path relative to the leg map or an absolute path")
    legs_d = data["legs"]
    if not isinstance(legs_d, dict) or set(legs_d) != set(SIDES):
        raise LegMapError(f"{where}: field 'legs' must have exactly the keys 'left' and 'right'")
    absent = data.get("absent_roles", []) or []
    if not isinstance(absent, list) or not set(absent) <= set(ABSENT_ALLOWED):
        raise LegMapError(f"{where}: absent_roles: {absent!r}; the roles a leg may lack are {list(ABSENT_ALLOWED)} "
                          "(a leg needs three hip joints, a knee and an ankle pitch to stand and be calibrated)")
    expected_roles = tuple(r for r in LEG_ROLES if r not in absent)
    legs = {}
    for side in SIDES:
        ld = legs_d[side]
        lw = f"{where}: legs.{side}"
        for key in ("joints", "sole", "corners"):
            if key not in ld:
                raise LegMapError(f"{lw}: missing field '{key}'")
        joints_d = ld["joints"]
        if not isinstance(joints_d, list):
            raise LegMapError(f"{lw}.joints: list the leg's joints from pelvis to foot, "
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
            if not isinstance(jd, dict) or "name" not in jd or "role" not in jd:
                raise LegMapError(f"{lw}.joints[{i}]: expected {{name: ..., role: ...}}, got {jd!r}")
            if jd["role"] not in LEG_ROLES:
                raise LegMapError(f"{lw}.joints[{i}].role: {jd['role']!r} is not one of {list(LEG_ROLES)}")
            joints.append(Joint(str(jd["name"]), str(jd["role"])))
        roles = [j.role for j in joints]
        if sorted(roles[:3]) != sorted(HIP_ROLES) or roles[3:] != list(expected_roles[3:]):
            raise LegMapError(
                f"{lw}.joints: roles must be the three hip joints (any order), then "
                f"{', '.join(expected_roles[3:])}, from pelvis to foot; got {roles}")
        corners_d = ld["corners"]
        if not isinstance(corners_d, dict) or set(corners_d) != set(CORNER_NAMES):
            raise LegMapError(f"{lw}.corners: give the four sole corners {list(CORNER_NAMES)} "
                              "as [x, y, z] in the sole frame")
        corners = {k: _vec(corners_d[k], f"{lw}.corners.{k}") for k in CORNER_NAMES}
        ft = _frame(ld["ft"], f"{lw}.ft") if "ft" in ld else None
        legs[side] = Leg(tuple(joints), _frame(ld["sole"], f"{lw}.sole"), corners, ft)
    if legs["left"].hip_order != legs["right"].hip_order:
        raise LegMapError(f"{where}: left and right legs have different hip orderings "
                          f"{legs['left'].hip_order} vs {legs['right'].hip_order}")
    names = [j.name for s in SIDES for j in legs[s].joints]
    if len(set(names)) != len(names):
        raise LegMapError(f"{where}: the {len(names)} leg joint names must be distinct; got {names}")
    held = data.get("held_joints_rad", {}) or {}
    if not isinstance(held, dict):
        raise LegMapError(f"{where}: field 'held_joints_rad' must map joint names to angles in radians")
    for k, v in held.items():
        if k in names:
            raise LegMapError(f"{where}: held_joints_rad.{k} is a leg joint; only non-leg joints are held")
        _vec([v], f"{where}: held_joints_rad.{k}", 1)
    gains = data.get("servo_gains", {}) or {}
    if not isinstance(gains, dict):
        raise LegMapError(f"{where}: field 'servo_gains' must map leg joint names to [kp, kd]")
    for k in gains:
        if k not in names:
            raise LegMapError(f"{where}: servo_gains.{k} is not one of the leg joints")
    urdf = None
    if kind == "urdf":
        sites = [f for f, spec in [("imu", data["imu"])] + [(f"legs.{s}.{k}", legs_d[s].get(k)) for s in SIDES
                                                             for k in ("sole", "ft")]
                 if isinstance(spec, dict) and "site" in spec]
        if sites:
            raise LegMapError(f"{where}: {', '.join(sites)}: a URDF has no sites; give each frame as a pose relative "
                              "to a link, {body: <link>, pos: [x, y, z], rpy: [r, p, y]}")
        from legcal_bench.robots.urdf import mjcf_of_urdf

        urdf, model = model, mjcf_of_urdf(model, where)
    return LegMap(
        name=str(data["name"]),
        mjcf=model,
        urdf=urdf,
        pelvis=str(data["pelvis"]),
        legs=legs,
        imu=_frame(data["imu"], f"{where}: imu"),
        knee_straight_rad=float(_vec([data.get("knee_straight_rad", 0.0)], f"{where}: knee_straight_rad", 1)[0]),
        held_joints_rad={k: float(v) for k, v in held.items()},
        servo_gains={k: _vec(v, f"{where}: servo_gains.{k} ([kp, kd])", 2) for k, v in gains.items()},
        source=source,
    )


def load_legmap(path: str | Path) -> LegMap:
    path = Path(path).resolve()
    if not path.is_file():
        raise LegMapError(f"leg map {path} does not exist")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        raise LegMapError(f"{path}: not valid YAML: {e}") from None
    return parse_legmap(data, path.parent, source=path)
