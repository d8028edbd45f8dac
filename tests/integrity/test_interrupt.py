"""Ctrl-C stops a command within 2 s with one line (what is kept, how to resume), no
traceback; its local workers and scratch folders go with it. SIGKILL leaves scratch
folders and partial results that the next command removes. (Resumed runs equal
uninterrupted ones: tests/evaluation/test_walk_eval_resume.py for walk-eval,
tests/benchmark/test_modelgap_resume.py for the model-gap suite, test_runner for cells;
SIGKILL's workers: tests/benchmark/test_process_hygiene.py and test_leftovers.py.)"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from legcal_bench.files.scratch import alive

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table from /proc")

COLLECT = ["collect", "--robot", "a3", "--mode", "weld", "--stance-seconds", "120", "--heldout", "0",
           "--standing-seconds", "1"]


def _start(args: list[str], tmp: Path) -> subprocess.Popen:
    """The command in a session of its own (a terminal's process group: Ctrl-C reaches
    every process in it), its scratch folders under tmp/scratch."""
    (tmp / "scratch").mkdir(exist_ok=True)
    env = {**os.environ, "TMPDIR": str(tmp / "scratch"), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-c", "import sys; from legcal_bench.cli import main; sys.exit(main())",
                             *args], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=_foreground)


def _foreground() -> None:
    """Ctrl-C's default action, as in a terminal's foreground job: a process inherits an
    ignored SIGINT (pytest-xdist's workers ignore it, as a shell's background jobs do),
    and Python then leaves it ignored."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _wait_for(cond, proc: subprocess.Popen, what: str, within_s: float = 120.0) -> None:
    end = time.monotonic() + within_s
    while not cond():
        assert proc.poll() is None, f"ended before {what}: {proc.stderr.read()[-2000:]}"
        assert time.monotonic() < end, f"no {what} within {within_s:g} s"
        time.sleep(0.05)


def _children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmd = (stat.parent / "cmdline").read_bytes()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z" and b"resource_tracker" not in cmd:
            out.append(int(stat.parent.name))
    return out


def _scratch(tmp: Path) -> list[Path]:
    return sorted((tmp / "scratch").glob("legcal_*"))


def _ctrl_c(proc: subprocess.Popen) -> tuple[int, float, str]:
    """Ctrl-C as a terminal sends it (to the process group); (exit code, seconds to exit, stderr)."""
    t = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    try:
        code = proc.wait(10)
    finally:
        took = time.monotonic() - t
        left = _group(proc.pid)
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    assert not left, [Path(f"/proc/{q}/cmdline").read_bytes() for q in left]  # nothing of the group left
    return code, took, proc.stderr.read()


def _group(pgid: int, within_s: float = 2.0) -> list[int]:
    """Live processes of process group `pgid`, waiting up to `within_s` for them to go."""
    end = time.monotonic() + within_s
    while True:
        left = []
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                fields = stat.read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[2]) == pgid and fields[0] != "Z":
                left.append(int(stat.parent.name))
        if not left or time.monotonic() > end:
            return left
        time.sleep(0.05)


def _one_line(err: str, command: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip() and "%|" not in ln]  # progress bars aside
    assert "Traceback" not in err and len(lines) == 1, err
    assert lines[0].startswith(f"legcal-bench {command}: interrupted; "), lines[0]
    return lines[0]


def test_ctrl_c_stops_collect_at_once_and_leaves_nothing(tmp_path):
    out = tmp_path / "set"
    p = _start([*COLLECT, "--out", str(out)], tmp_path)
    _wait_for(lambda: _scratch(tmp_path), p, "scratch folder")
    time.sleep(1.0)  # in the middle of simulating
    code, took, err = _ctrl_c(p)
    assert code == 130 and took < 2.0, (code, took)
    assert "rerun the command" in _one_line(err, "collect")
    assert not _scratch(tmp_path) and not out.exists()
    assert not [q for q in tmp_path.iterdir() if q.name.startswith(".set.")]  # no partial set beside it


def test_sigkill_of_collect_leaves_scratch_the_next_command_removes(tmp_path):
    from legcal_bench.cli import main

    p = _start([*COLLECT, "--out", str(tmp_path / "set")], tmp_path)
    _wait_for(lambda: _scratch(tmp_path), p, "scratch folder")
    left = _scratch(tmp_path)
    os.killpg(p.pid, signal.SIGKILL)
    p.wait(10)
    p.stderr.close()
    assert all(q.exists() for q in left) and not alive(p.pid)
    old = os.environ.get("TMPDIR")
    import tempfile

    tempfile.tempdir = str(tmp_path / "scratch")
    try:
        assert main(["info", "--robot", "a3"]) == 0  # any command sweeps the dead process's scratch
    finally:
        tempfile.tempdir = None
        if old is not None:
            os.environ["TMPDIR"] = old
    assert not any(q.exists() for q in left)


POOLED = {  # long commands with local workers: Ctrl-C while both work
    "bench": ["bench", "--suite", "smoke", "--out", "{tmp}/lb", "--data", "{tmp}/data", "--workers", "2", "--quiet"],
    "bench --suite modelgap": ["bench", "--suite", "modelgap", "--robots", "a3", "--seeds", "1", "--cases", "clean",
                               "--out", "{tmp}/lb", "--workers", "2", "--quiet"],
    "walk-eval": ["walk-eval", "--robot", "a3", "--policy", "a3", "--offsets", "random:3@5", "--trials", "2",
                  "--seconds", "1", "--workers", "2", "--out", "{tmp}/we", "--quiet"],
}


@pytest.mark.parametrize("name", POOLED)
def test_ctrl_c_stops_a_pooled_command_and_its_workers_and_says_how_to_resume(name, tmp_path):
    p = _start([a.format(tmp=tmp_path) for a in POOLED[name]], tmp_path)
    workers: list[int] = []

    def started() -> bool:
        workers[:] = _children(p.pid)
        return len(workers) >= 2 and bool(_scratch(tmp_path))  # workers up, one at least simulating

    _wait_for(started, p, "two workers at work")
    code, took, err = _ctrl_c(p)  # its process group: the workers are gone too
    assert code == 130 and took < 2.0, (code, took)
    assert "rerun the same command" in _one_line(err, name.split()[0])
    assert not _scratch(tmp_path)
