"""`legcal-bench import` (a robot's log in, recordings out) and `simulate-log` (a
simulated robot log written as a bag or table, with its mapping file)."""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from functools import partial

from legcal_bench import inputs
from legcal_bench.cli.robots import door, robot_args
from legcal_bench.sim.names import SENSOR_PRESET_NAMES

LOG_FORMATS = ("mcap", "sqlite3", "ros1", "csv", "parquet")


def cmd_import(a: argparse.Namespace) -> int:
    from legcal_bench.errors import ConfigError
    from legcal_bench.logs.importer import import_log, parse_ranges
    from legcal_bench.logs.mapping import example_mapping
    from legcal_bench.logs.timeline import format_timeline
    from legcal_bench.robots import load_robot

    door(a, out=inputs.output_folder)
    legmap = load_robot(a.robot, a.mjcf)
    if a.example_map:
        print(example_mapping(legmap), end="")
        return 0
    for opt, v in (("--log", a.log), ("--map", a.map), ("--out", a.out)):
        if not v:
            raise ConfigError(f"{opt} is required (or --example-map to print a mapping file to start from)")
    summary = import_log(a.log, a.map, legmap, a.out, heldout=a.heldout, ranges=parse_ranges(a.ranges),
                         plot=not a.no_plot)
    print(json.dumps(asdict(summary), indent=2) if a.json else format_timeline(summary))
    print(f"wrote {a.out}: {len(summary.segments)} recording(s)" + ("" if a.no_plot else f", {a.out}/timeline.png"))
    return 0


def cmd_simulate_log(a: argparse.Namespace) -> int:
    from legcal_bench.errors import ConfigError

    if a.mjcf is not None:
        # The long log walks and steps with the robot's frozen walking policy and its teacher,
        # trained on the leg map's own model: another MJCF is not simulated here.
        raise ConfigError(f"--mjcf {a.mjcf}: simulate-log simulates the leg map's own model (its walking policy "
                          "was trained on it) and does not take another MJCF; leave --mjcf out, or give --robot a "
                          "leg-map YAML of a robot with a frozen walker (policies/walkers/)")
    door(a, out=inputs.output_folder, seed=inputs.seed, sensors=partial(inputs.choice, options=SENSOR_PRESET_NAMES))
    from legcal_bench.api.logs import simulate_log

    out = simulate_log(a.robot, a.out, fmt=a.format, seed=a.seed, ft=not a.no_ft, sensors=a.sensors,
                       declare_sensors=not a.unknown_sensors, progress=not a.quiet)
    print(f"wrote {out['log']} ({a.format}), its mapping {out['mapping']} and the injected offsets "
          f"{out['truth']} (kept apart: a real log has none)")
    return 0


def add_commands(sub) -> None:
    im = sub.add_parser("import", help="import a robot's log (ROS 2 bag: MCAP or sqlite3; ROS 1 bag; CSV; Parquet) "
                                       "through a mapping file: static double-support segments found, one "
                                       "recording each (docs/log-import.md)",
                        description="Read the log through the mapping file, align its streams onto one clock, find "
                                    "the static double-support segments (or take --ranges), and write a session "
                                    "folder of recordings for `calibrate`, with the timeline (text, "
                                    "session.json, timeline.png).")
    robot_args(im)
    im.add_argument("--log", nargs="+", default=None, metavar="PATH",
                    help="the log: a ROS 2 bag folder (or its .mcap/.db3 file), ROS 1 .bag file(s), or .csv/.parquet "
                         "table(s) (required)")
    im.add_argument("--map", default=None, metavar="MAP.yaml",
                    help="the mapping file: topics or columns, joint names with sign and unit, IMU and F/T frames, "
                         "time source, sensor model (required; --example-map prints one)")
    im.add_argument("--out", default=None, metavar="SESSION",
                    help="session folder to write (required; replaced only if it holds an earlier session)")
    im.add_argument("--heldout", nargs="+", default=[], metavar="SEGMENT",
                    help="segment names to keep out of calibration, for scoring the result (default: none)")
    im.add_argument("--ranges", nargs="+", default=None, metavar="START:END",
                    help="take these time ranges (seconds from the log's first stamp) as the segments instead of "
                         "detecting them (default: detect)")
    im.add_argument("--no-plot", action="store_true", help="do not draw timeline.png (default: draw it)")
    im.add_argument("--example-map", action="store_true",
                    help="print a commented mapping file for --robot and exit")
    im.add_argument("--json", action="store_true", help="print the import summary as JSON (default: text)")
    im.set_defaults(func=cmd_import)

    sl = sub.add_parser("simulate-log", help="simulate a long robot log (standing, four stances, walking, stepping "
                                             "in place) with injected offsets and write it as a bag or table with "
                                             "its mapping file",
                        description="A simulated stand-in for a robot's log, to try `import` and `calibrate` end to "
                                    "end; the injected offsets are written apart (truth.json).")
    robot_args(sl)
    sl.add_argument("--format", default="mcap", choices=LOG_FORMATS, help="log format (default mcap)")
    sl.add_argument("--out", required=True, help="new folder for the log, mapping.yaml and truth.json")
    sl.add_argument("--seed", type=int, default=0, help="offsets, noise and placement seed: an integer in "
                                                        "[0, 2^32 - 1] (default 0)")
    sl.add_argument("--sensors", default="realistic", help=f"sensor preset: {', '.join(SENSOR_PRESET_NAMES)} "
                                                           "(default realistic)")
    sl.add_argument("--no-ft", action="store_true", help="log no ankle force/torque (default: log them)")
    sl.add_argument("--unknown-sensors", action="store_true",
                    help="write `sensor_model: unknown` in the mapping (default: the preset's declaration)")
    sl.add_argument("--quiet", action="store_true", help="no progress bar")
    sl.set_defaults(func=cmd_simulate_log)

    rp = sub.add_parser("report", help="write a calibration report for a robot engineer (markdown, HTML, figures): "
                                       "timeline, segments used, per-stance residuals before/after, posterior "
                                       "standard deviations, undetermined combinations, warnings with their fixes, "
                                       "the commands to reproduce",
                        description="Read a session folder (imported with `import`, or simulated with `collect`) and "
                                    "the result `calibrate` wrote from it, and write a report folder: report.md, "
                                    "report.html, report.json and PNG figures.")
    rp.add_argument("--bags", required=True, metavar="SESSION",
                    help="the session folder the result was calibrated from (required; no default)")
    rp.add_argument("--result", required=True, metavar="RESULT.json",
                    help="the result JSON `legcal-bench calibrate --out` wrote (required; no default)")
    rp.add_argument("--out", required=True, metavar="DIR",
                    help="report folder to write (required; no default; replaced only if it holds an earlier "
                         "report)")
    rp.add_argument("--robot", default=None,
                    help="built-in robot name or leg-map YAML path (default: the one the result was calibrated for)")
    rp.set_defaults(func=cmd_report)


def cmd_report(a: argparse.Namespace) -> int:
    door(a, out=inputs.output_folder)
    from legcal_bench.reports.calibration_report import write_calibration_report

    page = write_calibration_report(a.bags, a.result, a.out, robot=a.robot)
    print(f"wrote {a.out}:")
    for p in sorted(page.parent.iterdir()):
        print(f"  {p}")
    return 0
