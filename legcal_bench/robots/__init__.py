"""Robot registry: built-in robots by name (with tags), any robot by leg-map path."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from legcal_bench.robots.legmap import LegMap, LegMapError, load_legmap

ASSETS = Path(__file__).parent / "assets"


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


def load_robot(spec: str | Path, mjcf: str | Path | None = None) -> LegMap:
    """A built-in robot by name, or any robot by the path of its leg-map YAML.

    `mjcf` overrides the leg map's MJCF path (same joints, another model file).
    """
    spec_s = str(spec)
    if spec_s in BUILTIN:
        legmap = load_legmap(BUILTIN[spec_s].legmap_path)
    elif spec_s.endswith((".yaml", ".yml")) or Path(spec_s).is_file():
        legmap = load_legmap(spec_s)
    else:
        raise LegMapError(
            f"unknown robot {spec_s!r}: use a built-in name ({', '.join(BUILTIN)}) "
            "or the path of a leg-map YAML (see docs/leg-map.md)")
    if mjcf is not None:
        from dataclasses import replace

        path = Path(mjcf).resolve()
        if not path.is_file():
            raise LegMapError(f"--mjcf {path} does not exist")
        legmap = replace(legmap, mjcf=path)
    return legmap
