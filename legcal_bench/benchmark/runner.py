"""The runner: collect the session sets a plan needs, then calibrate and score its
unfinished cells, through a `concurrent.futures.Executor`: local processes by
default, or a Dask cluster's executor when a scheduler address is given (the same
code). Resumable: a cell whose file holds a complete result under the same key
(calibrator settings, data, RESULTS_VERSION) is kept; a partial, empty, foreign or
stale file is recomputed.
"""

from __future__ import annotations

import json
import os
import threading
import time
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from pathlib import Path

from tqdm import tqdm

from legcal_bench.benchmark.plan import Cell
from legcal_bench.benchmark.tasks import THREAD_VARIABLES, collect_dataset, run_cell
from legcal_bench.provenance import code_version

RESULT_KEYS = ("native", "injected", "paired_delta_rms_deg")


def make_executor(scheduler: str | None, workers: int) -> tuple[Executor, object | None]:
    """(executor, Dask client to close afterwards, or None)."""
    if scheduler:
        from distributed import Client

        client = Client(scheduler)
        return client.get_executor(), client
    # Worker processes read these when they start, before numpy does: one BLAS thread
    # each (faster here, and the same arithmetic, hence the same numbers, on every run).
    for k in THREAD_VARIABLES:
        os.environ.setdefault(k, "1")
    return ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"), initializer=watch_parent,
                               initargs=(os.getpid(),)), None


def watch_parent(parent_pid: int, period_s: float = 0.5) -> None:
    """Worker initializer: a daemon thread that ends this worker once its parent is
    gone (a killed `bench` would otherwise leave its workers waiting forever)."""
    def watch():
        while True:
            if os.getppid() != parent_pid:
                os._exit(1)
            time.sleep(period_s)

    threading.Thread(target=watch, name="legcal-watch-parent", daemon=True).start()


def is_done(cell: Cell, results_dir: Path) -> bool:
    """True if the cell's file is a whole result made under the cell's current key. A
    recorded failure is tried again on every run: its cause may be gone (a stale or
    half-written session set, a fixed bug); one that persists is recorded again."""
    try:
        c = json.loads(cell.path(results_dir).read_text())
    except (OSError, ValueError):
        return False
    if not isinstance(c, dict) or c.get("key") != cell.key():
        return False
    return "error" not in c and all(k in c for k in RESULT_KEYS)


def run(cells: list[Cell], data_dir: str | Path, results_dir: str | Path, executor: Executor | None = None,
        workers: int = 2, scheduler: str | None = None, progress: bool = True) -> dict:
    """Run every unfinished cell; returns counts. The code version is read once, here,
    so every cell of a run records the code the run started with."""
    provenance = code_version()
    data_dir, results_dir = str(Path(data_dir).resolve()), str(Path(results_dir).resolve())
    todo = [c for c in cells if not is_done(c, Path(results_dir))]
    own = executor is None
    ex, client = make_executor(scheduler, workers) if own else (executor, None)
    try:
        datasets = sorted({c.dataset(i) for c in todo for i in ("native", "injected")}, key=lambda d: d.name)
        futs = [ex.submit(collect_dataset, d, data_dir) for d in datasets]
        for f in tqdm(as_completed(futs), total=len(futs), desc="collect", unit="set", disable=not progress):
            f.result()
        futs = [ex.submit(run_cell, c, data_dir, results_dir, provenance) for c in todo]
        for f in tqdm(as_completed(futs), total=len(futs), desc="calibrate+score", unit="cell", disable=not progress):
            f.result()
    finally:
        if own:
            ex.shutdown()
        if client is not None:
            client.close()
    return {"cells": len(cells), "computed": len(todo), "skipped": len(cells) - len(todo)}
