"""Finding static double support in a long log (issue #39, test (c)): one simulated log
of standing, the four stances, walking, stepping in place and standing again, with
transitions between (legcal_bench.evaluation.long_log), imported with and without the
ankle F/T: every stance and standing phase is found, stances are told apart by foot
placement, and not one walking, stepping or transition frame is taken."""

from __future__ import annotations

import numpy as np
import pytest

from legcal_bench.api.logs import long_log_streams
from legcal_bench.logs.importer import import_log
from legcal_bench.logs.write import mapping_document, write_log, write_mapping
from legcal_bench.robots import load_robot
from legcal_bench.sim.sensors import SENSOR_PRESETS

pytestmark = pytest.mark.xdist_group("long_log")  # one process simulates the log (tests/conftest.py) for all
STATIC = ("standing", "stance_I", "stance_II", "stance_III", "stance_IV")


@pytest.fixture(scope="module")
def legmap():
    return load_robot("a3")


@pytest.mark.parametrize("fmt,ft", [("mcap", True), ("mcap", False), ("csv", False)],
                         ids=["mcap-with-ft", "mcap-without-ft", "csv-without-ft"])
def test_detection_finds_the_stances_and_takes_no_walking_frame(fmt, ft, long_log, legmap, tmp_path):
    log = write_log(tmp_path / ("bag" if fmt == "mcap" else "log.csv"), long_log_streams(long_log, ft), fmt)
    mapping = write_mapping(tmp_path / "map.yaml", mapping_document(
        "a3", legmap.joint_names, legmap.joint_names, [1] * legmap.n_joints, fmt, SENSOR_PRESETS["realistic"].model,
        ft))
    s = import_log([log], mapping, legmap, tmp_path / "session", plot=False)
    t, labels = long_log.time, long_log.labels
    taken = np.zeros(len(t), bool)
    by_label: dict[str, set] = {}
    for seg in s.segments:
        m = (t >= seg["t0"] - 1e-6) & (t <= seg["t1"] + 1e-6)
        assert m.sum() == seg["frames"]
        taken |= m
        kinds = set(labels[m])
        assert len(kinds) == 1, (seg["name"], kinds)  # one segment never spans two parts of the log
        (label,) = kinds
        assert label in STATIC, (seg["name"], label)  # no walking, stepping or transition frame
        assert seg["kind"] == ("standing" if label == "standing" else "stance"), (seg["name"], label)
        by_label.setdefault(label, set()).add(seg["stance"])
    assert not np.isin(labels[taken], ["walking", "stepping", "transition"]).any()
    for label in STATIC:  # each static part found, nearly whole (the trim and the stillness window aside)
        m = labels == label
        assert taken[m].mean() > 0.85, (label, taken[m].mean())
    stance_labels = [by_label[f"stance_{k}"] for k in ("I", "II", "III", "IV")]
    assert all(len(x) == 1 for x in stance_labels) and len(set.union(*stance_labels)) == 4  # four placements
    assert not any("stance placement" in w for w in s.warnings)


def test_a_log_of_walking_alone_yields_no_segment_and_says_why(long_log, legmap, tmp_path):
    """Walking and stepping only: nothing is taken, and the error gives the reasons."""
    from legcal_bench.errors import LogImportError

    walking = np.isin(long_log.labels, ["walking", "stepping"])
    streams = long_log_streams(long_log, True)
    for name in ("joint", "imu", "ft"):
        setattr(streams, f"{name}_time", getattr(streams, f"{name}_time")[walking])
    streams.joint_pos, streams.imu_acc, streams.imu_gyro = (long_log.q_enc[walking], long_log.imu_acc[walking],
                                                            long_log.imu_gyro[walking])
    streams.ft = long_log.ft[walking]
    log = write_log(tmp_path / "bag", streams, "mcap")
    mapping = write_mapping(tmp_path / "map.yaml", mapping_document(
        "a3", legmap.joint_names, legmap.joint_names, [1] * legmap.n_joints, "mcap", SENSOR_PRESETS["realistic"].model,
        True))
    with pytest.raises(LogImportError, match="no static double-support segment") as e:
        import_log([log], mapping, legmap, tmp_path / "session", plot=False)
    assert "unloaded" in str(e.value) or "move" in str(e.value)
    assert not (tmp_path / "session").exists()


def test_contact_states_instead_of_ft_and_a_held_out_segment(long_log, legmap, tmp_path):
    """A robot with contact topics (here columns) instead of F/T: detection reads them; a
    segment chosen as held-out is kept out of training."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    log = write_log(tmp_path / "log.csv", long_log_streams(long_log, False), "csv")
    table = pcsv.read_csv(log)
    fz = -long_log.ft[:, :, 2]
    loaded = fz / fz.sum(axis=1, keepdims=True) > 0.05  # a contact sensor's threshold
    for k, side in enumerate(("left", "right")):
        table = table.append_column(f"contact_{side}", pa.array(loaded[:, k].astype(int)))
    pcsv.write_csv(table, log)
    doc = mapping_document("a3", legmap.joint_names, legmap.joint_names, [1] * legmap.n_joints, "csv",
                           SENSOR_PRESETS["realistic"].model, False)
    doc["contact"] = {"left": {"field": "contact_left"}, "right": {"field": "contact_right"}}
    mapping = write_mapping(tmp_path / "map.yaml", doc)
    s = import_log([log], mapping, legmap, tmp_path / "session", heldout=["stance_S3"], plot=False)
    t, labels = long_log.time, long_log.labels
    for seg in s.segments:
        m = (t >= seg["t0"] - 1e-6) & (t <= seg["t1"] + 1e-6)
        assert set(labels[m]) <= set(STATIC), seg["name"]
    assert {g["name"]: g["kind"] for g in s.segments}["stance_S3"] == "heldout"
    assert sum(g["kind"] == "stance" for g in s.segments) == 3
    from legcal_bench.data.recording import load_session, training
    recs = load_session(tmp_path / "session", robot=legmap)
    assert "stance_S3" not in [r.name for r in training(recs)]
