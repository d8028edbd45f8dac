"""Training our walking policy (issue #14): a tiny run of the recipe end to end (the
teacher's rollouts, DAgger, selection by rollout success, TorchScript and ONNX
exports with their specs), and `train-policy`'s errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from legcal_bench.cli import main

TEACHERS = Path(__file__).resolve().parents[2] / "policies" / "teachers"
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def test_a_tiny_training_run_exports_a_policy_that_runs_in_both_formats(tmp_path, capsys):
    out = tmp_path / "walker"
    argv = ["train-policy", "--robot", "a3", "--iterations", "2", "--rollouts", "1", "--selection-walks", "1",
            "--out", str(out), "--quiet"]
    from legcal_bench.evaluation import distill

    tiny = distill.DistillConfig(seconds=1.5, train_steps=30)
    orig = distill.DistillConfig

    def shortened(**kw):  # the recipe, shortened
        return orig(**{**tiny.__dict__, **kw})

    shortened.eval_rollouts = orig.eval_rollouts  # the parser's default
    distill.DistillConfig = shortened
    try:
        assert main(argv) == 0
    finally:
        distill.DistillConfig = orig
    assert {p.name for p in out.iterdir()} == {"policy.pt", "policy.onnx", "policy.yaml", "policy.onnx.yaml",
                                               "teacher.yaml", "train.log", "training.json"}
    t = json.loads((out / "training.json").read_text())
    its = t["iterations"]
    assert len(its) == 2 and its[0]["beta"] == 1.0 and its[1]["beta"] == 0.5
    assert its[1]["samples"] > its[0]["samples"]  # DAgger aggregates
    key = [(r["eval_upright"], sum(e["upright"] for e in r["eval"] if not e["offsets"].startswith("random")),
            r["eval_mean_upright_s"], -r["val_loss"]) for r in its]
    # The rule: most upright, then the fixed patterns (none, paper@3), then longest, then lowest loss.
    assert key[t["selected_iteration"]] == max(key)
    assert "train-policy --robot a3" in t["made_by"] and "--selection-walks 1" in t["made_by"] and t["code"]
    assert its[0]["eval_total"] == 3  # none, paper@3 and one random pattern

    from legcal_bench.policies.runner import PolicyRunner
    from legcal_bench.robots import load_robot

    lm = load_robot("a3")
    ts, ox = PolicyRunner(out / "policy.yaml", lm), PolicyRunner(out / "policy.onnx.yaml", lm)
    assert ts.privileged == [] and [t.term for t in ts.spec.observation][-2:] == ["phase", "time"]
    rng = np.random.default_rng(0)
    obs = {"q_enc": np.asarray(ts.spec.default_q) + rng.normal(0, 0.05, 12), "dq_enc": rng.normal(0, 0.5, 12),
           "ang_vel": rng.normal(0, 0.1, 3), "gravity": np.array([0.02, -0.03, -0.999])}
    for time in (0.0, 0.7, 5.0):
        assert np.abs(ts.act(obs, {}, time) - ox.act(obs, {}, time)).max() < 1e-5

    # A second run may replace an earlier result, never another folder.
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    assert main(argv[:-3] + ["--out", str(other), "--quiet"]) == 2
    assert "holds other files" in capsys.readouterr().err


def test_train_policy_names_a_missing_teacher_and_bad_counts(tmp_path, capsys, testbot_legmap):
    assert main(["train-policy", "--robot", str(testbot_legmap), "--out", str(tmp_path / "x")]) == 2
    assert "--teacher" in capsys.readouterr().err
    assert main(["train-policy", "--robot", "a3", "--iterations", "0", "--out", str(tmp_path / "x")]) == 2
    assert "--iterations = 0" in capsys.readouterr().err
    assert main(["train-policy", "--robot", "a3", "--selection-walks", "-1", "--out", str(tmp_path / "x")]) == 2
    assert "--selection-walks = -1" in capsys.readouterr().err
    bad = tmp_path / "t.yaml"
    bad.write_text("format: legcal-teacher/1\nfeedback: {roll_gain: 1}\n")
    assert main(["train-policy", "--robot", "a3", "--teacher", str(bad), "--out", str(tmp_path / "x")]) == 2
    assert "feedback: unknown fields ['roll_gain']" in capsys.readouterr().err


def test_ties_go_to_the_checkpoint_upright_in_the_fixed_patterns():
    from legcal_bench.evaluation.distill import Evaluation

    rows = [{"offsets": "none", "upright": True}, {"offsets": "paper@3", "upright": False},
            {"offsets": "random#0", "upright": True}]
    a = Evaluation(2, 3, 15.0, rows)
    b = Evaluation(2, 3, 12.0, [dict(r, upright=r["offsets"] != "random#0") for r in rows])
    assert (a.fixed_upright, b.fixed_upright) == (1, 2)
