"""A model-gap case the robot cannot do is a row of its own, counted and listed in the
report, not an error ending the suite's run (issue #61: the five-joint robot's run
stopped at its first leg-length case); a clean case it cannot do is still an error."""

import json

import pytest

from legcal_bench.benchmark import modelgap as mg
from legcal_bench.errors import IKError
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import VARIATIONS

PROV = {"key": "k", "code": {"commit": "c0ffee"}, "command": "test"}


@pytest.fixture(scope="module")
def five(tmp_path_factory) -> str:
    return str(write_robot(next(d for d in VARIATIONS if d.name == "five_joint"), tmp_path_factory.mktemp("five")))


def test_an_edit_of_a_joint_the_robot_lacks_is_not_run_and_says_which(five, tmp_path):
    job = (five, "outside", "ankle_axes_distance", 0, None, mg.DEFAULT_CALIBRATOR)
    row = json.loads(open(mg.run_job(job, str(tmp_path), PROV)).read())["row"]
    assert row["not_run"] == ("joint_offset:joint=left_ankle_roll,axis=z,mm=1.5: the robot's legs have no "
                              "ankle_roll joint")
    assert (row["robot"], row["kind"], row["name"], row["seed"], row["side"]) == ("five_joint", "outside",
                                                                                   "ankle_axes_distance", 0, "left")
    # Six-joint legs have the joint: nothing lacking.
    assert mg._lacking_role("a3", ("joint_offset:joint=left_ankle_roll,axis=z,mm=1.5",)) is None


def test_an_effect_the_robot_cannot_stand_with_is_not_run_and_listed_in_the_report(five, tmp_path):
    # Legs without ankle roll stand straight-legged with both soles flat only if the legs
    # are as long: a shank 2.8 mm shorter makes the standing phase out of reach.
    job = (five, "library", "leg_length", 0, None, mg.DEFAULT_CALIBRATOR)
    row = json.loads(open(mg.run_job(job, str(tmp_path), PROV, {"stance_s": 1.0, "standing_s": 0.5})).read())["row"]
    assert row["spec"] == mg.library_spec("leg_length", 0) and "straight-leg standing" in row["not_run"]
    ran = {"robot": "five_joint", "kind": "clean", "name": None, "seed": 0, "verdict": "explained", "selected": [],
           "ambiguous": [], "at_truth": {"training": 1.0}, "offsets_rms_deg": {"before": 0.01, "after": 0.01},
           "p_value": 0.5, "z": 0.0, "poor_fit": []}
    summary = mg.summarize([ran, row])
    skipped = [s for s in summary if s["case"] == "not run"]
    assert len(skipped) == 1 and skipped[0]["seeds"] == 1 and skipped[0]["cases"][0].startswith("library leg_length seed 0:")
    assert not any(s["case"] == "leg_length" for s in summary)  # not counted as a library case
    page = mg.markdown({"summary": summary, "rows": [ran, row]}, "test", "c0ffee")
    assert "five_joint: 1 case(s) not run, the robot cannot do them" in page and "- library leg_length seed 0:" in page


def test_a_clean_case_the_robot_cannot_do_is_an_error_naming_it(monkeypatch, tmp_path):
    def unreachable(*a, **k):
        raise IKError("stance standing (straight-leg standing): its nominal posture is out of this robot's reach")

    monkeypatch.setattr(mg, "run_case", unreachable)
    with pytest.raises(IKError, match="the model-gap case clean seed 3 on a3: stance standing"):
        mg.run_job(("a3", "clean", None, 3, None, mg.DEFAULT_CALIBRATOR), str(tmp_path), PROV)
    assert not list(tmp_path.rglob("*.json"))


def test_a_generated_robot_runs_by_name_its_model_written_beside_the_cases(monkeypatch, tmp_path):
    seen = []

    def fake(robot, kind, name, seed, stances=None, calibrator=mg.DEFAULT_CALIBRATOR, collect=None):
        seen.append(robot)
        return {"robot": "five_joint", "kind": kind, "name": name, "seed": seed, "selected": [], "ambiguous": [],
                "verdict": "explained", "p_value": 0.5, "z": 0.0, "scale": None, "confounded": [],
                "at_truth": {"training": 1.0}, "offsets_rms_deg": {"before": 0.01, "after": 0.01}}

    monkeypatch.setattr(mg, "run_case", fake)
    monkeypatch.setattr(mg, "code_identity", lambda code: {"commit": "c0ffee"})
    data = mg.run(["five_joint"], clean_seeds=1, cases=("clean",), workers=1, progress=False, out=tmp_path)
    assert seen == [str(tmp_path / "_robots" / "five_joint.legmap.yaml")] * 2  # clean, clean_kinematic
    case = json.loads((tmp_path / "five_joint" / "clean" / "seed00.json").read_text())
    assert "robots=['five_joint']" in case["provenance"]["command"] and data["cases"]["computed"] == 2
