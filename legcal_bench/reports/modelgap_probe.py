"""Time the model-gap suite with whatever `legcal_bench` is importable (issue #36).

Run as a script (`python modelgap_probe.py --repeats N`), it runs
`legcal-bench bench --suite modelgap --cases clean library --seeds 2` (or the `--cases`,
`--seeds` and `--robots` given) in this process (`legcal_bench.cli.main`) into a
temporary folder, N times, and prints one JSON object: the wall seconds of each run
(`<key>_total`, `--key`, default `modelgap`) and per session set (`<key>_per_set`), and
the number of session sets a run diagnoses (`sets`). It uses
only the command line, so it runs on an older commit checked out beside the code at hand
(`PYTHONPATH=<its clone> python modelgap_probe.py`), for a comparison in the same run.

Each run starts in a fresh working folder (a link to this folder's `examples/` in it,
so `examples/...` robots resolve as here): a suite that keeps its finished cases under
the working folder starts from none.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import os
import shutil
import sys
import tempfile  # not files.scratch: a probe runs on the baseline's package too
import time

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_k, "1")
os.environ.setdefault("MUJOCO_GL", "egl")


def once(seeds: int, cases: list[str], extra: list[str], save: str | None = None) -> tuple[float, int]:
    """(wall seconds, session sets) of one run of the suite, from a fresh folder (its
    report, modelgap.json, copied to `save`); what the command prints goes to stderr."""
    # The command as a user runs it; a probe script drives the CLI from outside the
    # package's layers (it times any installed version's), so it is looked up by name.
    main = importlib.import_module("legcal_bench.cli").main

    here = os.getcwd()
    with tempfile.TemporaryDirectory(prefix="legcal_modelgap_probe_") as tmp:
        if os.path.isdir("examples"):
            os.symlink(os.path.abspath("examples"), os.path.join(tmp, "examples"))
        os.chdir(tmp)
        try:
            argv = ["bench", "--suite", "modelgap", "--cases", *cases, "--seeds", str(seeds), "--out",
                    os.path.join(tmp, "lb"), "--data", os.path.join(tmp, "data"), "--quiet", *extra]
            t0 = time.perf_counter()
            with contextlib.redirect_stdout(sys.stderr):
                code = main(argv)
            wall = time.perf_counter() - t0
            if code:
                raise SystemExit(f"legcal-bench {' '.join(argv)} exited with {code}")
            report = os.path.join(tmp, "lb", "modelgap", "modelgap.json")
            with open(report) as f:
                sets = len(json.load(f)["rows"])
            if save:
                shutil.copyfile(report, save)
        finally:
            os.chdir(here)
    return wall, sets


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--seeds", type=int, default=2)
    p.add_argument("--cases", nargs="+", default=["clean", "library"])
    p.add_argument("--robots", nargs="+", default=None, help="default: the suite's")
    p.add_argument("--workers", type=int, default=None, help="default: the command's")
    p.add_argument("--save", default=None, help="copy the last run's modelgap.json here (to compare results)")
    p.add_argument("--key", default="modelgap", help="the cases' names: <key>_per_set, <key>_total")
    a = p.parse_args(argv)
    extra = (["--robots", *a.robots] if a.robots else []) + (["--workers", str(a.workers)] if a.workers else [])
    import legcal_bench

    totals, sets = [], None
    for _ in range(a.repeats):
        wall, n = once(a.seeds, a.cases, extra, a.save and os.path.abspath(a.save))
        totals.append(wall)
        sets = n
        print(f"modelgap: {n} sets in {wall:.1f} s ({wall / n:.2f} s a set)", file=sys.stderr)
    print(json.dumps({"cases": {f"{a.key}_per_set": {"unit": "s", "values": [t / sets for t in totals]},
                                f"{a.key}_total": {"unit": "s", "values": totals}},
                      "sets": sets, "module": os.path.dirname(legcal_bench.__file__)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
