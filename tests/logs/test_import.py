"""Robot logs in (issue #39): a simulated session written as each log format a robot
team has, imported through a mapping file, calibrates as the native recordings do;
resampled multi-rate logs with jitter and a dropped message come close; every mapping
mistake is named by its field."""

from __future__ import annotations

import copy
import shutil

import numpy as np
import pytest
import yaml

from legcal_bench.calibrators.base import calibrate_training
from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import load_session
from legcal_bench.errors import LogImportError
from legcal_bench.logs.importer import import_log
from legcal_bench.logs.write import LogStreams, mapping_document, write_log, write_mapping
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot

pytestmark = pytest.mark.xdist_group("log_import")
FORMATS = ("mcap", "sqlite3", "ros1", "csv", "parquet")
LOG_NAME = {"mcap": "bag_mcap", "sqlite3": "bag_sqlite3", "ros1": "log.bag", "csv": "log.csv",
            "parquet": "log.parquet"}
FLIPPED = 3  # the leg joint whose axis the log reverses


@pytest.fixture(scope="module")
def legmap():
    return load_robot("a3")


def offsets(legmap, recordings) -> np.ndarray:
    return calibrate_training(get_calibrator("interfoot"), legmap, recordings).offsets_vector(legmap.joint_names)


def as_log(recordings, legmap, seed=0):
    """The session's segments back to back on one clock, joints renamed and shuffled,
    one axis reversed: (LogStreams, sources, signs, [(t0, t1)] per segment)."""
    rng = np.random.default_rng(seed)
    n = legmap.n_joints
    perm = rng.permutation(n)  # log column j holds leg joint perm[j]
    signs = np.ones(n, int)
    signs[FLIPPED] = -1
    names = [f"J{j:02d}_{legmap.joint_names[perm[j]].upper()}" for j in range(n)]
    sources = [names[int(np.flatnonzero(perm == i)[0])] for i in range(n)]
    dt = 1.0 / recordings[0].rate_hz
    t, spans, T = [], [], 0.0
    for r in recordings:
        ti = r.time - r.time[0] + T
        t.append(ti)
        spans.append((ti[0], ti[-1]))
        T = ti[-1] + dt
    t = np.concatenate(t)
    q = np.concatenate([r.q_enc for r in recordings]) * signs
    ft = np.concatenate([r.ft for r in recordings]) if recordings[0].ft is not None else None
    streams = LogStreams(names, t, q[:, perm], t, np.concatenate([r.imu_acc for r in recordings]),
                         np.concatenate([r.imu_gyro for r in recordings]), t if ft is not None else None, ft)
    return streams, sources, list(signs), spans


@pytest.fixture(scope="module")
def native(tmp_path_factory, legmap):
    """A weld-floor session with F/T (continuous motion, realistic sensors)."""
    out = tmp_path_factory.mktemp("native") / "set"
    collect(CollectConfig(robot="a3", mode="weld", heldout=0, stance_s=6.0, standing_s=3.0, seed=3), out,
            progress=False)
    recs = load_session(out, robot=legmap)
    return recs, offsets(legmap, recs)


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_session_as_any_log_format_calibrates_as_the_native_recordings(fmt, native, legmap, tmp_path):
    """(a): native rate, no jitter; names renamed, order shuffled, one sign flipped."""
    recs, want = native
    streams, sources, signs, spans = as_log(recs, legmap)
    log = write_log(tmp_path / LOG_NAME[fmt], streams, fmt)
    mapping = write_mapping(tmp_path / "map.yaml", mapping_document(
        "a3", legmap.joint_names, sources, signs, fmt, recs[0].sensor_model, ft=True))
    s = import_log([log], mapping, legmap, tmp_path / "session", ranges=spans, plot=False)
    assert [g["frames"] for g in s.segments] == [r.n_frames for r in recs]
    got = load_session(tmp_path / "session", robot=legmap)
    for r, g in zip(recs, got):
        np.testing.assert_array_equal(g.q_enc, r.q_enc)  # names, order and the flipped sign undone exactly
        np.testing.assert_allclose(g.ft, r.ft, rtol=0, atol=1e-12)
        assert g.kind == r.kind
    np.testing.assert_allclose(offsets(legmap, got), want, rtol=0, atol=1e-9)


def test_the_flipped_sign_matters(native, legmap, tmp_path):
    """The same log with the sign left unflipped in the mapping calibrates elsewhere (the test above can fail)."""
    recs, want = native
    streams, sources, signs, spans = as_log(recs, legmap)
    signs[FLIPPED] = 1
    log = write_log(tmp_path / "log.csv", streams, "csv")
    mapping = write_mapping(tmp_path / "map.yaml", mapping_document(
        "a3", legmap.joint_names, sources, signs, "csv", recs[0].sensor_model, ft=True))
    import_log([log], mapping, legmap, tmp_path / "session", ranges=spans, plot=False)
    try:
        got = offsets(legmap, load_session(tmp_path / "session", robot=legmap))
    except Exception:  # noqa: BLE001 - a refusal is also not the native answer
        return
    assert np.abs(got - want).max() > 1e-3


def test_multi_rate_log_with_jitter_and_a_dropped_message(native, legmap, tmp_path):
    """(b): the same session logged as a robot's logger would at other rates: the encoders
    (and F/T) at 500 Hz, the IMU at 200 Hz, each a smooth (cubic) curve through the native
    samples, stamps with jitter, one IMU message dropped. Imported onto a 50 Hz clock, the
    offsets are within 0.002 deg of the native recordings'; the drop is reported."""
    from scipy.interpolate import CubicSpline

    recs, want = native
    rng = np.random.default_rng(7)
    streams, sources, signs, spans = as_log(recs, legmap)
    t = streams.joint_time
    fast, slow = np.arange(t[0], t[-1], 1 / 500.0), np.arange(t[0], t[-1], 1 / 200.0)
    jitter = 2e-4  # s, uniform: stamps taken by a busy logger
    drop = len(slow) // 3
    keep = np.arange(len(slow)) != drop
    streams.joint_pos = CubicSpline(t, streams.joint_pos)(fast)
    streams.ft = CubicSpline(t, streams.ft)(fast)
    streams.imu_acc = CubicSpline(t, streams.imu_acc)(slow)[keep]
    streams.imu_gyro = CubicSpline(t, streams.imu_gyro)(slow)[keep]
    streams.joint_time = fast + rng.uniform(-jitter, jitter, fast.size)
    streams.ft_time = fast + rng.uniform(-jitter, jitter, fast.size)
    streams.imu_time = slow[keep] + rng.uniform(-jitter, jitter, keep.sum())
    log = write_log(tmp_path / "bag", streams, "mcap")
    doc = mapping_document("a3", legmap.joint_names, sources, signs, "mcap", recs[0].sensor_model, ft=True)
    mapping = write_mapping(tmp_path / "map.yaml", {**doc, "clock": 50.0})
    s = import_log([log], mapping, legmap, tmp_path / "session", ranges=spans, plot=False)
    assert abs(s.streams["joints"]["rate_hz"] - 500) < 1 and abs(s.streams["imu"]["rate_hz"] - 200) < 1
    assert s.streams["imu"]["dropped_count"] == 1 and s.streams["joints"]["dropped_count"] == 0
    assert abs(s.streams["imu"]["dropped"][0]["t0"] - slow[drop - 1]) < 2 * jitter
    assert sum("'imu'" in w and "dropped" in w for w in s.warnings) == 1
    got = offsets(legmap, load_session(tmp_path / "session", robot=legmap))
    assert np.rad2deg(np.abs(got - want).max()) < 0.002


# ------------------------------------------------------------------ (d) mapping errors
@pytest.fixture(scope="module")
def small_log(tmp_path_factory, legmap):
    out = tmp_path_factory.mktemp("small")
    collect(CollectConfig(robot="a3", mode="kinematic", heldout=0, stance_s=4.0, standing_s=3.0), out / "set",
            progress=False)
    recs = load_session(out / "set", robot=legmap)
    streams, sources, signs, spans = as_log(recs, legmap)
    write_log(out / "bag", streams, "mcap")
    write_log(out / "log.csv", streams, "csv")
    doc = mapping_document("a3", legmap.joint_names, sources, signs, "mcap", recs[0].sensor_model, ft=False)
    tdoc = mapping_document("a3", legmap.joint_names, sources, signs, "csv", recs[0].sensor_model, ft=False)
    return out, doc, tdoc


def _set(doc, path, value):
    d = copy.deepcopy(doc)
    keys = path.split(".")
    node = d
    for k in keys[:-1]:
        node = node[k]
    if value is _DELETE:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return d


class _Delete:
    def __repr__(self) -> str:  # a stable test id under xdist
        return "<deleted>"


_DELETE = _Delete()
J0 = "left_hip_pitch_joint"

# (change, value, the field the message must name)
BAD = [
    ("format", "legcal-log-map/9", "format"),
    ("robot", "g1", "robot"),
    ("time_source", "gps", "time_source"),
    ("gap_tolerance_s", -1, "gap_tolerance_s"),
    ("gap_tolerance_s", "fast", "gap_tolerance_s"),
    ("clock", 0, "clock"),
    ("sensor_model", _DELETE, "sensor_model"),
    ("sensor_model", "perfect", "sensor_model"),
    ("sensor_model.accel_bias_bound", _DELETE, "sensor_model"),
    ("sensor_model.gyro_noise_std", -0.1, "sensor_model"),
    ("motion", "walking", "motion"),
    ("joints", _DELETE, "joints"),
    ("joints.topic", "/nope", "joints.topic"),
    ("joints.topic", 5, "joints.topic"),
    ("joints.map", [], "joints.map"),
    ("joints.map.left_hip_pitch_joint", _DELETE, "joints.map"),
    ("joints.map.left_hip_pitch_joint.sign", 2, f"joints.map.{J0}.sign"),
    ("joints.map.left_hip_pitch_joint.unit", "grad", f"joints.map.{J0}.unit"),
    ("joints.map.left_hip_pitch_joint.source", "NOT_A_JOINT", f"joints.map.{J0}.source"),
    ("joints.map.left_hip_pitch_joint.sorce", "x", f"joints.map.{J0}.sorce"),
    ("joints.map.not_a_leg_joint", {"source": "x"}, "joints.map.not_a_leg_joint"),
    ("joints.position", "positions", "position"),
    ("imu", _DELETE, "imu"),
    ("imu.topic", "/imu/none", "imu.topic"),
    ("imu.acc_unit", "ft/s^2", "imu.acc_unit"),
    ("imu.gyro_unit", "rpm", "imu.gyro_unit"),
    ("imu.rotation", {"rpy_deg": [0, 0]}, "imu.rotation.rpy_deg"),
    ("imu.rotation", {"matrix": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}, "imu.rotation.matrix"),
    ("imu.rotation", {"rpy_deg": [0, 0, 0], "matrix": np.eye(3).tolist()}, "imu.rotation"),
    ("imu.acc", "accel", "accel"),
    ("ft", {"left": {"topic": "/ft/left"}}, "ft.right"),
    ("ft", {"left": {"topic": "/ft/nope"}, "right": {"topic": "/ft/nope2"}}, "ft.left.topic"),
    ("contact", {"left": {"topic": "/c"}, "right": {"topic": "/c", "field": "data"}}, "contact.left.field"),
    ("messages", {"my_msgs/Thing": "x.msg"}, "messages.my_msgs/Thing"),
    ("messages", {"my_msgs/msg/Thing": "missing.msg"}, "messages.my_msgs/msg/Thing"),
    ("detection", {"min_duration_s": 0}, "detection.min_duration_s"),
    ("detection", {"still_sped": 1}, "detection.still_sped"),
    ("extra_field", 1, "extra_field"),
]
BAD_TABLE = [
    ("time.column", "stamp", "time.column"),
    ("time.unit", "days", "time.unit"),
    ("joints.map.left_hip_pitch_joint.source", "nope_pos", f"joints.map.{J0}.source"),
    ("imu.acc", ["acc_x", "acc_y"], "imu.acc"),
    ("imu.gyro", ["gyro_x", "gyro_y", "nope"], "imu"),
]


@pytest.mark.parametrize("change,value,field", BAD + [("table:" + c, v, f) for c, v, f in BAD_TABLE],
                         ids=[f"{c}={v!r}"[:60] for c, v, _ in BAD] + [f"table:{c}" for c, _, _ in BAD_TABLE])
def test_every_mapping_error_names_its_field(change, value, field, small_log, legmap, tmp_path):
    """(d)"""
    out, doc, tdoc = small_log
    table = change.startswith("table:")
    change = change.removeprefix("table:")
    bad = _set(tdoc if table else doc, change, value)
    path = tmp_path / "map.yaml"
    path.write_text(yaml.safe_dump(bad))
    with pytest.raises(LogImportError) as e:
        import_log([out / ("log.csv" if table else "bag")], path, legmap, tmp_path / "session", plot=False)
    assert f"'{field}" in str(e.value) or f"{field}" in str(e.value), str(e.value)
    assert str(path) in str(e.value) or "column" in str(e.value) or "topic" in str(e.value)
    assert not (tmp_path / "session").exists()  # nothing half-written


def test_the_good_mapping_imports(small_log, legmap, tmp_path):
    """The baseline the error cases mutate is itself accepted (so each refusal is the mutation's)."""
    out, doc, tdoc = small_log
    for log, d in (("bag", doc), ("log.csv", tdoc)):
        path = tmp_path / f"{log}.yaml"
        path.write_text(yaml.safe_dump(d))
        s = import_log([out / log], path, legmap, tmp_path / f"s_{log}", plot=False)
        assert [g["kind"] for g in s.segments].count("stance") == 4
    shutil.rmtree(tmp_path)


# ------------------------------------------------------------- a vendor's own messages
MOTOR_MSG = "float64 q\nfloat64 dq\nfloat32 tau_est\n"
LOWSTATE_MSG = "uint32 tick\nvendor_msgs/MotorState[16] motor_state\nfloat64[3] accelerometer\nfloat64[3] gyroscope\n"


def test_a_vendors_low_level_state_message_through_field_paths(small_log, legmap, tmp_path):
    """One custom message carries every motor (an array of messages, no joint names) and
    the IMU: field paths (`motor_state.q`), index sources, receive-time stamps and the
    .msg definitions from the mapping file give the same recordings as the native ones."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    out, _, _ = small_log
    recs = load_session(out / "set", robot=legmap)
    (tmp_path / "msgs").mkdir()
    (tmp_path / "msgs" / "MotorState.msg").write_text(MOTOR_MSG)
    (tmp_path / "msgs" / "LowState.msg").write_text(LOWSTATE_MSG)
    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register({**get_types_from_msg(MOTOR_MSG, "vendor_msgs/msg/MotorState"),
                    **get_types_from_msg(LOWSTATE_MSG, "vendor_msgs/msg/LowState")})
    Motor, Low = store.types["vendor_msgs/msg/MotorState"], store.types["vendor_msgs/msg/LowState"]
    slots = np.random.default_rng(1).permutation(16)[:legmap.n_joints]  # motor slot of each leg joint
    streams, _, _, spans = as_log(recs, legmap)
    q = np.concatenate([r.q_enc for r in recs])
    with Writer(tmp_path / "bag", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/lowstate", "vendor_msgs/msg/LowState", typestore=store)
        for k, t in enumerate(streams.joint_time):
            motors = [Motor(q=0.0, dq=0.0, tau_est=0.0) for _ in range(16)]
            for j, s in enumerate(slots):
                motors[s] = Motor(q=float(q[k, j]), dq=0.0, tau_est=0.0)
            msg = Low(tick=k, motor_state=motors, accelerometer=streams.imu_acc[k].copy(),
                      gyroscope=streams.imu_gyro[k].copy())
            w.write(conn, int(streams.t0_ns + round(t * 1e9)), store.serialize_cdr(msg, "vendor_msgs/msg/LowState"))
    doc = {"format": "legcal-log-map/1", "robot": "a3", "time_source": "receive",
           "sensor_model": recs[0].sensor_model.to_dict(),
           "messages": {"vendor_msgs/msg/MotorState": "msgs/MotorState.msg",
                        "vendor_msgs/msg/LowState": "msgs/LowState.msg"},
           "joints": {"topic": "/lowstate", "position": "motor_state.q", "names": None,
                      "map": {n: {"source": int(s)} for n, s in zip(legmap.joint_names, slots)}},
           "imu": {"topic": "/lowstate", "acc": "accelerometer", "gyro": "gyroscope"}}
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(doc))
    import_log([tmp_path / "bag"], tmp_path / "map.yaml", legmap, tmp_path / "session", ranges=spans, plot=False)
    got = load_session(tmp_path / "session", robot=legmap)
    for r, g in zip(recs, got):
        np.testing.assert_array_equal(g.q_enc, r.q_enc)
        np.testing.assert_array_equal(g.imu_acc, r.imu_acc)
    # A header stamp asked of a message without a header is named, with the fix.
    (tmp_path / "map.yaml").write_text(yaml.safe_dump({**doc, "time_source": "header"}))
    with pytest.raises(LogImportError, match="time_source.*receive"):
        import_log([tmp_path / "bag"], tmp_path / "map.yaml", legmap, tmp_path / "s2", plot=False)
    # A .msg that does not parse is named by its field.
    (tmp_path / "msgs" / "LowState.msg").write_text("float64[ accelerometer\n")
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(LogImportError, match="messages.vendor_msgs/msg/LowState"):
        import_log([tmp_path / "bag"], tmp_path / "map.yaml", legmap, tmp_path / "s3", plot=False)


def test_an_import_replaces_an_earlier_import_only(small_log, legmap, tmp_path):
    out, doc, _ = small_log
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(doc))
    for _ in range(2):  # the second replaces the first (its timeline.png included)
        import_log([out / "bag"], tmp_path / "map.yaml", legmap, tmp_path / "session")
    assert (tmp_path / "session" / "timeline.png").is_file()
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    with pytest.raises(LogImportError, match="not a session folder"):
        import_log([out / "bag"], tmp_path / "map.yaml", legmap, tmp_path / "other")
    assert (tmp_path / "other" / "notes.txt").read_text() == "mine"


def test_a_gap_longer_than_the_tolerance_splits_a_segment_and_is_reported(small_log, legmap, tmp_path):
    out, doc, _ = small_log
    recs = load_session(out / "set", robot=legmap)
    streams, _, _, spans = as_log(recs, legmap)
    t0, t1 = spans[2]  # the second stance
    mid = (t0 + t1) / 2
    cut = (streams.imu_time > mid - 0.15) & (streams.imu_time < mid + 0.15)  # 0.3 s of IMU messages lost
    streams.imu_time, streams.imu_acc, streams.imu_gyro = (streams.imu_time[~cut], streams.imu_acc[~cut],
                                                           streams.imu_gyro[~cut])
    write_log(tmp_path / "bag", streams, "mcap")
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(doc))
    s = import_log([tmp_path / "bag"], tmp_path / "map.yaml", legmap, tmp_path / "session", ranges=spans,
                   plot=False)
    inside = [g for g in s.segments if t0 - 1e-6 <= g["t0"] and g["t1"] <= t1 + 1e-6]
    assert len(inside) == 2 and inside[0]["t1"] < mid - 0.15 and inside[1]["t0"] > mid + 0.15 - 1e-6
    assert [g["stream"] for g in s.gaps] == ["imu"] and 0.3 - 1e-6 <= s.gaps[0]["seconds"] <= 0.32 + 1e-6
    assert sum("'imu' has a gap" in w for w in s.warnings) == 1


def test_a_motion_declaration_the_data_contradict_is_named_at_import(small_log, legmap, tmp_path):
    """The small log is hold-and-log (the simulator's kinematic mode): declared continuous,
    the import measures static in every stance and says so."""
    out, doc, _ = small_log
    recs = load_session(out / "set", robot=legmap)
    spans = as_log(recs, legmap)[3]
    (tmp_path / "map.yaml").write_text(yaml.safe_dump({**doc, "motion": "continuous"}))
    s = import_log([out / "bag"], tmp_path / "map.yaml", legmap, tmp_path / "session", ranges=spans, plot=False)
    stances = [g for g in s.segments if g["kind"] == "stance"]
    assert [g["motion"] for g in stances] == ["static"] * 4
    assert sum("declared 'continuous', the data show 'static'" in w for w in s.warnings) == 4
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(doc))  # undeclared: measured, no alarm
    s = import_log([out / "bag"], tmp_path / "map.yaml", legmap, tmp_path / "session", ranges=spans, plot=False)
    assert [g["motion"] for g in s.segments if g["kind"] == "stance"] == ["static"] * 4
    assert not any("motion" in w for w in s.warnings)
