"""Ctrl-C stops a command with exit code 130 and one line on stderr (what is kept, how to
resume), no traceback; no process it started outlives it (its local workers are gone
when it exits), and nothing is half-written: no partial file or folder beside a result,
no scratch folder, nothing left in its temporary folder. SIGKILL leaves scratch folders
and partial results that the next command removes. (Resumed runs equal uninterrupted
ones: tests/evaluation/test_walk_eval_resume.py for walk-eval,
tests/benchmark/test_modelgap_resume.py for the model-gap suite, test_runner for cells;
SIGKILL's workers: tests/benchmark/test_process_hygiene.py and test_leftovers.py.)

These tests assert what the code controls, not how fast a shared machine is: the time
from Ctrl-C to the exit is bounded only by a hang guard, `HANG_S`, sized from a
measurement on a loaded machine (see there); a wall-time bound of 2 s failed at load ~9
(2.4–7.0 s) on a fresh-clone CI run."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from legcal_bench.files.scratch import alive

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table from /proc")

# The hang guard: seconds from Ctrl-C until the command has exited and nothing it started
# is left. Not a speed requirement, only the point past which a stop is a hang. Measured
# on the 2-core machine, with `python -c "while True: pass" &` twice (one per core) and
# `pytest -s tests/integrity/test_interrupt.py` (each stop prints its times), and the same
# stops repeated 3 times each: load average 4.9-7.6 (other engineers' work besides),
# 0.42-2.46 s (walk-eval the slowest, 1.4-2.5 s); without the busy loops, load ~5:
# 0.37-1.60 s. 30 s is 12x the worst seen, ~4x the 7.0 s once seen at load ~9.
HANG_S = 30.0
START_S = 600.0  # a guard as well: command start to the moment the test interrupts it (measured up to 35 s)

COLLECT = ["collect", "--robot", "a3", "--mode", "weld", "--stance-seconds", "120", "--heldout", "0",
           "--standing-seconds", "1"]
PARTIAL = re.compile(r"^\..+\.p\d+\..*\.(tmp|old)$")  # legcal_bench.files.atomic's partial file or folder


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


def _wait_for(cond, proc: subprocess.Popen, what: str, within_s: float = START_S) -> None:
    end = time.monotonic() + within_s
    while not cond():
        assert proc.poll() is None, f"ended before {what}: {proc.stderr.read()[-2000:]}"
        assert time.monotonic() < end, f"no {what} within {within_s:g} s (a hang guard)"
        time.sleep(0.05)


def _table() -> dict[int, tuple[int, int, str, int]]:
    """Every process: pid -> (parent, process group, state, start time in clock ticks)."""
    out = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            f = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        out[int(stat.parent.name)] = (int(f[1]), int(f[2]), f[0], int(f[19]))
    return out


def _children(pid: int) -> list[int]:
    """The live workers of `pid` (multiprocessing's resource tracker aside)."""
    out = []
    for q, (parent, _, state, _) in _table().items():
        if parent != pid or state == "Z":
            continue
        try:
            cmd = Path(f"/proc/{q}/cmdline").read_bytes()
        except OSError:
            continue
        if b"resource_tracker" not in cmd:
            out.append(q)
    return out


def _descendants(pid: int) -> dict[int, int]:
    """The live processes below `pid`, any depth: pid -> start time (a pid the system
    hands out again later is another process)."""
    table, out, todo = _table(), {}, [pid]
    while todo:
        parent = todo.pop()
        for q, (pp, _, state, start) in table.items():
            if pp == parent and q not in out and state != "Z":
                out[q] = start
                todo.append(q)
    return out


def _alive(procs: dict[int, int]) -> list[int]:
    table = _table()
    return [q for q, start in procs.items() if q in table and table[q][3] == start and table[q][2] != "Z"]


def _left(pgid: int, procs: dict[int, int], until: float) -> list[int]:
    """What is left of process group `pgid` and of `procs`, waiting until `until` for
    them to go (multiprocessing's resource tracker ends only once the command's exit
    closes its pipe)."""
    while True:
        left = sorted({*_alive(procs), *(q for q, (_, g, s, _) in _table().items() if g == pgid and s != "Z")})
        if not left or time.monotonic() > until:
            return left
        time.sleep(0.05)


def _scratch(tmp: Path) -> list[Path]:
    return sorted((tmp / "scratch").glob("legcal_*"))


def _half_written(tmp: Path) -> list[Path]:
    """What an interrupted write would leave under tmp: anything in the command's
    temporary folder (scratch folders and all), a hidden partial file or folder beside a
    result (legcal_bench.files.atomic), a JSON file that does not parse."""
    bad = sorted((tmp / "scratch").iterdir())
    for q in sorted(tmp.rglob("*")):
        if PARTIAL.match(q.name):
            bad.append(q)
        elif q.suffix == ".json" and q.is_file():
            try:
                json.loads(q.read_text())
            except ValueError:
                bad.append(q)
    return bad


def _ctrl_c(proc: subprocess.Popen) -> tuple[int, str]:
    """Ctrl-C as a terminal sends it (to the process group); (exit code, stderr). Asserts
    that the command exits within the hang guard, that the workers it had are gone when
    it exits (it stops them itself), and that nothing of its process group or below it is
    left after."""
    below = _descendants(proc.pid)
    workers = {q: below[q] for q in _children(proc.pid) if q in below}
    t = time.monotonic()
    os.killpg(proc.pid, signal.SIGINT)
    try:
        code = proc.wait(HANG_S)
    except subprocess.TimeoutExpired:
        code = None
    try:
        took = time.monotonic() - t
        at_exit = _alive(workers)
        left = _left(proc.pid, below, t + HANG_S)
        print(f"Ctrl-C to exit {took:.2f} s, to nothing left {time.monotonic() - t:.2f} s, "
              f"load {os.getloadavg()[0]:.1f}")  # `pytest -s` shows it: how HANG_S was measured
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        for q in _alive(below):
            with contextlib.suppress(ProcessLookupError):
                os.kill(q, signal.SIGKILL)
        proc.wait()
    err = proc.stderr.read()
    assert code is not None, f"still running {HANG_S:g} s after Ctrl-C (the hang guard): {err[-2000:]}"
    assert not at_exit, f"workers alive as the command exited ({took:.2f} s after Ctrl-C): {at_exit}"
    assert not left, [Path(f"/proc/{q}/cmdline").read_bytes() for q in left]  # nothing it started is left
    return code, err


def _one_line(err: str, command: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip() and "%|" not in ln]  # progress bars aside
    assert "Traceback" not in err and len(lines) == 1, err
    assert lines[0].startswith(f"legcal-bench {command}: interrupted; "), lines[0]
    return lines[0]


def test_ctrl_c_stops_collect_and_leaves_nothing(tmp_path):
    out = tmp_path / "set"
    p = _start([*COLLECT, "--out", str(out)], tmp_path)
    _wait_for(lambda: _scratch(tmp_path), p, "scratch folder")
    time.sleep(1.0)  # in the middle of simulating
    code, err = _ctrl_c(p)
    assert code == 130, (code, err)
    assert "rerun the command" in _one_line(err, "collect")
    assert not _half_written(tmp_path) and not out.exists()
    assert not [q for q in tmp_path.iterdir() if q.name.startswith(".set.")]  # no partial set beside it


def test_sigkill_of_collect_leaves_scratch_the_next_command_removes(tmp_path):
    from legcal_bench.cli import main

    p = _start([*COLLECT, "--out", str(tmp_path / "set")], tmp_path)
    _wait_for(lambda: _scratch(tmp_path), p, "scratch folder")
    left = _scratch(tmp_path)
    os.killpg(p.pid, signal.SIGKILL)
    p.wait(HANG_S)
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

    def started() -> bool:
        return len(_children(p.pid)) >= 2 and bool(_scratch(tmp_path))  # workers up, one at least simulating

    _wait_for(started, p, "two workers at work")
    code, err = _ctrl_c(p)  # its process group: the workers are gone too
    assert code == 130, (code, err)
    assert "rerun the same command" in _one_line(err, name.split()[0])
    assert not _half_written(tmp_path)
