"""Nothing a stopped or killed command made outlives it: its local workers end with it
(Ctrl-C stops them at once; SIGKILL of the parent ends them within a poll), and its
scratch folders and partial results are removed (on the way out, or by the next
command after SIGKILL)."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from legcal_bench.files import atomic, scratch
from legcal_bench.files.parallel import local_executor, stop

DEAD_PID = 2**22 + 12345  # above Linux's pid_max default of 4194304: no process has it


def _pids(ex) -> list[int]:
    return [p.pid for p in (getattr(ex, "_processes", None) or {}).values()]


def _gone(pids, within_s: float) -> bool:
    end = time.monotonic() + within_s
    while time.monotonic() < end:
        if not any(scratch.alive(p) and not _zombie(p) for p in pids):
            return True
        time.sleep(0.1)
    return False


def _zombie(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ", 1)[1].startswith("Z")
    except OSError:
        return False


def test_stopping_a_pool_ends_its_workers_and_their_jobs_at_once():
    ex = local_executor(2)
    futs = [ex.submit(time.sleep, 60) for _ in range(4)]
    end = time.monotonic() + 30
    while len(_pids(ex)) < 2 and time.monotonic() < end:
        time.sleep(0.05)
    pids = _pids(ex)
    assert len(pids) == 2
    t = time.monotonic()
    stop(ex)
    assert time.monotonic() - t < 2.0
    assert _gone(pids, 2.0)
    assert all(f.cancelled() or f.done() for f in futs)


CHILD = """
import sys, time
from legcal_bench.files.parallel import local_executor
ex = local_executor(2)
futs = [ex.submit(time.sleep, 60) for _ in range(2)]
while len(getattr(ex, "_processes", None) or {}) < 2:
    time.sleep(0.05)
time.sleep(1.0)  # both workers started
print(" ".join(str(p.pid) for p in ex._processes.values()), flush=True)
time.sleep(60)
"""


def test_sigkill_of_the_parent_leaves_no_worker_beyond_5_s(tmp_path):
    proc = subprocess.Popen([sys.executable, "-c", CHILD], stdout=subprocess.PIPE, text=True)
    try:
        pids = [int(p) for p in proc.stdout.readline().split()]
        assert len(pids) == 2 and all(scratch.alive(p) for p in pids)
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        assert _gone(pids, 5.0), "a worker outlived its killed parent by 5 s"
    finally:
        proc.kill()


def test_ctrl_c_reaches_only_the_parent(tmp_path):
    # A terminal's Ctrl-C signals the whole process group: the workers ignore it, so that
    # no worker prints a traceback; the parent stops them.
    ex = local_executor(1)
    try:
        assert ex.submit(signal.getsignal, signal.SIGINT).result(60) == signal.SIG_IGN
    finally:
        stop(ex)


def test_a_scratch_folder_goes_on_the_way_out_and_a_dead_ones_with_the_next_command(tmp_path, monkeypatch):
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    with pytest.raises(KeyboardInterrupt):
        with scratch.scratch_dir("reality") as d:
            assert Path(d).is_dir() and scratch.owner(Path(d).name) == os.getpid()
            raise KeyboardInterrupt
    assert not Path(d).exists()
    dead = tmp_path / f"legcal_reality_p{DEAD_PID}_abc"
    live = tmp_path / f"legcal_modelgap_probe_p{os.getpid()}_abc"
    other = tmp_path / "legcal_something_else"
    for p in (dead, live, other):
        p.mkdir()
    assert scratch.sweep(tmp_path) == [dead]
    assert not dead.exists() and live.exists() and other.exists()


def test_partial_results_of_a_dead_writer_are_removed_by_the_next_write(tmp_path):
    target = tmp_path / "set"
    stale = tmp_path / f".set.p{DEAD_PID}.x1y2.tmp"
    stale_old = tmp_path / f".set.p{DEAD_PID}.x1y3.old"
    mine = tmp_path / f".set.p{os.getpid()}.zz.tmp"  # a live writer's: left alone
    for p in (stale, stale_old, mine):
        p.mkdir()
    (tmp_path / f".other.p{DEAD_PID}.q.tmp").mkdir()  # another result's: not this write's
    atomic.atomic_write_dir(target, lambda d: (d / "a.txt").write_text("x"))
    assert (target / "a.txt").read_text() == "x"
    assert not stale.exists() and not stale_old.exists() and mine.exists()
    assert (tmp_path / f".other.p{DEAD_PID}.q.tmp").exists()
    f = tmp_path / "r.json"
    (tmp_path / f".r.json.p{DEAD_PID}.k.tmp").write_text("{")
    atomic.atomic_write_json(f, {"a": 1})
    assert not (tmp_path / f".r.json.p{DEAD_PID}.k.tmp").exists()
