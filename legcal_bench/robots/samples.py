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
                   ankle pitch (the leg map's `ratio`);
  linkage_ankle    both ankles turned by two motors on the shank through cranks and rods
                   (`LINKAGE`, the leg map's `linkage`); `closed_chain` adds the linkage's
                   bodies and loops to the model (MuJoCo equality constraints), which the
                   serial model and the calibration do not have.
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


# The linkage ankle on the A3-like shank: two motors 0.29 m above the ankle, 0.06 m cranks
# pointing back, rods straight down to the foot 0.05 m behind the ankle and 0.03 m to
# either side (at the ankle's zero, the encoders read zero).
LINKAGE = {"crank": 0.06, "behind": 0.05, "half_width": 0.03, "motor_height": 0.08, "foot_height": 0.02}


def linkage_ankle(root: Path) -> Path:
    import mujoco

    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    (root / "a3.xml").write_text((ASSETS / "a3.xml").read_text())
    model = mujoco.MjModel.from_xml_path(str(root / "a3.xml"))
    d = yaml.safe_load((ASSETS / "a3.legmap.yaml").read_text())
    d["name"] = "a3_linkage"
    g = LINKAGE
    for side in ("left", "right"):
        ankle, foot = (model.body(f"{side}_ankle_pitch_link"), model.body(f"{side}_foot_link"))
        if np.any(model.body_quat[[ankle.id, foot.id]] != [1, 0, 0, 0]):
            raise RuntimeError("the A3-like asset changed: update legcal_bench.robots.samples.linkage_ankle")
        o = model.body_pos[ankle.id] + model.body_pos[foot.id]  # the foot frame's origin in the shank's
        motors = []
        for sign in (1.0, -1.0):
            at_foot = np.array([-g["behind"], sign * g["half_width"], g["foot_height"]])
            x0 = o + at_foot
            pivot = np.array([x0[0] + g["crank"], x0[1], -g["motor_height"]])
            motors.append({"pivot": [round(float(x), 6) for x in pivot], "axis": [0.0, 1.0, 0.0],
                           "crank": [-g["crank"], 0.0, 0.0], "rod": round(float(pivot[2] - x0[2]), 6),
                           "foot": [float(x) for x in at_foot]})
        d["legs"][side]["linkage"] = {"motors": motors}
    (root / "a3.legmap.yaml").write_text(yaml.safe_dump(d, sort_keys=False))
    return root / "a3.legmap.yaml"


def closed_chain(legmap_path: Path, motor_angles: dict[str, tuple[float, float]]):
    """The robot's MuJoCo model with each linkage built in: per motor a crank body on a
    hinge at the pivot (locked at `motor_angles[side][i]` by a joint equality), a rod body on
    a ball joint at the crank's tip, its end joined to the foot's attachment by a `connect`
    equality (both points given by sites); gravity off, the ankle's own actuators removed,
    the pelvis welded to the world. Returns (model, {side: the ankle's two joint names})."""
    import mujoco

    from legcal_bench.robots import load_robot

    lm = load_robot(str(legmap_path))
    spec = mujoco.MjSpec.from_file(str(lm.mjcf))
    spec.option.gravity = [0.0, 0.0, 0.0]
    ankles = {}
    for side in ("left", "right"):
        leg = lm.legs[side]
        if leg.linkage is None:
            continue
        names = [j.name for j in leg.joints[-2:]]
        ankles[side] = names
        for a in list(spec.actuators):
            if a.target in names:
                spec.delete(a)
        first, second = spec.joint(names[0]).parent, spec.joint(names[1]).parent
        shank = first.parent
        for i, mo in enumerate(leg.linkage):
            crank = shank.add_body(name=f"{side}_crank{i}", pos=list(mo.pivot), mass=0.01,
                                   inertia=[1e-6, 1e-6, 1e-6])
            crank.add_joint(name=f"{side}_crank{i}_joint", type=mujoco.mjtJoint.mjJNT_HINGE, axis=list(mo.axis),
                            damping=0.05)
            rod_dir = np.asarray(mo.pivot) + np.asarray(mo.crank)  # the crank's tip (shank frame)
            rod = crank.add_body(name=f"{side}_rod{i}", pos=list(mo.crank), mass=0.01, inertia=[1e-6, 1e-6, 1e-6])
            rod.add_joint(name=f"{side}_rod{i}_ball", type=mujoco.mjtJoint.mjJNT_BALL, damping=0.05)
            # The rod's end at q = 0: the attachment's place in the shank frame, from the tip.
            T = _body_offset(spec, shank, second)
            end = T[:3, :3] @ np.asarray(mo.foot) + T[:3, 3] - rod_dir
            end *= mo.rod / np.linalg.norm(end)  # the rod's length along that line
            rod.add_site(name=f"{side}_rod{i}_end", pos=list(end))
            second.add_site(name=f"{side}_foot{i}", pos=list(mo.foot))
            eq = spec.add_equality(type=mujoco.mjtEq.mjEQ_CONNECT, objtype=mujoco.mjtObj.mjOBJ_SITE,
                                   name1=f"{side}_rod{i}_end", name2=f"{side}_foot{i}")
            eq.solref = [0.005, 1.0]
            lock = spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1=f"{side}_crank{i}_joint")
            lock.data[0] = motor_angles[side][i]
            lock.solref = [0.005, 1.0]
    pelvis = spec.body(lm.pelvis)
    for j in list(pelvis.joints):
        spec.delete(j)
    return spec.compile(), ankles


def _body_offset(spec, ancestor, body) -> np.ndarray:
    """`body`'s pose in `ancestor`'s frame at the model's zero (4 x 4), from their positions
    and orientations in the spec (quaternions w x y z)."""
    T = np.eye(4)
    b = body
    while b.name != ancestor.name:
        R = np.empty(9)
        import mujoco

        mujoco.mju_quat2Mat(R, np.asarray(b.quat, dtype=float))
        A = np.eye(4)
        A[:3, :3], A[:3, 3] = R.reshape(3, 3), b.pos
        T = A @ T
        b = b.parent
    return T


def framed_grouped(root: Path) -> Path:
    """`framed` with frames that carry their bodies' offsets: the A3-like robot, grouped."""
    return framed(root, same_robot=True)


SAMPLES = {"ros_package": ros_package, "framed": framed_grouped, "roll_first": roll_first, "torso_imu": torso_imu,
           "drive_joint": drive_joint, "fixed_ratio": fixed_ratio, "linkage_ankle": linkage_ankle}
