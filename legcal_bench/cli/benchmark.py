"""`legcal-bench bench`, `sweep` and `leaderboard`."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from legcal_bench import inputs
from legcal_bench.cli.parsing import pool_options
from legcal_bench.cli.robots import RUN_COUNT, door, floor_mode


# What Ctrl-C keeps (`legcal_bench.cli.main` prints it): each finished cell, session set
# and model-gap case is a whole file, and a rerun computes only the others.
BENCH_OUT = "runs/bench"  # the committed leaderboard/ changes only when --out names it

RESUME_CELLS = ("the finished cells and session sets are kept under --out and --data; rerun the same command to "
                "resume (only the unfinished ones are computed)")

def _door(a: argparse.Namespace, **more) -> None:
    """bench's and sweep's options checked before any planning: counts, modes, output
    folders, then the scheduler (reachable, and a Dask scheduler: a few seconds at most)."""
    door(a, seeds=RUN_COUNT, workers=inputs.count, out=inputs.output_folder,
         **{("modes" if hasattr(a, "modes") else "mode"): floor_mode}, **more)
    if a.scheduler:
        from legcal_bench.benchmark.runner import check_scheduler

        check_scheduler(a.scheduler)


def _exit_code(failed: list[dict], total: int) -> int:
    """A run's exit code: 1 if a cell failed (how many and why on stderr), else 0."""
    from legcal_bench.benchmark.runner import failure_summary

    summary = failure_summary(failed, total)
    if summary:
        print(summary, file=sys.stderr)
        return 1
    return 0


def cmd_bench(a: argparse.Namespace) -> int:
    _door(a, effect_seeds=RUN_COUNT, data=inputs.output_folder)
    from legcal_bench.benchmark import plan as planning
    from legcal_bench.benchmark.leaderboard import generate
    from legcal_bench.benchmark.runner import failures, run
    from legcal_bench.benchmark.suites import get_suite
    from legcal_bench.errors import ConfigError

    suite = get_suite(a.suite)
    for opt, val, hint in (("--effect-seeds", a.effect_seeds, "; use --seeds"), ("--cases", a.cases, ""),
                           ("--outside-robots", a.outside_robots, ""), ("--plugin-effects", a.plugin_effects, "")):
        if "modelgap" not in suite.tags and val:
            raise ConfigError(f"{opt}: the modelgap suite's option, not {a.suite!r}'s{hint}")
    if "closed_loop" in suite.tags:
        return _bench_closed_loop(a, suite)
    if "modelgap" in suite.tags:
        return _bench_modelgap(a, suite)
    cells = planning.plan(a.suite, robots=a.robots, modes=a.modes, seeds=a.seeds, calibrators=a.calibrators,
                          collect_overrides=_collect_overrides(a))
    out = Path(a.out)
    t0 = time.perf_counter()
    counts = run(cells, a.data, out / "results", workers=a.workers, scheduler=a.scheduler, progress=not a.quiet)
    wall = time.perf_counter() - t0
    failed = failures(cells, out / "results")
    text = generate(out)
    tables = text[text.index("## "):text.index("## Matched comparison")] if "## " in text else text
    print("\n".join(line for line in tables.splitlines() if not line.startswith("![")).strip() + "\n")
    print(f"{counts['computed']} cells computed, {counts['skipped']} already done, {len(failed)} failed, "
          f"{wall:.0f} s wall; leaderboard: {out / 'README.md'}")
    return _exit_code(failed, len(cells))


def _bench_closed_loop(a: argparse.Namespace, suite) -> int:
    """The closed-loop suite: walk-eval with every calibrator variant, then the leaderboard."""
    from legcal_bench.benchmark.closed_loop import run_closed_loop_suite
    from legcal_bench.benchmark.leaderboard import generate
    from legcal_bench.benchmark.runner import executing

    out = Path(a.out)
    t0 = time.perf_counter()
    with executing(a.scheduler, a.workers, local=True) as executor:
        files = run_closed_loop_suite(out, trials=a.seeds or suite.seeds, executor=executor, robots=a.robots or suite.robots,
                                      progress=not a.quiet)
    text = generate(out)
    if "## Closed loop" in text:
        section = text[text.index("## Closed loop"):]
        print("\n".join(section.split("\n## ")[0].splitlines()))
    print(f"{len(files)} closed-loop results in {out}, {time.perf_counter() - t0:.0f} s wall; leaderboard: "
          f"{out / 'README.md'}")
    return 0


def cmd_sweep(a: argparse.Namespace) -> int:
    _door(a, scales=inputs.positive)
    import numpy as np

    from legcal_bench.benchmark import plan as planning
    from legcal_bench.benchmark.runner import failures, run
    from legcal_bench.robots import robot_label

    cells = planning.plan("sweep", robots=a.robots, modes=[a.mode], seeds=a.seeds, scales=a.scales,
                          calibrators=a.calibrators,
                          collect_overrides=_collect_overrides(a, stance_s=a.stance_seconds, heldout=a.heldout))
    out = Path(a.out)
    counts = run(cells, out / "data", out / "results", workers=a.workers, scheduler=a.scheduler,
                 progress=not a.quiet)
    rows: dict = {}
    failed = failures(cells, out / "results")
    for c in cells:
        r = json.loads(c.path(out / "results").read_text())
        if "error" in r:
            continue
        key = (robot_label(c.robot), f"{c.calibrator}-{c.variant}", c.scale)
        rows.setdefault(key, []).append(r["injected"]["score"]["recovery"]["rms_error_deg"])
    print(f"{'robot':<12} {'calibrator-variant':<22} {'scale':>6} {'recovery RMS (deg), mean ± std':>32}")
    for (robot, name, scale), v in sorted(rows.items()):
        print(f"{robot:<12} {name:<22} {scale:>6g} {np.mean(v):>20.4f} ± {np.std(v):.4f}")
    print(f"{counts['computed']} cells computed, {counts['skipped']} already done, {len(failed)} failed; "
          f"results in {out / 'results'}")
    return _exit_code(failed, len(cells))


def _collect_overrides(a: argparse.Namespace, **more) -> dict:
    """The robot-fitting options bench and sweep share with collect (and `more` of
    collect's fields), each checked by collect's own rules (`CollectConfig`) before
    anything is planned."""
    from legcal_bench.errors import ConfigError
    from legcal_bench.protocol.collect import CollectConfig

    if a.mjcf is not None and (a.robots is None or len(a.robots) != 1):
        raise ConfigError("--mjcf replaces one robot's model: give exactly one robot with --robot")
    out = dict(more)
    if a.mjcf is not None:
        out["mjcf"] = a.mjcf
    if a.stances is not None:
        from legcal_bench.protocol.stances import check_stance_names

        check_stance_names(a.stances)
        out["stances"] = tuple(a.stances)
    if a.sensors is not None:
        from legcal_bench.sim.sensors import sim_sensors

        sim_sensors(a.sensors)  # an unknown preset fails here, naming the presets
        out["sensors"] = a.sensors
    if a.period_scale is not None:
        out["period_scale"] = a.period_scale
    if a.protocol is not None:
        from legcal_bench.protocol.stances import load_protocol

        load_protocol(a.protocol)  # a bad file fails here, naming the field
        out["protocol"] = str(Path(a.protocol).resolve())
    if a.native is not None:
        import numpy as np

        from legcal_bench.robots import load_robot
        from legcal_bench.sim.offsets import resolve_offsets

        resolve_offsets(a.native, load_robot("a3"), np.random.default_rng(0))  # a bad spec fails here
        out["native"] = a.native
    CollectConfig(**{k: v for k, v in out.items() if k not in ("native", "protocol", "mjcf")})  # collect's rules
    return out


def _robot_options(p: argparse.ArgumentParser, default) -> None:
    p.add_argument("--robots", "--robot", nargs="+", default=default,
                   help="robots: built-in names or leg-map paths; --suite modelgap also takes a generated "
                        "robot's name (legcal_bench.robots.design, e.g. five_joint), its model written under "
                        "--out (default: " + (" ".join(default) if default else "the suite's") + ")")
    p.add_argument("--mjcf", default=None, help="with one robot: use this MJCF instead of the one its leg map names "
                                                "(default: the leg map's)")
    p.add_argument("--stances", nargs="+", default=None,
                   help="stances to record, as in collect (default: I II III IV; e.g. I II III IV tall, the range "
                        "stance that separates a knee encoder scale); held-out sessions follow them")
    p.add_argument("--sensors", default=None, help="sensor preset, as in collect (default: the suite's, realistic)")
    p.add_argument("--period-scale", type=float, default=None,
                   help="slower posture motion, as in collect: a factor in [0.1, 10] (default 1; stance seconds are "
                        "not scaled with it)")
    p.add_argument("--protocol", default=None, help="a protocol file (legcal-bench design --out): its stances "
                                                    "instead of the suite's (default: none, the suite's stances)")
    p.add_argument("--native", default=None,
                   help="the robots' own (factory) offsets under the injection: random:<deg> (default random:1.2, "
                        "uniform per joint), paper-base (the paper's real robots' base offsets), none")


def cmd_compare(a: argparse.Namespace) -> int:
    from legcal_bench.benchmark.leaderboard import METRICS, compare
    from legcal_bench.errors import ConfigError

    if a.metric not in METRICS:
        raise ConfigError(f"--metric {a.metric!r}: use one of {list(METRICS)}")
    rows = compare(a.a, a.b, a.robot, a.mode, a.metric)
    if not rows:
        raise ConfigError(f"no calibrator variant has results for robot {a.robot!r}, mode {a.mode!r} in both "
                          f"{a.a} and {a.b}")
    print(f"{METRICS[a.metric][0]}, {a.robot}, {a.mode}: A = {a.a}, B = {a.b}, paired by seed")
    for r in rows:
        print(f"  {r['variant']:22s} {len(r['seeds'])} seeds: A {r['a_mean']:.4f}, B {r['b_mean']:.4f}; "
              f"A lower in {r['a_lower']}/{len(r['seeds'])}")
    return 0


def cmd_leaderboard(a: argparse.Namespace) -> int:
    door(a, out=inputs.output_folder)
    from legcal_bench.benchmark.leaderboard import generate

    generate(a.out)
    print(f"wrote {Path(a.out) / 'README.md'}")
    return 0


def _bench_modelgap(a: argparse.Namespace, suite) -> int:
    """The model-gap suite: diagnose every case, write modelgap/ under the leaderboard root,
    each case a file in modelgap/cases/ there (kept for a rerun of the same command)."""
    from legcal_bench.benchmark.leaderboard import generate
    from legcal_bench.benchmark.modelgap import CASES, DEFAULT_CALIBRATOR, RESULTS_NAME, markdown, run
    from legcal_bench.benchmark.plan import available
    from legcal_bench.errors import ConfigError
    from legcal_bench.files.reports import write_report
    from legcal_bench.protocol.stances import check_stance_names
    from legcal_bench.provenance import code_version, describe

    from legcal_bench.robots.design import GENERATED_DESIGNS

    robots = []
    for r in a.robots or suite.robots:
        missing = None if r in GENERATED_DESIGNS else available(r)  # a generated robot is written for the run
        if missing is not None:
            print(f"modelgap suite: skipping robot {r}: {missing}")
        else:
            robots.append(r)
    seeds = a.seeds or suite.seeds
    effect_seeds = a.effect_seeds or seeds
    calibrator = DEFAULT_CALIBRATOR
    if a.calibrators:
        from legcal_bench.calibrators.registry import get_calibrator

        if len(a.calibrators) != 1:
            raise ConfigError(f"--calibrators {' '.join(a.calibrators)}: the modelgap suite starts every diagnosis "
                              "from one calibrator's offsets; give one")
        get_calibrator(a.calibrators[0])  # an unknown name fails before any case runs
        calibrator = (a.calibrators[0], ())
    if a.stances:
        check_stance_names(a.stances)
    plugins = tuple(a.plugin_effects or ())
    if plugins:
        from legcal_bench.sim.effects import parse_effect

        for spec in plugins:
            parse_effect(spec)  # a misspelt or uninstalled effect fails before any case runs
    if a.outside_robots:
        stray = [r for r in a.outside_robots if r not in robots]
        if stray:
            raise ConfigError(f"--outside-robots: {', '.join(stray)} not among the robots run ({', '.join(robots)}); "
                              "give each in --robots too")
    made_by = (f"legcal-bench bench --suite modelgap --robots {' '.join(robots)} --seeds {seeds}"
               + (f" --effect-seeds {effect_seeds}" if a.effect_seeds else "")
               + (f" --stances {' '.join(a.stances)}" if a.stances else "")
               + (f" --cases {' '.join(a.cases)}" if a.cases else "")
               + (f" --outside-robots {' '.join(a.outside_robots)}" if a.outside_robots else "")
               + (f" --calibrators {calibrator[0]}" if a.calibrators else "")
               + (f" --plugin-effects {' '.join(plugins)}" if plugins else ""))
    code = code_version()
    t0 = time.perf_counter()
    data = run(robots, seeds=effect_seeds, clean_seeds=2 * seeds, outside_seeds=seeds, near_seeds=seeds,
               multi_seeds=seeds, workers=a.workers, progress=not a.quiet, stances=a.stances,
               cases=tuple(a.cases or CASES), outside_robots=tuple(a.outside_robots) if a.outside_robots else None,
               calibrator=calibrator, out=Path(a.out) / RESULTS_NAME / "cases", command=made_by, plugins=plugins)
    data.update(made_by=made_by, code=code, wall_s=time.perf_counter() - t0)
    md = markdown(data, made_by, describe(code))
    write_report(Path(a.out) / RESULTS_NAME, md, data, name=RESULTS_NAME)
    generate(a.out)
    print(md)
    print(f"{len(data['rows'])} cases, {data['wall_s']:.0f} s wall; {Path(a.out) / RESULTS_NAME / 'modelgap.md'}; "
          f"leaderboard: {Path(a.out) / 'README.md'}")
    return 0


def add_commands(sub) -> None:
    from legcal_bench.benchmark.suites import SUITES

    suites = ", ".join(f"{n} ({s.description}; tags: {', '.join(s.tags)})" for n, s in SUITES.items())
    bn = sub.add_parser("bench", help="run a benchmark suite (collect, calibrate, score every cell) and the "
                                      "leaderboard",
                        description="Plan a suite's cells (robot x floor x seed x calibrator variant), collect the "
                                    "session sets (cached under --data), calibrate and score every cell (one result "
                                    "file each under --out/results; a rerun computes only the missing ones) and "
                                    "write the leaderboard, --out/README.md with its plots. The committed "
                                    "leaderboard changes only when named: --out leaderboard.")
    bn.add_argument("--suite", default="smoke", help=f"the suite to run, one of: {suites}")
    _robot_options(bn, None)
    bn.add_argument("--modes", nargs="+", default=None, help="override the suite's floor modes: kinematic, weld, "
                                                             "contact (default: the suite's)")
    bn.add_argument("--seeds", type=int, default=None, help="override the suite's number of seeds, at least 1 "
                                                             "(closed-loop: trials; default: the suite's)")
    bn.add_argument("--effect-seeds", type=int, default=None,
                    help="modelgap suite: seeds per library effect (default --seeds; clean sets are 2x --seeds, the "
                         "near-threshold, multi-effect and outside cases --seeds each)")
    bn.add_argument("--cases", nargs="+", default=None,
                    help="modelgap suite: only these case groups, of clean (with the kinematic floor), library, near, "
                         "multi (with the pair of a link length and an IMU tilt at realistic sizes), outside (with its "
                         "reference runs); default all (e.g. --cases clean library "
                         "--effect-seeds 20: the library effects with more seeds, beside their floor)")
    bn.add_argument("--plugin-effects", nargs="+", default=None, metavar="SPEC",
                    help="modelgap suite: also run these effect specs (an installed plug-in's physics, as in collect "
                         "--effect; e.g. backlash:joint=left_knee,deg=0.2 with docs/examples/backlash_plugin), "
                         "--effect-seeds each; named when that effect alone is selected (default: none)")
    bn.add_argument("--outside-robots", nargs="+", default=None,
                    help="modelgap suite: the robots (of --robots) the edits outside the library run on (default "
                         "every robot run; 5 edits x --seeds each, ~15-60 s a diagnosis)")
    bn.add_argument("--calibrators", nargs="+", default=None,
                    help="only these registered calibrators (modelgap suite: the one whose offsets every diagnosis "
                         "starts from, default interfoot)")
    pool_options(bn)
    bn.add_argument("--data", default="runs/bench/data", help="where session sets are cached (a writable folder; "
                                                              "default runs/bench/data)")
    bn.add_argument("--out", default=BENCH_OUT,
                    help=f"leaderboard root: results/ and README.md (a writable folder; default {BENCH_OUT}; the "
                         f"committed leaderboard changes only when named: --out leaderboard). Exit code 1 if a cell "
                         f"failed (the summary says how many and why), 2 for a refused option")
    bn.add_argument("--quiet", action="store_true", help="no progress bars (default: progress bars)")
    bn.set_defaults(func=cmd_bench, resume=RESUME_CELLS)

    cp = sub.add_parser("compare", help="two result folders (e.g. a designed protocol's and the default's) "
                                        "paired seed by seed, per calibrator variant",
                        description="Pair the result files of two folders cell by cell (same robot, floor and "
                                    "seed) and print, per calibrator variant, the metric's mean in each and how "
                                    "often A is lower. Reads result files only; writes nothing.")
    cp.add_argument("--a", required=True, help="result folder A (e.g. leaderboard/designed_a2/results)")
    cp.add_argument("--b", required=True, help="result folder B (e.g. leaderboard/results)")
    cp.add_argument("--robot", required=True, help="robot whose cells to pair (as named in the result files)")
    cp.add_argument("--mode", default="weld", help="floor mode of the cells to pair: kinematic, weld or contact "
                                                   "(default weld)")
    cp.add_argument("--metric", default="recovery_rms", help="a leaderboard metric key, e.g. recovery_rms (deg) "
                                                             "(default recovery_rms; an unknown key lists them)")
    cp.set_defaults(func=cmd_compare)

    sw = sub.add_parser("sweep", help="seeds x robots x calibrators x offset scales, through local processes or Dask",
                        description="Collect, calibrate and score every cell of robots x calibrators x seeds x "
                                    "multiples of the paper's offset injection on one floor, and print each "
                                    "variant's recovery RMS (deg) per scale. Session sets go to --out/data, one "
                                    "result file per cell to --out/results (a rerun computes only the missing "
                                    "ones).")
    _robot_options(sw, ["a2", "a3"])
    sw.add_argument("--calibrators", nargs="+", default=None, help="only these registered calibrators (default all)")
    sw.add_argument("--mode", default="weld", help="floor mode: kinematic, weld or contact (default weld)")
    sw.add_argument("--seeds", type=int, default=3, help="seeds per robot and scale, at least 1 (default 3)")
    sw.add_argument("--scales", nargs="+", type=float, default=[0.5, 1.0, 2.0],
                    help="multiples of the paper's injection, each > 0 (default 0.5 1 2)")
    sw.add_argument("--stance-seconds", type=float, default=12.0, help="seconds of each stance, as in collect "
                                                                       "(default 12)")
    sw.add_argument("--heldout", type=int, default=3, help="held-out sessions, as in collect (default 3)")
    pool_options(sw)
    sw.add_argument("--out", default="runs/sweep", help="a writable folder for data/ and results/ (default "
                                                        "runs/sweep). Exit code 1 if a cell failed, 2 for a refused "
                                                        "option")
    sw.add_argument("--quiet", action="store_true", help="no progress bars (default: progress bars)")
    sw.set_defaults(func=cmd_sweep, resume=RESUME_CELLS)

    lb = sub.add_parser("leaderboard", help="regenerate a leaderboard's README.md and plots from its result files",
                        description="Read the result files under --out/results and write --out/README.md and its "
                                    "plots again (the same files give the same bytes); no cell is run. The "
                                    "committed leaderboard changes only when named: --out leaderboard.")
    lb.add_argument("--out", default=BENCH_OUT,
                    help=f"leaderboard root holding results/ (default {BENCH_OUT}, where bench writes; the "
                         f"committed leaderboard changes only when named: --out leaderboard)")
    lb.set_defaults(func=cmd_leaderboard)
