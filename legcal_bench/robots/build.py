"""Generate MJCF files and leg maps from a `LegDesign` (dm_control's mjcf).

`python -m legcal_bench.robots.build` rewrites `assets/`; a test checks that the
committed files equal what this module generates, so the design stays the source.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import NamedTuple

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import yaml
from scipy.spatial.transform import Rotation
from dm_control import mjcf

from legcal_bench.files.atomic import atomic_write_text
from legcal_bench.geometry.poses import from_wxyz, wxyz
from legcal_bench.robots.design import DESIGNS, LEG_ROLES, LegDesign
from legcal_bench.robots.legmap import CORNER_NAMES, SIDES, FrameSpec, Joint, Leg, LegMap

ASSETS = Path(__file__).parent / "assets"


def _mirror(v, side: str):
    return (v[0], v[1] if side == "left" else 0.0 - v[1], v[2])


def _box_inertia(mass: float, half: tuple[float, float, float]) -> list[float]:
    a, b, c = (2 * h for h in half)
    return [mass * (b * b + c * c) / 12, mass * (a * a + c * c) / 12, mass * (a * a + b * b) / 12]


def _rod_inertia(mass: float, to_child) -> tuple[np.ndarray, np.ndarray]:
    """(centre of mass, diagonal inertia) of a rod-like link between a body's origin and
    its child's origin."""
    v = np.asarray(to_child, dtype=float)
    length = max(float(np.linalg.norm(v)), 0.04)
    half = (0.03, 0.03, length / 2) if abs(v[2]) >= max(abs(v[0]), abs(v[1])) else (length / 2, 0.03, 0.03)
    return (v / 2).round(6), np.round(_box_inertia(mass, half), 9)


def _link_inertial(body, mass: float, to_child) -> None:
    """A rod-like link between this body's origin and its child's origin."""
    com, diag = _rod_inertia(mass, to_child)
    body.add("inertial", pos=com.tolist(), mass=round(mass, 6), diaginertia=diag.tolist())


def _limits(design: LegDesign, role: str, side: str) -> tuple[float, float]:
    lo, hi = design.limits[role]
    # Roll and yaw limits mirror for the right leg (abduction stays positive outward).
    if side == "right" and role in ("hip_roll", "hip_yaw", "ankle_roll"):
        lo, hi = -hi, -lo
    # A flipped axis turns the same way at the opposite angle.
    if side == "right" and role in design.flipped_axes:
        lo, hi = -hi, -lo
    return (lo, hi)


def _chain(design: LegDesign) -> tuple[list[str], list]:
    """The leg's roles from pelvis to foot and each chain slot's origin in its parent
    (left leg; `_mirror` for the right)."""
    roles = list(design.roles)
    assert set(roles) | set(design.absent_roles) == set(LEG_ROLES)
    return roles, [design.hip_origin, *design.hip_slot_offsets, design.thigh, design.shin, design.ankle_gap][:len(roles)]


class _Foot(NamedTuple):
    sole: np.ndarray  # the sole centre in the foot body
    com: np.ndarray  # the foot's centre of mass and diagonal inertia
    inertia: np.ndarray
    corners: dict  # the four sole corners in the sole frame
    box: np.ndarray  # the sole's collision box: centre and half sizes
    box_half: tuple[float, float, float]


def _foot(design: LegDesign, side: str) -> _Foot:
    """The foot of `side`: sole frame, mass properties, corners, collision box."""
    sole = np.asarray(_mirror(design.foot_sole_offset, side))
    hl, hw = design.sole_half
    t = design.sole_thickness
    corners = {"toe_left": (hl, hw, 0.0), "toe_right": (hl, -hw, 0.0),
               "heel_left": (-hl, hw, 0.0), "heel_right": (-hl, -hw, 0.0)}
    return _Foot(sole, (sole + [0, 0, t]).round(6), np.round(_box_inertia(design.foot_mass, (hl, hw, t)), 9), corners,
                 (sole + [0, 0, t / 2]).round(6), (hl, hw, t / 2))


def _sole_geoms(design: LegDesign, f: _Foot, side: str) -> list[dict]:
    """The sole's collision geoms (`LegDesign.heel`): one box, or a toe box over the front
    half and the heel a capsule along the foot's centre line, its bottom on the sole plane."""
    name = f"{side}_sole_geom"
    if design.heel == "box":
        return [dict(name=name, type="box", size=list(f.box_half), pos=f.box.tolist())]
    if design.heel != "capsule":
        raise ValueError(f"heel={design.heel!r}: 'box' or 'capsule'")
    hl, hw, r = f.box_half
    toe = (f.box + [hl / 2, 0.0, 0.0]).round(6)
    heel = [(f.sole + [x, 0.0, r]).round(6).tolist() for x in (-hl + r, -r)]
    return [dict(name=name, type="box", size=[hl / 2, hw, r], pos=toe.tolist()),
            dict(name=name.replace("sole", "heel"), type="capsule", fromto=[*heel[0], *heel[1]], size=[r])]


def build_model(design: LegDesign, *, upper_body: bool = False, sole_sites: bool = True,
                foot_frame_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0),
                waist: int = 1) -> tuple[mjcf.RootElement, LegMap]:
    """MJCF model and leg map for `design`.

    `upper_body` adds a waist and two arm joints (held joints): the waist of `waist` joints
    (1: yaw; 3: yaw, roll, pitch, with an IMU site `imu_in_torso` in the torso above
    them, tilted by 2 and 3 deg as a mounting is: the leg map's IMU stays the pelvis's,
    the torso's twin names it with `imu.through`), `sole_sites=False`
    gives the soles as poses relative to the foot body instead of sites, and
    `foot_frame_rpy` rotates the foot body's frame away from the sole: both shape
    the synthetic test robot that exercises what external robots need.
    """
    m = mjcf.RootElement(model=design.name)
    m.compiler.angle = "radian"
    m.option.timestep = 0.001
    m.option.integrator = "implicitfast"
    m.default.joint.armature = design.armature
    m.default.joint.damping = design.joint_damping
    m.default.geom.rgba = (0.7, 0.7, 0.75, 1)

    pelvis = m.worldbody.add("body", name="pelvis", pos=(0, 0, 1.0))
    pelvis.add("freejoint", name="root")
    pelvis.add("inertial", pos=list(design.pelvis_com), mass=design.pelvis_mass,
               diaginertia=np.round(_box_inertia(design.pelvis_mass, design.pelvis_box), 9).tolist())
    pelvis.add("geom", name="trunk", type="box", size=list(design.pelvis_box), pos=list(design.pelvis_com),
               contype=0, conaffinity=0, rgba=(0.35, 0.4, 0.5, 1))
    pelvis.add("site", name="imu", pos=list(design.imu_pos), size=[0.01])
    held: dict[str, float] = {}
    if upper_body:
        if waist not in (1, 3):
            raise ValueError(f"waist={waist!r}: 1 (yaw) or 3 (yaw, roll, pitch) joints")
        torso = pelvis.add("body", name="torso", pos=[0, 0, 0.25 * design.pelvis_box[2] * 4])
        torso.add("joint", name="waist_yaw_joint", axis=[0, 0, 1], range=[-1, 1])
        if waist == 3:  # yaw, then roll and pitch in bodies of their own (a serial waist)
            for joint, axis in (("waist_roll_joint", [1, 0, 0]), ("waist_pitch_joint", [0, 1, 0])):
                torso.add("inertial", pos=[0, 0, 0.02], mass=0.3, diaginertia=[0.001, 0.001, 0.001])
                torso = torso.add("body", name=joint.replace("_joint", "_link"), pos=[0, 0, 0.04])
                torso.add("joint", name=joint, axis=axis, range=[-0.5, 0.5])
            torso.add("site", name="imu_in_torso", pos=[0.03, 0.0, 0.12], size=[0.01],
                      quat=wxyz(Rotation.from_euler("xyz", [np.deg2rad(2.0), np.deg2rad(3.0), 0.0])).tolist())
        torso.add("inertial", pos=[0, 0, 0.1], mass=4.0, diaginertia=[0.05, 0.05, 0.03])
        for side in SIDES:
            arm = torso.add("body", name=f"{side}_arm", pos=_mirror((0, 0.2, 0.15), side))
            arm.add("joint", name=f"{side}_shoulder_pitch_joint", axis=[0, 1, 0], range=[-3, 3])
            arm.add("inertial", pos=[0, 0, -0.15], mass=2.0, diaginertia=[0.02, 0.02, 0.005])
            fore = arm.add("body", name=f"{side}_forearm", pos=[0, 0, -0.28])
            fore.add("joint", name=f"{side}_elbow_joint", axis=[0, 1, 0], range=[-2.5, 0.1])
            fore.add("inertial", pos=[0, 0, -0.12], mass=1.2, diaginertia=[0.01, 0.01, 0.002])
        held = {"waist_yaw_joint": 0.1, "left_shoulder_pitch_joint": 0.3, "right_shoulder_pitch_joint": 0.3,
                "left_elbow_joint": -0.5, "right_elbow_joint": -0.5}
        if waist == 3:
            held.update(waist_roll_joint=0.05, waist_pitch_joint=0.15)

    legs: dict[str, Leg] = {}
    roles, slot_pos = _chain(design)  # slot origins in their parent, each the offset to the previous slot's child
    for side in SIDES:
        parent = pelvis
        joints = []
        for slot, role in enumerate(roles):
            last = slot == len(roles) - 1
            name = "foot" if last else role
            body = parent.add("body", name=f"{side}_{name}_link", pos=list(_mirror(slot_pos[slot], side)))
            jname = f"{side}_{role}_joint"
            body.add("joint", name=jname, axis=list(design.axis(role, side)), range=list(_limits(design, role, side)))
            joints.append(Joint(jname, role))
            servo = design.servos[role]
            m.actuator.add("position", name=f"{side}_{role}", joint=jname, kp=servo.kp, kv=servo.kv,
                           forcelimited="true", forcerange=[-servo.torque_limit, servo.torque_limit])
            if not last:
                child = _mirror(slot_pos[slot + 1], side)
                _link_inertial(body, design.masses[slot], child)
                if np.linalg.norm(child) > 0.05:
                    body.add("geom", name=f"{side}_{name}_geom", type="capsule", fromto=[0, 0, 0, *child], size=[0.035],
                             contype=0, conaffinity=0)
            parent = body
        foot = parent
        f = _foot(design, side)
        sole_pos, corners = f.sole, f.corners
        foot.add("inertial", pos=f.com.tolist(), mass=design.foot_mass, diaginertia=f.inertia.tolist())
        for geom in _sole_geoms(design, f, side):
            foot.add("geom", **geom, rgba=(0.25, 0.25, 0.3, 1), friction=[1.0, 0.02, 0.001], condim=6)
        ft = FrameSpec(site=f"{side}_ft")
        foot.add("site", name=f"{side}_ft", pos=list(design.ft_pos), size=[0.01])
        if sole_sites:
            foot.add("site", name=f"{side}_sole", pos=sole_pos.round(6).tolist(), size=[0.01])
            for c in CORNER_NAMES:
                foot.add("site", name=f"{side}_sole_{c}", pos=(sole_pos + corners[c]).round(6).tolist(), size=[0.005])
            sole = FrameSpec(site=f"{side}_sole")
        else:
            sole = FrameSpec(body=foot.name, pos=tuple(sole_pos.round(6).tolist()))
        if any(foot_frame_rpy):
            # Rotate the foot body's frame; the sole frame stays where it was.
            rot = Rotation.from_euler("xyz", foot_frame_rpy)
            foot.quat = wxyz(rot).tolist()
            inv = rot.inv()
            for child in foot.all_children():
                if child.tag == "joint":
                    child.axis = inv.apply(child.axis).round(12).tolist()
                elif child.tag in ("geom", "site", "inertial"):
                    child.pos = inv.apply(child.pos).round(9).tolist()
                    q = inv * from_wxyz(child.quat) if child.quat is not None else inv
                    child.quat = wxyz(q).round(12).tolist()
            sole = FrameSpec(body=foot.name, pos=tuple(inv.apply(sole_pos).round(9).tolist()),
                             rpy=tuple(inv.as_euler("xyz").tolist()))
        legs[side] = Leg(tuple(joints), sole, corners, ft)

    m.sensor.add("accelerometer", name="imu_acc", site="imu")
    m.sensor.add("gyro", name="imu_gyro", site="imu")
    for side in SIDES:
        m.sensor.add("force", name=f"{side}_ft_force", site=f"{side}_ft")
        m.sensor.add("torque", name=f"{side}_ft_torque", site=f"{side}_ft")

    legmap = LegMap(
        name=design.name,
        mjcf=Path(f"{design.name}.xml"),
        pelvis="pelvis",
        legs=legs,
        imu=FrameSpec(site="imu"),
        knee_straight_rad=design.knee_straight_rad,
        held_joints_rad=held,
    )
    return m, legmap


def to_clean_xml(model: mjcf.RootElement) -> str:
    """MJCF text without dm_control's scoping artefacts (`class="/"`), so that any
    MJCF reader, dm_control's own included, loads it back."""
    root = ET.fromstring(model.to_xml_string(precision=9))
    outer = root.find("default")
    inner = outer.find("default") if outer is not None else None
    if inner is not None and inner.get("class") == "/":
        outer.remove(inner)
        outer.extend(list(inner))
    for el in root.iter():
        if el.get("class") == "/":
            del el.attrib["class"]
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def write_robot(design: LegDesign, out_dir: Path, **kwargs) -> Path:
    """Write `<name>.xml` and `<name>.legmap.yaml` into `out_dir`; returns the leg map path."""
    model, legmap = build_model(design, **kwargs)
    return _write(design, legmap, Path(out_dir) / f"{design.name}.xml", to_clean_xml(model))


def write_designs(robots: list[str], folder: Path) -> list[str]:
    """`robots` with each generated robot's name (`design.GENERATED_DESIGNS`) replaced by
    the leg-map path of its model written under `folder`; built-in names and leg-map
    paths as given."""
    from legcal_bench.robots.design import GENERATED_DESIGNS

    return [str(write_robot(GENERATED_DESIGNS[r], Path(folder))) if r in GENERATED_DESIGNS else r for r in robots]


def build_urdf(design: LegDesign) -> tuple[str, LegMap]:
    """The URDF twin of `build_model(design)` and its leg map: the same links, joints,
    axes, limits and inertias (each link's inertia as in the MJCF), the soles as collision
    boxes, the leg map's frames as poses relative to links (a URDF has no sites) and the
    design's servo gains in the leg map (a URDF has no actuators). The joints' armature
    has no URDF field: the twin simulates without it."""
    if design.heel != "box":
        raise ValueError(f"{design.name}: heel={design.heel!r} has no URDF twin (a URDF has no capsule): heel='box'")
    robot = ET.Element("robot", name=f"{design.name}_urdf")

    def num(v) -> str:
        return " ".join(f"{float(x):.12g}" for x in np.atleast_1d(v))

    def link(name: str, mass: float | None = None, com=None, diag=None):
        el = ET.SubElement(robot, "link", name=name)
        if mass is not None:
            inertial = ET.SubElement(el, "inertial")
            ET.SubElement(inertial, "origin", xyz=num(com), rpy="0 0 0")
            ET.SubElement(inertial, "mass", value=num(mass))
            ET.SubElement(inertial, "inertia", ixx=num(diag[0]), ixy="0", ixz="0", iyy=num(diag[1]), iyz="0",
                          izz=num(diag[2]))
        return el

    link("pelvis", design.pelvis_mass, design.pelvis_com, _box_inertia(design.pelvis_mass, design.pelvis_box))
    roles, slot_pos = _chain(design)
    legs: dict[str, Leg] = {}
    gains: dict[str, tuple[float, float]] = {}
    for side in SIDES:
        parent, joints = "pelvis", []
        for slot, role in enumerate(roles):
            name = f"{side}_{'foot' if slot == len(roles) - 1 else role}_link"
            if slot < len(roles) - 1:
                link(name, round(design.masses[slot], 6),
                     *_rod_inertia(design.masses[slot], _mirror(slot_pos[slot + 1], side)))
            else:
                f = _foot(design, side)
                collision = ET.SubElement(link(name, design.foot_mass, f.com, f.inertia), "collision")
                ET.SubElement(collision, "origin", xyz=num(f.box), rpy="0 0 0")
                ET.SubElement(ET.SubElement(collision, "geometry"), "box", size=num(2 * np.asarray(f.box_half)))
            jname = f"{side}_{role}_joint"
            joint = ET.SubElement(robot, "joint", name=jname, type="revolute")
            ET.SubElement(joint, "parent", link=parent)
            ET.SubElement(joint, "child", link=name)
            ET.SubElement(joint, "origin", xyz=num(_mirror(slot_pos[slot], side)), rpy="0 0 0")
            ET.SubElement(joint, "axis", xyz=num(design.axis(role, side)))
            lo, hi = _limits(design, role, side)
            servo = design.servos[role]
            ET.SubElement(joint, "limit", lower=num(lo), upper=num(hi), effort=num(servo.torque_limit), velocity="30")
            ET.SubElement(joint, "dynamics", damping=num(design.joint_damping))
            joints.append(Joint(jname, role))
            gains[jname] = (servo.kp, servo.kv)
            parent = name
        legs[side] = Leg(tuple(joints), FrameSpec(body=parent, pos=tuple(f.sole.round(6).tolist())), f.corners,
                         FrameSpec(body=parent, pos=tuple(design.ft_pos)))
    ET.indent(robot, space="  ")
    urdf = Path(f"{design.name}.urdf")  # MuJoCo's compilation of it is made when the leg map is loaded
    legmap = LegMap(name=design.name, mjcf=urdf, pelvis="pelvis", legs=legs,
                    imu=FrameSpec(body="pelvis", pos=tuple(design.imu_pos)), knee_straight_rad=design.knee_straight_rad,
                    servo_gains=gains, urdf=urdf)
    return ET.tostring(robot, encoding="unicode") + "\n", legmap


def write_urdf_robot(design: LegDesign, out_dir: Path) -> Path:
    """Write `<name>.urdf` and `<name>.legmap.yaml` (the URDF twin, `build_urdf`) into
    `out_dir`; returns the leg map path."""
    text, legmap = build_urdf(design)
    return _write(design, legmap, Path(out_dir) / f"{design.name}.urdf", text, " (URDF twin)")


def _write(design: LegDesign, legmap: LegMap, model_path: Path, model_text: str, what: str = "") -> Path:
    """Write the model file and `<name>.legmap.yaml` naming it beside it; the leg map's path."""
    model_path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(model_path, model_text)
    lm_path = model_path.parent / f"{design.name}.legmap.yaml"
    d = legmap.to_dict()
    d["urdf" if legmap.urdf is not None else "mjcf"] = model_path.name
    header = f"# Generated by legcal_bench.robots.build from design '{design.name}'{what}; do not edit.\n"
    atomic_write_text(lm_path, header + yaml.safe_dump(d, sort_keys=False))
    return lm_path


def main() -> None:
    for design in DESIGNS.values():
        print(write_robot(design, ASSETS))


if __name__ == "__main__":
    main()
