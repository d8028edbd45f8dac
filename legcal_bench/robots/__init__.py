"""Robot registry: built-in robots by name (with tags), example robots shipped with
the package, and any robot by the path of its leg map.

A robot reference ("spec") is a built-in name (`a3`), a leg-map path, or
`examples/<file>.legmap.yaml` (found in the working directory first, then among the
installed examples: `legcal_bench.files.packaged`, the rule for every file a user names). `resolve_robot` turns a spec into a reference that works from any
folder (the name, or an absolute path); `robot_label` gives its short name.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from legcal_bench.errors import LegMapError, MissingModelError
from legcal_bench.files.packaged import packaged
from legcal_bench.robots.legmap import LegMap, load_legmap

ASSETS = Path(__file__).parent / "assets"
LEGMAP_SUFFIXES = (".legmap.yaml", ".yaml", ".yml")


@dataclass(frozen=True)
class RobotEntry:
    name: str
    description: str
    tags: tuple[str, ...]

    @property
    def legmap_path(self) -> Path:
        return ASSETS / f"{self.name}.legmap.yaml"


BUILTIN: dict[str, RobotEntry] = {
    e.name: e
    for e in (
        RobotEntry("a2", "A2-like humanoid legs, hip roll->yaw->pitch", ("builtin", "ryp")),
        RobotEntry("a3", "A3-like humanoid legs, hip pitch->roll->yaw", ("builtin", "pry")),
        RobotEntry("pair_ryp", "matched pair, roll->yaw->pitch (identical to pair_pry but the hip order)",
                   ("builtin", "matched_pair", "ryp")),
        RobotEntry("pair_pry", "matched pair, pitch->roll->yaw (identical to pair_ryp but the hip order)",
                   ("builtin", "matched_pair", "pry")),
    )
}


def robot_label(spec: str | Path) -> str:
    """Short name of a robot reference: the built-in name, or the leg-map file name
    without its suffix."""
    s = str(spec)
    if s in BUILTIN:
        return s
    name = Path(s).name
    for suffix in LEGMAP_SUFFIXES:
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return name


def resolve_robot(spec: str | Path) -> str:
    """A reference to the same robot that works from any folder: the built-in name, or
    the absolute path of its leg map."""
    s = str(spec)
    if s in BUILTIN:
        return s
    p = packaged(s)  # a path from the working directory, else an installed example
    if p.is_file():
        return str(p.resolve())
    if s.endswith(LEGMAP_SUFFIXES):
        raise LegMapError(f"leg map {p.resolve()} does not exist")
    raise LegMapError(f"unknown robot {s!r}: use a built-in name ({', '.join(BUILTIN)}) "
                      "or the path of a leg-map YAML (see docs/leg-map.md)")


def load_robot(spec: str | Path, mjcf: str | Path | None = None) -> LegMap:
    """A built-in robot by name, or any robot by the path of its leg-map YAML.

    `mjcf` overrides the leg map's MJCF path (same joints, another model file).
    """
    ref = resolve_robot(spec)
    legmap = load_legmap(BUILTIN[ref].legmap_path if ref in BUILTIN else ref)
    if mjcf is not None:
        path = Path(mjcf).resolve()
        if not path.is_file():
            raise MissingModelError(f"--mjcf {path} does not exist")
        legmap = replace(legmap, mjcf=path, urdf=None)  # that MJCF is the model, for Pinocchio too
    return legmap


def available(spec: str | Path) -> str | None:
    """None if the robot loads, else why not (e.g. its MJCF is missing): suites use it
    to skip, with that message, a robot whose model is not on this machine."""
    try:
        load_robot(spec)
    except MissingModelError as e:
        return str(e)
    return None
