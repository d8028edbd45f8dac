"""Applying a calibration on the robot: the offsets in the robot's own joint names (as
legcal-bench YAML and as a ROS 2 parameter file), and a copy of its MJCF or URDF with the
correction folded in.

Convention (the paper's): the corrected angle is q = q_enc + dq. A robot applies dq by
adding it to every encoder reading before its kinematics and controllers see them.

Write-back formats:

- `write_offsets_yaml` (`export --out`): format `legcal-offsets/1`, the offsets in
  radians and degrees keyed by joint name, with the robot, the convention and the source.
- `write_ros2_params` (`export --ros2-params`): a standard ROS 2 parameter file
  (`<node>: {ros__parameters: {...}}`, loadable with `--ros-args --params-file`), the
  node's parameters being `robot` (string), `units` ("rad"), `convention`
  ("q = q_enc + offset"), `joint_names` (string array, leg-map order) and `offsets`
  (double array, the same order, radians), plus `source` (the result file) when known.
  Parallel arrays rather than one parameter per joint: a node reads them with two plain
  `declare_parameter` calls (the `joints:` list of ros2_control controllers is the same
  idea) without knowing the joint names in advance or allowing undeclared parameters,
  and a joint name with a dot in it (a dot makes a nested parameter name) is harmless.
  The file is replaced if it exists (written atomically), like `--out`.
- `fold_into_mjcf` (`export --mjcf-out`): an MJCF copy with each leg joint's `ref` moved.
- `fold_into_urdf` (`export --urdf-out`): a URDF copy with each leg joint's `<origin>`
  moved; the copy is checked with Pinocchio before it is written (`check_urdf_fold`).

Folding into a model: an MJCF hinge or slide joint's `ref` is the joint value at which
the body sits as written, so the model's kinematics at joint value v are those of the
written pose at v - ref. Setting ref' = ref - dq gives kinematics at the raw encoder
reading v = q_enc equal to the original model's at q_enc + dq: a model that takes the
uncorrected encoder readings and computes the calibrated kinematics. `ref` is written in
the model's own angle unit (`<compiler angle>`, degrees unless it says radian); the
effective value before the change is read from the compiled model, so a `ref` set by a
default class is honoured too.

A URDF joint has no `ref`: its child frame is origin(xyz, R(rpy)) * motion(a, q). For a
revolute or continuous joint with unit axis a, origin(xyz, R) * Rot(a, q_enc + dq) =
origin(xyz, R @ Rot(a, dq)) * Rot(a, q_enc), so the copy's origin keeps xyz and gets the
rotation R @ Rot(a, dq), written back as rpy with full float precision (a conversion
that stays exact at the gimbal lock, pitch = +-pi/2, and is verified). For a prismatic
joint, xyz' = xyz + R @ a * dq (= xyz + a * dq when the origin has no rotation). Every
angle the URDF states in joint coordinates moves by -dq so that it keeps naming the same
physical angle: `<limit lower upper>` (absent values are URDF's default 0, and are
written; a continuous joint's limit is ignored by URDF and left alone),
`<safety_controller soft_lower_limit soft_upper_limit>` and `<calibration rising
falling>` (the attributes present). A `<mimic>` of a leg joint gets offset' = offset +
multiplier * dq. Everything else is copied as parsed (xml.etree, comments kept); relative
mesh and texture `filename`s are rewritten relative to the copy's folder, so the copy
may be written anywhere and still finds the original's meshes (`package://` and
absolute paths are kept as they are). Before anything is written, Pinocchio builds both
URDFs and the copy's frames (every link and joint frame) at random encoder readings
within its limits must match the original's at q_enc + dq to 1e-12; a copy that fails
is never written.
"""

from __future__ import annotations

import io
import math
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import yaml

from legcal_bench.errors import ConfigError, LegMapError
from legcal_bench.files.atomic import atomic_write_dir, atomic_write_text
from legcal_bench.robots.frames import mjcf_element
from legcal_bench.robots.legmap import LegMap
from legcal_bench.robots.urdf import urdf_text

FORMAT = "legcal-offsets/1"
CONVENTION = "q = q_enc + offset"
# A ROS 2 node name for a parameter file: a name, a namespaced name or a wildcard.
ROS2_NODE = re.compile(r"^(/?\*\*|/?(\*\*/)?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*)$")
FK_TOL = 1e-12  # max |T_copy(q_enc) - T_original(q_enc + dq)| over frames and entries (m, unitless)
FK_CONFIGS = 8  # random encoder readings the URDF check tries (fixed seed)


def offsets_document(legmap: LegMap, offsets_rad: dict[str, float], source: str = "") -> dict:
    """The offsets as a YAML-able mapping in the robot's joint names."""
    missing = [n for n in legmap.joint_names if n not in offsets_rad]
    if missing:
        raise ConfigError(f"offsets: no value for leg joints {missing} of robot {legmap.name}")
    return {
        "format": FORMAT,
        "robot": legmap.name,
        "convention": "q = q_enc + offset: add each offset to that joint's encoder reading",
        "source": source,
        "offsets_rad": {n: float(offsets_rad[n]) for n in legmap.joint_names},
        "offsets_deg": {n: float(np.rad2deg(offsets_rad[n])) for n in legmap.joint_names},
    }


def write_offsets_yaml(path: str | Path, legmap: LegMap, offsets_rad: dict[str, float], source: str = "") -> Path:
    doc = offsets_document(legmap, offsets_rad, source)
    header = ("# Joint-offset calibration for the robot's leg joints (legcal-bench export).\n"
              "# Apply as q = q_enc + offset, per joint, before kinematics and control.\n")
    return atomic_write_text(path, header + yaml.safe_dump(doc, sort_keys=False))


def fold_into_mjcf(legmap: LegMap, offsets_rad: dict[str, float], out_dir: str | Path) -> Path:
    """A copy of the robot's MJCF (with its assets) in `out_dir`, each leg joint's `ref`
    lowered by its offset; returns the new MJCF's path. `out_dir` must not exist yet: the
    copy is written beside it and renamed into place whole."""
    from dm_control import mjcf

    out_dir = Path(out_dir)
    if out_dir.exists():
        raise ConfigError(f"--mjcf-out {out_dir} exists: give a new folder (the corrected model is written whole)")
    offsets_document(legmap, offsets_rad)  # checks every leg joint has a value
    compiled = mujoco.MjModel.from_xml_path(str(legmap.mjcf))
    model = mjcf_element(legmap.mjcf)
    degrees = (model.compiler.angle or "degree") == "degree"
    for name in legmap.joint_names:
        joint = model.find("joint", name)
        jid = mujoco.mj_name2id(compiled, mujoco.mjtObj.mjOBJ_JOINT, name)
        if joint is None or jid < 0:
            raise LegMapError(f"{legmap.source}: leg joint '{name}' is not in {legmap.mjcf}")
        jtype = int(compiled.jnt_type[jid])
        if jtype not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
            raise LegMapError(f"{legmap.source}: leg joint '{name}' is not a hinge or slide joint")
        ref = float(compiled.qpos0[compiled.jnt_qposadr[jid]]) - float(offsets_rad[name])
        angular = jtype == int(mujoco.mjtJoint.mjJNT_HINGE)
        joint.ref = float(np.rad2deg(ref)) if (angular and degrees) else ref
    atomic_write_dir(out_dir, lambda tmp: mjcf.export_with_assets(model, str(tmp),
                                                                  out_file_name=Path(legmap.mjcf).name))
    return out_dir / Path(legmap.mjcf).name


def _finite_offsets(legmap: LegMap, offsets_rad: dict[str, float]) -> dict[str, float]:
    """The leg joints' offsets as floats, in leg-map order; every one present and finite."""
    offsets_document(legmap, offsets_rad)  # checks every leg joint has a value
    out = {}
    for n in legmap.joint_names:
        v = offsets_rad[n]
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not np.isfinite(v):
            raise ConfigError(f"offsets: {n} must be a finite number of radians, got {v!r}")
        out[n] = float(v)
    return out


def write_ros2_params(path: str | Path, legmap: LegMap, offsets_rad: dict[str, float], node: str = "joint_offsets",
                      source: str = "") -> Path:
    """The offsets as a ROS 2 parameter file for node `node` (see the module docstring
    for the layout); replaces `path` atomically."""
    if not isinstance(node, str) or not ROS2_NODE.match(node):
        raise ConfigError(f"ROS 2 node name {node!r}: give a node name such as joint_offsets, a namespaced "
                          "/ns/joint_offsets, or /** for every node")
    offsets = _finite_offsets(legmap, offsets_rad)
    params: dict = {
        "robot": legmap.name,
        "units": "rad",
        "convention": CONVENTION,
        "joint_names": list(offsets),
        "offsets": list(offsets.values()),
    }
    if source:
        params["source"] = str(source)
    header = (f"# Joint-offset calibration of {legmap.name}'s leg joints for ROS 2 (legcal-bench export).\n"
              f"# Convention: {CONVENTION}, per joint, in radians: add offsets[i] to the encoder reading of\n"
              "# joint_names[i] before kinematics and control.\n"
              "# Load with: ros2 run <pkg> <exe> --ros-args --params-file <this file>; read with\n"
              "# declare_parameter(\"joint_names\", string array) and declare_parameter(\"offsets\", double array).\n")
    body = yaml.safe_dump({node: {"ros__parameters": params}}, sort_keys=False, default_flow_style=False)
    return atomic_write_text(path, header + body)


def _floats(text: str | None, default: tuple[float, ...], where: str) -> np.ndarray:
    if text is None:
        return np.array(default, dtype=float)
    try:
        v = np.array([float(x) for x in text.split()], dtype=float)
    except ValueError:
        v = np.array([])
    if v.size != len(default) or not np.all(np.isfinite(v)):
        raise LegMapError(f"{where}: expected {len(default)} finite numbers, got {text!r}")
    return v


def _rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """URDF's rpy: R = Rz(yaw) @ Ry(pitch) @ Rx(roll)."""
    (cr, cp, cy), (sr, sp, sy) = np.cos(rpy), np.sin(rpy)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _matrix_rpy(R: np.ndarray) -> np.ndarray:
    """rpy with R = Rz(y) Ry(p) Rx(r), exact also at the gimbal lock: yaw from the first
    column (any value will do where that column is ~(0, 0, +-1)), then roll and pitch from
    Rz(y)^T R, so whatever yaw is chosen the three angles rebuild R."""
    y = math.atan2(R[1, 0], R[0, 0])
    M = np.array([[math.cos(y), math.sin(y), 0.0], [-math.sin(y), math.cos(y), 0.0], [0.0, 0.0, 1.0]]) @ R
    r = math.atan2(-M[1, 2], M[1, 1])
    p = math.atan2(-M[2, 0], M[0, 0])
    return np.array([r, p, y]) + 0.0  # no -0.0


def _axis_rotation(a: np.ndarray, angle: float) -> np.ndarray:
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def _text(v) -> str:
    return " ".join(repr(float(x) + 0.0) for x in v)


def _parse_urdf(text: str, where: str) -> ET.Element:
    try:
        for _, (prefix, uri) in ET.iterparse(io.StringIO(text), events=("start-ns",)):
            try:
                ET.register_namespace(prefix, uri)  # keep e.g. xacro: as it is written
            except ValueError:  # a prefix etree reserves (ns0, ...): written as etree names it
                pass
        parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True, insert_pis=True))
        root = ET.fromstring(text, parser=parser)
    except ET.ParseError as e:
        raise LegMapError(f"{where}: field 'urdf': not valid XML ({e})") from None
    if root.tag != "robot":
        raise LegMapError(f"{where}: field 'urdf': the root element is <{root.tag}>, not <robot>")
    return root


def _shift(el: ET.Element | None, attrs: tuple[str, ...], dq: float, defaults: bool, where: str) -> None:
    """Move the joint-coordinate values `attrs` of `el` by -dq (absent ones are URDF's
    default 0, written only when `defaults`)."""
    if el is None:
        return
    for a in attrs:
        if el.get(a) is not None or defaults:
            v = _floats(el.get(a, "0"), (0.0,), f"{where}: <{el.tag} {a}>")[0]
            el.set(a, repr(float(v - dq) + 0.0))


def _folded_urdf_text(legmap: LegMap, offsets: dict[str, float], out_dir: Path) -> str:
    """The URDF copy's text (see the module docstring); `out_dir` is where it will live."""
    src = Path(legmap.urdf)
    where = str(legmap.source or src)
    root = _parse_urdf(urdf_text(src, where), where)
    joints = {j.get("name"): j for j in root.findall("joint")}
    for name, dq in offsets.items():
        j = joints.get(name)
        if j is None:
            raise LegMapError(f"{where}: leg joint '{name}' is not a <joint> of {src}")
        jw = f"{src}: joint '{name}'"
        kind = j.get("type")
        if kind not in ("revolute", "continuous", "prismatic"):
            raise LegMapError(f"{jw}: type {kind!r}; a leg joint must be revolute, continuous or prismatic")
        axis_el = j.find("axis")
        a = _floats(None if axis_el is None else axis_el.get("xyz"), (1.0, 0.0, 0.0), f"{jw}: <axis xyz>")
        if np.linalg.norm(a) < 1e-12:
            raise LegMapError(f"{jw}: <axis xyz> is zero; give the joint's axis")
        a = a / np.linalg.norm(a)
        origin = j.find("origin")
        if origin is None:
            origin = ET.SubElement(j, "origin")
            origin.set("xyz", "0 0 0")
        xyz = _floats(origin.get("xyz"), (0.0, 0.0, 0.0), f"{jw}: <origin xyz>")
        rpy = _floats(origin.get("rpy"), (0.0, 0.0, 0.0), f"{jw}: <origin rpy>")
        R = _rpy_matrix(rpy)
        if kind == "prismatic":
            origin.set("xyz", _text(xyz + R @ a * dq))
        else:
            R_new = R @ _axis_rotation(a, dq)
            rpy_new = _matrix_rpy(R_new)
            err = np.abs(_rpy_matrix(rpy_new) - R_new).max()
            if err > 1e-14:  # the conversion is exact by construction; this guards it
                raise LegMapError(f"{jw}: could not write the folded origin as rpy (error {err:.1e})")
            origin.set("rpy", _text(rpy_new))
        if kind != "continuous":
            _shift(j.find("limit"), ("lower", "upper"), dq, True, jw)
        _shift(j.find("safety_controller"), ("soft_lower_limit", "soft_upper_limit"), dq, False, jw)
        _shift(j.find("calibration"), ("rising", "falling"), dq, False, jw)
    for j in root.findall("joint"):  # a joint mimicking a leg joint follows the calibrated angle
        mimic = j.find("mimic")
        if mimic is not None and mimic.get("joint") in offsets:
            m = _floats(mimic.get("multiplier", "1"), (1.0,), f"{src}: joint '{j.get('name')}' <mimic multiplier>")[0]
            o = _floats(mimic.get("offset", "0"), (0.0,), f"{src}: joint '{j.get('name')}' <mimic offset>")[0]
            mimic.set("offset", repr(float(o + m * offsets[mimic.get("joint")]) + 0.0))
    for el in root.iter():
        f = el.get("filename") if el.tag in ("mesh", "texture") else None
        if f and "://" not in f and not os.path.isabs(f):
            el.set("filename", os.path.relpath(src.parent.resolve() / f, out_dir.resolve()))
    note = (f"<!-- Made by legcal-bench export from {src.resolve()}: each leg joint's <origin> folds its calibration "
            f"offset in ({CONVENTION}), limits moved by -offset, so this model fed the raw encoder readings has "
            "the calibrated kinematics. -->\n")
    return '<?xml version="1.0"?>\n' + note + ET.tostring(root, encoding="unicode") + "\n"


def _pin_models(original: str, folded: str):
    """Pinocchio models of both URDFs (fixed root), mimic joints following their joint
    where Pinocchio can model them (so a folded <mimic> offset is checked too)."""
    import pinocchio as pin

    try:
        return pin.buildModelFromXML(original, True), pin.buildModelFromXML(folded, True)
    except Exception:  # noqa: BLE001 - a mimic Pinocchio cannot model: mimic joints as free joints
        pass
    models = []
    for text, what in ((original, "the original URDF"), (folded, "the folded URDF")):
        try:
            models.append(pin.buildModelFromXML(text))
        except Exception as e:  # noqa: BLE001 - Pinocchio raises bare RuntimeErrors
            raise LegMapError(f"Pinocchio could not load {what}: {e}") from None
    return tuple(models)


def _urdf_fk_error(original: str, folded: str, offsets: dict[str, float], configs: int = FK_CONFIGS,
                   seed: int = 0) -> float:
    """max over `configs` random encoder readings (within the folded URDF's limits, fixed
    seed), every frame and every entry of |T_folded(q_enc) - T_original(q_enc + dq)|."""
    import pinocchio as pin

    m_old, m_new = _pin_models(original, folded)
    if [f.name for f in m_old.frames] != [f.name for f in m_new.frames] or m_old.nq != m_new.nq:
        raise LegMapError("the folded URDF does not have the original's joints and links")
    d_old, d_new = m_old.createData(), m_new.createData()
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(configs):
        q_enc, q_cal = pin.neutral(m_new), pin.neutral(m_old)
        for jid in range(1, m_new.njoints):
            jn, jo = m_new.joints[jid], m_old.joints[m_old.getJointId(m_new.names[jid])]
            dq = offsets.get(m_new.names[jid], 0.0)
            if jn.nq == 1 and jn.nv == 1:  # revolute, prismatic
                lo, hi = m_new.lowerPositionLimit[jn.idx_q], m_new.upperPositionLimit[jn.idx_q]
                if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi and hi - lo < 1e3):
                    lo, hi = -math.pi, math.pi
                v = rng.uniform(lo, hi)
                q_enc[jn.idx_q], q_cal[jo.idx_q] = v, v + dq
            elif jn.nq == 2 and jn.nv == 1:  # continuous: (cos, sin)
                v = rng.uniform(-math.pi, math.pi)
                q_enc[jn.idx_q:jn.idx_q + 2] = math.cos(v), math.sin(v)
                q_cal[jo.idx_q:jo.idx_q + 2] = math.cos(v + dq), math.sin(v + dq)
        pin.framesForwardKinematics(m_new, d_new, q_enc)
        pin.framesForwardKinematics(m_old, d_old, q_cal)
        for T_new, T_old in zip(d_new.oMf, d_old.oMf):
            worst = max(worst, float(np.abs(T_new.homogeneous - T_old.homogeneous).max()))
    return worst


def check_urdf_fold(legmap: LegMap, offsets_rad: dict[str, float], folded_urdf: str | Path) -> float:
    """The largest difference (any frame, any entry of its 4x4 pose; metres or unitless)
    between the folded URDF at random encoder readings q_enc and the robot's URDF at
    q_enc + offsets (Pinocchio, fixed seed); 0 up to rounding when the fold is right."""
    if legmap.urdf is None:
        raise LegMapError(f"{legmap.source}: robot {legmap.name} is described by an MJCF, not a URDF")
    return _urdf_fk_error(urdf_text(legmap.urdf, str(legmap.source or legmap.urdf)), Path(folded_urdf).read_text(),
                          _finite_offsets(legmap, offsets_rad))


def fold_into_urdf(legmap: LegMap, offsets_rad: dict[str, float], out_path: str | Path) -> Path:
    """A copy of the robot's URDF at `out_path` with each leg joint's origin folding its
    offset in and its limits moved by -offset (module docstring); returns `out_path`.
    The copy is checked with Pinocchio against the original before it is written
    (`check_urdf_fold`, tolerance FK_TOL); a copy that fails the check raises and is not
    written. `out_path` must not exist."""
    out_path = Path(out_path)
    if legmap.urdf is None:
        raise LegMapError(f"{legmap.source}: robot {legmap.name} is described by an MJCF ({legmap.mjcf}), not a "
                          "URDF (field 'urdf' of its leg map): fold the offsets into its MJCF (--mjcf-out) instead")
    if out_path.exists():
        raise ConfigError(f"--urdf-out {out_path} exists: give a new file name (an existing file is not replaced)")
    offsets = _finite_offsets(legmap, offsets_rad)
    text = _folded_urdf_text(legmap, offsets, out_path.parent)
    err = _urdf_fk_error(urdf_text(legmap.urdf, str(legmap.source or legmap.urdf)), text, offsets)
    if not err <= FK_TOL:
        raise LegMapError(f"the URDF with the offsets folded in does not reproduce the calibrated kinematics "
                          f"(largest frame difference {err:.3g} > {FK_TOL:g}); nothing written to {out_path}")
    return atomic_write_text(out_path, text)
