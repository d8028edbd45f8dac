"""The docs' example plug-in (docs/examples/dispersion_plugin), registered from a
temporary package's entry point, runs through everything the framework offers a
method: calibrate, diagnose, the model-gap suite and the closed-loop evaluation
(issue #35). Its code in docs/calibrators.md is the file's, so the docs cannot drift."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from legcal_bench.cli import main
from legcal_bench.data.recording import list_segments, load_truth
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "dispersion_plugin"
DOCS = Path(__file__).resolve().parents[2] / "docs" / "calibrators.md"


@pytest.fixture
def dispersion(install_plugin):
    install_plugin("dispersion_method", (EXAMPLE / "dispersion_method.py").read_text(), "dispersion",
                   "DispersionCalibrator")


def test_the_docs_show_the_example_as_it_is():
    text = DOCS.read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert (EXAMPLE / "dispersion_method.py").read_text() in blocks
    entry = re.search(r'^dispersion = "(.*)"$', (EXAMPLE / "pyproject.toml").read_text(), re.M).group(1)
    assert f'dispersion = "{entry}"' in text


def test_the_example_recovers_zero_noise_offsets_for_any_robot_it_is_given(dispersion, tmp_path):
    for robot in ("a3", "pair_pry"):
        out = tmp_path / robot
        collect(CollectConfig(robot=robot, mode="kinematic", sensors="zero", seed=1, stances=("I", "II", "III"),
                              stance_s=4.0, heldout=0, standing_s=1.0), out, progress=False)
        assert main(["calibrate", "--robot", robot, "--bags", str(out), "--calibrator", "dispersion",
                     "--option", "frames=40", "--out", str(tmp_path / f"{robot}.json")]) == 0
        res = json.loads((tmp_path / f"{robot}.json").read_text())
        truth = load_truth(list_segments(out)[0]).offsets
        est = np.array([res["offsets_rad"][n] for n in load_robot(robot).joint_names])
        assert np.rad2deg(np.abs(est - truth).max()) < 1e-8, robot


def test_the_example_runs_through_diagnose_the_model_gap_suite_and_the_closed_loop(dispersion, tmp_path,
                                                                                  monkeypatch, collected):
    # The model-gap suite keeps its cases under --out (lb/modelgap/cases), a fresh folder
    # here, so that every run computes them (never reuses an earlier run's) and parallel
    # test processes share nothing; the working directory is the test's too. Its cases
    # record this test's short sessions.
    from legcal_bench.benchmark import modelgap

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(modelgap, "COLLECT", {"stance_s": 4.0, "standing_s": 1.0})
    # Read only: shared per test process (test_training_only collects the same set).
    bags = collected(robot="a3", mode="weld", sensors="calibrated-imu", seed=0, stances=("I", "II", "III"),
                     stance_s=4.0, heldout=1, heldout_s=2.0, standing_s=1.0)
    assert main(["diagnose", "--robot", "a3", "--bags", str(bags), "--calibrator", "dispersion",
                 "--out", str(tmp_path / "dg"), "--quiet"]) == 0
    doc = json.loads((tmp_path / "dg" / "diagnosis.json").read_text())
    assert doc["start"]["calibrator"] == "dispersion" and doc["verdict"] == "explained"
    assert main(["bench", "--suite", "modelgap", "--cases", "clean", "--seeds", "1", "--robots", "a3",
                 "--calibrators", "dispersion", "--stances", "I", "II", "III", "--workers", "1",
                 "--out", str(tmp_path / "lb"), "--quiet"]) == 0
    rows = json.loads((tmp_path / "lb" / "modelgap" / "modelgap.json").read_text())["rows"]
    assert len(rows) == 4 and all(r["calibrator"]["name"] == "dispersion" for r in rows)
    cases = [json.loads(p.read_text()) for p in (tmp_path / "lb" / "modelgap" / "cases").rglob("*.json")]
    assert len(cases) == 4 and not (tmp_path / "runs").exists()  # under --out, not the working directory
    assert all(c["provenance"]["command"].startswith("legcal-bench bench --suite modelgap") for c in cases)
    assert "`dispersion` (offsets the diagnosis starts from)" in (tmp_path / "lb" / "modelgap" / "modelgap.md").read_text()
    assert main(["walk-eval", "--robot", "a3", "--policy", "a3", "--calibrator", "dispersion", "--trials", "2",
                 "--seconds", "1", "--workers", "1", "--out", str(tmp_path / "we"), "--quiet"]) == 0
    trials = json.loads(next((tmp_path / "we").glob("*.json")).read_text())
    assert "dispersion" in json.dumps(trials)
