"""Time the command's start-up with whatever `legcal_bench` is importable (issue #36).

Run as a script (`python startup_probe.py --repeats 5`), it prints one JSON object: for
each case the wall times, in seconds, of fresh interpreters running
`from legcal_bench.cli import main; main([...])`, the way the `legcal-bench` entry point
starts. The children get this process's environment (PYTHONPATH included, its entries made
absolute) and run in an empty folder, so `PYTHONPATH=<an older install> python
startup_probe.py` times that version. Standard library only, and it uses nothing of
legcal_bench but `legcal_bench.cli.main`, so it runs against old commits too.

A child ends `main`'s SystemExit itself: exit code 0 (help) and 2 (an argument error)
both count as success; anything else stops the probe with the child's error.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_k, "1")
os.environ.setdefault("MUJOCO_GL", "egl")

# name -> the command's arguments
CASES = {
    "help": ["--help"],
    "calibrate_help": ["calibrate", "--help"],
    "calibrate_bad_flag": ["calibrate", "--no-such-flag"],
}

CHILD = """import sys
from legcal_bench.cli import main
try:
    code = main({argv!r})
except SystemExit as e:
    code = e.code
sys.exit(0 if code in (0, 2, None) else 3)
"""
WHERE = "import os, legcal_bench; print(os.path.dirname(legcal_bench.__file__))"


def child_env() -> dict:
    """This process's environment with PYTHONPATH's entries absolute (the children run elsewhere)."""
    env = dict(os.environ)
    if env.get("PYTHONPATH"):
        env["PYTHONPATH"] = os.pathsep.join(os.path.abspath(p) if p else p
                                            for p in env["PYTHONPATH"].split(os.pathsep))
    return env


def run_once(argv: list[str], env: dict, cwd: str) -> float:
    """Wall seconds of one fresh interpreter running `main(argv)`."""
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CHILD.format(argv=list(argv))], env=env, cwd=cwd,
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, check=False)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        raise RuntimeError(f"legcal-bench {' '.join(argv)} exited {done.returncode}:\n{done.stderr}")
    return wall


def probe(repeats: int = 5, cases: dict[str, list[str]] | None = None) -> dict:
    """{"module": the legcal_bench folder timed, "cases": {name: {"unit": "s", "values": [...]}}}.
    One untimed run per case first (it writes the bytecode caches); then the cases take
    turns, `repeats` rounds, so a passing load falls on all of them alike."""
    cases = CASES if cases is None else cases
    env = child_env()
    with tempfile.TemporaryDirectory() as cwd:
        where = subprocess.run([sys.executable, "-c", WHERE], env=env, cwd=cwd, capture_output=True, text=True,
                               check=True).stdout.strip()
        for argv in cases.values():
            run_once(argv, env, cwd)
        values: dict[str, list[float]] = {name: [] for name in cases}
        for _ in range(repeats):
            for name, argv in cases.items():
                values[name].append(run_once(argv, env, cwd))
    return {"module": where, "cases": {name: {"unit": "s", "values": v} for name, v in values.items()}}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=5, help="timed runs per case (default 5)")
    p.add_argument("--help-of", nargs="+", default=[], metavar="COMMAND",
                   help="also time these commands' --help (e.g. collect walk train-policy)")
    a = p.parse_args(argv)
    cases = {**CASES, **{f"{c.replace('-', '_')}_help": [c, "--help"] for c in a.help_of}}
    print(json.dumps(probe(a.repeats, cases)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
