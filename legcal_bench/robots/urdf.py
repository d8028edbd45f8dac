"""Robots described by a URDF: Pinocchio reads the URDF itself; MuJoCo compiles it into
the MJCF the simulator loads, made here once per URDF text and kept in a cache folder.

A leg map names the URDF (`urdf: robot.urdf` instead of `mjcf:`); the floating base is
the leg map's pelvis (the URDF's root link), and the IMU, soles and F/T sensors are
poses relative to links (`{body: <link>, pos, rpy}`: a URDF has no sites). MuJoCo's
URDF import keeps every link as a body (`fusestatic` off, so a link on a fixed joint can
carry a frame), drops visual geometry and reads meshes relative to the URDF's folder.
URDF transmissions mean nothing to MuJoCo: each 1-DoF joint gets a torque motor (its
effort limit as the force range), driven by the leg map's `servo_gains` or the
documented default gains (docs/leg-map.md, Servo gains).
"""

from __future__ import annotations

import hashlib
import os
import xml.etree.ElementTree as ET
from pathlib import Path

from legcal_bench.errors import LegMapError

CONVERSION = "1"  # bump when the conversion below changes: cached MJCFs are remade
COMPILER = {"fusestatic": "false", "discardvisual": "true", "strippath": "false", "balanceinertia": "true"}


def cache_dir() -> Path:
    """Where converted URDFs are kept: $LEGCAL_CACHE, else $XDG_CACHE_HOME/legcal-bench,
    else ~/.cache/legcal-bench; a folder per URDF text."""
    root = os.environ.get("LEGCAL_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "legcal-bench")
    return Path(root) / "urdf"


def mjcf_of_urdf(urdf: Path, where: str) -> Path:
    """The MJCF MuJoCo compiles `urdf` into (with a motor per 1-DoF joint), made once
    per URDF text and folder and kept in `cache_dir()`."""
    urdf = Path(urdf).resolve()
    try:
        text = urdf.read_text()
    except OSError as e:
        raise LegMapError(f"{where}: field 'urdf': cannot read {urdf} ({e})") from None
    key = hashlib.sha256(f"{CONVERSION}\0{urdf.parent}\0{text}".encode()).hexdigest()[:16]
    out = cache_dir() / key / f"{urdf.stem}.xml"
    if not out.is_file():
        from legcal_bench.files.atomic import atomic_write_text

        atomic_write_text(out, _convert(text, urdf, where))
    return out


def _convert(text: str, urdf: Path, where: str) -> str:
    import mujoco

    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise LegMapError(f"{where}: field 'urdf': {urdf} is not valid XML ({e})") from None
    if root.tag != "robot":
        raise LegMapError(f"{where}: field 'urdf': {urdf} is not a URDF (its root element is <{root.tag}>, "
                          "not <robot>); an MJCF goes in field 'mjcf'")
    ext = root.find("mujoco")
    if ext is None:
        ext = ET.SubElement(root, "mujoco")
    compiler = ext.find("compiler")
    if compiler is None:
        compiler = ET.SubElement(ext, "compiler")
    compiler.attrib.update(COMPILER)
    compiler.set("meshdir", str(urdf.parent))
    try:
        model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    except ValueError as e:
        raise LegMapError(f"{where}: field 'urdf': MuJoCo could not compile {urdf}: {e}") from None
    from legcal_bench.files.scratch import scratch_dir

    with scratch_dir("urdf") as tmp:
        saved = Path(tmp) / "robot.xml"
        mujoco.mj_saveLastXML(str(saved), model)
        mj = ET.parse(saved).getroot()
    actuators = mj.find("actuator")
    if actuators is None:
        actuators = ET.SubElement(mj, "actuator")
    # A body's joints only: MuJoCo writes a URDF <mimic> as an <equality><joint/> (no name).
    for joint in (j for body in mj.iter("body") for j in body.findall("joint")):
        if joint.get("type", "hinge") in ("hinge", "slide"):
            motor = ET.SubElement(actuators, "motor", name=f"legcal_motor_{joint.get('name')}", joint=joint.get("name"))
            if joint.get("actuatorfrcrange") is not None:
                motor.set("forcelimited", "true")
                motor.set("forcerange", joint.get("actuatorfrcrange"))
    ET.indent(mj, space="  ")
    header = (f"<!-- Made by legcal_bench.robots.urdf (conversion {CONVERSION}) from {urdf}; MuJoCo compiled the "
              "URDF, a torque motor per 1-DoF joint added. Remade when the URDF changes. -->\n")
    return header + ET.tostring(mj, encoding="unicode") + "\n"
