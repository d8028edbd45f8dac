"""Applying a calibration on the robot: the offsets in the robot's own joint names, and
a copy of its MJCF with the correction folded in.

Convention (the paper's): the corrected angle is q = q_enc + dq. A robot applies dq by
adding it to every encoder reading before its kinematics and controllers see them.

Folding into a model: an MJCF hinge or slide joint's `ref` is the joint value at which
the body sits as written, so the model's kinematics at joint value v are those of the
written pose at v - ref. Setting ref' = ref - dq gives kinematics at the raw encoder
reading v = q_enc equal to the original model's at q_enc + dq: a model that takes the
uncorrected encoder readings and computes the calibrated kinematics. `ref` is written in
the model's own angle unit (`<compiler angle>`, degrees unless it says radian); the
effective value before the change is read from the compiled model, so a `ref` set by a
default class is honoured too.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import yaml

from legcal_bench.errors import ConfigError, LegMapError
from legcal_bench.files.atomic import atomic_write_dir, atomic_write_text
from legcal_bench.robots.legmap import LegMap

FORMAT = "legcal-offsets/1"


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
    model = mjcf.from_path(str(legmap.mjcf))
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
