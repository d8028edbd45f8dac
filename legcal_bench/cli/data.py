"""`legcal-bench collect`: simulate a session set."""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import asdict

from legcal_bench import inputs
from legcal_bench.cli.robots import door, robot_args
from legcal_bench.sim.names import EFFECTS_HELP, PRESETS_HELP, SENSOR_PRESET_NAMES


def cmd_collect(a: argparse.Namespace) -> int:
    door(a, out=inputs.output_folder)
    from legcal_bench.protocol.collect import CollectConfig, collect, format_summary

    # CollectConfig checks every other value (rate, durations, seed, counts, the knee's
    # error) before anything is simulated, naming the option.
    mjcf_file = a.sim_model is not None and a.sim_model.lower().endswith(".xml")
    cfg = CollectConfig(
        robot=a.robot, mjcf=a.mjcf, sim_robot=None if mjcf_file else a.sim_model,
        sim_model=a.sim_model if mjcf_file else None, effects=tuple(a.effect or ()), mode=a.mode,
        stances=tuple(a.stances),
        offsets=a.offsets, sensors=a.sensors, seed=a.seed, heldout=a.heldout, rate_hz=a.rate,
        stance_s=a.stance_seconds, heldout_s=a.heldout_seconds, standing_s=a.standing_seconds,
        knee_straight_error_rad=math.radians(a.knee_error_deg), period_scale=a.period_scale,
        protocol=a.protocol, standing=a.standing, contact_floor=a.floor)
    summary = collect(cfg, a.out, progress=not a.quiet)
    print(json.dumps(asdict(summary), indent=2) if a.json else format_summary(summary))
    return 0


def add_commands(sub) -> None:
    c = sub.add_parser("collect", help="simulate static double-support recordings with known offsets",
                       description="Simulate a session set on the static double-support env: a straight-leg "
                                   "standing phase, the stances (I to IV, or a protocol file's) and held-out "
                                   "sessions, the encoders reading the injected offsets. Each recording is a file "
                                   "with its ground truth kept beside it (for `score`), plus a session manifest; "
                                   "the folder is what `calibrate --bags` reads.")
    robot_args(c)
    c.add_argument("--sim-model", default=None,
                   help="simulate this instead: an MJCF file (.xml; an edited copy of the robot's, same joint "
                        "names: the generic model gap) or a robot (name or leg map); recordings still name "
                        "--robot, the nominal model calibrators use (default: --robot's own model)")
    c.add_argument("--effect", action="append", default=None, metavar="NAME:key=value,...",
                   help=f"a reality effect the calibration model lacks (repeatable; default: none; only the ground "
                        f"truth says it is there): {EFFECTS_HELP}")
    c.add_argument("--mode", default="weld", choices=("kinematic", "weld", "contact"), help="floor model (default weld)")
    c.add_argument("--stances", nargs="+", default=["I", "II", "III", "IV"],
                   help="stances to record (default I II III IV; the optional load-varied push and press: feet "
                        "pushed against the floor, for compliance)")
    c.add_argument("--offsets", default="paper", help=f"injected offsets: {PRESETS_HELP} (default paper)")
    c.add_argument("--sensors", default="realistic", choices=sorted(SENSOR_PRESET_NAMES), help="sensor model (default realistic)")
    c.add_argument("--seed", type=int, default=0, help="placement, motion, noise and random-offset seed: an "
                                                       "integer in [0, 2^32 - 1] (default 0)")
    c.add_argument("--heldout", type=int, default=3, help="held-out sessions, 0 to 100 (default 3)")
    c.add_argument("--rate", type=float, default=50.0, help="logging rate, Hz: 1 to 1000, one frame per 1 ms physics "
                                                            "step at the fastest (default 50)")
    c.add_argument("--stance-seconds", type=float, default=12.0, help="seconds of each stance (default 12; at least "
                                                                      "two frames, at most 3600)")
    c.add_argument("--heldout-seconds", type=float, default=10.0, help="seconds of each held-out session (default 10)")
    c.add_argument("--standing-seconds", type=float, default=5.0, help="straight-leg phase, seconds (0: none; "
                                                                       "default 5)")
    c.add_argument("--knee-error-deg", type=float, default=0.3,
                   help="true knee minus mechanical straight angle while standing, deg, within +-5 (default 0.3)")
    c.add_argument("--protocol", default=None, help="a protocol file (legcal-bench design --out): record its stances "
                                                    "instead of --stances (default: none, --stances)")
    c.add_argument("--period-scale", type=float, default=1.0,
                   help="slower posture motion: its periods x this (2: a quarter of the IMU's motion acceleration; "
                        "give --stance-seconds x this to cover the same motion)")
    c.add_argument("--standing", default="auto", choices=("auto", "cop", "none"),
                   help="standing controller: cop moves the ankles' targets so each sole's centre of pressure stays "
                        "centred (from the ankle force/torque sensors; docs/contact-floor.md), none holds the "
                        "planned targets; auto (default): cop on a contact floor for a robot with ankle sensors")
    c.add_argument("--floor", default="", metavar="KEY=VALUE,...",
                   help="the contact floor's parameters changed from the documented table (docs/contact-floor.md), "
                        "for robustness studies: timeconst (s), dampratio, dmin, dmax, friction (sliding)")
    c.add_argument("--out", default="runs/collect",
                   help="output directory, checked writable before anything is simulated (default runs/collect)")
    c.add_argument("--json", action="store_true", help="print the summary as JSON")
    c.add_argument("--quiet", action="store_true", help="no progress bar")
    c.set_defaults(func=cmd_collect)
