"""`legcal-bench bench`, `sweep` and `leaderboard`."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def cmd_bench(a: argparse.Namespace) -> int:
    from legcal_bench.benchmark import plan as planning
    from legcal_bench.benchmark.leaderboard import generate
    from legcal_bench.benchmark.runner import run
    from legcal_bench.benchmark.suites import get_suite

    get_suite(a.suite)
    cells = planning.plan(a.suite, robots=a.robots, modes=a.modes, seeds=a.seeds, calibrators=a.calibrators)
    out = Path(a.out)
    t0 = time.perf_counter()
    counts = run(cells, a.data, out / "results", workers=a.workers, scheduler=a.scheduler, progress=not a.quiet)
    wall = time.perf_counter() - t0
    text = generate(out)
    tables = text[text.index("## "):text.index("## Matched comparison")] if "## " in text else text
    print("\n".join(line for line in tables.splitlines() if not line.startswith("![")).strip() + "\n")
    print(f"{counts['computed']} cells computed, {counts['skipped']} already done, {wall:.0f} s wall; "
          f"leaderboard: {out / 'README.md'}")
    return 0


def cmd_sweep(a: argparse.Namespace) -> int:
    from legcal_bench.benchmark import plan as planning
    from legcal_bench.benchmark.runner import run
    from legcal_bench.robots import robot_label

    cells = planning.plan("sweep", robots=a.robots, modes=[a.mode], seeds=a.seeds, scales=a.scales,
                          calibrators=a.calibrators,
                          collect_overrides=dict(stance_s=a.stance_seconds, heldout=a.heldout))
    out = Path(a.out)
    counts = run(cells, out / "data", out / "results", workers=a.workers, scheduler=a.scheduler,
                 progress=not a.quiet)
    rows: dict = {}
    failed = 0
    for c in cells:
        r = json.loads(c.path(out / "results").read_text())
        if "error" in r:
            failed += 1
            continue
        key = (robot_label(c.robot), f"{c.calibrator}-{c.variant}", c.scale)
        rows.setdefault(key, []).append(r["injected"]["score"]["recovery"]["rms_error_deg"])
    print(f"{'robot':<12} {'calibrator-variant':<22} {'scale':>6} {'recovery RMS (deg), mean ± std':>32}")
    for (robot, name, scale), v in sorted(rows.items()):
        print(f"{robot:<12} {name:<22} {scale:>6g} {np.mean(v):>20.4f} ± {np.std(v):.4f}")
    print(f"{counts['computed']} cells computed, {counts['skipped']} already done, {failed} failed; "
          f"results in {out / 'results'}")
    return 0


def cmd_leaderboard(a: argparse.Namespace) -> int:
    from legcal_bench.benchmark.leaderboard import generate

    generate(a.out)
    print(f"wrote {Path(a.out) / 'README.md'}")
    return 0


def add_commands(sub) -> None:
    from legcal_bench.benchmark.suites import SUITES

    suites = ", ".join(f"{n} ({s.description}; tags: {', '.join(s.tags)})" for n, s in SUITES.items())
    bn = sub.add_parser("bench", help="run a benchmark suite (collect, calibrate, score every cell) and the leaderboard")
    bn.add_argument("--suite", default="smoke", help=f"one of: {suites}")
    bn.add_argument("--robots", nargs="+", default=None, help="override the suite's robots")
    bn.add_argument("--modes", nargs="+", default=None, help="override the suite's floor modes")
    bn.add_argument("--seeds", type=int, default=None, help="override the suite's number of seeds")
    bn.add_argument("--calibrators", nargs="+", default=None, help="only these registered calibrators")
    bn.add_argument("--workers", type=int, default=2, help="local worker processes (default 2)")
    bn.add_argument("--scheduler", default=None, help="Dask scheduler address (tcp://host:8786): run there instead")
    bn.add_argument("--data", default="runs/bench/data", help="where session sets are cached")
    bn.add_argument("--out", default="leaderboard", help="leaderboard root: results/ and README.md (default leaderboard)")
    bn.add_argument("--quiet", action="store_true")
    bn.set_defaults(func=cmd_bench)

    sw = sub.add_parser("sweep", help="seeds x robots x calibrators x offset scales, through local processes or Dask")
    sw.add_argument("--robots", nargs="+", default=["a2", "a3"])
    sw.add_argument("--calibrators", nargs="+", default=None)
    sw.add_argument("--mode", default="weld")
    sw.add_argument("--seeds", type=int, default=3)
    sw.add_argument("--scales", nargs="+", type=float, default=[0.5, 1.0, 2.0], help="multiples of the paper's injection")
    sw.add_argument("--stance-seconds", type=float, default=12.0)
    sw.add_argument("--heldout", type=int, default=3)
    sw.add_argument("--workers", type=int, default=2)
    sw.add_argument("--scheduler", default=None, help="Dask scheduler address")
    sw.add_argument("--out", default="runs/sweep")
    sw.add_argument("--quiet", action="store_true")
    sw.set_defaults(func=cmd_sweep)

    lb = sub.add_parser("leaderboard", help="regenerate leaderboard/README.md and plots from the result files")
    lb.add_argument("--out", default="leaderboard")
    lb.set_defaults(func=cmd_leaderboard)
