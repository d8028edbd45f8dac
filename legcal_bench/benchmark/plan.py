"""The plan: which session sets to collect and which cells to calibrate and score.

A plan is robots x modes x seeds x offset scales x calibrator variants. For each
(robot, mode, seed, scale) two session sets are collected with the same placements,
motions and noise: `native` (the robot's own factory residual, by default drawn
uniformly in +-1.2 deg per joint, 0.69 deg RMS, the scale of the paper's real robots'
0.57-0.81 deg; nothing injected) and `injected` (native + the paper's injection x
scale). The native spec is a collection override like the others (`native`:
`random:<deg>`, `paper-base`, `none`). Calibrators come from the registry (entry-point group); each runs
once per variant of its `benchmark_variants()` (name -> options; by default one, "default").

Each cell has a resume key: a hash of the calibrator's settings, the two session sets'
collection configs (what their manifests record) and `RESULTS_VERSION`. A finished cell
file is kept only if its key matches (see `runner.is_done`).
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from legcal_bench import inputs
from legcal_bench.benchmark.suites import SUITES, Suite, get_suite
from legcal_bench.calibrators.registry import available_calibrators, get_calibrator
from legcal_bench.errors import ConfigError, CalibrationError
from legcal_bench.protocol.collect import CollectConfig
from legcal_bench.provenance import RESULTS_VERSION, stable_hash
from legcal_bench.robots import available, load_robot, resolve_robot, robot_label
from legcal_bench.sim.offsets import paper_injection, resolve_offsets
from legcal_bench.sim.scene import MODES

NATIVE = "random:1.2"  # factory residual: offsets drawn uniformly in +-1.2 deg (was +-0.3 before issue #11)
NATIVE_SEED_BASE = 10_000  # the native offsets of seed s come from default_rng(NATIVE_SEED_BASE + s)


class MissingRobotWarning(UserWarning):
    """A suite's robot is skipped because its model is not on this machine."""


@dataclass(frozen=True)
class Dataset:
    robot: str
    mode: str
    seed: int
    scale: float
    injection: str  # native | injected
    collect: tuple = ()  # CollectConfig overrides, as sorted items

    @property
    def name(self) -> str:
        return (f"{robot_label(self.robot)}_{self.mode}_s{self.seed:02d}_x{self.scale:g}_{self.injection}"
                + ("_" + "_".join(f"{k}{_short(v)}" for k, v in self.collect) if self.collect else ""))

    def legmap(self):
        return load_robot(self.robot, dict(self.collect).get("mjcf"))

    def offsets(self) -> np.ndarray:
        """The true offsets of this session set: native, plus scale x the paper's injection."""
        legmap = self.legmap()
        native = dict(self.collect).get("native", NATIVE)
        dq = resolve_offsets(native, legmap, np.random.default_rng(NATIVE_SEED_BASE + self.seed))
        if self.injection == "injected":
            dq = dq + self.scale * paper_injection(legmap)
        return dq

    def config(self) -> CollectConfig:
        overrides = {k: v for k, v in self.collect if k != "native"}
        return CollectConfig(robot=resolve_robot(self.robot), mode=self.mode, seed=self.seed,
                             offsets=tuple(float(v) for v in self.offsets()), **overrides)


def _short(value) -> str:
    """A collection override's value in a folder name: numbers as %g, stances joined by
    "-", an MJCF by its file name without the suffix, other words without colons."""
    if isinstance(value, (tuple, list)):
        return "-".join(str(v) for v in value)
    if isinstance(value, str):
        return Path(value).stem if "/" in value or value.endswith(".xml") else value.replace(":", "")
    return f"{value:g}"


@dataclass(frozen=True)
class Cell:
    suite: str
    robot: str
    mode: str
    seed: int
    scale: float
    calibrator: str
    variant: str
    options: tuple = ()
    collect: tuple = ()

    def dataset(self, injection: str) -> Dataset:
        return Dataset(self.robot, self.mode, self.seed, self.scale, injection, self.collect)

    def legmap(self):
        return self.dataset("native").legmap()

    def path(self, results: Path) -> Path:
        scale = "" if self.scale == 1.0 else f"_x{self.scale:g}"
        return (results / self.suite / robot_label(self.robot) / self.mode / f"{self.calibrator}-{self.variant}"
                / f"seed{self.seed:02d}{scale}.json")

    def key(self) -> str:
        return _cell_key(self)


@lru_cache(maxsize=4096)
def _cell_key(cell: Cell) -> str:
    settings = get_calibrator(cell.calibrator, **dict(cell.options)).settings()
    data = {inj: _config_dict(cell.dataset(inj)) for inj in ("native", "injected")}
    return stable_hash({"results_version": RESULTS_VERSION, "calibrator": cell.calibrator, "variant": cell.variant,
                        "settings": settings, "data": data})


def _config_dict(ds: Dataset) -> dict:
    d = asdict(ds.config())
    # Where the robot and its model live on this machine is not part of the data.
    d["robot"] = robot_label(ds.robot)
    if d.get("mjcf"):
        d["mjcf"] = Path(d["mjcf"]).name
    if d.get("protocol"):  # the protocol's content, not where it lies
        d["protocol"] = stable_hash(Path(d["protocol"]).read_text())
    return d


def calibrator_variants(names: list[str] | None = None) -> list[tuple[str, str, dict]]:
    found = available_calibrators()
    if names:
        unknown = [n for n in names if n not in found]
        if unknown:
            raise CalibrationError(f"unknown calibrators {unknown}; registered: {sorted(found)}")
        found = {n: found[n] for n in names}
    out = []
    for name in sorted(found):
        for variant, options in found[name].benchmark_variants().items():
            out.append((name, variant, options))
    return out


def plan(suite: str, robots=None, modes=None, seeds=None, scales=(1.0,), calibrators=None,
         collect_overrides: dict | None = None) -> list[Cell]:
    """Cells of a suite (or of an ad-hoc plan named `suite`, e.g. "sweep"), with any of
    its robots, modes, seeds or collection overrides replaced."""
    if suite in SUITES:
        s = SUITES[suite]
        if "closed_loop" in s.tags:
            raise ConfigError(f"suite {suite!r} walks, it has no static cells: run it with legcal-bench bench "
                              f"--suite {suite} (legcal_bench.benchmark.closed_loop)")
        if "modelgap" in s.tags:
            raise ConfigError(f"suite {suite!r} diagnoses session sets, it has no calibrator cells: run it with "
                              f"legcal-bench bench --suite {suite} (legcal_bench.benchmark.modelgap)")
    elif robots is not None and modes is not None and seeds is not None:
        s = Suite(suite, (), (), 1)  # an ad-hoc plan, e.g. a sweep
    else:
        s = get_suite(suite)  # raises: names the known suites
    if seeds is not None:
        inputs.count("seeds", seeds, fix="seeds per robot and mode")
    for mode in modes or ():
        inputs.choice("modes", mode, MODES)
    for scale in scales:
        inputs.positive("scales", scale, fix="multiples of the paper's injection")
    overrides = {k: v for k, v in (collect_overrides or {}).items() if v is not None}
    if overrides.get("mjcf") is not None:
        overrides["mjcf"] = str(Path(overrides["mjcf"]).resolve())
    if "stances" in overrides:
        overrides["stances"] = tuple(overrides["stances"])
    col = tuple(sorted({**s.collect, **overrides}.items()))
    variants = calibrator_variants(calibrators)
    if not variants:
        raise ConfigError("no calibrator to run: none is registered (entry-point group legcal_bench.calibrators)")
    cells, skipped = [], []
    for robot in robots or s.robots:
        missing = available(robot)
        if missing is not None:
            warnings.warn(f"skipping robot {robot}: {missing}", MissingRobotWarning, stacklevel=2)
            skipped.append(f"{robot}: {missing}")
            continue
        for mode in modes or s.modes:
            for seed in range(seeds if seeds is not None else s.seeds):
                for scale in scales:
                    for name, variant, options in variants:
                        cells.append(Cell(suite, robot, mode, seed, float(scale), name, variant,
                                          tuple(sorted(options.items())), col))
    if not cells:
        raise ConfigError(f"suite {suite!r}: no cells to run: " + ("every robot was skipped (" + "; ".join(skipped)
                          + ")" if skipped else "no robots, modes, seeds or scales") + "; give robots whose models "
                          "are on this machine (--robots)")
    return cells
