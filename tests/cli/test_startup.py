"""The command's start-up stays light (issue #36): building the parser, `--help`, a
command's `--help` and an argument error import none of the numerical packages; each
command imports them in its `cmd_*` function. Checked by module set in a fresh
interpreter, not by timing (`legcal_bench/reports/startup_probe.py` times it)."""

import json
import subprocess
import sys

from legcal_bench.cli import build_parser

HEAVY = ("torch", "mujoco", "dm_control", "pinocchio", "onnxruntime", "matplotlib", "scipy", "dask", "distributed",
         "gymnasium", "numpy")  # numpy too: a tenth of a second of the half-second start-up budget

CHILD = r"""
import contextlib, io, json, sys

heavy, cases = json.loads(sys.argv[1]), json.loads(sys.argv[2])
loaded = lambda: sorted(m for m in heavy if m in sys.modules)
from legcal_bench.cli import build_parser, main

build_parser()
report = {"build_parser": {"loaded": loaded()}}
for argv in cases:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as e:
            code = e.code
    report[" ".join(argv)] = {"exit": code, "loaded": loaded(), "out": out.getvalue(), "err": err.getvalue()}
print(json.dumps(report))
"""


def commands() -> list[str]:
    return list(next(a for a in build_parser()._actions if a.dest == "command").choices)


def start(*cases: list[str]) -> dict:
    """Each case run by `main` in turn in one fresh interpreter: its exit code, output and the
    heavy packages loaded by then."""
    done = subprocess.run([sys.executable, "-c", CHILD, json.dumps(HEAVY), json.dumps(cases)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_help_and_argument_errors_import_no_heavy_package():
    report = start(["--help"], ["calibrate", "--help"], ["calibrate", "--no-such-flag"], ["calibrate", "--calibrator"])
    for case, r in report.items():
        assert r["loaded"] == [], f"{case}: {r['loaded']}"
    assert report["--help"]["exit"] == 0 and "calibrate" in report["--help"]["out"]
    assert report["calibrate --help"]["exit"] == 0 and "--calibrator" in report["calibrate --help"]["out"]
    assert report["calibrate --no-such-flag"]["exit"] == 2  # the missing --bags is named first
    assert "legcal-bench calibrate: error:" in report["calibrate --no-such-flag"]["err"]
    assert report["calibrate --calibrator"]["exit"] == 2
    assert "expected one argument" in report["calibrate --calibrator"]["err"]


def test_every_command_help_imports_no_heavy_package():
    every = commands()
    assert len(every) >= 18 and {"collect", "walk", "train-policy", "bench-speed"} <= set(every)
    report = start(*([c, "--help"] for c in every))
    for case, r in report.items():
        assert r["loaded"] == [], f"{case}: {r['loaded']}"
        if case != "build_parser":
            assert r["exit"] == 0 and r["out"].startswith("usage: legcal-bench"), case


def test_the_options_show_the_facts_of_the_modules_that_use_them(capsys):
    """A fact an option shows (a preset name, a default) is the one the simulation or the
    training uses: kept once, in a light module both import."""
    from legcal_bench.evaluation.distill import DistillConfig
    from legcal_bench.reports.bench_speed import BASELINE
    from legcal_bench.sim.effects import EFFECTS_HELP
    from legcal_bench.sim.offsets import PRESETS_HELP
    from legcal_bench.sim.sensors import SENSOR_PRESETS

    parser = build_parser()
    a = parser.parse_args(["train-policy"])
    assert a.selection_walks == DistillConfig.eval_rollouts and a.func.__name__ == "cmd_train_policy"
    assert (a.iterations, a.rollouts, a.offsets_deg) == (DistillConfig.iterations, DistillConfig.rollouts,
                                                         DistillConfig.offsets_deg)
    collect = next(x for x in parser._subparsers._group_actions[0].choices["collect"]._actions
                   if x.dest == "sensors")
    assert sorted(collect.choices) == sorted(SENSOR_PRESETS)
    assert parser.parse_args(["bench-speed"]).baseline == BASELINE
    assert parser.parse_args(["collect", "--sensors", "zero"]).sensors == "zero"
    for command, shown in (("collect", "imu_tilt (roll, pitch: IMU mounting tilt (deg))"),
                           ("walk", "none | paper | paper@<deg>"), ("bench-speed", f"(default {BASELINE},")):
        try:
            build_parser().parse_args([command, "--help"])
        except SystemExit:
            pass
        assert shown in " ".join(capsys.readouterr().out.split()), command
    # Whole, compared without white space (help wraps lines at hyphens too).
    for command, shown in (("collect", EFFECTS_HELP), ("collect", PRESETS_HELP), ("walk", PRESETS_HELP),
                           ("walk", "sensor preset: " + ", ".join(SENSOR_PRESETS))):
        try:
            build_parser().parse_args([command, "--help"])
        except SystemExit:
            pass
        assert "".join(shown.split()) in "".join(capsys.readouterr().out.split()), (command, shown)
