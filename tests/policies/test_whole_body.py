"""Whole-body policies through the spec (issue #40): MuJoCo Playground's 29-joint G1
(../shared/external/playground_g1, `examples/playground_g1.*`) observed exactly as its
play script observes it, walking 20 s upright; and a legs-only policy on the same
whole-body robot, its waist and arms held by the spec, through the same code."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from legcal_bench.envs.walking import WalkingEnv
from legcal_bench.evaluation.walk import walk
from legcal_bench.policies.runner import PolicyRunner
from legcal_bench.robots import load_robot
from tests.policies import playground_g1_reference as ref

REPO = Path(__file__).resolve().parents[2]
LEGMAP = REPO / "examples" / "playground_g1.legmap.yaml"
SPEC = REPO / "examples" / "playground_g1.policy.yaml"

pytestmark = pytest.mark.skipif(not ref.SCENE_XML.is_file(), reason="../shared/external/playground_g1 not present")


@pytest.fixture(scope="module")
def legmap():
    return load_robot(str(LEGMAP))


def test_the_observation_is_the_play_scripts_formula(legmap):
    """Recorded states of a walk (perfect sensors): the spec's observation equals the
    play script's `get_obs` on the same state, phase advanced as it advances it (1e-6)."""
    env = WalkingEnv(robot=legmap, policy=str(SPEC), sensors="zero")
    runner = PolicyRunner(env.policy_spec, legmap)
    obs, info = env.reset(seed=0)
    runner.reset()
    u = env.unwrapped
    ref.joint_order_check(u.sim.model)
    default = np.asarray(runner.spec.default_q)
    np.testing.assert_allclose(default, ref.default_angles(u.sim.model), atol=1e-9)  # the keyframe's pose
    phase = ref.initial_phase()
    worst = 0.0
    for _ in range(100):
        got = runner.observation(obs, info, u.sim.time)
        want = ref.reference_observation(u.sim.model, u.sim.data, default, phase, runner.command, runner.last_action)
        assert got.shape == want.shape == (ref.OBS_SIZE,)
        worst = max(worst, float(np.abs(got - want).max()))
        action = runner.model(got)
        obs, _, terminated, _, info = env.step(runner.targets(action))
        phase = ref.reference_phase_step(phase)
        assert not terminated
    assert worst <= 1e-6, worst


def test_the_whole_body_g1_walks_20_s_upright(legmap):
    env = WalkingEnv(robot=legmap, policy=str(SPEC), sensors="realistic")
    w = walk(env, PolicyRunner(env.policy_spec, legmap), 20.0, seed=0)
    assert w.fallen_at is None
    travelled = np.linalg.norm(w.pelvis[-1, :2] - w.pelvis[0, :2])
    assert travelled > 0.5 * 0.5 * 20.0, travelled  # at least half the commanded 0.5 m/s
    assert sorted(w.privileged) == ["gravity_true", "sensor"]


def test_a_legs_only_policy_with_the_waist_and_arms_held_runs_through_the_same_code(legmap, tmp_path):
    """A small stand-in policy drives the 12 leg joints of the whole-body G1; the spec
    holds the other 17 at its angles with the model's actuators."""
    import torch

    spec = yaml.safe_load(SPEC.read_text())
    legs, others = spec["joints"][:12], spec["joints"][12:]
    held = dict(zip(others, spec["default_q"][12:]))
    held["left_elbow_joint"] = 0.9  # not the keyframe's: the hold is the spec's angle

    class Zero(torch.nn.Module):  # the stand-in: hold the legs' default pose
        def forward(self, obs: torch.Tensor) -> torch.Tensor:
            return torch.zeros(obs.shape[:-1] + (12,), dtype=obs.dtype)

    torch.jit.script(Zero()).save(str(tmp_path / "zero.pt"))
    spec.update(name="legs_only", model={"file": str(tmp_path / "zero.pt"), "format": "torchscript"}, joints=legs,
                default_q=spec["default_q"][:12], hold=held,
                observation=[{"term": "gravity"}, {"term": "joint_pos"}, {"term": "joint_vel"},
                             {"term": "gait_phase", "frequency": 1.5, "initial": [0.0, 3.14159],
                              "stop_at_zero_command": True}])
    path = tmp_path / "legs_only.policy.yaml"
    path.write_text(yaml.safe_dump(spec))
    env = WalkingEnv(robot=legmap, policy=str(path), sensors="zero")
    runner = PolicyRunner(env.policy_spec, legmap)
    assert runner.n_obs == 3 + 12 + 12 + 4 and runner.n_body == 29
    obs, info = env.reset(seed=1)
    runner.reset()
    sim = env.unwrapped.sim
    for _ in range(25):  # 0.5 s
        obs, _, _, _, info = env.step(runner.act(obs, info, sim.time))
    names = list(legmap.joint_names) + list(sim.config.extra_joints)  # the body vector: legs, then the held
    assert sorted(sim.config.extra_joints) == sorted(held)
    q, ctrl = sim.data.qpos[sim.body_qpos], sim.data.ctrl[sim.body_act]
    for name, angle in held.items():  # each held joint's own servo is told the spec's angle ...
        assert ctrl[names.index(name)] == angle, name
    assert q[names.index("left_elbow_joint")] > 0.85  # ... and follows it (from the keyframe's 0.6 to 0.9)
    assert set(obs) >= {"q_extra", "dq_extra"} and obs["q_extra"].shape == (17,)
    # The command is not zero: the phase advances; with a zero command it would stay put.
    ctx_obs = runner.observation(obs, info, 0.5)
    assert not np.allclose(ctx_obs[-4:], [1.0, np.cos(3.14159), 0.0, np.sin(3.14159)])


def test_the_floor_a_policy_was_trained_on_and_a_missing_keyframe(tmp_path):
    """`sim.floor_friction` is the contacts' friction (the floor's, not the larger of floor
    and feet); a keyframe the robot's MJCF lacks is named."""
    from legcal_bench.errors import ConfigError
    from legcal_bench.policies.spec import resolve_policy

    shipped = resolve_policy("a3")
    spec = yaml.safe_load(shipped.read_text())
    spec["model"]["file"] = str((shipped.parent / spec["model"]["file"]).resolve())
    frictions = {}
    for friction in (None, 0.6):
        if friction is not None:
            spec["sim"] = {"floor_friction": friction}
        path = tmp_path / f"a3_{friction}.policy.yaml"
        path.write_text(yaml.safe_dump(spec))
        env = WalkingEnv(robot="a3", policy=str(path), sensors="zero")
        env.reset(seed=0)
        for _ in range(5):
            env.step(np.asarray(env.unwrapped.sim.config.default_q))
        d = env.unwrapped.sim.data
        assert d.ncon > 0
        frictions[friction] = set(np.round(d.contact.friction[:d.ncon, 0], 9))
    assert frictions == {None: {1.0}, 0.6: {0.6}}
    spec["sim"] = {"keyframe": "knees_bent"}
    path = tmp_path / "a3_key.policy.yaml"
    path.write_text(yaml.safe_dump(spec))
    with pytest.raises(ConfigError, match="keyframe 'knees_bent' is not in"):
        WalkingEnv(robot="a3", policy=str(path))
