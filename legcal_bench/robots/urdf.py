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

Files a URDF names by URI (`package://<name>/<path>`, `file://<path>`) are found as
ROS finds them (`find_package`): the leg map's `packages: {name: folder}` first, then
the folders on `ROS_PACKAGE_PATH`, `share/<name>` under each `AMENT_PREFIX_PATH` prefix,
a folder of that name above the URDF (a URDF kept inside its package), and last the
installed Python package of that name (a robot-description package from PyPI). A URI
none of them resolves is refused, naming the package and these ways. A `.xacro` file is
expanded by the `xacro` package when it is installed (refused, with the fix, when not).
Visual geometry is dropped before MuJoCo compiles the URDF (it discards it anyway, and
cannot read a COLLADA visual mesh).
"""

from __future__ import annotations

import hashlib
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from legcal_bench.errors import LegMapError

CONVERSION = "2"  # bump when the conversion below changes: cached MJCFs are remade
COMPILER = {"fusestatic": "false", "discardvisual": "true", "strippath": "false", "balanceinertia": "true"}


def cache_dir() -> Path:
    """Where converted URDFs are kept: $LEGCAL_CACHE, else $XDG_CACHE_HOME/legcal-bench,
    else ~/.cache/legcal-bench; a folder per URDF text."""
    root = os.environ.get("LEGCAL_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "legcal-bench")
    return Path(root) / "urdf"


PACKAGE_PATHS = ("ROS_PACKAGE_PATH", "AMENT_PREFIX_PATH")  # the environment's package folders, as ROS 1 / 2 set them
URI = re.compile(r"^(package|file)://(.*)$")


def _package_name(folder: Path) -> str | None:
    """The <name> a ROS package.xml in `folder` declares (None: no package.xml)."""
    try:
        root = ET.parse(folder / "package.xml").getroot()
    except (OSError, ET.ParseError):
        return None
    el = root.find("name")
    return el.text.strip() if el is not None and el.text else None


def find_package(name: str, urdf: Path, packages: dict[str, Path] | None = None) -> Path | None:
    """The folder of package `name` (see the module docstring for the order), or None."""
    if packages and name in packages:
        return Path(packages[name])
    for d in filter(None, os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)):
        d = Path(d)
        if (d / name).is_dir():
            return d / name
        if d.name == name or _package_name(d) == name:
            return d
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        if (Path(prefix) / "share" / name).is_dir():
            return Path(prefix) / "share" / name
    for d in Path(urdf).resolve().parents:
        if d.name == name or _package_name(d) == name:
            return d
        if (d / name / "package.xml").is_file():
            return d / name
    import importlib.util

    try:
        spec = importlib.util.find_spec(name) if name.isidentifier() else None
    except (ImportError, ValueError):
        spec = None
    if spec is not None and spec.submodule_search_locations:
        return Path(list(spec.submodule_search_locations)[0])
    return None


def resolve_uri(uri: str, urdf: Path, packages: dict[str, Path] | None, where: str) -> str:
    """`uri` (a `filename` of the URDF) as a path MuJoCo can open: `package://` and
    `file://` resolved, anything else as written."""
    m = URI.match(uri)
    if m is None:
        return uri
    if m.group(1) == "file":
        return m.group(2)
    name, _, rest = m.group(2).partition("/")
    folder = find_package(name, urdf, packages)
    if folder is None:
        raise LegMapError(
            f"{where}: field 'urdf': {urdf} names the file {uri} in ROS package '{name}', which was not found: give "
            f"its folder in the leg map (packages: {{{name}: <folder>}}, relative to the leg map), put it on "
            "ROS_PACKAGE_PATH or AMENT_PREFIX_PATH (source the workspace's setup), keep the URDF inside that "
            f"package's folder, or install the Python package '{name}' (docs/leg-map.md, URDF packages)")
    path = folder / rest
    if not path.is_file():
        raise LegMapError(f"{where}: field 'urdf': {urdf} names {uri}; package '{name}' is {folder}, which has no "
                          f"file {rest}: is it the right package (packages: in the leg map names another)?")
    return str(path)


def urdf_text(urdf: Path, where: str) -> str:
    """The URDF's text: the file as written, or a `.xacro` expanded by the `xacro` package."""
    urdf = Path(urdf)
    if urdf.suffix != ".xacro":
        try:
            return urdf.read_text()
        except OSError as e:
            raise LegMapError(f"{where}: field 'urdf': cannot read {urdf} ({e})") from None
    try:
        import xacro
    except ImportError:
        raise LegMapError(f"{where}: field 'urdf': {urdf} is a xacro file and the xacro package is not installed: "
                          f"install it (pip install xacro) or expand it yourself (xacro {urdf.name} > "
                          f"{urdf.stem}) and name that URDF") from None
    try:
        return xacro.process_file(str(urdf)).toprettyxml(indent="  ")
    except Exception as e:  # noqa: BLE001 - xacro raises its own XacroException and others
        raise LegMapError(f"{where}: field 'urdf': xacro could not expand {urdf}: {e}") from None


def mjcf_of_urdf(urdf: Path, where: str, packages: dict[str, Path] | None = None) -> Path:
    """The MJCF MuJoCo compiles `urdf` into (with a motor per 1-DoF joint), made once
    per URDF text, folder and resolved files, and kept in `cache_dir()`."""
    urdf = Path(urdf).resolve()
    text = _resolved(urdf_text(urdf, where), urdf, packages, where)
    key = hashlib.sha256(f"{CONVERSION}\0{urdf.parent}\0{text}".encode()).hexdigest()[:16]
    out = cache_dir() / key / f"{urdf.name.split('.')[0]}.xml"
    if not out.is_file():
        from legcal_bench.files.atomic import atomic_write_text

        atomic_write_text(out, _convert(text, urdf, where))
    return out


def _resolved(text: str, urdf: Path, packages: dict[str, Path] | None, where: str) -> str:
    """`text` without its visual geometry, every collision mesh's URI resolved."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise LegMapError(f"{where}: field 'urdf': {urdf} is not valid XML ({e})") from None
    for link in root.iter("link"):
        for visual in link.findall("visual"):
            link.remove(visual)
    for el in root.iter("mesh"):
        if el.get("filename"):
            el.set("filename", resolve_uri(el.get("filename"), urdf, packages, where))
    return ET.tostring(root, encoding="unicode")


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
        dae = sorted({el.get("filename") for el in root.iter("mesh") if str(el.get("filename")).lower().endswith(".dae")})
        hint = (f"; MuJoCo reads STL, OBJ and MSH meshes, not COLLADA: convert the collision meshes {', '.join(dae[:3])}"
                + (" …" if len(dae) > 3 else "") if dae else "")
        raise LegMapError(f"{where}: field 'urdf': MuJoCo could not compile {urdf}: {e}{hint}") from None
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
