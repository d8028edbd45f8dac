"""The benchmark runner: collect, calibrate and score every cell of a plan.

A plan is robots x modes x seeds x offset scales x calibrator variants. For each
(robot, mode, seed, scale) two session sets are collected with the same placements,
motions and noise: `native` (the robot's own factory residual, drawn at random, a few
tenths of a degree; nothing injected) and `injected` (native + the paper's injection x
scale). Each calibrator variant calibrates both, and the cell records:
  recovery      on `injected`, against the true total offsets (native + injection)
  paired Delta  estimate(injected) - estimate(native) - injection (the paper's metric)
  held-out      on `native` (the paper's non-injection validation): foot-height and
                sole-normal RMS before/after, from the logged sensors and on the true
                postures
  conditioning and solve time.
Calibrators come from the registry (entry-point group); a class may offer
`benchmark_variants()` (name -> options), else it runs once as "default".

Work goes through a `concurrent.futures.Executor`: local processes by default, or a
Dask cluster's executor when a scheduler address is given (the same code). Finished
cells are not recomputed (resumable); every result is written atomically, one JSON
per cell.
"""

from __future__ import annotations

import json
import os
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from multiprocessing import get_context
from pathlib import Path

import numpy as np
from tqdm import tqdm

REPO = Path(__file__).resolve().parents[1]
NATIVE_DEG = 0.3  # factory residual: offsets drawn uniformly in +-0.3 deg
HIST_EDGES_MM = np.linspace(-4.0, 4.0, 81)  # held-out foot-height bins; outliers land in the end bins


@dataclass(frozen=True)
class Suite:
    robots: tuple[str, ...]
    modes: tuple[str, ...]
    seeds: int
    collect: dict = field(default_factory=dict)


SUITES = {
    "smoke": Suite(("a2", "a3"), ("weld",), 1,
                   dict(stance_s=6.0, heldout_s=4.0, standing_s=2.0, heldout=2)),
    "standard": Suite(("a2", "a3", "pair_ryp", "pair_pry"), ("weld",), 10),
    "full": Suite(("a2", "a3", "pair_ryp", "pair_pry", "examples/unitree_g1.legmap.yaml"),
                  ("kinematic", "weld", "contact"), 10),
}


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
                + ("_" + "_".join(f"{k}{v:g}" for k, v in self.collect) if self.collect else ""))


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

    def path(self, results: Path) -> Path:
        scale = "" if self.scale == 1.0 else f"_x{self.scale:g}"
        return (results / self.suite / robot_label(self.robot) / self.mode / f"{self.calibrator}-{self.variant}"
                / f"seed{self.seed:02d}{scale}.json")


def robot_label(robot: str) -> str:
    return Path(robot).name.replace(".legmap.yaml", "") if robot.endswith((".yaml", ".yml")) else robot


def _resolve_robot(robot: str) -> str:
    p = REPO / robot
    return str(p) if robot.endswith((".yaml", ".yml")) and not Path(robot).is_absolute() and p.is_file() else robot


def calibrator_variants(names: list[str] | None = None) -> list[tuple[str, str, dict]]:
    from legcal_bench.calibration import available_calibrators

    found = available_calibrators()
    if names:
        unknown = [n for n in names if n not in found]
        if unknown:
            raise ValueError(f"unknown calibrators {unknown}; registered: {sorted(found)}")
        found = {n: found[n] for n in names}
    out = []
    for name in sorted(found):
        variants = getattr(found[name], "benchmark_variants", None)
        for variant, options in (variants() if variants else {"default": {}}).items():
            out.append((name, variant, options))
    return out


def plan(suite: str, robots=None, modes=None, seeds=None, scales=(1.0,), calibrators=None,
         collect_overrides: dict | None = None) -> list[Cell]:
    s = SUITES[suite] if suite in SUITES else Suite((), (), 1)
    col = tuple(sorted({**s.collect, **(collect_overrides or {})}.items()))
    cells = []
    for robot in robots or s.robots:
        for mode in modes or s.modes:
            for seed in range(seeds if seeds is not None else s.seeds):
                for scale in scales:
                    for name, variant, options in calibrator_variants(calibrators):
                        cells.append(Cell(suite, robot, mode, seed, float(scale), name, variant,
                                          tuple(sorted(options.items())), col))
    return cells


# ------------------------------------------------------------------ worker tasks
def _single_thread() -> None:
    for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(k, "1")


def collect_dataset(ds: Dataset, data_dir: str) -> str:
    """Collect one session set (idempotent); returns its directory."""
    _single_thread()
    from legcal_bench.collect import CollectConfig, collect
    from legcal_bench.offsets import PAPER_INJECTION, resolve_offsets
    from legcal_bench.recording import MANIFEST
    from legcal_bench.robots import load_robot

    out = Path(data_dir) / ds.name
    if (out / MANIFEST).is_file():
        return str(out)
    robot = _resolve_robot(ds.robot)
    legmap = load_robot(robot)
    native = resolve_offsets(f"random:{NATIVE_DEG}", legmap, np.random.default_rng(10_000 + ds.seed))
    dq = native.copy()
    if ds.injection == "injected":
        dq += ds.scale * np.array([PAPER_INJECTION[r] for r in legmap.joint_roles])
    cfg = CollectConfig(robot=robot, mode=ds.mode, seed=ds.seed, offsets=",".join(f"{v:.17g}" for v in dq),
                        **dict(ds.collect))
    collect(cfg, out, progress=False)
    return str(out)


def run_cell(cell: Cell, data_dir: str, results_dir: str) -> dict:
    """Calibrate both session sets of a cell, score, write the cell's JSON."""
    _single_thread()
    from legcal_bench.calibration import CalibrationError
    from legcal_bench.io_utils import atomic_write_json
    from legcal_bench.robots import load_robot

    robot = _resolve_robot(cell.robot)
    legmap = load_robot(robot)
    names = legmap.joint_names
    out: dict = {"cell": asdict(cell), "robot": legmap.name, "joint_names": names}
    try:
        _calibrate_and_score(cell, legmap, data_dir, out)
    except CalibrationError as e:
        # A method that cannot calibrate this data is a result too, not a crash.
        out["error"] = str(e)
    atomic_write_json(cell.path(Path(results_dir)), out)
    return out


def _calibrate_and_score(cell: Cell, legmap, data_dir: str, out: dict) -> None:
    from legcal_bench.calibration import get_calibrator
    from legcal_bench.offsets import PAPER_INJECTION
    from legcal_bench.recording import list_segments, load_session, load_truth
    from legcal_bench.scoring import score

    names = legmap.joint_names
    est = {}
    for inj in ("native", "injected"):
        bags = Path(data_dir) / cell.dataset(inj).name
        recs = load_session(bags, names)
        res = get_calibrator(cell.calibrator, **dict(cell.options)).calibrate(legmap, recs)
        est[inj] = res.offsets_vector(names)
        s = score(str(bags), res, legmap)
        residuals = s.get("heldout", {}).pop("foot_height_residuals_mm", None)
        out[inj] = {"score": s, "timing_s": res.timing_s, "warnings": res.warnings,
                    "conditioning": {k: v for k, v in res.conditioning.items()
                                     if k.startswith("kappa") or k.startswith("eigenvalues")},
                    "offsets_rad": res.offsets_rad}
        if inj == "native" and residuals:
            # Held-out foot heights as counts on fixed bins (for the pooled histograms).
            out[inj]["heldout_foot_height_hist"] = {
                "edges_mm": [float(HIST_EDGES_MM[0]), float(HIST_EDGES_MM[-1]), len(HIST_EDGES_MM) - 1],
                **{k: np.histogram(np.clip(v, HIST_EDGES_MM[0], HIST_EDGES_MM[-1]), HIST_EDGES_MM)[0].tolist()
                   for k, v in residuals.items()}}
        out[inj]["truth_offsets_rad"] = load_truth(list_segments(bags)[0]).offsets.tolist()
    injection = cell.scale * np.array([PAPER_INJECTION[r] for r in legmap.joint_roles])
    delta = est["injected"] - est["native"] - injection
    out["paired_delta_deg"] = {n: float(np.rad2deg(v)) for n, v in zip(names, delta)}
    out["paired_delta_rms_deg"] = float(np.rad2deg(np.sqrt(np.mean(delta**2))))


# ------------------------------------------------------------------ driver
def make_executor(scheduler: str | None, workers: int) -> tuple[Executor, object | None]:
    """(executor, Dask client to close afterwards, or None)."""
    if scheduler:
        from distributed import Client

        client = Client(scheduler)
        return client.get_executor(), client
    return ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")), None


def _done(path: Path) -> bool:
    try:
        json.loads(path.read_text())
        return True
    except (OSError, ValueError):
        return False


def run(cells: list[Cell], data_dir: str | Path, results_dir: str | Path, executor: Executor | None = None,
        workers: int = 2, scheduler: str | None = None, progress: bool = True) -> dict:
    """Run every unfinished cell; returns counts."""
    data_dir, results_dir = str(Path(data_dir).resolve()), str(Path(results_dir).resolve())
    todo = [c for c in cells if not _done(c.path(Path(results_dir)))]
    own = executor is None
    ex, client = make_executor(scheduler, workers) if own else (executor, None)
    try:
        datasets = sorted({c.dataset(i) for c in todo for i in ("native", "injected")}, key=lambda d: d.name)
        futs = [ex.submit(collect_dataset, d, data_dir) for d in datasets]
        for f in tqdm(as_completed(futs), total=len(futs), desc="collect", unit="set", disable=not progress):
            f.result()
        futs = [ex.submit(run_cell, c, data_dir, results_dir) for c in todo]
        for f in tqdm(as_completed(futs), total=len(futs), desc="calibrate+score", unit="cell", disable=not progress):
            f.result()
    finally:
        if own:
            ex.shutdown()
        if client is not None:
            client.close()
    return {"cells": len(cells), "computed": len(todo), "skipped": len(cells) - len(todo)}
