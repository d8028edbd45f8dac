"""Each shipped walking policy of ours (policies/walkers/*, issue #14) walks: a few
seconds through its spec and the same runner as any published policy, upright and
forward, in both exported formats, and encoder offsets change where it goes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

WALKERS = sorted((Path(__file__).resolve().parents[2] / "policies" / "walkers").glob("*/policy.yaml"))
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def test_there_are_shipped_policies_for_the_a3_and_a2_like_robots():
    assert {p.parent.name for p in WALKERS} >= {"a3", "a2"}


@pytest.mark.parametrize("spec", WALKERS, ids=lambda p: p.parent.name)
def test_a_shipped_policy_walks_and_offsets_change_its_path(spec):
    from legcal_bench.envs.walking import WalkingEnv
    from legcal_bench.evaluation.walk import walk
    from legcal_bench.policies.runner import PolicyRunner

    robot = spec.parent.name
    env = WalkingEnv(robot=robot, policy=str(spec), sensors="realistic")
    runner = PolicyRunner(env.policy_spec, env.legmap)
    assert runner.privileged == []
    seconds = 4.0
    nominal = walk(env, runner, seconds, seed=3)
    assert nominal.upright
    # Forward, at the teacher's pace once stepping (its recipe: step_length per step_period after start_s).
    import yaml

    gait = yaml.safe_load((spec.parent / "teacher.yaml").read_text())["gait"]
    planned = gait["step_length"] * (seconds - gait.get("start_s", 1.0)) / gait["step_period"]
    assert 0.5 * planned < nominal.pelvis[-1, 0] - nominal.pelvis[0, 0] < 1.5 * planned
    assert min(len(nominal.strikes[s]["time"]) for s in ("left", "right")) >= 3
    # paper@3 uncorrected: still upright, on another path (the same seed's noise and jitter).
    bent = walk(env, runner, seconds, seed=3, options={"offsets": "paper@3"})
    assert bent.upright
    gap = np.linalg.norm(bent.pelvis[:, :2] - nominal.pelvis[:, :2], axis=1)
    assert gap[-1] > 0.02
    # The ONNX export is the same policy.
    onnx = PolicyRunner(spec.parent / "policy.onnx.yaml", env.legmap)
    rng = np.random.default_rng(0)
    obs = {"q_enc": np.asarray(runner.spec.default_q) + rng.normal(0, 0.05, 12), "dq_enc": rng.normal(0, 0.5, 12),
           "ang_vel": rng.normal(0, 0.1, 3), "gravity": np.array([0.02, -0.03, -0.999])}
    runner.reset()
    assert np.abs(runner.act(obs, {}, 1.3) - onnx.act(obs, {}, 1.3)).max() < 1e-5
