"""Every result says whether to apply it: each warning classed by what it means for the
offsets, the verdict they add up to, kept through the result file, refused by export
unless forced; a result names the session set it was calibrated on, and score, export
and report refuse another one."""

import json
import pickle

import numpy as np
import pytest

from legcal_bench.calibrators.base import CalibrationResult
from legcal_bench.cli import main
from legcal_bench.errors import CalibrationError
from legcal_bench.estimation.information.uncertainty import bound_warnings
from legcal_bench.estimation.verdict import (APPLY, DO_NOT_APPLY, DOUBTS, HARMLESS, INVALIDATES, LIMITS, REVIEW,
                                             Finding, headline, judge)
from legcal_bench.robots import load_robot

SMALL = dict(mode="kinematic", sensors="realistic", heldout=1, stance_s=3.0, standing_s=1.0, heldout_s=2.0)


def test_the_worst_meaning_decides():
    assert judge([])["verdict"] == APPLY
    assert judge([Finding("a", HARMLESS), Finding("b", LIMITS)])["verdict"] == APPLY
    assert judge([Finding("a", LIMITS), Finding("b", DOUBTS)])["verdict"] == REVIEW
    v = judge([Finding("a", DOUBTS), Finding("b", INVALIDATES), Finding("c", LIMITS)])
    assert v["verdict"] == DO_NOT_APPLY
    assert [r["meaning"] for r in v["reasons"]] == [INVALIDATES, DOUBTS, LIMITS]  # most serious first
    assert v["counts"] == {HARMLESS: 0, LIMITS: 1, DOUBTS: 1, INVALIDATES: 1}
    assert headline(v).startswith("verdict: do-not-apply (1 finding(s) invalidate the result; first: b")


def test_a_warning_no_check_classed_is_a_doubt():
    """A plug-in's own warning (a plain string) is not taken for harmless."""
    assert judge(["my method's own warning"])["verdict"] == REVIEW


def test_a_finding_is_its_text_and_keeps_its_meaning_across_processes():
    f = Finding("offsets at the bound", INVALIDATES)
    assert f == "offsets at the bound" and json.dumps([f]) == '["offsets at the bound"]'
    g = pickle.loads(pickle.dumps(f))
    assert g.meaning == INVALIDATES and g == f
    with pytest.raises(ValueError, match="meaning 'bad'"):
        Finding("x", "bad")


def test_offsets_at_the_bound_invalidate():
    names = ["a", "b"]
    (w,) = bound_warnings(np.array([0.08, 0.01]), 0.08, names)
    assert w.meaning == INVALIDATES
    assert bound_warnings(np.array([0.07, 0.01]), 0.08, names) == []


def _result(warnings, **kw) -> CalibrationResult:
    names = load_robot("a3").joint_names
    return CalibrationResult(calibrator="interfoot", robot="a3", offsets_rad=dict.fromkeys(names, 0.01),
                             warnings=warnings, **kw)


def test_the_verdict_survives_the_result_file(tmp_path):
    r = _result([Finding("the IMU moved against both soles alike", INVALIDATES), Finding("tilt", LIMITS)])
    assert r.decision == DO_NOT_APPLY
    r.save(tmp_path / "r.json")
    back = CalibrationResult.load(tmp_path / "r.json")
    assert back.decision == DO_NOT_APPLY and back.verdict == r.verdict
    # A result written before verdicts: judged on load, its warnings unclassed.
    d = json.loads((tmp_path / "r.json").read_text())
    d.pop("verdict"), d.pop("session")
    (tmp_path / "old.json").write_text(json.dumps(d))
    assert CalibrationResult.load(tmp_path / "old.json").decision == REVIEW
    d["verdict"] = {"verdict": "maybe", "reasons": []}
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(CalibrationError, match="field 'verdict'"):
        CalibrationResult.load(tmp_path / "bad.json")


def test_export_refuses_a_do_not_apply_result_unless_forced(tmp_path, capsys):
    _result([Finding("offsets at the bound ±4.58°: ['left_knee_joint']", INVALIDATES)]).save(tmp_path / "r.json")
    out = tmp_path / "offsets.yaml"
    assert main(["export", "--result", str(tmp_path / "r.json"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "verdict is do-not-apply" in err and "offsets at the bound" in err and "--force" in err
    assert not out.exists()
    assert main(["export", "--result", str(tmp_path / "r.json"), "--out", str(out), "--force"]) == 0
    assert "--force: writing a result whose verdict is do-not-apply" in capsys.readouterr().out
    assert out.is_file()
    _result([Finding("tilt", LIMITS)]).save(tmp_path / "ok.json")
    assert main(["export", "--result", str(tmp_path / "ok.json"), "--out", str(tmp_path / "ok.yaml")]) == 0
    assert "verdict" not in capsys.readouterr().out  # an apply result: no alarm


@pytest.fixture(scope="module")
def two_sets(tmp_path_factory):
    from legcal_bench.api import calibrate
    from legcal_bench.protocol.collect import CollectConfig, collect

    root = tmp_path_factory.mktemp("sets")
    for seed in (0, 1):
        collect(CollectConfig(robot="a3", seed=seed, **SMALL), root / f"s{seed}", progress=False)
    result = calibrate(root / "s0", robot="a3")
    result.save(root / "r0.json")
    return root, result


def test_a_result_names_its_session_set(two_sets):
    root, result = two_sets
    assert result.session["recordings"] == ["stance_I", "stance_II", "stance_III", "stance_IV", "standing"]
    assert len(result.session["sha256"]) == 64 and result.session["sessions"]
    assert result.decision in (APPLY, REVIEW, DO_NOT_APPLY) and result.verdict["reasons"] is not None


@pytest.mark.parametrize("command", ["score", "export", "report"])
def test_another_session_set_is_refused(two_sets, tmp_path, capsys, command):
    root, _ = two_sets
    args = {"score": ["score", "--bags", str(root / "s1"), "--result", str(root / "r0.json")],
            "export": ["export", "--result", str(root / "r0.json"), "--bags", str(root / "s1"), "--out",
                       str(tmp_path / "o.yaml"), "--force"],
            "report": ["report", "--bags", str(root / "s1"), "--result", str(root / "r0.json"), "--out",
                       str(tmp_path / "rep")]}[command]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "calibrated on session set" in err and "other recordings" in err, err
    assert not (tmp_path / "o.yaml").exists() and not (tmp_path / "rep").exists()
    # The set it was calibrated on passes the same check.
    ok = [str(root / "s0") if a == str(root / "s1") else a for a in args]
    assert main(ok) == 0, capsys.readouterr().err


def test_a_do_not_apply_trial_walks_with_no_correction_and_is_counted():
    """walk-eval's rule: a do-not-apply estimate is not applied (a failed calibration,
    scored as no correction); its report says how many and why."""
    from legcal_bench.evaluation.closed_loop import applied
    from legcal_bench.reports.closed_loop import verdicts

    legmap = load_robot("a3")
    assert np.all(applied(_result([Finding("not rigid", INVALIDATES)]), legmap) == 0.0)
    assert np.all(applied(_result([Finding("a slide", DOUBTS)]), legmap) == 0.01)
    summary = {"verdicts": {APPLY: 1, REVIEW: 1, DO_NOT_APPLY: 1},
               "rejected": {"count": 1, "seeds": [2], "first_reason": "offsets at the bound"}}
    (line, _) = verdicts(summary)
    assert line.startswith("Calibration verdicts: 1 apply, 1 review") and "seeds [2]: failed calibrations" in line
    assert "offsets at the bound" in line
    assert verdicts({"verdicts": {APPLY: 0, REVIEW: 0, DO_NOT_APPLY: 0}}) == []
