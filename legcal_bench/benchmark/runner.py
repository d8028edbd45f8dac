"""The runner: collect the session sets a plan needs, then calibrate and score its
unfinished cells, through a `concurrent.futures.Executor`: local processes by
default, or a Dask cluster's executor when a scheduler address is given (the same
code). Resumable: a cell whose file holds a complete result under the same key
(calibrator settings, data, RESULTS_VERSION) is kept; a partial, empty, foreign or
stale file is recomputed. A cell that fails for a reason of its input (a `LegcalError`:
a robot that does not hold a posture, data a calibrator cannot use) is a result too,
with its error; `failures` lists them and `failure_summary` says how many and why.
"""

from __future__ import annotations

import json
import socket
import time
from concurrent.futures import Executor, as_completed
from contextlib import contextmanager
from pathlib import Path

from tqdm import tqdm

from legcal_bench import inputs
from legcal_bench.benchmark.plan import Cell
from legcal_bench.benchmark.tasks import collect_dataset, run_cell
from legcal_bench.errors import ConfigError
from legcal_bench.files.parallel import local_executor, stop, stopping
from legcal_bench.provenance import code_version

RESULT_KEYS = ("native", "injected", "paired_delta_rms_deg")
SCHEDULER_TIMEOUT_S = 2.0  # a scheduler that does not accept a connection within this is refused


def check_scheduler(address: str, field: str = "--scheduler", timeout_s: float = SCHEDULER_TIMEOUT_S) -> None:
    """Refuse a Dask scheduler address that is malformed, where nothing accepts a
    connection within `timeout_s`, or where what answers is not a Dask scheduler (the
    client itself would wait 30 s, after the work was planned, or read a proxy's reply
    as a message). A scheduler greets a TCP connection at once with its handshake (a
    framed message naming its compression and pickle protocol); for tls:// only the
    connection is tried, and another protocol (inproc://, ucx://) is left to the client."""
    text = str(address).strip()
    protocol, sep, rest = text.partition("://")
    if not sep:
        protocol, rest = "tcp", text
    if protocol not in ("tcp", "tls"):
        return
    host, sep, port = rest.rstrip("/").rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"{field} {address!r}: expected a scheduler address tcp://HOST:PORT (e.g. "
                          "tcp://10.0.0.5:8786)")
    fix = (f"start one there (dask scheduler --port {port}), give the address it prints, or leave {field} out to "
           "run on local worker processes (--workers)")
    try:
        conn = socket.create_connection((host, int(port)), timeout=timeout_s)
    except OSError as e:
        why = "timed out" if isinstance(e, (socket.timeout, TimeoutError)) else (e.strerror or str(e))
        raise ConfigError(f"{field} {address!r}: no scheduler answers at {host}:{port} ({why}, {timeout_s:g} s "
                          f"allowed); {fix}") from None
    with conn:
        if protocol == "tls":
            return
        greeting, deadline = b"", time.monotonic() + timeout_s
        try:
            while len(greeting) < 256 and b"compression" not in greeting and time.monotonic() < deadline:
                conn.settimeout(max(deadline - time.monotonic(), 0.01))
                chunk = conn.recv(256)
                if not chunk:
                    break
                greeting += chunk
        except OSError:  # the timeout: nothing (more) said
            pass
    length = int.from_bytes(greeting[:8], "little") if len(greeting) >= 8 else 0
    if b"compression" not in greeting or not 0 < length < 1 << 20:
        said = f"it sent {greeting[:40]!r}" if greeting else f"it said nothing within {timeout_s:g} s"
        raise ConfigError(f"{field} {address!r}: something accepts connections at {host}:{port} but it is not a Dask "
                          f"scheduler ({said}; a scheduler greets with its handshake at once); {fix}")


@contextmanager
def executing(scheduler: str | None, workers: int, local: bool = True):
    """`with executing(scheduler, workers) as ex:` an executor for the block (None when
    neither a scheduler nor, with `local`, more than one worker asks for one): shut
    down at the end, stopped at once on Ctrl-C (`legcal_bench.files.parallel.stopping`:
    the work in progress ends, finished results are kept), its Dask client closed."""
    if not scheduler and not (local and workers > 1):
        yield None
        return
    ex, client = make_executor(scheduler, workers)
    try:
        with stopping(ex):
            yield ex
    finally:
        if client is not None:
            client.close()


def make_executor(scheduler: str | None, workers: int) -> tuple[Executor, object | None]:
    """(executor, Dask client to close afterwards, or None)."""
    if scheduler:
        check_scheduler(scheduler, "scheduler")
        from distributed import Client

        client = Client(scheduler)
        return client.get_executor(), client
    # One BLAS thread per worker (faster here, and the same arithmetic, hence the same
    # numbers, on every run); workers that ignore Ctrl-C and end with their parent.
    return local_executor(inputs.count("workers", workers, fix="local worker processes")), None


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
    so every cell of a run records the code the run started with. No cells at all is
    refused (ConfigError). The failed cells: `failures`."""
    if not cells:
        raise ConfigError("no cells to run: the plan is empty (no seeds, robots or calibrators); give at least one of "
                          "each")
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
    except BaseException as e:
        if not isinstance(e, Exception):  # Ctrl-C: the cells in progress end now; finished cells are kept
            stop(ex)
        raise
    finally:
        if own:
            ex.shutdown()
        if client is not None:
            client.close()
    return {"cells": len(cells), "computed": len(todo), "skipped": len(cells) - len(todo)}


def failures(cells: list[Cell], results_dir: str | Path) -> list[dict]:
    """The cells whose result file records an error (a `LegcalError` of their input: a
    set that could not be collected, data the calibrator cannot use), each as its file
    and error; a cell without a readable file counts as failed too."""
    out = []
    for c in cells:
        path = c.path(Path(results_dir))
        try:
            r = json.loads(path.read_text())
        except (OSError, ValueError) as e:
            out.append({"cell": str(path), "error": f"no readable result ({e})"})
            continue
        if not isinstance(r, dict) or "error" in r:
            out.append({"cell": str(path), "error": str(r.get("error") if isinstance(r, dict) else r)})
    return out


def failure_summary(failed: list[dict], total: int, shown: int = 3, width: int = 400) -> str:
    """How many of `total` cells failed and why (`failed`: `failures`'s list): each
    distinct error (up to `shown`, cut at `width` characters) with how many cells it
    failed and one cell's file; "" if none failed."""
    if not failed:
        return ""
    by_reason: dict[str, list[str]] = {}
    for f in failed:
        by_reason.setdefault(f["error"], []).append(f["cell"])
    lines = [f"{len(failed)} of {total} cells failed ({len(by_reason)} distinct "
             f"reason{'s' if len(by_reason) > 1 else ''}; each cell's file holds its error):"]
    for reason, where in sorted(by_reason.items(), key=lambda kv: -len(kv[1]))[:shown]:
        text = reason if len(reason) <= width else reason[:width] + " ..."
        lines.append(f"  {len(where)} cell{'s' if len(where) > 1 else ''}, e.g. {where[0]}: {text}")
    if len(by_reason) > shown:
        lines.append(f"  and {len(by_reason) - shown} other reasons")
    return "\n".join(lines)
