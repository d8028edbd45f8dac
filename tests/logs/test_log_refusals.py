"""The log import's silent-garbage and misdirected-message cases (issue #58): sizes that
would exhaust memory refused before the work, with the number; an unindexed MCAP with
out-of-order log times read (front to back, sorted by log time); a duplicated joint
name, degrees declared on radians, header stamps never set and milliseconds declared as
seconds each refused naming their cause and field; `simulate-log --mjcf` refused."""

from __future__ import annotations

import struct
from io import BytesIO

import numpy as np
import pytest
import yaml

from legcal_bench.data.recording import load_session
from legcal_bench.errors import LogImportError
from legcal_bench.logs.importer import import_log
from legcal_bench.logs.write import write_log
from tests.logs.test_import import as_log, legmap, small_log  # noqa: F401 - fixtures

pytestmark = pytest.mark.xdist_group("log_import")


@pytest.fixture(scope="module")
def log(small_log, legmap):
    """test_import's small hold-and-log session (19 s at 50 Hz, no F/T) as a log: (folder,
    streams, sources, signs, spans, bag mapping, table mapping, recordings)."""
    out, doc, tdoc = small_log
    recs = load_session(out / "set", robot=legmap)
    streams, sources, signs, spans = as_log(recs, legmap)
    return out, streams, sources, signs, spans, doc, tdoc, recs


def _map(tmp_path, doc, name="map.yaml"):
    (tmp_path / name).write_text(yaml.safe_dump(doc))
    return tmp_path / name


# ------------------------------------------------------------------ sizes
def test_a_clock_rate_no_recording_takes_is_refused_with_the_number(log, legmap, tmp_path):
    out, doc = log[0], log[5]
    with pytest.raises(LogImportError, match=r"field 'clock' is 1e\+07 Hz, outside 1-5000 Hz") as e:
        import_log([out / "bag"], _map(tmp_path, {**doc, "clock": 1e7}), legmap, tmp_path / "s", plot=False)
    assert "100" in str(e.value)  # the fix: a rate the calibration needs
    assert not (tmp_path / "s").exists()


def test_more_frames_than_the_limit_are_refused_before_reading_with_the_number(log, legmap, tmp_path, monkeypatch):
    """The limit is lowered to this small log's size: the joint topic's message count
    (from the bag's index, before any message is read) and a clock rate's frames over the
    log's span are each refused with the number."""
    import legcal_bench.logs.align as align
    import legcal_bench.logs.mapping as mapping
    import legcal_bench.logs.read as read

    out, streams, *_ = log
    doc = log[5]
    for m in (align, mapping, read):
        monkeypatch.setattr(m, "MAX_FRAMES", 500)
    decoded = []
    monkeypatch.setattr(read, "_stamp_ns", lambda *a: decoded.append(1))  # no message may be read
    with pytest.raises(LogImportError, match=r"topic /joint_states \(950 messages\) would give 950 frames, more "
                                             r"than this import holds \(500"):
        import_log([out / "bag"], _map(tmp_path, doc), legmap, tmp_path / "s", plot=False)
    for m in (align, mapping, read):
        monkeypatch.setattr(m, "MAX_FRAMES", 1000)  # the joints' 950 messages pass, 100 Hz over 19 s does not
    with pytest.raises(LogImportError, match=r"field 'clock' 100 Hz over the log's 19.0 s would give 1,[89]\d\d frames"):
        import_log([out / "bag"], _map(tmp_path, {**doc, "clock": 100.0}), legmap, tmp_path / "s", plot=False)
    assert not decoded and not (tmp_path / "s").exists()


# ------------------------------------------------------------------ an unindexed MCAP
def _records(data: bytes):
    """(op, body) of an MCAP's records, the chunks' inner records in place of each chunk."""
    bio = BytesIO(data[8:])
    while True:
        head = bio.read(9)
        if len(head) < 9:
            return
        op, size = head[0], struct.unpack("<Q", head[1:])[0]
        body = bio.read(size)
        if op == 0x06:  # chunk: start, end, uncompressed size, crc, compression, compressed records
            (clen,) = struct.unpack("<I", body[28:32])
            assert body[32:32 + clen] == b""  # rosbags writes chunks uncompressed by default
            yield from _records(b"\0" * 8 + body[32 + clen + 8:])
        else:
            yield op, body


def _streaming_mcap(indexed: bytes) -> bytes:
    """The same messages as a streaming writer leaves them: no chunks, no index, no
    summary (the footer's summary offset 0), topics interleaved slightly out of log-time
    order (every 7th message written after its successor)."""
    recs = list(_records(indexed))
    head = [r for r in recs if r[0] == 0x01]
    meta = [r for r in recs if r[0] in (0x03, 0x04)]
    msgs = sorted((r for r in recs if r[0] == 0x05), key=lambda r: struct.unpack("<Q", r[1][6:14])[0])
    for k in range(0, len(msgs) - 1, 7):
        msgs[k], msgs[k + 1] = msgs[k + 1], msgs[k]

    def rec(op, body):
        return bytes([op]) + struct.pack("<Q", len(body)) + body

    magic = b"\x89MCAP0\r\n"
    return (magic + b"".join(rec(*r) for r in head + meta + msgs) + rec(0x0F, struct.pack("<I", 0))
            + rec(0x02, struct.pack("<QQI", 0, 0, 0)) + magic)


def test_an_unindexed_mcap_with_out_of_order_log_times_is_read_in_log_time_order(log, legmap, tmp_path):
    out, streams, sources, signs, spans, _, _, recs = log
    bag = out / "bag"
    mcap = next(bag.glob("*.mcap"))
    doc = {**log[5], "time_source": "receive"}  # receive times are the out-of-order ones
    stream = tmp_path / "stream.mcap"
    stream.write_bytes(_streaming_mcap(mcap.read_bytes()))
    want = import_log([bag], _map(tmp_path, doc), legmap, tmp_path / "indexed", ranges=spans, plot=False)
    got = import_log([stream], _map(tmp_path, doc), legmap, tmp_path / "streamed", ranges=spans, plot=False)
    assert got.segments == want.segments and got.warnings == want.warnings
    for a, b in zip(load_session(tmp_path / "indexed", robot=legmap), load_session(tmp_path / "streamed",
                                                                                     robot=legmap)):
        np.testing.assert_array_equal(a.q_enc, b.q_enc)
        np.testing.assert_array_equal(a.imu_acc, b.imu_acc)


# ------------------------------------------------------------------ misdirected messages
def test_a_joint_name_twice_in_every_joint_state_is_named(log, legmap, tmp_path):
    out, streams, sources, signs, spans, doc, _, _ = log
    k = streams.joint_names.index(sources[0])
    other = len(streams.joint_names)  # the logger appends a 13th position under a leg joint's name
    pos = np.hstack([streams.joint_pos, streams.joint_pos[:, [(k + 1) % other]]])
    streams = type(streams)(**{**streams.__dict__, "joint_names": [*streams.joint_names, sources[0]],
                               "joint_pos": pos})
    write_log(tmp_path / "bag", streams, "mcap")
    with pytest.raises(LogImportError, match=rf"joint name '{sources[0]}' \(field 'joints.map.{legmap.joint_names[0]}"
                                             rf".source' .*\) appears 2 times in one message, at positions "
                                             rf"\[{min(k, other)}, {max(k, other)}\]") as e:
        import_log([tmp_path / "bag"], _map(tmp_path, doc), legmap, tmp_path / "s", plot=False)
    assert "names: null" in str(e.value)


def test_degrees_declared_on_radian_readings_name_the_unit(log, legmap, tmp_path):
    out, *_ = log
    doc = log[5]
    deg = {**doc, "joints": {**doc["joints"], "map": {n: {**e, "unit": "deg"} for n, e in doc["joints"]["map"].items()}}}
    with pytest.raises(LogImportError, match=rf"field 'joints.map.{legmap.joint_names[0]}.unit' is deg \(and "
                                             rf"{legmap.n_joints - 1} more joints\).*the readings are radians: write "
                                             r"`unit: rad`"):
        import_log([out / "bag"], _map(tmp_path, deg), legmap, tmp_path / "s", plot=False)
    assert not (tmp_path / "s").exists()


def _zero_header_bag(path, streams):
    """The log with every header stamp 0 (a logger that never sets them), receive times kept."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from legcal_bench.logs.write import _messages

    store = get_typestore(Stores.ROS2_HUMBLE)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        for topic, typ, msgs in _messages(streams, store):
            conn = w.add_connection(topic, typ, typestore=store)
            for ns, m in msgs:
                m.header.stamp.sec = m.header.stamp.nanosec = 0
                w.write(conn, int(ns), store.serialize_cdr(m, typ))


def test_header_stamps_never_set_point_at_receive_times(log, legmap, tmp_path):
    out, streams, sources, signs, spans, doc, _, _ = log
    _zero_header_bag(tmp_path / "bag", streams)
    with pytest.raises(LogImportError, match=r"stream 'joints' \(/joint_states\): its 950 messages carry one header "
                                             r"stamp \(all zero: the logger never set header.stamp\).*use "
                                             r"`time_source: receive`"):
        import_log([tmp_path / "bag"], _map(tmp_path, doc), legmap, tmp_path / "s", plot=False)
    # The fix it names imports the log.
    s = import_log([tmp_path / "bag"], _map(tmp_path, {**doc, "time_source": "receive"}), legmap, tmp_path / "s",
                   plot=False)
    assert [g["kind"] for g in s.segments].count("stance") == 4


def test_milliseconds_declared_as_seconds_name_the_time_unit(log, legmap, tmp_path):
    out, streams, sources, signs, spans, _, tdoc, _ = log
    ms = type(streams)(**{**streams.__dict__, "joint_time": streams.joint_time * 1e3,
                          "imu_time": streams.imu_time * 1e3})
    write_log(tmp_path / "log.csv", ms, "csv")
    with pytest.raises(LogImportError, match=r"stream 'joints' \(columns .*\): 950 samples over 18980 s, one every "
                                             r"20 s \(0.05 Hz\): the log is implausibly long for its sample count.*"
                                             r"field 'time.unit' is 's'"):
        import_log([tmp_path / "log.csv"], _map(tmp_path, tdoc), legmap, tmp_path / "s", plot=False)
    s = import_log([tmp_path / "log.csv"], _map(tmp_path, {**tdoc, "time": {"column": "time", "unit": "ms"}}),
                   legmap, tmp_path / "s", plot=False)
    assert [g["kind"] for g in s.segments].count("stance") == 4


# ------------------------------------------------------------------ simulate-log --mjcf
def test_simulate_log_refuses_an_mjcf_it_would_not_simulate(tmp_path, capsys):
    from legcal_bench.cli import main

    assert main(["simulate-log", "--robot", "a3", "--mjcf", str(tmp_path / "missing.xml"), "--out",
                 str(tmp_path / "out"), "--quiet"]) == 2
    assert "--mjcf" in (err := capsys.readouterr().err) and "leave --mjcf out" in err
    assert not (tmp_path / "out").exists()
