import json

import numpy as np
import pytest

from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.data.recording import (Recording, RecordingError, load_recording, load_session, load_truth,
                                    list_segments)
from legcal_bench.robots import load_robot
from legcal_bench.sim.sensors import SENSOR_PRESETS

SHORT = dict(stance_s=1.0, heldout_s=0.6, standing_s=0.4, heldout=1, stances=("I", "II"))
pytestmark = pytest.mark.xdist_group("recording")  # one process collects `session` for all


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec")
    collect(CollectConfig(robot="a3", mode="kinematic", **SHORT), out, progress=False)
    return out


def _rec(n=20, **kw):
    names = load_robot("a3").joint_names
    d = dict(name="s", kind="stance", stance="I", robot="a3", joint_names=names, time=np.arange(n) * 0.02,
             q_enc=np.full((n, 12), 0.1), imu_acc=np.tile([0, 0, 9.81], (n, 1)), imu_gyro=np.zeros((n, 3)),
             sensor_model=SENSOR_PRESETS["realistic"].model)
    d.update(kw)
    return Recording(**d)


def test_round_trip_keeps_float64_and_metadata(tmp_path):
    rec = _rec(q_enc=np.random.default_rng(0).normal(0, 0.3, (20, 12)), ft=np.ones((20, 2, 6)))
    path = rec.save(tmp_path / "a.npz")
    back = load_recording(path, rec.joint_names)
    for k in ("time", "q_enc", "imu_acc", "imu_gyro", "ft"):
        np.testing.assert_array_equal(getattr(back, k), getattr(rec, k))
        assert getattr(back, k).dtype == np.float64
    assert back.sensor_model == rec.sensor_model and back.kind == "stance" and back.stance == "I"


def test_session_layout_and_truth_kept_apart(session):
    files = json.loads((session / "session.json").read_text())["files"]
    assert files == ["standing.npz", "stance_I.npz", "stance_II.npz", "heldout_1.npz"]
    recs = load_session(session, load_robot("a3").joint_names)
    assert [r.kind for r in recs] == ["standing", "stance", "stance", "heldout"]
    assert not any(hasattr(r, "q_true") or hasattr(r, "offsets") for r in recs)
    truth = load_truth(list_segments(session)[1])
    assert truth.q_true.shape == recs[1].q_enc.shape
    np.testing.assert_allclose(truth.offsets, [0.03, 0.04, -0.02, -0.04, 0.02, -0.03] * 2)


def test_same_seed_same_recordings(tmp_path):
    for out in ("x", "y"):
        collect(CollectConfig(robot="a2", mode="weld", seed=5, **SHORT), tmp_path / out, progress=False)
    for name in ("standing", "stance_I", "stance_II", "heldout_1"):
        a, b = (load_recording(tmp_path / o / f"{name}.npz") for o in ("x", "y"))
        np.testing.assert_array_equal(a.q_enc, b.q_enc)
        np.testing.assert_array_equal(a.imu_acc, b.imu_acc)
    c = tmp_path / "z"
    collect(CollectConfig(robot="a2", mode="weld", seed=6, **SHORT), c, progress=False)
    assert not np.array_equal(load_recording(c / "stance_I.npz").q_enc, load_recording(tmp_path / "x" / "stance_I.npz").q_enc)


def _save_raw(tmp_path, arrays, meta):
    p = tmp_path / "bad.npz"
    np.savez(p, meta=np.array(json.dumps(meta)), **arrays)
    return p


@pytest.mark.parametrize("edit, message", [
    (lambda a, m: a.pop("imu_gyro"), "missing field 'imu_gyro'"),
    (lambda a, m: m.pop("joint_names"), "missing metadata field 'joint_names'"),
    (lambda a, m: a.update(q_enc=a["q_enc"][:, :11]), r"field 'q_enc' has shape \(20, 11\)"),
    (lambda a, m: a["q_enc"].__setitem__((4, 2), np.nan), "NaN/inf in 1 frame"),
    (lambda a, m: a["time"].__setitem__(5, 0.0), "not strictly increasing"),
    (lambda a, m: a.update(q_enc=np.rad2deg(a["q_enc"]) * 10), "looks like degrees"),
    (lambda a, m: m.update(joint_names=m["joint_names"][::-1]), "reorder the q_enc columns"),
    (lambda a, m: m["joint_names"].__setitem__(0, "hip"), r"missing \['left_hip_pitch_joint'\]"),
    (lambda a, m: m.update(version=99), "format version 99"),
    (lambda a, m: a.update(imu_acc=a["imu_acc"] / 9.81), "mean norm 1"),
    (lambda a, m: a.update(time=a["time"][:10]), "has 20 frames but 'time' has 10"),
])
def test_bad_recording_gets_a_clear_error(tmp_path, edit, message):
    rec = _rec(q_enc=np.random.default_rng(1).normal(0, 0.5, (20, 12)))
    arrays = {"time": rec.time.copy(), "q_enc": rec.q_enc.copy(), "imu_acc": rec.imu_acc.copy(),
              "imu_gyro": rec.imu_gyro.copy()}
    meta = rec.meta()
    edit(arrays, meta)
    with pytest.raises(RecordingError, match=message):
        load_recording(_save_raw(tmp_path, arrays, meta), load_robot("a3").joint_names)


def test_save_refuses_invalid_and_leaves_nothing(tmp_path):
    q = np.full((20, 12), 0.1)
    q[3, 3] = np.inf
    with pytest.raises(RecordingError, match="NaN/inf"):
        _rec(q_enc=q).save(tmp_path / "x.npz")
    assert list(tmp_path.iterdir()) == []


def test_not_an_npz(tmp_path):
    p = tmp_path / "x.npz"
    p.write_text("hello")
    with pytest.raises(RecordingError, match="not a readable .npz"):
        load_recording(p)
