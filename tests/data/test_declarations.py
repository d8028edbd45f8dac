"""Declarations that cannot be silently wrong (issue #39, item 3).

The sensor model is complete or explicitly "unknown" (conservative bounds, named in
every result); the motion (static or continuous) is measured from the data, and a
declaration the data contradict is replaced with a warning."""

from __future__ import annotations

import io
import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from legcal_bench.calibrators.base import calibrate_training
from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import load_recording, load_session
from legcal_bench.errors import RecordingError, SensorModelError
from legcal_bench.estimation.checks.motion import measure_motion, resolve_motion
from legcal_bench.estimation.imu.imu_motion import imu_acceleration
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.sim.sensors import SENSOR_PRESETS, UNKNOWN_SENSORS, SensorModel

pytestmark = pytest.mark.xdist_group("declarations")  # one process collects `sets` for all
DOCS = Path(__file__).resolve().parents[2] / "docs" / "recording-format.md"
# Two stances of 6 s (3 s of it the motion's fade-in): enough motion to measure, quick to collect.
SHORT = dict(robot="a3", stances=("I", "IV"), stance_s=6.0, standing_s=1.0, heldout=0)


@pytest.fixture(scope="module")
def sets(tmp_path_factory):
    lm = load_robot("a3")
    root = tmp_path_factory.mktemp("declarations")
    out = {}
    for mode in ("kinematic", "weld", "contact"):
        collect(CollectConfig(mode=mode, **SHORT), root / mode, progress=False)
        out[mode] = load_session(root / mode, robot=lm)
    return lm, LegKinematics(lm), out


def _rewrite(path: Path, meta_edit) -> None:
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays.pop("meta")))
    meta_edit(meta)
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(meta)), **arrays)
    path.write_bytes(buf.getvalue())


# ------------------------------------------------------------------ sensor model
def test_a_partial_sensor_model_is_refused_naming_the_missing_fields(sets, tmp_path):
    lm, _, recs = sets
    path = recs["kinematic"][1].save(tmp_path / "s.npz")
    _rewrite(path, lambda m: [m["sensor_model"].pop(k) for k in ("accel_bias_bound", "imu_mount_bound")])
    with pytest.raises(RecordingError, match=r"s.npz: field 'sensor_model' is invalid .*missing fields "
                                             r"\['accel_bias_bound', 'imu_mount_bound'\].*declare it from the "
                                             r"datasheet .*or write \"sensor_model\": \"unknown\""):
        load_recording(path, lm.joint_names)
    with pytest.raises(SensorModelError, match=r"missing fields \['encoder_resolution'"):
        SensorModel.from_dict({"encoder_noise_std": 1e-4})
    assert SensorModel.from_dict({"encoder_noise_std": 1e-4}, complete=False).accel_bias_bound == 0.0
    with pytest.raises(RecordingError, match="no sensor_model: declare it from the datasheet"):
        replace(recs["kinematic"][1], sensor_model=None)


def test_version_1_files_load_with_the_same_checks(sets, tmp_path):
    lm, _, recs = sets
    path = recs["weld"][1].save(tmp_path / "v1.npz")
    _rewrite(path, lambda m: m.update(version=1))
    back = load_recording(path, lm.joint_names)
    assert back.motion == "continuous" and back.sensor_declared and back.sensor_model == recs["weld"][1].sensor_model
    _rewrite(path, lambda m: m["sensor_model"].pop("gyro_bias_bound"))
    with pytest.raises(RecordingError, match=r"missing fields \['gyro_bias_bound'\]"):
        load_recording(path, lm.joint_names)
    _rewrite(path, lambda m: m.update(version=3))
    with pytest.raises(RecordingError, match=r"format version 3 is not supported \(this reader: 1, 2\)"):
        load_recording(path, lm.joint_names)


def test_unknown_round_trips_and_every_result_says_so(sets, tmp_path):
    lm, _, recs = sets
    unknown = [replace(r, sensor_model=SensorModel.unknown(), sensor_declared=False) for r in recs["kinematic"]]
    paths = [r.save(tmp_path / f"{r.name}.npz") for r in unknown]
    with np.load(paths[0]) as z:
        assert json.loads(str(z["meta"]))["sensor_model"] == "unknown"
    back = [load_recording(p, lm.joint_names) for p in paths]
    assert all(not r.sensor_declared and r.sensor_model == UNKNOWN_SENSORS for r in back)
    res = calibrate_training(get_calibrator("interfoot"), lm, back)
    (note,) = [w for w in res.warnings if w.startswith("sensor model not declared")]
    assert "standing, stance_I, stance_IV" in note and "accel_bias_bound 0.2" in note and "imu_mount_bound 0.0174533" \
        in note and "declare the sensors' datasheet values" in note
    # The conservative IMU bounds (2.2 deg of tilt) are what static data cannot separate: said too.
    assert any(w.startswith("IMU tilt not separable") for w in res.warnings)
    with pytest.raises(RecordingError, match="sensor_declared=False with a sensor model other than"):
        replace(recs["kinematic"][1], sensor_declared=False)


def test_a_declared_set_gets_no_declaration_warning(sets):
    lm, _, recs = sets
    res = calibrate_training(get_calibrator("interfoot"), lm, recs["kinematic"])
    assert not [w for w in res.warnings if "sensor model not declared" in w or "motion" in w], res.warnings
    ev = res.diagnostics["motion"]
    assert [ev[n]["used"] for n in ("standing", "stance_I", "stance_IV")] == ["static"] * 3
    assert [ev[n]["motion"] for n in ("standing", "stance_I", "stance_IV")] == [None, "static", "static"]


# ------------------------------------------------------------------ motion
@pytest.mark.parametrize("mode", ["kinematic", "weld", "contact"])
def test_motion_is_measured(sets, mode):
    _, kin, recs = sets
    want = "static" if mode == "kinematic" else "continuous"
    for r in recs[mode]:
        ev = measure_motion(kin, r)
        if r.kind == "standing":  # no motion: the data cannot tell, whatever the mode
            assert ev.motion is None and abs(ev.accel.dchi2) < 5, ev
            continue
        # Measured (realistic sensors, 6 s stances I / IV): kinematic dchi2 -533 / -104 (k -0.03,
        # 0.07), weld +667 / +173 (k 1.06, 1.05), contact +723 / +146 (k 1.08, 0.99).
        assert ev.motion == want, ev.describe()
        assert (ev.accel.dchi2 < -25) if want == "static" else (ev.accel.dchi2 > 25), ev.describe()


def test_hold_and_log_reads_static_from_the_gyro_alone(sets):
    """Each frame logged at rest: the gyro reads its bias and noise while the encoders'
    orientation turns; at a 2 Hz logging rate the accelerometer's prediction has no
    window to work with and the gyro decides."""
    _, kin, recs = sets
    rng = np.random.default_rng(1)
    r = recs["kinematic"][1]
    rest = replace(r, motion=None, imu_gyro=np.array([0.001, -0.0015, 0.0005]) + 0.003 * rng.standard_normal((r.n_frames, 3)))
    ev = measure_motion(kin, rest)
    assert ev.motion == "static" and ev.accel.verdict == "static" and ev.gyro.verdict == "static", ev.describe()
    sparse = replace(rest, **{k: getattr(rest, k)[::25] for k in ("time", "q_enc", "imu_acc", "imu_gyro")})
    ev = measure_motion(kin, sparse)
    assert ev.accel is None and ev.gyro.verdict == "static" and ev.motion == "static", ev
    (out,), warnings = resolve_motion(kin, [sparse])
    assert out.motion == "static" and warnings == []


def test_a_contradicted_declaration_is_replaced_and_warned(sets):
    lm, kin, recs = sets
    # A weld set relabelled static (the IMU's acceleration would be left in), and a
    # hold-and-log set converted with the old default "continuous" (the case).
    for mode, wrong, right in (("weld", "static", "continuous"), ("kinematic", "continuous", "static")):
        relabelled = [replace(r, motion=wrong) for r in recs[mode]]
        out, warnings = resolve_motion(kin, relabelled)
        assert [r.motion for r in out] == [wrong, right, right]  # the standing phase cannot tell: kept
        assert len(warnings) == 2 and all(re.match(rf"stance_(I|IV): motion declared '{wrong}', the data show "
                                                   rf"'{right}': the accelerometer reads .* fix the declaration", w)
                                          for w in warnings), warnings
    res = calibrate_training(get_calibrator("interfoot"), lm, [replace(r, motion="continuous") for r in recs["kinematic"]])
    assert sum("motion declared 'continuous', the data show 'static'" in w for w in res.warnings) == 2


def test_undeclared_motion_is_measured_without_alarm(sets):
    _, kin, recs = sets
    for mode, want in (("kinematic", "static"), ("weld", "continuous"), ("contact", "continuous")):
        out, warnings = resolve_motion(kin, [replace(r, motion=None) for r in recs[mode]])
        assert [r.motion for r in out] == ["continuous", want, want] and warnings == [], (mode, warnings)


def test_undeclared_and_undecidable_is_taken_continuous_with_a_warning(sets):
    """An accelerometer that reads half the predicted acceleration fits neither
    hypothesis: taken as continuous, and said, since the choice matters here."""
    _, kin, recs = sets
    r = recs["weld"][1]
    half = replace(r, motion=None, imu_acc=r.imu_acc - 0.5 * imu_acceleration(kin, r.time, r.q_enc))
    (out,), warnings = resolve_motion(kin, [half])
    assert out.motion == "continuous" and len(warnings) == 1, warnings
    assert warnings[0].startswith("stance_I: motion not declared and the data cannot tell static from continuous "
                                  "(the accelerometer reads 0.5")
    (kept,), warnings = resolve_motion(kin, [replace(half, motion="static")])  # a declaration is kept
    assert kept.motion == "static" and warnings == []


# ------------------------------------------------------------------ the docs
def test_the_docs_conversion_snippet_makes_a_recording_that_loads(sets, tmp_path, monkeypatch):
    lm, kin, recs = sets
    text = DOCS.read_text()
    section = text[text.index("## Converting a real robot's log"):]
    snippet = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    assert 'sensor_model="unknown"' not in snippet and "motion=" not in snippet.replace("# motion", "")
    # A fake logger's file: joints in another order, time from the robot's clock.
    src = recs["weld"][1]
    order = np.random.default_rng(0).permutation(lm.n_joints)
    np.savez(tmp_path / "my_log_stance1.npz", t=src.time + 1234.5, joint_pos=src.q_enc[:, order],
             imu_acc=src.imu_acc, imu_gyro=src.imu_gyro)
    log_joint_index = {lm.joint_names[j]: i for i, j in enumerate(order)}
    monkeypatch.chdir(tmp_path)
    exec(snippet.replace("path/to/my_robot.legmap.yaml", "a3"), {"log_joint_index": log_joint_index})
    back = load_recording(tmp_path / "my_session" / "stance_I.npz", lm.joint_names)
    np.testing.assert_allclose(back.q_enc, src.q_enc)
    assert back.sensor_declared and back.motion is None and back.sensor_model.imu_mount_bound > 0
    (resolved,), warnings = resolve_motion(kin, [back])
    assert resolved.motion == "continuous" and warnings == []
    # A conversion that drops a line of the declaration fails instead of declaring a perfect IMU.
    edited = re.sub(r'\n\s*"imu_mount_bound": [^\n]*', "", snippet)
    assert edited != snippet
    with pytest.raises(SensorModelError, match=r"missing fields \['imu_mount_bound'\]"):
        exec(edited.replace("path/to/my_robot.legmap.yaml", "a3"), {"log_joint_index": log_joint_index})


def test_the_docs_table_lists_the_unknown_bounds():
    text = DOCS.read_text()
    for field, value in SensorModel.unknown().to_dict().items():
        row = re.search(rf"^\| `{field}` \| ([^|]+) \|", text, re.M)
        assert row, field
        assert f"{value:g}" in row.group(1) or (field == "imu_mount_bound" and "0.01745" in row.group(1)), row.group(1)
    assert SENSOR_PRESETS["realistic"].model.accel_bias_bound < UNKNOWN_SENSORS.accel_bias_bound


def test_a_declared_recording_saves_as_version_1_for_an_older_reader(tmp_path):
    """bench-speed's baseline (before #39) reads version 1: a recording that declares its
    sensors and motion writes it; one that does not is refused, not written half-true."""
    from legcal_bench.data.recording import Recording, load_recording
    from legcal_bench.sim.sensors import SENSOR_PRESETS

    n = 50
    rec = Recording(name="stance_I", kind="stance", stance="I", robot="a3",
                    joint_names=load_robot("a3").joint_names, time=np.arange(n) * 0.02, q_enc=np.zeros((n, 12)),
                    imu_acc=np.tile([0.0, 0.0, 9.81], (n, 1)), imu_gyro=np.zeros((n, 3)),
                    sensor_model=SENSOR_PRESETS["realistic"].model, motion="static")
    rec.save(tmp_path / "v1.npz", version=1)
    with np.load(tmp_path / "v1.npz") as z:
        assert json.loads(str(z["meta"]))["version"] == 1
    assert load_recording(tmp_path / "v1.npz").motion == "static"
    for bad in (dict(motion=None), dict(sensor_model=None, sensor_declared=False)):
        with pytest.raises(RecordingError, match="version 1"):
            Recording(**{**rec.__dict__, **bad}).save(tmp_path / "bad.npz", version=1)
    assert not (tmp_path / "bad.npz").exists()
