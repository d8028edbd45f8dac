"""Time what a user waits for in the closed loop, with whatever `legcal_bench` is importable.

Run as a script (`python closed_loop_probe.py --repeats 5 [--trials 35]`), it prints one
JSON object: for each case the list of wall times (s), measured alternately, plus the
module timed and the settings. It uses only the command line both old and new
versions have (`legcal_bench.cli.main`, stdlib otherwise), so the same file times the
code at hand and an older commit checked out beside it (`bench_speed.install_baseline`,
run with `PYTHONPATH=<its clone>`).

  walk_eval_a3   `legcal-bench walk-eval --robot a3 --policy <our A3-like walker> --trials N
                 --quiet`, every other setting the default a user gets: 2 local worker
                 processes (`--workers 2`, spawned), offsets paper@3, calibrator interfoot
                 (its sensor-matched setting), static session sets weld with calibrated-imu
                 sensors, 20 s walks with realistic sensors
  collect_weld   `legcal-bench collect --robot a3 --mode weld --sensors realistic --quiet`:
                 the default session set (standing, stances I-IV, 3 held-out sessions; 8
                 recordings, 4150 frames)

Each run is a fresh interpreter calling `legcal_bench.cli.main` (a user's cold start:
imports and the worker pool included), with its output in a temporary folder and one
BLAS/OpenMP thread per process. Beside each case's wall time, `<case>_cpu`: the CPU
seconds (user + system) of that run's processes, workers included, which move less
than the wall on a machine shared with other jobs.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile  # not files.scratch: a probe runs on the baseline's package too
import time
from pathlib import Path

THREADS = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "MUJOCO_GL": "egl"}
CALL_MAIN = "import sys; from legcal_bench.cli import main; sys.exit(main(sys.argv[1:]))"


def walker_spec() -> str:
    """Our A3-like walker as a user names it (`a3`), or its spec file in the checkout
    beside this script where the imported package has no shipped policies (an install
    made with `pip install --target` leaves them out)."""
    try:
        from legcal_bench.policies.spec import WALKERS_DIR

        if (Path(WALKERS_DIR) / "a3" / "policy.yaml").is_file():
            return "a3"
    except ImportError:
        pass
    spec = Path(__file__).resolve().parents[2] / "policies" / "walkers" / "a3" / "policy.yaml"
    if not spec.is_file():
        sys.exit(f"closed_loop_probe: no A3-like walker found (looked for {spec})")
    return str(spec)


def run_cli(args: list[str], env: dict) -> tuple[float, float]:
    """(wall, CPU) seconds of one fresh `legcal_bench.cli.main(args)`, run in an empty
    folder (so the package comes from the path, not the working directory); CPU: user +
    system of that process and its worker processes."""
    with tempfile.TemporaryDirectory(prefix="legcal_probe_") as tmp:
        out = os.path.join(tmp, "out")
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        p = subprocess.run([sys.executable, "-c", CALL_MAIN, *args, "--out", out], cwd=tmp, env=env,
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, check=False)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        sys.exit(f"closed_loop_probe: legcal-bench {' '.join(args)} failed ({p.returncode}):\n{p.stderr[-3000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def probe(repeats: int, trials: int) -> dict:
    import legcal_bench

    env = {**os.environ, **{k: os.environ.get(k, v) for k, v in THREADS.items()}}
    policy = walker_spec()
    cases = {
        "walk_eval_a3": ["walk-eval", "--robot", "a3", "--policy", policy, "--trials", str(trials), "--quiet"],
        "collect_weld": ["collect", "--robot", "a3", "--mode", "weld", "--sensors", "realistic", "--quiet"],
    }
    values: dict[str, list[float]] = {k: [] for name in cases for k in (name, f"{name}_cpu")}
    for _ in range(repeats):
        for name, args in cases.items():  # alternating: both cases see the same machine load
            wall, cpu = run_cli(args, env)
            values[name].append(wall)
            values[f"{name}_cpu"].append(cpu)
    return {"cases": {name: {"unit": "s", "values": v} for name, v in values.items()},
            "module": os.path.dirname(legcal_bench.__file__),
            "settings": {"walk_eval_a3": {"robot": "a3", "policy": policy, "trials": trials, "workers": 2,
                                          "executor": "local processes (spawn)", "offsets": "paper@3",
                                          "calibrator": "interfoot", "static_sensors": "calibrated-imu",
                                          "walk_sensors": "realistic", "seconds": 20.0},
                         "collect_weld": {"robot": "a3", "mode": "weld", "sensors": "realistic"},
                         "threads_per_process": 1, "cpus": os.cpu_count()}}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=5, help="runs of each case, alternating (default 5)")
    p.add_argument("--trials", type=int, default=35, help="closed-loop trials (default 35, walk-eval's default)")
    a = p.parse_args(argv)
    if a.repeats < 1 or a.trials < 1:
        p.error("--repeats and --trials need at least 1")
    print(json.dumps(probe(a.repeats, a.trials)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
