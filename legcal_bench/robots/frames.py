"""MJCF `<frame>` elements folded away for Pinocchio, by MuJoCo's own compiler.

A `<frame>` moves the bodies, sites, geoms and joints inside it without being a body
itself; Pinocchio's MJCF parser does not know it. MuJoCo compiles the file, and each
element that sat inside a frame is given its compiled pose relative to its parent body
(`body_pos`/`body_quat`, `site_pos`/`site_quat`, `geom_pos`/`geom_quat`, `jnt_pos`/
`jnt_axis`, full precision), the frame's `childclass` as its class where it names none,
and is lifted out of the frame. Everything else keeps its text, so the file Pinocchio
reads is the model MuJoCo simulates. The compiled elements are matched in document
order: bodies over the whole tree (MuJoCo numbers them depth first, frames transparent),
sites, geoms and joints within their body.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from legcal_bench.errors import LegMapError

FRAME = re.compile(r"<frame[\s/>]")  # the element, not <framepos> and the other frame sensors

KINDS = ("site", "geom", "joint")
ORIENTATION = ("quat", "euler", "axisangle", "xyaxes", "zaxis")


def _num(v) -> str:
    return " ".join(repr(float(x) + 0.0) for x in np.atleast_1d(v))


def _own(body: ET.Element, kind: str) -> list[ET.Element]:
    """`body`'s elements of `kind` in document order, through frames, not into child bodies."""
    out = []
    for child in body:
        if child.tag == kind or (kind == "joint" and child.tag == "freejoint"):
            out.append(child)
        elif child.tag == "frame":
            out.extend(_own(child, kind))
    return out


def _bodies(parent: ET.Element) -> list[ET.Element]:
    """The bodies under `parent` in depth-first document order, through frames."""
    out = []
    for child in parent:
        if child.tag == "body":
            out.append(child)
            out.extend(_bodies(child))
        elif child.tag == "frame":
            out.extend(_bodies(child))
    return out


def fold_frames(text: str, model) -> str:
    """`text` (an MJCF whose includes are already folded) without its `<frame>`s, each
    element inside one posed as `model` (MuJoCo's compilation of `text`) has it."""
    root = ET.fromstring(text)
    world = root.find("worldbody")
    if world is None or not any(True for _ in world.iter("frame")):
        return text
    bodies = [world] + _bodies(world)
    if len(bodies) != model.nbody:
        raise ValueError(f"{len(bodies)} bodies in the text, {model.nbody} compiled")
    inside = {id(e) for f in world.iter("frame") for e in f.iter() if e is not f}
    for b_id, body in enumerate(bodies):
        if id(body) in inside:
            _pose(body, model.body_pos[b_id], model.body_quat[b_id])
        for kind, adr, num, pos, rot in (
                ("site", None, None, model.site_pos, model.site_quat),
                ("geom", model.body_geomadr, model.body_geomnum, model.geom_pos, model.geom_quat),
                ("joint", model.body_jntadr, model.body_jntnum, model.jnt_pos, None)):
            own = _own(body, kind)
            ids = (np.flatnonzero(model.site_bodyid == b_id) if adr is None
                   else np.arange(adr[b_id], adr[b_id] + num[b_id]) if num[b_id] > 0 else np.zeros(0, int))
            if len(ids) != len(own):
                raise ValueError(f"body {body.get('name')}: {len(own)} {kind}s in the text, {len(ids)} compiled")
            for el, i in zip(own, ids):
                if id(el) not in inside:
                    continue
                if kind == "joint":
                    el.set("pos", _num(pos[i]))
                    el.set("axis", _num(model.jnt_axis[i]))
                else:
                    if kind == "geom" and el.get("fromto") is not None:  # its size came from the segment
                        el.set("size", _num(model.geom_size[i][:2]))
                    _pose(el, pos[i], rot[i])
    _lift(world)
    return ET.tostring(root, encoding="unicode")


def has_frames(text: str) -> bool:
    return FRAME.search(text) is not None


def mjcf_element(path):
    """dm_control's `mjcf` element of the MJCF at `path` (what the simulator builds its
    scene from), its frames folded (`fold_frames`); dm_control does not know `<frame>`."""
    from dm_control import mjcf

    path = Path(path)
    text = path.read_text()
    if not has_frames(text):
        return mjcf.from_path(str(path))
    import mujoco

    if "<include" in text:
        raise LegMapError(f"{path} has both <include> and <frame> elements; fold the includes into one file "
                          "and name that file")
    try:
        folded = fold_frames(text, mujoco.MjModel.from_xml_path(str(path)))
    except ValueError as e:  # MuJoCo's compile error, or elements the folding could not match
        raise LegMapError(f"{path}: its <frame> elements could not be folded: {e}") from None
    return mjcf.from_xml_string(folded, model_dir=str(path.parent))


def _pose(el: ET.Element, pos, quat) -> None:
    for a in ORIENTATION + ("pos", "fromto"):
        el.attrib.pop(a, None)
    el.set("pos", _num(pos))
    el.set("quat", _num(quat))


def _lift(parent: ET.Element) -> None:
    """Replace every `<frame>` under `parent` by its children (their class the frame's
    childclass where they name none), recursively."""
    i = 0
    while i < len(parent):
        child = parent[i]
        if child.tag == "frame":
            _lift(child)
            cls = child.get("childclass")
            parent.remove(child)
            for k, grand in enumerate(list(child)):
                if cls is not None and grand.get("class") is None and grand.get("childclass") is None:
                    grand.set("childclass" if grand.tag in ("body", "frame") else "class", cls)
                parent.insert(i + k, grand)
            i += len(child)
        else:
            _lift(child)
            i += 1
