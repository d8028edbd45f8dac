"""Robots as they come: generated robots with every hip order, soft servos and narrow
ankles run the whole tool through their leg maps alone; a robot that cannot hold a
posture is an error (collect) or a failed cell (bench), never data."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from legcal_bench.cli import main
from legcal_bench.errors import ConfigError, HoldError
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.protocol.servos import DEFAULT_KP_PER_MGL, servo_gains, total_mass
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import GENERATED, HIP_ORDERS, stiff_twin
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.sim.hold import HOLD_LIMITS, HoldReport

# bench and sweep run their cells in this process (`in_process_cells`): what is checked
# is what they compute through a leg map; the worker pool is tested in tests/benchmark.
SHORT = ["--stance-seconds", "4", "--heldout-seconds", "2", "--standing-seconds", "1", "--heldout", "1", "--quiet"]
NAMES = [d.name for d in GENERATED]


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> dict[str, Path]:
    """Leg-map paths of the generated robots and their stiff-servo twins."""
    out = tmp_path_factory.mktemp("generated")
    paths = {}
    for d in GENERATED:
        paths[d.name] = write_robot(d, out)
        paths[d.name + "_stiff"] = write_robot(stiff_twin(d), out)
    return paths


def test_the_generated_robots_cover_every_hip_order_gain_and_ankle_range():
    assert sorted(d.hip_order for d in GENERATED) == sorted(HIP_ORDERS) and len(set(HIP_ORDERS)) == 6
    assert {(d.servos["knee"].kp, d.limits["ankle_pitch"][1]) for d in GENERATED} == {
        (kp, np.deg2rad(a)) for kp in (10.0, 30.0, 100.0) for a in (25.0, 35.0)}


def _score(tmp_path, capsys, robot: Path, bags: Path, *calibrate_args) -> dict:
    result = tmp_path / f"{bags.name}.json"
    assert main(["calibrate", "--robot", str(robot), "--bags", str(bags), "--out", str(result), *calibrate_args]) == 0
    capsys.readouterr()
    assert main(["score", "--bags", str(bags), "--result", str(result), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


# The test command runs the first robot (pitch first, the softest servos, the narrowest
# ankles); the other five hip orders are `slow` (`make test-slow`): about 65 s of CPU each,
# more than the 5-minute budget holds.
@pytest.mark.parametrize("name", [NAMES[0]] + [pytest.param(n, marks=pytest.mark.slow) for n in NAMES[1:]])
def test_a_generated_robot_runs_every_command_through_its_leg_map(name, generated, tmp_path, capsys, in_process_cells):
    robot, twin = generated[name], generated[name + "_stiff"]
    # Zero-noise kinematic recovery, stances shrunk to fit the narrow ankles.
    bags = tmp_path / "kinematic"
    assert main(["collect", "--robot", str(robot), "--mode", "kinematic", "--sensors", "zero", "--out", str(bags),
                 "--json", *SHORT]) == 0
    summary = json.loads(capsys.readouterr().out)
    scales = {g["stance"]: g["stance_scale"] for g in summary["segments"]}
    assert scales["II"] < 1.0 and scales["III"] < 1.0  # the lunges need more ankle than +-35 deg
    s = _score(tmp_path, capsys, robot, bags, "--setting", "matched")
    assert s["recovery"]["rms_error_deg"] < 1e-10 and s["recovery"]["max_error_deg"] < 1e-10

    # Weld and contact: the MJCF's soft servos fold, the default gains hold every segment.
    for mode in ("weld", "contact"):
        bags = tmp_path / mode
        assert main(["collect", "--robot", str(robot), "--mode", mode, "--out", str(bags), "--json", *SHORT]) == 0
        summary = json.loads(capsys.readouterr().out)
        assert set(summary["servo_gains"]["source"]) == {"default"}
        assert "do not hold stance I" in summary["servo_gains"]["note"]
        assert all(g["hold"]["held"] for g in summary["segments"])
        assert max(g["hold"]["pelvis_mm"] for g in summary["segments"]) > 0.5  # measured, not skipped
    weld = _score(tmp_path, capsys, robot, tmp_path / "weld")
    assert main(["collect", "--robot", str(twin), "--mode", "weld", "--out", str(tmp_path / "twin"), *SHORT]) == 0
    capsys.readouterr()
    stiff = _score(tmp_path, capsys, twin, tmp_path / "twin")
    assert weld["recovery"]["rms_error_deg"] <= 2 * stiff["recovery"]["rms_error_deg"], (weld, stiff)

    # bench and sweep through the leg map: every cell computed, none failed.
    assert main(["bench", "--suite", "smoke", "--robot", str(robot), "--out", str(tmp_path / "lb"),
                 "--data", str(tmp_path / "lbdata"), "--quiet"]) == 0
    cells = [json.loads(p.read_text()) for p in (tmp_path / "lb" / "results").rglob("*.json")]
    assert len(cells) >= 3 and not [c["error"] for c in cells if "error" in c]
    capsys.readouterr()
    assert main(["sweep", "--robot", str(robot), "--seeds", "1", "--scales", "1", "--stance-seconds", "4",
                 "--heldout", "1", "--out", str(tmp_path / "sweep"), "--quiet"]) == 0
    assert ", 0 failed;" in capsys.readouterr().out


@pytest.fixture(scope="module")
def floppy(tmp_path_factory, generated) -> Path:
    """A generated robot whose leg map forces servo gains far too soft to stand."""
    path = generated[NAMES[0]]
    d = yaml.safe_load(path.read_text())
    d["mjcf"] = str(path.parent / d["mjcf"])
    names = [j["name"] for side in ("left", "right") for j in d["legs"][side]["joints"]]
    d["servo_gains"] = {n: [20.0, 0.8] for n in names}
    out = tmp_path_factory.mktemp("floppy") / "floppy.legmap.yaml"
    out.write_text(yaml.safe_dump(d))
    return out


def test_a_robot_that_cannot_hold_is_an_error_in_collect(floppy, tmp_path, capsys):
    gains = servo_gains(load_robot(floppy))
    assert set(gains.source) == {"leg map"} and gains.kp[0] == 20.0  # overrides the position actuators
    with pytest.raises(HoldError, match=r"segment standing, stance standing .* did not hold the posture: the pelvis "
                                        r"was .* mm from its commanded pose .*servo_gains"):
        collect(CollectConfig(robot=str(floppy), mode="weld", stance_s=2.0, heldout=0, standing_s=1.0),
                tmp_path / "out", progress=False)
    assert not (tmp_path / "out").exists()  # nothing half-written for calibrate to accept
    assert main(["collect", "--robot", str(floppy), "--mode", "weld", "--out", str(tmp_path / "cli"), *SHORT]) == 2
    assert "did not hold the posture" in capsys.readouterr().err


def test_a_robot_that_cannot_hold_is_a_failed_cell_in_bench(floppy, tmp_path, capsys, in_process_cells):
    assert main(["bench", "--suite", "smoke", "--robot", str(floppy), "--calibrators", "zero",
                 "--out", str(tmp_path / "lb"), "--data", str(tmp_path / "data"), "--quiet"]) == 1
    assert "cells failed" in capsys.readouterr().err  # the run says how many failed and why, and exits 1
    cells = [json.loads(p.read_text()) for p in (tmp_path / "lb" / "results").rglob("*.json")]
    assert cells and all("did not hold the posture" in c["error"] for c in cells)
    assert "HoldError" in cells[0]["error"] and "collecting floppy_weld_s00" in cells[0]["error"]


def test_builtin_robots_keep_their_mjcf_gains_and_the_default_follows_mass_and_leg_length():
    for robot in ("a2", "a3"):
        g = servo_gains(load_robot(robot))
        assert set(g.source) == {"MJCF"} and "hold stance I" in g.note
    lm = load_robot("a3")
    mgl = total_mass(lm) * 9.81 * LegKinematics(lm).dims.leg_length
    assert mgl == pytest.approx(54.5 * 9.81 * 0.935, rel=1e-3)
    # Twice the A3-like robot's own servos per m g L.
    assert DEFAULT_KP_PER_MGL["knee"] * mgl == pytest.approx(2 * 2000.0, rel=1e-3)
    assert DEFAULT_KP_PER_MGL["hip_pitch"] * mgl == pytest.approx(2 * 1500.0, rel=1e-3)


def test_hold_report_limits():
    L = 0.9
    ok = {"pelvis_hold_error_m": np.array([0.0, 0.04]), "sole_drift_m": np.array([[0.0, 0.001], [0.0019, 0.0]]),
          "sole_drift_rad": np.full((2, 2), np.deg2rad(0.9))}
    assert HoldReport.from_truth(ok, L).held
    assert HOLD_LIMITS.pelvis_leg_fraction * L == pytest.approx(0.045)
    bad = {**ok, "pelvis_hold_error_m": np.array([0.046]), "sole_drift_m": np.array([[0.0, 0.0021]]),
           "sole_drift_rad": np.array([[np.deg2rad(1.1), 0.0]])}
    f = HoldReport.from_truth(bad, L).failures()
    assert f == ["the pelvis was 46.0 mm from its commanded pose (limit 45.0 mm, 5 % of the leg length)",
                 "the left sole tilted 1.10 deg (limit 1 deg)", "the right sole moved 2.1 mm (limit 2 mm)"]


def test_collect_replaces_an_earlier_session_set_but_not_other_files(tmp_path):
    cfg = CollectConfig(robot="a3", mode="kinematic", stance_s=0.4, heldout=0, standing_s=0.2, stances=("I",))
    collect(cfg, tmp_path / "s", progress=False)
    collect(cfg, tmp_path / "s", progress=False)  # an earlier set is replaced whole
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == [
        "session.json", "stance_I.npz", "stance_I.truth.npz", "standing.npz", "standing.truth.npz"]
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    with pytest.raises(ConfigError, match="exists and holds other files"):
        collect(cfg, tmp_path / "mine", progress=False)
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"


def test_bench_takes_collects_stance_and_mjcf_options(tmp_path, capsys, in_process_cells):
    from legcal_bench.robots import ASSETS

    assert main(["bench", "--suite", "smoke", "--robots", "a2", "a3", "--mjcf", str(ASSETS / "a3.xml"),
                 "--quiet"]) == 2
    assert "--mjcf replaces one robot's model" in capsys.readouterr().err
    assert main(["bench", "--suite", "smoke", "--robot", "a3", "--mjcf", str(ASSETS / "a3.xml"), "--stances",
                 "I", "IV", "--calibrators", "zero", "--out", str(tmp_path / "lb"), "--data", str(tmp_path / "data"),
                 "--quiet"]) == 0
    sets = sorted(p.name for p in (tmp_path / "data").iterdir())
    assert sets[0].startswith("a3_weld_s00_x1_injected_") and "mjcfa3" in sets[0] and "stancesI-IV" in sets[0]
    held = [json.loads((tmp_path / "data" / s / "session.json").read_text()) for s in sets]
    for m in held:
        assert m["config"]["stances"] == ["I", "IV"]
        assert {v["stance"] for k, v in m["stances"].items() if k.startswith("heldout")} <= {"I", "IV"}
