"""Every command-line argument is checked at the door, before any work (issue #42): a bad
value, an output path that cannot be written, an unreachable scheduler, another robot's
result or leg map is refused with exit code 2 and one line naming the option, at once;
`bench` and `sweep` exit 1 when a cell failed, saying how many and why."""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path

import pytest

from legcal_bench.cli import main

A3_POLICY = ["--robot", "a3", "--policy", "a3"]
LEGMAP = Path(__file__).resolve().parents[2] / "legcal_bench" / "robots" / "assets" / "a3.legmap.yaml"


# ------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def places(tmp_path_factory) -> dict:
    """Paths the cases name: a file (under which no folder can be made, even as root),
    a folder, another robot's calibration result, a session set of pair_ryp and a leg
    map of a3 with a misspelt knee."""
    from legcal_bench.calibrators.base import CalibrationResult
    from legcal_bench.protocol.collect import CollectConfig, collect
    from legcal_bench.robots import load_robot

    root = tmp_path_factory.mktemp("door")
    (root / "afile").write_text("x")
    (root / "adir").mkdir()
    names = load_robot("pair_ryp").joint_names
    CalibrationResult("zero", "pair_ryp", {n: 0.0 for n in names}, settings={"robot_spec": "pair_ryp"}).save(
        root / "ryp_result.json")
    collect(CollectConfig(robot="pair_ryp", mode="kinematic", stances=("I",), stance_s=0.4, standing_s=0.2,
                          heldout=0), root / "ryp", progress=False)
    collect(CollectConfig(robot="a3", mode="kinematic", stances=("I",), stance_s=0.4, standing_s=0.2, heldout=0),
            root / "a3set", progress=False)
    text = LEGMAP.read_text().replace("mjcf: a3.xml", f"mjcf: {LEGMAP.parent / 'a3.xml'}")
    (root / "typo.legmap.yaml").write_text(text.replace("left_knee_joint", "left_kne_joint", 1))
    with socket.socket() as s:  # a port where nothing listens (bound, then freed)
        s.bind(("127.0.0.1", 0))
        closed = s.getsockname()[1]
    return {"root": root, "closed": f"tcp://127.0.0.1:{closed}", "impostor": _impostor()}


def _impostor() -> str:
    """A TCP server that answers like an HTTP proxy (as a transparent proxy does for
    any address): it accepts, but it is no Dask scheduler."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)

    def serve():
        while True:
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            with conn:
                try:
                    conn.sendall(b"HTTP/1.1 400 Bad Request\r\nconnection: close\r\n\r\n")
                except OSError:
                    pass

    threading.Thread(target=serve, daemon=True).start()
    return f"tcp://127.0.0.1:{srv.getsockname()[1]}"


@pytest.fixture
def no_work(monkeypatch):
    """Every command's work (simulation, calibration, walks, the runner) fails the test if
    reached: a refusal must come first."""
    import importlib

    def reached(*args, **kwargs):
        raise AssertionError("the work started before the bad argument was refused")

    for module, names in {
        "legcal_bench.protocol.collect": ["_collect"],
        "legcal_bench.benchmark.runner": ["run", "make_executor"],
        "legcal_bench.benchmark.modelgap": ["run"],
        "legcal_bench.benchmark.closed_loop": ["run_closed_loop_suite"],
        "legcal_bench.envs.walking": ["WalkingEnv"],
        "legcal_bench.envs.static_double_support": ["StaticDoubleSupportEnv"],
        "legcal_bench.evaluation.walk": ["walk", "walk_trials"],
        "legcal_bench.evaluation.closed_loop": ["evaluate"],
        "legcal_bench.evaluation.modelgap": ["diagnose"],
        "legcal_bench.evaluation.excitation": ["learn_excitation"],
        "legcal_bench.evaluation.distill": ["train"],
        "legcal_bench.estimation.information.design": ["design"],
        "legcal_bench.calibrators.base": ["calibrate_training"],
        "legcal_bench.api.logs": ["simulate_log"],
        "legcal_bench.logs.importer": ["import_log"],
        "legcal_bench.reports.calibration_report": ["write_calibration_report"],
        "legcal_bench.robots.export": ["write_offsets_yaml"],
        "legcal_bench.benchmark.leaderboard": ["generate"],
        "legcal_bench.reports.reproduce": ["reproduce"],
        "legcal_bench.reports.bench_speed": ["run_bench_speed", "rerender"],
        "legcal_bench.reports.bench_env": ["run_bench_env"],
        "legcal_bench.reports.robots_check": ["run_data_checks", "run_robots_check"],
        "legcal_bench.reports.effects_table": ["build"],
        "legcal_bench.reports.contact_table": ["build"],
        "legcal_bench.reports.contact_floor": ["build"],
        "legcal_bench.reports.contact_holds": ["build"],
        "legcal_bench.reports.regression": ["compute", "update"],
        "legcal_bench.reports.verdicts": ["measure"],
        "legcal_bench.reports.imu_mount": ["measure"],
        "legcal_bench.reports.vendor_cases": ["measure"],
    }.items():
        mod = importlib.import_module(module)
        for name in names:
            monkeypatch.setattr(mod, name, reached)


def run(argv: list[str], capsys) -> tuple[int, list[str], float]:
    """(exit code, stderr lines, seconds) of the command."""
    capsys.readouterr()
    t0 = time.perf_counter()
    try:
        code = main(argv)
    except SystemExit as e:  # argparse's own refusals (a missing value, an unknown flag)
        code = e.code
    elapsed = time.perf_counter() - t0
    return code, capsys.readouterr().err.strip().splitlines(), elapsed


# ---------------------------------------------------------------------- the corpus
# (argv, the option the message names, other words it holds). {root}: the module's
# folder; {closed}: a port nothing listens on; {impostor}: a server that is no scheduler.
OUT = ["--out", "{root}/o"]
CASES = [
    # collect: numbers, counts, seeds, durations against the rate, the knee, outputs
    (["collect", "--seed", "-1", *OUT], "--seed", ["non-negative integer"]),
    (["collect", "--seed", "4294967296", *OUT], "--seed", []),
    (["collect", "--rate", "0", *OUT], "--rate", ["[1, 1000]"]),
    (["collect", "--rate", "-50", *OUT], "--rate", []),
    (["collect", "--rate", "1e6", *OUT], "--rate", ["1 ms physics step"]),
    (["collect", "--rate", "nan", *OUT], "--rate", ["finite"]),
    (["collect", "--stance-seconds", "0", *OUT], "--stance-seconds", []),
    (["collect", "--stance-seconds", "0.01", *OUT], "--stance-seconds", ["2 frames"]),
    (["collect", "--stance-seconds", "1e9", *OUT], "--stance-seconds", ["3600"]),
    (["collect", "--heldout-seconds", "0", *OUT], "--heldout-seconds", []),
    (["collect", "--standing-seconds", "-1", *OUT], "--standing-seconds", []),
    (["collect", "--heldout", "-1", *OUT], "--heldout", []),
    (["collect", "--heldout", "100000", *OUT], "--heldout", []),
    (["collect", "--knee-error-deg", "90", *OUT], "--knee-error-deg", ["90 deg", "5 deg"]),
    (["collect", "--knee-error-deg", "-6", *OUT], "--knee-error-deg", []),
    (["collect", "--period-scale", "0", *OUT], "--period-scale", []),
    (["collect", "--stances", "V", *OUT], "--stances", ["stance 'V'"]),
    (["collect", "--out", "{root}/afile"], "--out", ["is a file"]),
    (["collect", "--out", "{root}/afile/sub"], "--out", ["cannot be made"]),
    # walk: numbers, sensors, outputs, another robot's correction
    (["walk", *A3_POLICY, "--seed", "-1"], "--seed", []),
    (["walk", *A3_POLICY, "--seconds", "0"], "--seconds", []),
    (["walk", *A3_POLICY, "--trials", "-1"], "--trials", []),
    (["walk", *A3_POLICY, "--strip-every", "0"], "--strip-every", []),
    (["walk", *A3_POLICY, "--sensors", "realistc"], "--sensors", ["did you mean 'realistic'"]),
    (["walk", *A3_POLICY, "--out", "{root}/afile/walk.json"], "--out", ["is a file"]),
    (["walk", *A3_POLICY, "--out", "{root}/adir"], "--out", ["is a folder"]),
    (["walk", *A3_POLICY, "--strip", "{root}/afile/strip.png"], "--strip", []),
    (["walk", *A3_POLICY, "--correction", "{root}/ryp_result.json"], "--correction", ["'pair_ryp'", "'a3'"]),
    # walk-eval
    (["walk-eval", *A3_POLICY, "--trials", "0"], "--trials", []),
    (["walk-eval", *A3_POLICY, "--seconds", "-1"], "--seconds", []),
    (["walk-eval", *A3_POLICY, "--workers", "0"], "--workers", []),
    (["walk-eval", *A3_POLICY, "--sweep", "1", "0"], "--sweep", []),
    (["walk-eval", *A3_POLICY, "--static-sensors", "bogus"], "--static-sensors", []),
    (["walk-eval", *A3_POLICY, "--out", "{root}/afile/x"], "--out", []),
    (["walk-eval", *A3_POLICY, "--scheduler", "{closed}"], "--scheduler", ["no scheduler answers"]),
    # diagnose, calibrate, check, score's relatives
    (["diagnose", "--bags", "{root}/ryp", "--out", "{root}/afile/dg"], "--out", []),
    (["diagnose", "--robot", "a3", "--bags", "{root}/ryp", "--result", "{root}/ryp_result.json", *OUT], "--result",
     ["'pair_ryp'", "'a3'"]),
    (["check", "--robot", "a3", "--bags", "{root}/ryp", "--result", "{root}/ryp_result.json"], "--result",
     ["'pair_ryp'", "'a3'"]),
    (["calibrate", "--bags", "{root}/ryp", "--plots", "{root}/afile/plots"], "--plots", []),
    (["calibrate", "--bags", "{root}/ryp", "--out", "{root}/adir"], "--out", ["is a folder"]),
    # a wrong --robot and a misspelt leg-map joint blame the robot and the leg map, not the recording
    (["calibrate", "--robot", "pair_pry", "--bags", "{root}/ryp", "--out", "{root}/r.json"], "--robot",
     ["'pair_ryp'", "'pair_pry'", "--robot pair_ryp"]),
    (["calibrate", "--robot", "{root}/typo.legmap.yaml", "--bags", "{root}/a3set", "--out", "{root}/r.json"],
     "leg map", ["'left_kne_joint' where the recording has 'left_knee_joint'", "legs.<side>.joints"]),
    # bench
    (["bench", "--seeds", "0", *OUT], "--seeds", []),
    (["bench", "--seeds", "-1", *OUT], "--seeds", []),
    (["bench", "--modes", "bogus", *OUT], "--modes", ["kinematic, weld, contact"]),
    (["bench", "--modes", "weld", "wled", *OUT], "--modes", ["did you mean 'weld'"]),
    (["bench", "--workers", "0", *OUT], "--workers", []),
    (["bench", "--workers", "-1", *OUT], "--workers", []),
    (["bench", "--out", "{root}/afile/lb"], "--out", []),
    (["bench", "--data", "{root}/afile/data", *OUT], "--data", []),
    (["bench", "--scheduler", "{closed}", *OUT], "--scheduler", ["no scheduler answers", "--workers"]),
    (["bench", "--scheduler", "{impostor}", *OUT], "--scheduler", ["not a Dask scheduler", "HTTP/1.1"]),
    (["bench", "--scheduler", "tcp://nohost", *OUT], "--scheduler", ["tcp://HOST:PORT"]),
    (["bench", "--period-scale", "0", *OUT], "--period-scale", []),
    (["bench", "--suite", "modelgap", "--effect-seeds", "0", *OUT], "--effect-seeds", []),
    (["bench", "--suite", "closed-loop", "--seeds", "0", *OUT], "--seeds", []),
    # sweep
    (["sweep", "--workers", "0", *OUT], "--workers", []),
    (["sweep", "--workers", "-1", *OUT], "--workers", []),
    (["sweep", "--seeds", "0", *OUT], "--seeds", []),
    (["sweep", "--scales", "1", "0", *OUT], "--scales", []),
    (["sweep", "--mode", "bogus", *OUT], "--mode", []),
    (["sweep", "--stance-seconds", "0", *OUT], "--stance-seconds", []),
    (["sweep", "--heldout", "-1", *OUT], "--heldout", []),
    (["sweep", "--out", "{root}/afile/sw"], "--out", []),
    (["sweep", "--scheduler", "{closed}", *OUT], "--scheduler", []),
    # the other commands' options
    (["train-policy", "--seed", "-1", *OUT], "--seed", []),
    (["train-policy", "--offsets-deg", "-1", *OUT], "--offsets-deg", []),
    (["render", "--seed", "-1", "--out", "{root}/r.png"], "--seed", []),
    (["render", "--out", "{root}/afile/r.png"], "--out", []),
    (["design", "--margin", "0"], "--margin", []),
    (["design", "--seed", "-1"], "--seed", []),
    (["design", "--contact-seeds", "-1"], "--contact-seeds", []),
    (["design", "--plot", "{root}/afile/d.png"], "--plot", []),
    (["excite", "--elite", "0"], "--elite", []),
    (["excite", "--frames", "0"], "--frames", []),
    (["export", "--result", "{root}/ryp_result.json", "--out", "{root}/adir"], "--out", []),
    (["export", "--result", "{root}/ryp_result.json", "--mjcf-out", "{root}/afile/m"], "--mjcf-out", []),
    (["export", "--result", "{root}/ryp_result.json", "--robot", "a3", "--out", "{root}/o.yaml"], "--result",
     ["'pair_ryp'", "'a3'"]),
    (["simulate-log", "--seed", "-1", *OUT], "--seed", []),
    (["simulate-log", "--sensors", "bogus", *OUT], "--sensors", []),
    (["import", "--out", "{root}/afile/s"], "--out", []),
    (["report", "--bags", "{root}/ryp", "--result", "{root}/ryp_result.json", "--out", "{root}/afile/rp"], "--out",
     []),
]


# An output under a folder no file can be made in (as root, os.access says yes to every
# folder: only making the folder or a probe file tells), for every command's every output
# option; each was a traceback after the work (or a run until killed) before issue #58.
NOPE = "/proc/nope"
UNWRITABLE = ["cannot make the folder '/proc/nope' (No such file or directory)", "give a folder you can write to"]
RYP = ["--bags", "{root}/ryp", "--result", "{root}/ryp_result.json"]
CASES += [(argv, option, UNWRITABLE if words is None else words) for argv, option, words in [
    (["collect", "--out", f"{NOPE}/c"], "--out", None),
    (["import", "--log", "{root}/log.mcap", "--map", "{root}/map.yaml", "--out", f"{NOPE}/s"], "--out", None),
    (["simulate-log", "--out", f"{NOPE}/s"], "--out", None),
    (["report", *RYP, "--out", f"{NOPE}/rp"], "--out", None),
    (["render", "--out", f"{NOPE}/r.png"], "--out", None),
    (["diagnose", "--bags", "{root}/ryp", "--out", f"{NOPE}/dg"], "--out", None),
    (["calibrate", "--bags", "{root}/ryp", "--out", f"{NOPE}/r.json"], "--out", ["/proc/nope",
                                                                                  "No such file or directory"]),
    (["calibrate", "--bags", "{root}/ryp", "--plots", f"{NOPE}/p"], "--plots", None),
    (["design", "--out", f"{NOPE}/p.yaml"], "--out", None),
    (["design", "--plot", f"{NOPE}/d.png"], "--plot", None),
    (["excite", "--out", f"{NOPE}/e.json"], "--out", None),
    (["export", "--result", "{root}/ryp_result.json", "--out", f"{NOPE}/o.yaml"], "--out", None),
    (["export", "--result", "{root}/ryp_result.json", "--mjcf-out", f"{NOPE}/m"], "--mjcf-out", None),
    (["export", "--result", "{root}/ryp_result.json", "--ros2-params", f"{NOPE}/p.yaml"], "--ros2-params", None),
    (["export", "--result", "{root}/ryp_result.json", "--urdf-out", f"{NOPE}/r.urdf"], "--urdf-out", None),
    (["walk", *A3_POLICY, "--out", f"{NOPE}/w.json"], "--out", None),
    (["walk", *A3_POLICY, "--strip", f"{NOPE}/s.png"], "--strip", None),
    (["walk-eval", *A3_POLICY, "--out", f"{NOPE}/we"], "--out", None),
    (["train-policy", "--out", f"{NOPE}/t"], "--out", None),
    (["bench", "--data", f"{NOPE}/d", *OUT], "--data", None),
    (["bench", "--out", f"{NOPE}/lb"], "--out", None),
    (["bench", "--suite", "modelgap", "--data", f"{NOPE}/d", *OUT], "--data", None),
    (["bench", "--suite", "modelgap", "--out", f"{NOPE}/lb"], "--out", None),
    (["bench", "--suite", "closed-loop", "--out", f"{NOPE}/lb"], "--out", None),
    (["sweep", "--out", f"{NOPE}/sw"], "--out", None),
    (["leaderboard", "--out", f"{NOPE}/lb"], "--out", None),
    (["reproduce", "--out", f"{NOPE}/r"], "--out", None),
    (["bench-speed", "--out", f"{NOPE}/r"], "--out", None),
    (["bench-speed", "--rerender", "--out", f"{NOPE}/r"], "--out", None),
    (["bench-env", "--out", f"{NOPE}/r"], "--out", None),
    (["robots-check", "--out", f"{NOPE}/r"], "--out", None),
    (["data-checks", "--out", f"{NOPE}/r"], "--out", None),
    (["effects-table", "--out", f"{NOPE}/r"], "--out", None),
    (["contact-table", "--out", f"{NOPE}/r"], "--out", None),
    (["contact-floor", "--out", f"{NOPE}/r"], "--out", None),
    (["contact-holds", "--out", f"{NOPE}/r"], "--out", None),
    (["verdicts", "--out", f"{NOPE}/r"], "--out", None),
    (["imu-mount", "--out", f"{NOPE}/r"], "--out", None),
    (["imu-mount", "--workers", "0", *OUT], "--workers", [">= 1"]),
    (["vendor-cases", "--out", f"{NOPE}/r"], "--out", None),
    (["vendor-cases", "--workers", "0", *OUT], "--workers", [">= 1"]),
    (["regression", "--update", "--fixture", f"{NOPE}/f.json"], "--fixture", None),
    # the report commands' numbers (they skipped the door before #58: these ran until killed)
    (["contact-floor", "--workers", "0", *OUT], "--workers", [">= 1"]),
    (["contact-table", "--seeds", "0", *OUT], "--seeds", ["[1, 100000]"]),
    (["contact-holds", "--workers", "-1", *OUT], "--workers", []),
    (["effects-table", "--seeds", "1000000000", *OUT], "--seeds", ["1000000000", "[1, 100000]"]),
    (["data-checks", "--seeds", "-1", *OUT], "--seeds", ["non-negative integer"]),
    (["data-checks", "--seeds", "0", "4294967296", *OUT], "--seeds", ["4294967296", "[0, 4294967295]"]),
    (["data-checks", "--offsets", "lots", *OUT], "--offsets", ["'lots' not understood"]),
    (["data-checks", "--offsets", "paper", "random:x", *OUT], "--offsets", ["random:<deg>"]),
    (["data-checks", "--offsets", "0.01,x", *OUT], "--offsets", ["'x'", "one radian per leg joint"]),
    (["robots-check", "--seeds", "0", *OUT], "--seeds", []),
    (["bench-env", "--seed", "-1", *OUT], "--seed", []),
    (["bench-env", "--modes", "wled", *OUT], "--modes", ["did you mean 'weld'"]),
    (["bench-speed", "--rounds", "0", *OUT], "--rounds", []),
    (["bench-speed", "--repeats", "0", *OUT], "--repeats", []),
    (["regression", "--workers", "0"], "--workers", []),
    # sizes that would exhaust memory (or never end), refused with the number
    (["walk", *A3_POLICY, "--seconds", "1e9"], "--seconds", ["1000000000.0", "(0, 3600]"]),
    (["walk", *A3_POLICY, "--trials", "1000000"], "--trials", ["1000000", "100000"]),
    (["walk-eval", *A3_POLICY, "--seconds", "1e5"], "--seconds", ["3600"]),
    (["walk-eval", *A3_POLICY, "--trials", "1000000"], "--trials", ["100000"]),
    (["bench", "--seeds", "1000000000", *OUT], "--seeds", ["1000000000", "100000"]),
    (["design", "--frames", "1000000000"], "--frames", ["1000000000", "[1, 2000000]"]),
    (["excite", "--frames", "2000001"], "--frames", ["2000001", "2,000,000 frames"]),
    (["bench", "--suite", "modelgap", "--effect-seeds", "1000000", *OUT], "--effect-seeds", ["100000"]),
    (["sweep", "--seeds", "1000000", *OUT], "--seeds", ["100000"]),
    (["train-policy", "--iterations", "0", *OUT], "--iterations", []),
    (["train-policy", "--rollouts", "1000000", *OUT], "--rollouts", ["100000"]),
    (["train-policy", "--selection-walks", "-1", *OUT], "--selection-walks", ["[0, 100000]"]),
]]


@pytest.mark.parametrize("argv, option, words", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_a_bad_argument_is_refused_at_the_door(places, no_work, capsys, argv, option, words):
    argv = [a.format(**places) for a in argv]
    code, err, elapsed = run(argv, capsys)
    assert code == 2, err
    assert len(err) == 1, err
    line = err[0]
    assert line.startswith(f"legcal-bench {argv[0]}: error: ") and option in line, line
    for w in words:
        assert w in line, (w, line)


def test_the_corpus_is_large_and_touches_every_measured_case():
    assert len(CASES) >= 50
    seen = {(c[0][0], c[1]) for c in CASES}
    for need in [("walk", "--seed"), ("collect", "--seed"), ("collect", "--rate"), ("collect", "--stance-seconds"),
                 ("bench", "--workers"), ("sweep", "--workers"), ("bench", "--scheduler"), ("bench", "--seeds"),
                 ("bench", "--modes"), ("collect", "--heldout"), ("collect", "--knee-error-deg"),
                 ("walk", "--correction"), ("walk", "--out"), ("walk", "--strip"), ("walk-eval", "--out"),
                 ("diagnose", "--out"), ("collect", "--out"), ("bench", "--out")]:
        assert need in seen, need


def test_every_output_option_of_every_command_has_an_unwritable_case():
    """A command (or an output option) added later is in the corpus of refusals too."""
    from legcal_bench.cli import build_parser

    outputs = {(name, action.option_strings[0])
               for name, parser in build_parser().commands().items() for action in parser._actions
               if action.option_strings and (action.dest in ("out", "data", "strip", "plot", "plots", "fixture",
                                                             "ros2_params") or action.dest.endswith("_out"))}
    assert len(outputs) >= 34
    covered = {(argv[0], option) for argv, option, _ in CASES if any(a.startswith(NOPE) for a in argv)}
    assert outputs - covered == set()


# ------------------------------------------------------- bench and sweep exit codes
def _failing_cells(monkeypatch, in_process_cells, reason="CalibrationError: the data cannot determine it"):
    """The runner with every cell failing for `reason` (as `run_cell` records a LegcalError),
    nothing collected."""
    from legcal_bench.benchmark import runner
    from legcal_bench.files.atomic import atomic_write_json

    def run_cell(cell, data_dir, results_dir, provenance=None):
        out = {"cell": {}, "key": cell.key(), "error": reason}
        atomic_write_json(cell.path(Path(results_dir)), out)
        return out

    monkeypatch.setattr(runner, "collect_dataset", lambda ds, data_dir: str(Path(data_dir) / ds.name))
    monkeypatch.setattr(runner, "run_cell", run_cell)


def test_sweep_exits_1_when_a_cell_failed_and_says_how_many_and_why(tmp_path, capsys, monkeypatch,
                                                                      in_process_cells):
    _failing_cells(monkeypatch, in_process_cells)
    assert main(["sweep", "--robots", "a3", "--mode", "kinematic", "--seeds", "1", "--scales", "0.5", "1",
                 "--calibrators", "zero", "--out", str(tmp_path), "--quiet"]) == 1
    captured = capsys.readouterr()
    assert "2 cells computed, 0 already done, 2 failed;" in captured.out
    err = captured.err
    assert "2 of 2 cells failed (1 distinct reason" in err and "2 cells, e.g. " in err
    assert "CalibrationError: the data cannot determine it" in err


def test_failures_are_read_from_the_cells_and_no_cells_is_refused(tmp_path, monkeypatch, in_process_cells):
    from legcal_bench.benchmark import plan as planning
    from legcal_bench.benchmark.runner import failure_summary, failures, run
    from legcal_bench.errors import ConfigError

    _failing_cells(monkeypatch, in_process_cells, reason="x" * 1000)
    cells = planning.plan("sweep", robots=["a3"], modes=["kinematic"], seeds=1, calibrators=["zero"])
    assert run(cells, tmp_path / "data", tmp_path / "results", progress=False)["computed"] == 1
    failed = failures(cells, tmp_path / "results")
    assert len(failed) == 1 and failed[0]["error"] == "x" * 1000
    assert failure_summary(failed, 1).endswith("x" * 400 + " ...")
    assert failure_summary([], 1) == ""
    with pytest.raises(ConfigError, match="no cells to run"):
        run([], tmp_path / "data", tmp_path / "results", progress=False)
    with pytest.raises(ConfigError, match="seeds = 0"):
        planning.plan("sweep", robots=["a3"], modes=["kinematic"], seeds=0, calibrators=["zero"])
    with pytest.raises(ConfigError, match="modes = 'bogus'"):
        planning.plan("sweep", robots=["a3"], modes=["bogus"], seeds=1, calibrators=["zero"])


def test_a_plan_whose_robots_are_all_missing_is_refused(tmp_path):
    import yaml

    from legcal_bench.benchmark import plan as planning
    from legcal_bench.errors import ConfigError

    d = yaml.safe_load(LEGMAP.read_text())
    d["mjcf"] = str(tmp_path / "nowhere" / "robot.xml")
    ghost = tmp_path / "ghost.legmap.yaml"
    ghost.write_text(yaml.safe_dump(d))
    with pytest.warns(planning.MissingRobotWarning), pytest.raises(ConfigError, match="every robot was skipped"):
        planning.plan("sweep", robots=[str(ghost)], modes=["weld"], seeds=1, calibrators=["zero"])


def test_the_python_api_keeps_the_same_rules(tmp_path):
    """The rules live once: CollectConfig and the runner refuse what the options refuse."""
    from legcal_bench.benchmark.runner import check_scheduler, make_executor
    from legcal_bench.errors import ConfigError
    from legcal_bench.protocol.collect import CollectConfig, collect

    for bad, field in ((dict(rate_hz=1e6), "rate_hz"), (dict(seed=-1), "seed"), (dict(heldout=-1), "heldout"),
                       (dict(stance_s=0), "stance_s"), (dict(knee_straight_error_rad=1.0), "knee_straight_error_rad"),
                       (dict(mode="bogus"), "mode"), (dict(standing="cpo"), "standing")):
        with pytest.raises(ConfigError, match=field):
            CollectConfig(**bad)
    CollectConfig(heldout=0, heldout_s=0, standing_s=0)  # none of either: fine
    (tmp_path / "f").write_text("x")
    with pytest.raises(ConfigError, match="out_dir"):
        collect(CollectConfig(), tmp_path / "f" / "set", progress=False)
    with pytest.raises(ConfigError, match="workers = 0"):
        make_executor(None, 0)
    check_scheduler("inproc://127.0.0.1/1/2")  # another protocol: left to the client
    with pytest.raises(ConfigError, match="tcp://HOST:PORT"):
        check_scheduler("tcp://host:port")


def test_every_option_of_the_commands_changed_has_a_help_text():
    from legcal_bench.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for command in ("collect", "walk", "walk-eval", "train-policy", "diagnose", "calibrate", "score", "check",
                    "design", "excite", "export", "bench", "sweep", "compare", "leaderboard", "import",
                    "simulate-log", "report", "info", "render"):
        for action in sub.choices[command]._actions:
            if action.option_strings and action.dest != "help":
                assert action.help, f"{command} {action.option_strings[0]} has no help text"
