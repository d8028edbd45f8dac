"""Robots shaped as vendors ship them, generated from the A3-like design (issue #59).

Each writer puts a robot and its leg map into a folder and returns the leg map's path;
nothing in the model or the leg map is edited for legcal-bench afterwards. They are what
the tests and `legcal-bench vendor-cases` (`legcal_bench.reports.vendor_cases`) run:

  ros_package      the A3-like URDF twin inside a ROS package (`package.xml`), its
                   collision meshes STL boxes and its visual meshes COLLADA files named
                   by `package://` URIs, the leg map in the package's `config/`;
  framed           the A3-like MJCF with MuJoCo `<frame>` elements around a leg, a knee,
                   a sole site and the IMU: carrying their bodies' offsets (the robot
                   grouped, `framed_grouped`), or turned (another robot; the file's
                   angles are radians);
  roll_first       ankles whose roll comes before their pitch (`ROLL_FIRST_ANKLE`);
  torso_imu        the A3-like robot with a waist of yaw, roll, pitch and its IMU in the
                   torso above them, declared with `imu.through` (`torso_imu_twins`: with
                   its twins, the IMU on the pelvis and the torso IMU undeclared);
  drive_joint      the left hip yaw turned by a drive joint at 1:2 (a joint equality);
  fixed_ratio      encoders behind gears: ratio 2 on the left knee, -1.5 on the right
                   ankle pitch (the leg map's `ratio`).
"""

from __future__ import annotations

import struct
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import yaml

from legcal_bench.robots.build import ASSETS, write_robot, write_urdf_robot
from legcal_bench.robots.design import A3, DESIGNS, ROLL_FIRST_ANKLE

PACKAGE = "a3_description"
WAIST = ("waist_yaw_joint", "waist_roll_joint", "waist_pitch_joint")  # `build_model(..., waist=3)`'s
TORSO_SITE = "imu_in_torso"


def box_stl(path: Path, size) -> None:
    """A binary STL of a box of `size` (x, y, z) centred on the origin."""
    h = np.asarray(size, dtype=float) / 2
    c = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    out = [b"\0" * 80, struct.pack("<I", len(faces))]
    for f in faces:
        a, b, d = c[list(f)]
        n = np.cross(b - a, d - a)
        n /= np.linalg.norm(n)
        if n @ (a + b + d) < 0:  # outward
            b, d, n = d, b, -n
        out.append(struct.pack("<12fH", *n, *a, *b, *d, 0))
    path.write_bytes(b"".join(out))


def ros_package(root: Path) -> Path:
    root = Path(root)
    twin = root / "twin"
    legmap = yaml.safe_load(write_urdf_robot(A3, twin).read_text())
    pkg = root / "src" / PACKAGE
    for sub in ("urdf", "meshes", "config"):
        (pkg / sub).mkdir(parents=True, exist_ok=True)
    (pkg / "package.xml").write_text(f'<?xml version="1.0"?>\n<package format="3"><name>{PACKAGE}</name>'
                                     "<version>0.1.0</version></package>\n")
    tree = ET.parse(twin / legmap["urdf"])
    for link in tree.getroot().iter("link"):
        for col in link.findall("collision"):
            box = col.find("geometry/box")
            mesh = f"meshes/{link.get('name')}.stl"
            box_stl(pkg / mesh, [float(x) for x in box.get("size").split()])
            geometry = col.find("geometry")
            geometry.remove(box)
            ET.SubElement(geometry, "mesh", filename=f"package://{PACKAGE}/{mesh}")
            visual = ET.SubElement(link, "visual")  # a COLLADA mesh MuJoCo cannot read: never opened
            ET.SubElement(ET.SubElement(visual, "geometry"), "mesh", filename=f"package://{PACKAGE}/meshes/foot.dae")
    tree.write(pkg / "urdf" / "a3.urdf")
    legmap["urdf"] = "../urdf/a3.urdf"
    (pkg / "config" / "a3.legmap.yaml").write_text(yaml.safe_dump(legmap, sort_keys=False))
    return pkg / "config" / "a3.legmap.yaml"


def framed(root: Path, same_robot: bool = False) -> Path:
    """`same_robot`: frames that only carry their bodies' offsets (the robot unchanged,
    as a model grouped by frames has it); else turned frames (another robot)."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    model = ET.parse(ASSETS / "a3.xml").getroot()

    def wrap(parent, child, **attrs):
        i = list(parent).index(child)
        parent.remove(child)
        frame = ET.Element("frame", **attrs)
        frame.append(child)
        parent.insert(i, frame)
        return frame

    pelvis = model.find(".//body[@name='pelvis']")
    yaw = model.find(".//body[@name='left_hip_yaw_link']")
    foot = model.find(".//body[@name='right_foot_link']")
    if same_robot:
        for parent, kind, name in ((pelvis, "body", "left_hip_pitch_link"), (yaw, "body", "left_knee_link"),
                                   (foot, "site", "right_sole"), (pelvis, "site", "imu")):
            el = parent.find(f"{kind}[@name='{name}']")
            wrap(parent, el, pos=el.get("pos"))
            el.set("pos", "0 0 0")
    else:
        wrap(pelvis, pelvis.find("body[@name='left_hip_pitch_link']"), pos="0.004 -0.003 0.005", euler="2 -3 4")
        wrap(yaw, yaw.find("body[@name='left_knee_link']"), quat="0.999 0.02 -0.03 0.01")
        wrap(foot, foot.find("site[@name='right_sole']"), pos="0.001 0 -0.002", euler="0 1 0")
        wrap(pelvis, pelvis.find("site[@name='imu']"), euler="0 0 3")
    xml = root / "a3_framed.xml"
    ET.ElementTree(model).write(xml)
    d = yaml.safe_load((ASSETS / "a3.legmap.yaml").read_text())
    d["mjcf"] = xml.name
    (root / "a3_framed.legmap.yaml").write_text(yaml.safe_dump(d))
    return root / "a3_framed.legmap.yaml"


def roll_first(root: Path) -> Path:
    return write_robot(ROLL_FIRST_ANKLE, Path(root))


def imu_twins(pelvis: Path, site: str, waist) -> dict[str, Path]:
    """A robot's leg map (IMU on the pelvis) and its torso-IMU twins written beside it:
    {"pelvis": it, "torso": the IMU on `site` declared through `waist`, "undeclared": on
    `site`, no `through`}."""
    pelvis = Path(pelvis)
    doc = yaml.safe_load(pelvis.read_text())
    stem = pelvis.name.removesuffix(".legmap.yaml")
    out = {"pelvis": pelvis}
    for twin, imu in (("torso", {"site": site, "through": list(waist)}), ("undeclared", {"site": site})):
        out[twin] = pelvis.parent / f"{stem}_{twin}.legmap.yaml"
        out[twin].write_text(yaml.safe_dump(dict(doc, name=f"{doc['name']}_{twin}_imu", imu=imu), sort_keys=False))
    return out


def torso_imu_twins(root: Path) -> dict[str, Path]:
    """The A3-like robot with a 3-joint waist: its `imu_twins`."""
    return imu_twins(write_robot(DESIGNS["a3"], Path(root), upper_body=True, waist=3), TORSO_SITE, WAIST)


def torso_imu(root: Path) -> Path:
    """The A3-like robot's IMU in the torso, declared through its waist."""
    return torso_imu_twins(root)["torso"]


ROTOR = ('<body name="left_hip_yaw_rotor" pos="0 0 -0.05"><joint name="left_hip_yaw_drive" axis="0 0 1" '
         'range="-2 2"/><inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/></body>\n')


def a3_with_transmissions(root: Path, coupled: bool = False, ratio: dict | None = None) -> Path:
    """The A3-like robot; `coupled`: its left hip yaw turned by a drive joint on a rotor
    body at 1:2 (the actuator on the drive, kp 200 there = the original 800 at the joint;
    the joint equality hip_yaw = 0.5 drive); `ratio`: the leg map's ratio per joint."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    xml = (ASSETS / "a3.xml").read_text()
    if coupled:
        anchor = '<body name="left_hip_yaw_link" pos="0 0 -0.075">'
        actuator = 'joint="left_hip_yaw_joint" kp="800" kv="32"'
        if anchor not in xml or actuator not in xml:
            raise RuntimeError("the A3-like asset changed: update legcal_bench.robots.samples.a3_with_transmissions")
        xml = xml.replace(anchor, ROTOR + anchor, 1)
        xml = xml.replace(actuator, 'joint="left_hip_yaw_drive" kp="200" kv="8"')
        xml = xml.replace("</actuator>", "</actuator>\n  <equality><joint joint1=\"left_hip_yaw_joint\" "
                          "joint2=\"left_hip_yaw_drive\" polycoef=\"0 0.5 0 0 0\"/></equality>", 1)
    (root / "a3.xml").write_text(xml)
    d = yaml.safe_load((ASSETS / "a3.legmap.yaml").read_text())
    d["name"] = "a3_transmission"
    for side in ("left", "right"):
        for j in d["legs"][side]["joints"]:
            if j["name"] in (ratio or {}):
                j["ratio"] = ratio[j["name"]]
    (root / "a3.legmap.yaml").write_text(yaml.safe_dump(d))
    return root / "a3.legmap.yaml"


def drive_joint(root: Path) -> Path:
    return a3_with_transmissions(root, coupled=True)


def fixed_ratio(root: Path) -> Path:
    return a3_with_transmissions(root, ratio={"left_knee_joint": 2.0, "right_ankle_pitch_joint": -1.5})


def framed_grouped(root: Path) -> Path:
    """`framed` with frames that carry their bodies' offsets: the A3-like robot, grouped."""
    return framed(root, same_robot=True)


SAMPLES = {"ros_package": ros_package, "framed": framed_grouped, "roll_first": roll_first, "torso_imu": torso_imu,
           "drive_joint": drive_joint, "fixed_ratio": fixed_ratio}
