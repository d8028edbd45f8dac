"""Policy specs and the runner: every observation term, every model format, the
refusals (issue #13)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from legcal_bench.errors import ConfigError
from legcal_bench.policies.observation import ObsContext, bind, build_observation
from legcal_bench.policies.runner import PolicyRunner, walking_config
from legcal_bench.policies.spec import load_policy_spec
from legcal_bench.robots import load_robot

# Exporting the tiny models: torch 2.13 marks TorchScript and the legacy ONNX exporter deprecated.
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")
A3 = load_robot("a3")
# The policy's own joint order: the right leg first, reversed within each leg.
JOINTS = A3.joint_names[11:5:-1] + A3.joint_names[5::-1]
OBS = [{"term": "ang_vel", "scale": 0.25}, {"term": "gravity"}, {"term": "command", "scale": [2.0, 2.0, 0.25]},
       {"term": "joint_pos"}, {"term": "joint_vel", "scale": 0.05}, {"term": "last_action"},
       {"term": "phase", "period": 0.8}]
N_OBS = 3 + 3 + 3 + 12 + 12 + 12 + 2


def write_spec(tmp_path, model_file="policy.pt", fmt="torchscript", observation=OBS, **changes):
    doc = {"format": "legcal-policy/1", "name": "tiny", "model": {"file": model_file, "format": fmt},
           "joints": JOINTS, "default_q": [0.1 * k for k in range(12)], "action": {"scale": 0.5},
           "pd": {"kp": [100.0 + k for k in range(12)], "kd": [2.0] * 12}, "rates": {"physics_hz": 500, "control_hz": 50},
           "command": [0.4, 0.0, 0.1], "observation": observation}
    doc.update(changes)
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def tiny_net(n_obs=N_OBS, n_act=12):
    import torch

    torch.manual_seed(0)
    return torch.nn.Sequential(torch.nn.Linear(n_obs, 16), torch.nn.Tanh(), torch.nn.Linear(16, n_act)).eval()


def export_all(net, tmp_path, n_obs=N_OBS):
    import torch

    x = torch.zeros(1, n_obs)
    torch.jit.trace(net, x).save(str(tmp_path / "policy.pt"))
    torch.export.save(torch.export.export(net, (x,)), str(tmp_path / "policy.pt2"))
    torch.onnx.export(net, (x,), str(tmp_path / "policy.onnx"), dynamo=False, input_names=["obs"],
                      output_names=["action"])


def context(obs_overrides=None, time=0.3):
    rng = np.random.default_rng(1)
    obs = {"q_enc": rng.normal(size=12), "dq_enc": rng.normal(size=12), "ang_vel": np.array([0.1, -0.2, 0.3]),
           "gravity": np.array([0.0, 0.1, -0.99])}
    obs.update(obs_overrides or {})
    index = np.array([A3.joint_names.index(j) for j in JOINTS])
    return ObsContext(obs, {"base_lin_vel": np.array([0.5, -0.1, 0.02])}, time, np.arange(12) / 10.0,
                      np.array([0.4, 0.0, 0.1]), index, np.array([0.1 * k for k in range(12)])), obs, index


@pytest.mark.parametrize("term, extra, expect", [
    ("ang_vel", {"scale": 0.25}, lambda c, o, i: 0.25 * o["ang_vel"]),
    ("gravity", {}, lambda c, o, i: o["gravity"]),
    ("base_lin_vel", {"scale": 2.0}, lambda c, o, i: 2.0 * np.array([0.5, -0.1, 0.02])),
    ("command", {"scale": [2.0, 2.0, 0.25]}, lambda c, o, i: np.array([0.8, 0.0, 0.025])),
    ("joint_pos", {}, lambda c, o, i: o["q_enc"][i] - 0.1 * np.arange(12)),
    ("joint_pos", {"mask": [JOINTS[2], JOINTS[7]]}, lambda c, o, i: o["q_enc"][i][[2, 7]] - [0.2, 0.7]),
    ("joint_vel", {"scale": 0.05, "clip": 0.04}, lambda c, o, i: np.clip(0.05 * o["dq_enc"][i], -0.04, 0.04)),
    ("last_action", {}, lambda c, o, i: np.arange(12) / 10.0),
    ("last_action", {"mask": [JOINTS[0]]}, lambda c, o, i: np.array([0.0])),
    ("phase", {"period": 0.8}, lambda c, o, i: [np.sin(2 * np.pi * 0.3 / 0.8), np.cos(2 * np.pi * 0.3 / 0.8)]),
    ("foot_phase", {"period": 0.8, "offsets": [0.0, 0.5]},
     lambda c, o, i: [np.sin(2 * np.pi * 0.375), np.cos(2 * np.pi * 0.375), np.sin(2 * np.pi * 0.875),
                      np.cos(2 * np.pi * 0.875)]),
])
def test_each_observation_term_reads_what_it_says(tmp_path, term, extra, expect):
    export_all(tiny_net(), tmp_path)  # the spec needs a model file; the term test reads no model
    spec = load_policy_spec(write_spec(tmp_path, observation=OBS + [{"term": term, **extra}]))
    ctx, obs, index = context()
    full = build_observation(bind(spec), ctx)
    got = full[N_OBS:]
    assert np.allclose(got, np.asarray(expect(ctx, obs, index), dtype=np.float32), atol=1e-6)
    assert spec.privileged == (["base_lin_vel"] if term == "base_lin_vel" else [])


def test_the_three_formats_give_the_same_actions_through_the_runner(tmp_path):
    net = tiny_net()
    export_all(net, tmp_path)
    runners = [PolicyRunner(load_policy_spec(write_spec(tmp_path, f, fmt)), A3)
               for f, fmt in (("policy.pt", "torchscript"), ("policy.pt2", "torch.export"), ("policy.onnx", "onnx"))]
    ctx, obs, _ = context()
    for t in (0.0, 0.02, 0.5):
        actions = [r.act(obs, ctx.truth, t) for r in runners]
        assert np.abs(actions[0] - actions[1]).max() < 1e-5 and np.abs(actions[0] - actions[2]).max() < 1e-5
    # Targets: default_q + scale * action, put back into leg-map order by name.
    import torch

    r = runners[0]
    r.reset()
    o = r.observation(obs, ctx.truth, 0.0)
    a = net(torch.from_numpy(o[None])).detach().numpy()[0]
    target = r.act(obs, ctx.truth, 0.0)
    for k, name in enumerate(JOINTS):
        assert target[A3.joint_names.index(name)] == pytest.approx(0.1 * k + 0.5 * a[k], abs=1e-6)
    cfg = walking_config(r.spec, A3)
    assert cfg.kp[A3.joint_names.index(JOINTS[3])] == 103.0 and cfg.decimation == 10 and cfg.physics_dt == 0.002


def test_a_recurrent_policy_starts_each_episode_from_the_state_in_its_file(tmp_path):
    import torch

    class Counter(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.register_buffer("memory", torch.zeros(1, 12))

        def forward(self, x):
            self.memory.add_(1.0)
            return self.memory + 0 * x[:, :12]

    torch.jit.script(Counter()).save(str(tmp_path / "policy.pt"))
    r = PolicyRunner(load_policy_spec(write_spec(tmp_path)), A3)
    ctx, obs, _ = context()
    r.reset()
    first = [r.act(obs, ctx.truth, 0.0) for _ in range(3)]
    r.reset()
    assert np.allclose(r.act(obs, ctx.truth, 0.0), first[0]) and not np.allclose(first[0], first[2])


@pytest.mark.parametrize("change, match", [
    (dict(format="legcal-policy/0"), "field 'format'"),
    (dict(model={"file": "missing.pt", "format": "torchscript"}), "no such file"),
    (dict(model={"file": "policy.pt", "format": "tflite"}), "model.format"),
    (dict(joints=JOINTS[:11]), "default_q"),
    (dict(joints=JOINTS[:11] + ["waist_joint"]), "not in the leg map: \\['waist_joint'\\]"),
    (dict(default_q=[0.0] * 11), "default_q"),
    (dict(pd={"kp": [100.0] * 12}), "pd.kd"),
    (dict(rates={"physics_hz": 500, "control_hz": 30}), "whole multiple"),
    (dict(observation=[{"term": "joint_accel"}]), "'term' must be one of"),
    (dict(observation=[{"term": "phase"}]), "needs 'period'"),
    (dict(observation=[{"term": "gravity", "mask": ["x"]}]), "joint terms only"),
    (dict(observation=[{"term": "command", "scale": [1.0, 2.0]}]), "give 1 or 3"),
    (dict(observation=OBS[:-1]), "does not accept 45 observation values"),
    (dict(extra_field=1), "unknown fields"),
])
def test_bad_specs_are_refused_naming_the_field(tmp_path, change, match):
    export_all(tiny_net(), tmp_path)
    with pytest.raises(ConfigError, match=match):
        PolicyRunner(load_policy_spec(write_spec(tmp_path, **change)), A3)


def test_an_onnx_model_of_the_wrong_size_is_named(tmp_path):
    export_all(tiny_net(n_obs=40), tmp_path, n_obs=40)
    with pytest.raises(ConfigError, match="takes 40 observation values; the spec's observation terms give 47"):
        PolicyRunner(load_policy_spec(write_spec(tmp_path, "policy.onnx", "onnx")), A3)
    export_all(tiny_net(n_act=10), tmp_path)
    with pytest.raises(ConfigError, match="outputs 10 values; the spec's joints need 12"):
        PolicyRunner(load_policy_spec(write_spec(tmp_path)), A3)


def test_paper_at_deg_has_the_papers_signs_by_role_and_one_magnitude():
    from legcal_bench.errors import OffsetSpecError
    from legcal_bench.sim.offsets import paper_injection, resolve_offsets

    for robot in ("a2", "a3"):
        lm = load_robot(robot)
        dq = resolve_offsets("paper@3", lm)
        assert np.allclose(np.abs(dq), np.deg2rad(3)) and (np.sign(dq) == np.sign(paper_injection(lm))).all()
        signs = dict(zip(lm.joint_roles, np.sign(dq)))
        assert signs == {"hip_pitch": 1, "hip_roll": 1, "hip_yaw": -1, "knee": -1, "ankle_pitch": 1, "ankle_roll": -1}
    with pytest.raises(OffsetSpecError, match="paper@<deg>"):
        resolve_offsets("paper@x", A3)


def test_an_mlp_runs_eagerly_with_its_modules_actions_and_other_networks_as_they_are(tmp_path):
    import torch

    from legcal_bench.policies.models import load_model

    # Our walkers: (obs - mean) / std into an MLP; the eager replica answers bit for bit.
    shipped = Path(__file__).resolve().parents[2] / "policies" / "walkers" / "a3" / "policy.pt"
    module = torch.jit.load(str(shipped))
    model = load_model(shipped, "torchscript", 45, 12)
    assert model._run.__name__ == "eager"
    for x in np.random.default_rng(3).standard_normal((20, 45)).astype(np.float32):
        with torch.inference_mode():
            expected = module(torch.from_numpy(x[None])).numpy().reshape(-1).astype(np.float64)
        assert np.array_equal(model(x), expected)
    # A traced Sequential too; a network with state (an LSTM, a counter) runs as it is.
    export_all(tiny_net(), tmp_path)
    assert load_model(tmp_path / "policy.pt", "torchscript", N_OBS, 12)._run.__name__ == "eager"
    class Recurrent(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.lstm = torch.nn.LSTM(N_OBS, 12, batch_first=True)

        def forward(self, x):
            return self.lstm(x[:, None])[0][:, 0]

    torch.jit.trace(Recurrent().eval(), torch.zeros(1, N_OBS)).save(str(tmp_path / "lstm.pt"))
    assert load_model(tmp_path / "lstm.pt", "torchscript", N_OBS, 12)._run.__name__ == "run"
