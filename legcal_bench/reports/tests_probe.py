"""Time the test command with whatever `legcal_bench` is importable (issue #36).

Run as a script (`python tests_probe.py --src DIR`), it runs `python -m pytest` in the
source tree DIR (a checkout of legcal-bench: its tests and its pytest settings, so an
older commit's suite runs the way it ran then) with this process's environment
(PYTHONPATH included, so `PYTHONPATH=<an older install> python tests_probe.py --src
<its tree>` times that version), in as many processes as that tree's `make test` uses, and prints one JSON object: the wall time, the count of
tests passed and failed, and the slowest 20 (`--durations=20`). Standard library only.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_k, "1")
os.environ.setdefault("MUJOCO_GL", "egl")

SLOWEST = 20
_DURATION = re.compile(r"^\s*([0-9.]+)s\s+(call|setup|teardown)\s+(\S+)")
_COUNT = re.compile(r"(\d+) (passed|failed|errors?|skipped|deselected|xfailed|xpassed)")


def _makefile(src: str) -> str:
    makefile = os.path.join(src, "Makefile")
    return open(makefile).read() if os.path.exists(makefile) else ""


def workers(src: str) -> list[str]:
    """The test command's own process count: `make test` runs `pytest -n $(TEST_WORKERS)`
    (default 2) in a tree whose Makefile says so (since issue #36); before, one process."""
    return ["-n", os.environ.get("TEST_WORKERS", "2")] if "pytest -n $(TEST_WORKERS)" in _makefile(src) else []


def run_suite(src: str) -> dict:
    """One run of the suite in `src`: wall seconds, counts by outcome, the slowest tests.
    As that tree's `make test` runs it: without PYTHONDONTWRITEBYTECODE where its Makefile
    unexports it (Python then caches bytecode)."""
    env = dict(os.environ)
    if "unexport PYTHONDONTWRITEBYTECODE" in _makefile(src):
        env.pop("PYTHONDONTWRITEBYTECODE", None)
    if env.get("PYTHONPATH"):
        env["PYTHONPATH"] = os.pathsep.join(os.path.abspath(p) if p else p
                                            for p in env["PYTHONPATH"].split(os.pathsep))
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "pytest", *workers(src), "-q", "-p", "no:cacheprovider",
                           f"--durations={SLOWEST}"], cwd=src, env=env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    lines = done.stdout.splitlines()
    summary = next((ln for ln in reversed(lines) if " in " in ln and _COUNT.search(ln)), "")
    counts = {kind.rstrip("s") if kind.startswith("error") else kind: int(n) for n, kind in _COUNT.findall(summary)}
    slowest = [{"seconds": float(m.group(1)), "phase": m.group(2), "test": m.group(3)}
               for m in map(_DURATION.match, lines) if m]
    return {"wall_s": wall, "returncode": done.returncode, "counts": counts, "summary": summary.strip("= "),
            "slowest": slowest[:SLOWEST]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--src", required=True, help="the source tree whose tests run (its pytest settings apply)")
    p.add_argument("--repeats", type=int, default=1)
    a = p.parse_args(argv)
    runs = [run_suite(a.src) for _ in range(a.repeats)]
    print(json.dumps({"cases": {"test_suite": {"unit": "s", "values": [r["wall_s"] for r in runs]}},
                      "runs": runs}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
