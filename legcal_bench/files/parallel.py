"""Local worker processes, one way for every command: a pool whose workers ignore
Ctrl-C (the parent stops them, at once, in `stopping`), end themselves when their
parent is gone (SIGKILL of a command leaves no worker behind), and run one BLAS
thread each; and `map_with_progress`, a map over jobs with a progress bar (the
reports' and suites' many independent session sets)."""

from __future__ import annotations

import os
import signal
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from multiprocessing import get_context

THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
PARENT_POLL_S = 0.5  # how often a worker checks that its parent is alive


def single_thread() -> None:
    """Small problems on these machines run faster on one BLAS thread per process (for
    libraries that read these later: set before workers start, they inherit it)."""
    for k in THREAD_VARIABLES:
        os.environ.setdefault(k, "1")


def local_executor(workers: int) -> ProcessPoolExecutor:
    """A pool of `workers` fresh (spawned) processes, each started by `worker_start`."""
    single_thread()
    return ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"), initializer=worker_start,
                               initargs=(os.getpid(),))


def worker_start(parent_pid: int, period_s: float = PARENT_POLL_S) -> None:
    """Worker initializer: Ctrl-C in a terminal reaches the whole process group, but
    only the parent acts on it (`stopping` ends the workers); a daemon thread ends this
    worker once its parent is gone (a killed command would otherwise leave its workers
    running or waiting forever)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def watch():
        while True:
            if os.getppid() != parent_pid:
                os._exit(1)
            time.sleep(period_s)

    threading.Thread(target=watch, name="legcal-watch-parent", daemon=True).start()


def stop(executor) -> None:
    """End a local pool's workers now (the jobs in progress with them) and shut it down:
    on Ctrl-C nothing more is started and nothing running is waited for. Their results
    are written atomically, so a stopped job leaves no half file. Other executors (a
    Dask cluster's) are shut down without waiting; their workers are the scheduler's."""
    for proc in list((getattr(executor, "_processes", None) or {}).values()):
        try:
            proc.terminate()
        except (OSError, AttributeError):
            pass
    try:
        executor.shutdown(wait=isinstance(executor, ProcessPoolExecutor), cancel_futures=True)
    except TypeError:  # an executor without cancel_futures
        executor.shutdown(wait=False)


@contextmanager
def stopping(executor):
    """`with stopping(ex):` the pool shut down normally at the end, or stopped (`stop`)
    when the block is left by Ctrl-C or another interruption."""
    try:
        yield executor
    except BaseException as e:
        if isinstance(e, Exception):
            executor.shutdown(wait=True, cancel_futures=True)
        else:
            stop(executor)
        raise
    executor.shutdown(wait=True)


def map_with_progress(fn, jobs: list, workers: int = 2, desc: str = "", progress: bool = True) -> list:
    """[fn(job) for job in jobs] on `workers` processes (1: in this process); `fn` must
    be picklable (a module-level function)."""
    from tqdm import tqdm

    out = []
    bar = tqdm(total=len(jobs), desc=desc, unit="set", disable=not progress)
    try:
        if workers <= 1:
            for j in jobs:
                out.append(fn(j))
                bar.update(1)
        else:
            with stopping(local_executor(workers)) as ex:
                for r in ex.map(fn, jobs):
                    out.append(r)
                    bar.update(1)
    finally:
        bar.close()
    return out
