"""`legcal-bench reproduce`, `bench-speed`, `bench-env` and `regression`: reports on
legcal-bench itself."""

from __future__ import annotations

import argparse
from pathlib import Path

from legcal_bench import inputs
from legcal_bench.cli.parsing import pool_options
from legcal_bench.cli.robots import RUN_COUNT, door, floor_mode

DEFAULT_FIXTURE = Path("tests/fixtures/regression.json")
RUNS = "runs"  # where every report command writes unless --out names a committed report


def cmd_reproduce(a: argparse.Namespace) -> int:
    door(a, out=inputs.output_folder)
    from legcal_bench.reports.reproduce import reproduce

    print(reproduce(a.out, progress=not a.quiet))
    return 0


def cmd_bench_speed(a: argparse.Namespace) -> int:
    door(a, out=inputs.output_folder, repeats=RUN_COUNT, rounds=RUN_COUNT)
    from legcal_bench.reports.bench_speed import rerender, run_bench_speed

    if a.readme:
        from legcal_bench.reports.bench_speed import write_speed_line

        print(f"wrote {a.readme}'s speed line: {write_speed_line(a.readme, a.out)}")
        return 0
    if a.rerender:
        print(rerender(a.out))
        return 0
    print(run_bench_speed(a.out, robot=a.robot, repeats=a.repeats, rounds=a.rounds, baseline=a.baseline,
                          groups=a.groups, progress=not a.quiet))
    return 0


def cmd_bench_env(a: argparse.Namespace) -> int:
    door(a, out=inputs.output_folder, seed=inputs.seed, modes=floor_mode)
    from legcal_bench.reports.bench_env import run_bench_env

    print(run_bench_env(a.robots, a.modes, a.out, seed=a.seed, progress=not a.quiet))
    return 0


def cmd_data_checks(a: argparse.Namespace) -> int:
    door(a, out=inputs.output_folder, seeds=inputs.seed, offsets=_offsets)
    from legcal_bench.reports.robots_check import run_data_checks

    print(run_data_checks(a.out, a.robots, a.seeds, a.offsets, a.modes, short=a.short, defects=not a.no_defects,
                          progress=not a.quiet))
    return 0


def cmd_verdicts(a: argparse.Namespace) -> int:
    door(a, out=inputs.output_folder, seeds=inputs.seed, workers=inputs.count)
    from legcal_bench.reports.verdicts import measure

    d = measure(a.out, a.robots, a.modes, a.seeds, workers=a.workers, progress=not a.quiet)
    print(f"wrote {a.out}/verdicts.md, .json ({len(d['rows'])} cases)")
    return 0


def cmd_imu_mount(a: argparse.Namespace) -> int:
    door(a, out=inputs.output_folder, seeds=inputs.seed, workers=inputs.count)
    from legcal_bench.reports.imu_mount import measure, summary_lines

    print("\n".join(summary_lines(measure(a.out, a.robots, a.seeds, workers=a.workers, progress=not a.quiet), a.out)))
    return 0


def cmd_vendor_cases(a: argparse.Namespace) -> int:
    door(a, out=inputs.output_folder, seeds=inputs.seed, workers=inputs.count)
    from legcal_bench.reports.vendor_cases import measure, summary_lines

    print("\n".join(summary_lines(measure(a.out, a.cases, a.seeds, workers=a.workers, progress=not a.quiet), a.out)))
    return 0


def cmd_robots_check(a: argparse.Namespace) -> int:
    door(a, out=inputs.output_folder, seeds=RUN_COUNT)
    from legcal_bench.reports.robots_check import run_robots_check

    print(run_robots_check(a.out, seeds=a.seeds, progress=not a.quiet, extra=a.extra))
    return 0


def cmd_regression(a: argparse.Namespace) -> int:
    from legcal_bench.errors import ConfigError
    from legcal_bench.files.scratch import scratch_dir
    from legcal_bench.reports import regression

    door(a, workers=inputs.count, **({"fixture": inputs.output_file} if a.update else {}))
    if a.update:
        regression.update(a.fixture, workers=a.workers, progress=not a.quiet)
        print(f"wrote {a.fixture}: the numbers of the code at hand are now the reference")
        return 0
    if not Path(a.fixture).is_file():
        raise ConfigError(f"--fixture {a.fixture}: no such file (run from a checkout, or give its path)")
    with scratch_dir("regression") as tmp:
        problems = regression.compare(regression.load_fixture(a.fixture),
                                      regression.compute(Path(tmp), workers=a.workers, progress=not a.quiet))
    for p in problems:
        print(p)
    print(f"{len(problems)} value(s) moved beyond 1e-7 relative / 1e-9 deg absolute" if problems
          else "every fixture value reproduced")
    return 1 if problems else 0


def _offsets(field: str, spec: str) -> None:
    """An offsets spec of the clean sets, understood before any set is collected (a spec
    the collection does not understand would fail every set, one by one): a preset is
    resolved on a3; a list of radians, whose length is each robot's, must be numbers."""
    from legcal_bench.errors import ConfigError, LegcalError

    if "," in spec:
        for part in spec.split(","):
            inputs.number(f"{field} {spec!r}: the value", part, fix="one radian per leg joint, comma-separated")
        return
    import numpy as np

    from legcal_bench.robots import load_robot
    from legcal_bench.sim.offsets import resolve_offsets

    try:
        resolve_offsets(spec, load_robot("a3"), np.random.default_rng(0))
    except LegcalError as e:
        raise ConfigError(f"{field}: {e}") from None


def _case_table(a: argparse.Namespace, module, option: str, known, name: str, made_by: str, **build) -> dict:
    """A per-robot, per-case, per-seed report (`module.build` / `markdown`): the choices
    in `--<option>` checked against `known`, written to `--out` as `name`.md/.json."""
    from legcal_bench.errors import ConfigError
    from legcal_bench.files.reports import write_report
    from legcal_bench.provenance import code_version, describe

    chosen = getattr(a, option)
    unknown = sorted(set(chosen) - set(known))
    if unknown:
        raise ConfigError(f"--{option} {unknown}: use {option} from {list(known)}")
    code = code_version()
    data = module.build(a.robots, chosen, a.seeds, a.workers, progress=not a.quiet, **build)
    data.update(made_by=made_by, code=code)
    md = module.markdown(data, made_by, describe(code))
    write_report(a.out, md, data, name=name)
    print(md)
    return data


def _fill_default(a: argparse.Namespace, option: str, default) -> None:
    """An option the parser leaves None because its default lives in a heavy report module."""
    if getattr(a, option) is None:
        setattr(a, option, list(default))


def _table_door(a: argparse.Namespace) -> None:
    """A per-robot, per-case report's options, before its report module (which loads the
    simulation) is imported: the folder, the seeds and the workers."""
    door(a, out=inputs.output_folder, seeds=RUN_COUNT, workers=inputs.count)


def cmd_effects_table(a: argparse.Namespace) -> int:
    _table_door(a)
    from pathlib import Path

    from legcal_bench.reports import effects_table

    from legcal_bench.protocol.stances import check_stance_names

    _fill_default(a, "effects", effects_table.EFFECTS)
    _fill_default(a, "stances", effects_table.DEFAULT_STANCES)
    check_stance_names(a.stances)
    made_by = (f"legcal-bench effects-table --robots {' '.join(a.robots)} --effects {' '.join(a.effects)} "
               f"--seeds {a.seeds}" + ("" if tuple(a.stances) == effects_table.DEFAULT_STANCES
                                       else f" --stances {' '.join(a.stances)}"))
    data = _case_table(a, effects_table, "effects", effects_table.EFFECTS, "effects_table", made_by,
                       stances=tuple(a.stances))
    effects_table.plot(data, Path(a.out) / "effects_table.png")
    print(f"wrote {a.out}/effects_table.md, .json, .png")
    return 0


def _cases_report(a: argparse.Namespace, command: str, module, known, name: str) -> int:
    """A per-robot, per-case report command (`_case_table`) whose `--cases` default lives in
    `module.CASES`, made_by naming the robots, cases (quoted where they have spaces) and seeds."""
    _fill_default(a, "cases", module.CASES)
    cases = " ".join(f"'{c}'" if " " in c else c for c in a.cases)
    made_by = f"legcal-bench {command} --robots {' '.join(a.robots)} --cases {cases} --seeds {a.seeds}"
    _case_table(a, module, "cases", known, name, made_by)
    print(f"wrote {a.out}/{name}.md, .json")
    return 0


def cmd_contact_table(a: argparse.Namespace) -> int:
    _table_door(a)
    from legcal_bench.reports import contact_table

    return _cases_report(a, "contact-table", contact_table, contact_table.KNOWN_CASES, "contact_table")


def cmd_contact_floor(a: argparse.Namespace) -> int:
    _table_door(a)
    from legcal_bench.reports import contact_floor

    return _cases_report(a, "contact-floor", contact_floor, contact_floor.KNOWN_CASES, "contact_floor")


def cmd_contact_holds(a: argparse.Namespace) -> int:
    _table_door(a)
    from legcal_bench.reports import contact_holds

    _fill_default(a, "robots", contact_holds.default_robots())
    return _cases_report(a, "contact-holds", contact_holds, contact_holds.CASES, "contact_holds")


def report_out(command: str) -> str:
    """A report command's default folder: under runs/, never the committed report (which
    changes only when --out names it)."""
    return f"{RUNS}/{command}"


def _kept_cases_options(p: argparse.ArgumentParser, command: str, committed: str, what: str, seeds,
                        seeds_are: str = "collect seeds") -> None:
    """--seeds, --workers, --out and --quiet of a report whose cases are kept under --out/cases."""
    p.add_argument("--seeds", nargs="+", type=int, default=list(seeds),
                   help=f"{seeds_are}, each an integer in [0, 2^32 - 1] (default {' '.join(map(str, seeds))})")
    pool_options(p, scheduler=False, note=" (default 2)")
    _out(p, command, committed, what)
    _quiet(p)


def _out(p: argparse.ArgumentParser, command: str, committed: str, what: str) -> None:
    """The --out option of a report command: `runs/<command>` by default; `committed`, the
    report folder the repository keeps, named in the help as the way to update it."""
    p.add_argument("--out", default=report_out(command),
                   help=f"report folder: {what} (default {report_out(command)}; the committed report changes only "
                        f"when named: --out {committed})")


def _quiet(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quiet", action="store_true", help="no progress bars (default: progress bars)")


def add_commands(sub) -> None:
    from legcal_bench.benchmark.suites import EXTERNAL_ROBOT

    rp = sub.add_parser("reproduce", help="the paper's experiments side by side with its numbers (markdown report)",
                        description="Collect the simulated data the paper's experiments need (cached under "
                                    "--out/data, reused when present), run the inter-foot calibrator in every "
                                    "configuration (the paper's alternating solver and the default projected one) "
                                    "and write report.md, report.json and plots beside the paper's numbers.")
    _out(rp, "reproduce", "reports/reproduction", "report.md, report.json, plots, data/ (the cached session sets)")
    _quiet(rp)
    rp.set_defaults(func=cmd_reproduce)

    _bench_speed_options(sub.add_parser(
        "bench-speed", help="time where users wait (calibration, collection, start-up, the closed loop, the model-gap "
                            "suite, the tests), the code at hand against a baseline commit in one run",
        description="Install the baseline commit beside the code at hand, run each group's probe once per version "
                    "per round (alternating which goes first) and write the report (markdown and JSON): per case the "
                    "medians, the speed-up and whether its target is met."))

    b = sub.add_parser("bench-env", help="measure foot drift per floor mode and collection speed; writes a report",
                       description="For every robot and floor mode, collect the default session set and report, "
                                   "from the ground truth, the largest sole drift within any segment (mm, deg) and "
                                   "the collection speed (frames per wall second, simulated over wall time).")
    b.add_argument("--robots", nargs="+", default=["a2", "a3", "pair_ryp", "pair_pry", EXTERNAL_ROBOT],
                   help="robots to measure: built-in names or leg-map paths")
    b.add_argument("--modes", nargs="+", default=["kinematic", "weld", "contact"],
                   help="floor modes to measure: kinematic, weld, contact")
    b.add_argument("--seed", type=int, default=0, help="collection seed: an integer in [0, 2^32 - 1]")
    _out(b, "bench-env", "reports/bench_env", "the report (markdown and JSON)")
    _quiet(b)
    b.set_defaults(func=cmd_bench_env)

    rc = sub.add_parser("robots-check", help="servo gains, stance fit, hold check and recovery of the built-in and "
                                             "generated test robots (every hip order, soft servos, narrow ankles)",
                        description="Take every built-in, generated and variation robot through its leg map alone: "
                                    "the servo gains in use and their source, how much each stance shrank to fit, "
                                    "the hold check's largest excursions (weld and contact) against its limits, "
                                    "the weld-mode recovery beside the robot's stiff-servo twin, and the data "
                                    "checks' false alarms on these clean sets. Writes the report (markdown and JSON).")
    rc.add_argument("--seeds", type=int, default=2, help="seeds per robot and mode, at least 1 (default 2)")
    rc.add_argument("--extra", nargs="+", default=[EXTERNAL_ROBOT], help=f"more robots, built-in names or leg-map paths "
                                                                     f"(default {EXTERNAL_ROBOT})")
    _out(rc, "robots-check", "reports/robots_check", "the report (markdown and JSON)")
    _quiet(rc)
    rc.set_defaults(func=cmd_robots_check)

    dc = sub.add_parser("data-checks", help="the data checks on clean sets of each robot variation (false alarms) "
                                            "and the planted defects they catch; writes data_checks.md/.json",
                        description="Run the data checks on clean session sets of each robot variation (every "
                                    "warning there is a false alarm) and on sets with planted defects (frozen "
                                    "channels, swapped columns, IMU axes, slides ...; each must be caught). Writes "
                                    "data_checks.md and data_checks.json.")
    dc.add_argument("--robots", nargs="+", default=None,
                    help="variation or generated-robot names, built-ins or leg maps (default: every variation in "
                         "legcal_bench.robots.design.VARIATIONS and the first generated robot)")
    dc.add_argument("--seeds", nargs="+", type=int, default=list(range(5)), help="collect seeds, each an integer in "
                                                                                 "[0, 2^32 - 1]")
    dc.add_argument("--offsets", nargs="+", default=None,
                    help="offset specs of the clean sets, e.g. paper, random:3 or one radian per leg joint, "
                         "comma-separated (default paper random:3: robots_check.CHECK_OFFSETS)")
    dc.add_argument("--modes", nargs="+", default=None, choices=["kinematic", "weld", "contact"],
                    help="floors of the clean sets (default kinematic weld: robots_check.CHECK_MODES)")
    dc.add_argument("--short", action="store_true", help="4 s stances and 1 s standing instead of 12 s and 5 s")
    dc.add_argument("--no-defects", action="store_true", help="skip the planted defects (default: planted and "
                                                              "checked)")
    _out(dc, "data-checks", "reports/robots_check", "data_checks.md and data_checks.json")
    _quiet(dc)
    dc.set_defaults(func=cmd_data_checks)

    from legcal_bench.reports import verdicts as vd

    vp = sub.add_parser("verdicts", help="the results' verdicts measured: clean realistic sets of each robot (weld, "
                                         "contact) and the torso-IMU case; writes verdicts.md/.json",
                        description="Collect clean realistic-sensor session sets of each robot on each floor, "
                                    "calibrate each with interfoot and count the verdicts (on clean sets every "
                                    "do-not-apply is a false refusal, every review an unearned doubt), and the "
                                    "whole-body example with its IMU in the torso above its undeclared waist (must be "
                                    "do-not-apply). Each case is kept under --out/cases as it finishes: a stopped "
                                    "run resumes. Writes verdicts.md and verdicts.json.")
    vp.add_argument("--robots", nargs="+", default=list(vd.ROBOTS),
                    help=f"robots, built-in names or leg maps (default {' '.join(vd.ROBOTS)})")
    vp.add_argument("--modes", nargs="+", default=list(vd.MODES), choices=["kinematic", "weld", "contact"],
                    help=f"floors (default {' '.join(vd.MODES)})")
    _kept_cases_options(vp, "verdicts", "reports/verdicts", "verdicts.md, verdicts.json and cases/", vd.SEEDS)
    vp.set_defaults(func=cmd_verdicts)

    from legcal_bench.reports import imu_mount as im

    ip = sub.add_parser("imu-mount", help="a torso IMU declared through its waist against its pelvis-IMU twin; "
                                          "writes imu_mount.md/.json",
                        description="For each robot, three twins differing only in the IMU: on the pelvis, in the "
                                    "torso declared through the waist (imu.through), in the torso undeclared. Each "
                                    "seed collects a realistic weld set per twin, calibrates it with interfoot and "
                                    "scores it: the torso twin's IMU-removed recovery against the pelvis twin's "
                                    f"(bar: within {im.RATIO_BAR:g}x) and the verdicts (undeclared: do-not-apply). "
                                    "Each case is kept under --out/cases as it finishes: a stopped run resumes.")
    ip.add_argument("--robots", nargs="+", default=list(im.ROBOTS), choices=list(im.ROBOTS),
                    help=f"robots (default {' '.join(im.ROBOTS)}: the generated A3-like robot with a 3-joint waist, "
                         "the whole-body example of examples/cases.yaml)")
    _kept_cases_options(ip, "imu-mount", "reports/imu_mount", "imu_mount.md, imu_mount.json and cases/", im.SEEDS)
    ip.set_defaults(func=cmd_imu_mount)

    from legcal_bench.reports import vendor_cases as vc

    cp = sub.add_parser("vendor-cases", help="robots as vendors ship them (URDF package, frames, ankle order, torso "
                                             "IMU, transmissions) against the A3-like robot; writes vendor_cases.md",
                        description="Each case of legcal_bench.robots.samples, through its leg map alone: a zero-noise "
                                    "kinematic set (bar: recovery <= 1e-9 deg, at the encoders too) and realistic "
                                    "weld sets calibrated by interfoot (bar: IMU-removed recovery within "
                                    f"{vc.RATIO_BAR:g}x of the A3-like robot's). Each case is kept under --out/cases "
                                    "as it finishes: a stopped run resumes.")
    cp.add_argument("--cases", nargs="+", default=list(vc.CASES), choices=list(vc.CASES),
                    help=f"cases (default {' '.join(vc.CASES)})")
    _kept_cases_options(cp, "vendor-cases", "reports/vendor_cases", "vendor_cases.md, vendor_cases.json and cases/",
                        vc.SEEDS, "weld seeds")
    cp.set_defaults(func=cmd_vendor_cases)

    # The cases' and stances' defaults (None here) are filled in by the command from its
    # report module, which loads the simulation.
    for name, option, seeds, committed, func, text, description in (
            ("effects-table", "effects", 10, "reports/effects", cmd_effects_table,
             "model gap: for each library effect at a realistic size, the offsets-only fit and the fit with the "
             "effect added, beside the clean floor",
             "For each robot, library effect (at a realistic size) and seed, collect a session set with the effect "
             "in the simulation, fit the offsets alone and with the effect added, and tabulate the offsets' error "
             "(deg) and the effect's estimate beside the clean floor. Writes effects_table.md, .json and .png."),
            ("contact-table", "cases", 5, "reports/contact_check", cmd_contact_table,
             "the per-stance contact check measured: clean data, a wedge under one sole in one stance, the "
             "contact floor (flags against the truth)",
             "Measure the inter-foot calibrator's per-stance contact check on clean data, on sets with a wedge "
             "under one sole in one stance, and on the contact floor, its flags against the truth, with the test's "
             "chi2/dof; 'kinematic' is clean data in kinematic mode; a case with ' random:3' before any ' realistic' "
             "injects random:3@seed instead of the paper's offsets; cases ending in ' realistic' use realistic "
             "sensors (e.g. 'contact random:3 realistic'). Writes contact_table.md and .json."),
            ("contact-floor", "cases", 5, "leaderboard/contact_floor", cmd_contact_floor,
             "the contact floor against the weld floor (zero and realistic sensors) and its parts",
             "The contact floor against the weld floor (zero and realistic sensors) and its parts: the soles' "
             "sink, tilt and slip, each taken out of the encoders; robustness cases 'contact zero @<key=value>' "
             "change one of the floor's parameters (timeconst, dampratio, dmin, dmax, friction). Writes "
             "contact_floor.md and .json."),
            ("contact-holds", "cases", 50, "leaderboard/contact_holds", cmd_contact_holds,
             "how many contact sets hold with factory (+-1.2 deg) plus +-3 deg offsets, with and without the "
             "standing controller (cases: cop none)",
             "Count the contact-floor session sets that pass the hold check with factory (+-1.2 deg) plus +-3 deg "
             "offsets, per robot, with the standing controller (cop) and without it (none). Writes "
             "contact_holds.md and .json.")):
        t = sub.add_parser(name, help=text, description=description)
        robots = (["a3", "a2", "pair_pry", "pair_ryp", EXTERNAL_ROBOT] if name in ("contact-floor", "contact-holds")
                  else ["a3", "a2", EXTERNAL_ROBOT])
        if name == "contact-holds":  # the generated robots' names are filled in by the command
            t.add_argument("--robots", nargs="+", default=None,
                           help="built-in names, leg-map paths or generated robots' names (legcal_bench.robots.design; "
                                f"default {' '.join(robots)} and every generated robot)")
        elif name in ("contact-floor", "contact-table"):
            t.add_argument("--robots", nargs="+", default=robots,
                           help="built-in names, leg-map paths or generated robots' names (legcal_bench.robots.design."
                                f"GENERATED_DESIGNS, e.g. five_joint_capsule_heel; default {' '.join(robots)})")
        else:
            t.add_argument("--robots", nargs="+", default=robots, help="built-in names or leg-map paths")
        t.add_argument(f"--{option}", nargs="+", default=None, help=f"which {option} (default all)")
        t.add_argument("--seeds", type=int, default=seeds, help="seeds 0..N-1 per robot and case, at least 1")
        pool_options(t, scheduler=False)
        _out(t, name, committed, f"{name.replace('-', '_')}.md and .json")
        _quiet(t)
        if name == "effects-table":
            t.add_argument("--stances", nargs="+", default=None,
                           help="stances to record (default I II III IV; the range stance 'tall' separates the "
                                "encoder scales from the offsets)")
        t.set_defaults(func=func)

    rg = sub.add_parser("regression", help="recompute the regression fixture's numbers and compare (exit 1 if any "
                                           "moved)",
                        description="Recompute the numbers the regression fixture holds (a subset of the standard "
                                    "suite's cells and reproduce's zero-noise rows) with the code at hand and list "
                                    "every value that moved beyond its tolerance (exit 1 if any did). --update "
                                    "writes the fixture instead, only when numbers are meant to move.")
    rg.add_argument("--fixture", default=str(DEFAULT_FIXTURE), help="fixture JSON, read (written only with --update)")
    rg.add_argument("--update", action="store_true",
                    help="write the fixture from the code at hand (only when numbers are meant to move)")
    pool_options(rg, scheduler=False)
    _quiet(rg)
    rg.set_defaults(func=cmd_regression)


def _bench_speed_options(bs: argparse.ArgumentParser) -> None:
    from legcal_bench.reports.bench_speed import BASELINE, DEFAULT_GROUPS, GROUPS

    bs.add_argument("--groups", nargs="+", default=list(DEFAULT_GROUPS), choices=list(GROUPS), metavar="GROUP",
                    help=f"what to time: {', '.join(GROUPS)} (default: {' '.join(DEFAULT_GROUPS)}; the others "
                         "take minutes to tens of minutes a round)")
    bs.add_argument("--robot", default="a3", help="the robot of the calibration and collection groups (default a3)")
    bs.add_argument("--repeats", type=int, default=None,
                    help="repeats per probe and round (default: calibration and startup 5, the others 1)")
    bs.add_argument("--rounds", type=int, default=2,
                    help="rounds, each running the baseline and the code at hand, alternating which goes first "
                         "(default 2)")
    bs.add_argument("--baseline", default=BASELINE,
                    help=f"commit to compare with, checked out in a local clone of this repository (default "
                         f"{BASELINE}, the commit issue #36 measured); none: only the code at hand")
    _out(bs, "bench-speed", "reports/bench_speed", "the report (markdown and JSON)")
    bs.add_argument("--quiet", action="store_true", help="no progress lines (default: progress lines)")
    bs.add_argument("--rerender", action="store_true",
                    help="run nothing: write --out's report again from the probe runs its report.json keeps, with "
                         "the labels and targets of the code at hand")
    bs.add_argument("--readme", default=None, metavar="FILE",
                    help="run nothing: write the speed line of --out's report into FILE (README.md), between its "
                         "speed-line markers (added at the end if it has none); default: no FILE, nothing written")
    bs.set_defaults(func=cmd_bench_speed)
