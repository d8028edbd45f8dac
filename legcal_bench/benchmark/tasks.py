"""The work a benchmark process does: collect a session set, or calibrate and score a
cell. Both are top-level functions of picklable arguments, so local processes and Dask
workers run them alike; both are idempotent and write atomically."""

from __future__ import annotations

import json
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from legcal_bench.benchmark.plan import Cell, Dataset
from legcal_bench.calibrators.base import calibrate_training
from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import list_segments, load_session, load_truth
from legcal_bench.errors import LegcalError
from legcal_bench.estimation.verdict import DO_NOT_APPLY
from legcal_bench.evaluation.metrics import rms
from legcal_bench.evaluation.scoring import score
from legcal_bench.files.atomic import atomic_write_json
from legcal_bench.files.parallel import single_thread
from legcal_bench.protocol.collect import collect, is_collected
from legcal_bench.provenance import code_version
from legcal_bench.sim.offsets import paper_injection

HIST_EDGES_MM = np.linspace(-4.0, 4.0, 81)  # held-out foot-height bins; outliers land in the end bins


def is_current(out: Path, ds: Dataset) -> bool:
    """True if `out` holds a whole session set collected with `ds`'s config under the
    current `RESULTS_VERSION` (a set from other offsets, sensors or code is stale)."""
    return is_collected(out, ds.config())


def collect_dataset(ds: Dataset, data_dir: str) -> str:
    """Collect one session set (kept if its manifest records the same config and
    results version; a stale one is replaced); returns its directory. A set that cannot
    be collected (the robot does not hold a posture, a stance does not fit) leaves
    `<name>.failed.json` with the reason instead, which the set's cells record as their
    error; it is tried again on the next run."""
    single_thread()
    out = Path(data_dir) / ds.name
    failed = failure_path(data_dir, ds)
    if not is_current(out, ds):
        try:
            collect(ds.config(), out, progress=False)
        except LegcalError as e:
            atomic_write_json(failed, {"dataset": ds.name, "error": f"{type(e).__name__}: {e}"})
            return str(out)
    failed.unlink(missing_ok=True)
    return str(out)


def failure_path(data_dir: str | Path, ds: Dataset) -> Path:
    return Path(data_dir) / f"{ds.name}.failed.json"


def run_cell(cell: Cell, data_dir: str, results_dir: str, provenance: dict | None = None) -> dict:
    """Calibrate both session sets of a cell, score, write the cell's JSON (with its
    resume key and the code version that made it: `provenance`, read by the runner when
    the run starts, else now)."""
    single_thread()
    legmap = cell.legmap()
    out: dict = {"cell": asdict(cell), "robot": legmap.name, "joint_names": legmap.joint_names,
                 "key": cell.key(), "provenance": provenance or code_version()}
    # A session set that could not be collected, or a method that cannot calibrate the
    # data, is a result too (a failed cell with its reason), not a crash.
    failed = [failure_path(data_dir, cell.dataset(inj)) for inj in ("native", "injected")]
    failed = [f"collecting {p.name[:-len('.failed.json')]}: {json.loads(p.read_text())['error']}"
              for p in failed if p.is_file()]
    if failed:
        out["error"] = "; ".join(failed)
    else:
        try:
            _calibrate_and_score(cell, legmap, data_dir, out)
        except LegcalError as e:
            out["error"] = str(e)
    atomic_write_json(cell.path(Path(results_dir)), out)
    return out


def _calibrate_and_score(cell: Cell, legmap, data_dir: str, out: dict) -> None:
    names = legmap.joint_names
    est = {}
    for inj in ("native", "injected"):
        bags = Path(data_dir) / cell.dataset(inj).name
        recs = load_session(bags, robot=legmap)
        res = calibrate_training(get_calibrator(cell.calibrator, **dict(cell.options)), legmap, recs)
        # A do-not-apply verdict is a failed calibration: scored as no correction (its
        # estimate kept beside), counted as such by the leaderboard.
        rejected = res.decision == DO_NOT_APPLY
        applied = replace(res, offsets_rad=dict.fromkeys(names, 0.0)) if rejected else res
        est[inj] = applied.offsets_vector(names)
        s = score(str(bags), applied, legmap)
        residuals = s.get("heldout", {}).pop("foot_height_residuals_mm", None)
        out[inj] = {"score": s, "timing_s": res.timing_s, "warnings": res.warnings, "verdict": res.decision,
                    **({"rejected_offsets_rad": res.offsets_rad} if rejected else {}),
                    "conditioning": {k: v for k, v in res.conditioning.items()
                                     if k.startswith("kappa") or k.startswith("eigenvalues")},
                    "offsets_rad": applied.offsets_rad}
        if inj == "native" and residuals:
            # Held-out foot heights as counts on fixed bins (for the pooled histograms).
            out[inj]["heldout_foot_height_hist"] = {
                "edges_mm": [float(HIST_EDGES_MM[0]), float(HIST_EDGES_MM[-1]), len(HIST_EDGES_MM) - 1],
                **{k: np.histogram(np.clip(v, HIST_EDGES_MM[0], HIST_EDGES_MM[-1]), HIST_EDGES_MM)[0].tolist()
                   for k, v in residuals.items()}}
        out[inj]["truth_offsets_rad"] = load_truth(list_segments(bags)[0]).offsets.tolist()
    delta = est["injected"] - est["native"] - cell.scale * paper_injection(legmap)
    out["paired_delta_deg"] = {n: float(np.rad2deg(v)) for n, v in zip(names, delta)}
    out["paired_delta_rms_deg"] = float(np.rad2deg(rms(delta)))
