"""The spec vocabulary training frameworks need (issue #40): gait phases in any per-foot
cos/sin layout and frozen at zero command, a term's observation history, and recurrent
ONNX policies whose state goes in and comes out beside the observation and the action."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from legcal_bench.errors import ConfigError
from legcal_bench.policies.models import load_model
from legcal_bench.policies.runner import PolicyRunner
from legcal_bench.policies.spec import load_policy_spec, resolve_policy
from legcal_bench.robots import load_robot


def _spec(tmp_path, observation, model=None):
    """The shipped A3-like policy's spec with another observation (and model)."""
    shipped = resolve_policy("a3")
    doc = yaml.safe_load(shipped.read_text())
    doc["model"]["file"] = str((shipped.parent / doc["model"]["file"]).resolve())
    if model is not None:
        doc["model"] = model
    doc["observation"] = observation
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


class _Zero:
    def __call__(self, obs):
        return np.zeros(12)


def _observe(runner, t, command=None):
    obs = {"q_enc": np.zeros(12), "dq_enc": np.zeros(12), "gravity": np.array([0, 0, -1.0]), "ang_vel": np.zeros(3)}
    if command is not None:
        runner.command = np.asarray(command, dtype=float)
    return runner.observation(obs, {}, t)


def test_gait_phase_layouts_and_the_frozen_phase(tmp_path):
    legmap = load_robot("a3")
    a = (0.25, 0.7)  # initial angles, rad
    rows = {}
    for layout in ("grouped", "interleaved"):
        spec = load_policy_spec(_spec(tmp_path, [{"term": "gait_phase", "frequency": 2.0, "initial": list(a),
                                                  "layout": layout, "stop_at_zero_command": True}]))
        runner = PolicyRunner(spec, legmap, model=_Zero())
        rows[layout] = _observe(runner, 0.1, [0.5, 0, 0])
        frozen = _observe(runner, 0.1, [0, 0, 0])
        phi = np.array(a) + 2 * np.pi * 2.0 * 0.1
        want = ([np.cos(phi[0]), np.cos(phi[1]), np.sin(phi[0]), np.sin(phi[1])] if layout == "grouped"
                else [np.cos(phi[0]), np.sin(phi[0]), np.cos(phi[1]), np.sin(phi[1])])
        np.testing.assert_allclose(rows[layout], want, atol=1e-6)
        np.testing.assert_allclose(frozen[[0, 1]] if layout == "grouped" else frozen[[0, 2]], np.cos(a), atol=1e-6)
    assert not np.allclose(rows["grouped"], rows["interleaved"])
    with pytest.raises(ConfigError, match="layout"):
        load_policy_spec(_spec(tmp_path, [{"term": "gait_phase", "frequency": 1.0, "layout": "stacked"}]))


def test_a_terms_history_is_its_last_values_oldest_first(tmp_path):
    spec = load_policy_spec(_spec(tmp_path, [{"term": "time", "history": 3}, {"term": "command"}]))
    runner = PolicyRunner(spec, load_robot("a3"), model=_Zero())
    assert runner.n_obs == 3 + 3
    runner.reset()
    got = [_observe(runner, t)[:3] for t in (0.0, 0.02, 0.04, 0.06)]
    np.testing.assert_allclose(got, [[0, 0, 0], [0, 0, 0.02], [0, 0.02, 0.04], [0.02, 0.04, 0.06]], atol=1e-7)
    runner.reset()  # a new episode starts from its own first frame
    np.testing.assert_allclose(_observe(runner, 0.5)[:3], [0.5] * 3, atol=1e-7)
    with pytest.raises(ConfigError, match="history"):
        load_policy_spec(_spec(tmp_path, [{"term": "time", "history": 0}]))


def _recurrent_onnx(path, n_obs: int, n_act: int = 12):
    """A recurrent ONNX policy: action_j = h[0]; h_out = h_in + [1, 0] (a step counter)."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    w = np.zeros((2, n_act), dtype=np.float32)
    w[0] = 1.0
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["h_in", "W"], ["actions"]), helper.make_node("Add", ["h_in", "one"], ["h_out"])],
        "recurrent", [helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, n_obs]),
                      helper.make_tensor_value_info("h_in", TensorProto.FLOAT, [1, 2])],
        [helper.make_tensor_value_info("actions", TensorProto.FLOAT, [1, n_act]),
         helper.make_tensor_value_info("h_out", TensorProto.FLOAT, [1, 2])],
        [numpy_helper.from_array(w, "W"), numpy_helper.from_array(np.array([[1.0, 0.0]], np.float32), "one")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 9  # what onnxruntime reads
    onnx.save(model, str(path))


def test_a_recurrent_onnx_policy_carries_its_state_and_resets(tmp_path):
    _recurrent_onnx(tmp_path / "rnn.onnx", 6)
    model = load_model(tmp_path / "rnn.onnx", "onnx", 6, 12)
    obs = np.zeros(6, dtype=np.float32)
    assert [model(obs)[0] for _ in range(3)] == [0.0, 1.0, 2.0]
    model.reset()
    assert model(obs)[0] == 0.0
    with pytest.raises(ConfigError, match="observation values"):
        load_model(tmp_path / "rnn.onnx", "onnx", 7, 12)


def test_a_command_schedule_changes_the_command_at_its_times(tmp_path):
    path = _spec(tmp_path, [{"term": "command"}])
    doc = yaml.safe_load(path.read_text())
    doc["command_schedule"] = [{"t": 0.0, "command": [0.0, 0.0, 0.0]}, {"t": 1.0, "command": [0.5, 0.0, 0.2]}]
    path.write_text(yaml.safe_dump(doc))
    runner = PolicyRunner(load_policy_spec(path), load_robot("a3"), model=_Zero())
    np.testing.assert_allclose(_observe(runner, 0.98), [0, 0, 0])
    np.testing.assert_allclose(_observe(runner, 1.0), [0.5, 0, 0.2])
    assert "commands [0.0, 0.0, 0.0] from 0 s" in runner.spec.settings
    doc["command_schedule"] = [{"t": 1.0, "command": [0, 0, 0]}, {"t": 0.5, "command": [0, 0, 0]}]
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match="times must increase"):
        load_policy_spec(path)
