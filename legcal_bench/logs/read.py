"""Reading a robot's log into timed streams, through the mapping file.

Bags (ROS 2 MCAP or sqlite3, ROS 1) are read by `rosbags`, which needs no ROS install:
message definitions embedded in the bag are used, else the standard ROS 2 types plus
the `.msg` files the mapping names. Tables (CSV, Parquet) are read by pyarrow. Every
stream comes out in the leg map's conventions: joints in leg-map order, signed, in
radians; the IMU's specific force (m/s^2) and angular rate (rad/s) and the ankle
wrenches rotated into the leg map's frames; times in seconds from the log's first
stamp (kept as integer nanoseconds until then, so no precision is lost).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from legcal_bench.errors import LogImportError
from legcal_bench.logs.mapping import MAX_FRAMES, SIDES, LogMapping, too_many

BAG_SUFFIXES = (".mcap", ".db3", ".bag")
TABLE_SUFFIXES = (".csv", ".parquet")


@dataclass
class Streams:
    """Timed streams in the leg map's conventions. `time` values: seconds from `t0_ns`."""

    t0_ns: int
    joints: tuple[np.ndarray, np.ndarray]  # (M,), (M, n) rad, leg-map order
    imu: tuple[np.ndarray, np.ndarray]  # (M,), (M, 6) [specific force m/s^2, angular rate rad/s]
    ft: dict  # side -> ((M,), (M, 6) [force N, torque N m])
    contact: dict  # side -> ((M,), (M, 1) reading)
    sources: dict  # stream -> what it was read from (topic or columns), for the report

    def named(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        out = {"joints": self.joints, "imu": self.imu}
        out.update({f"ft_{s}": v for s, v in self.ft.items()})
        out.update({f"contact_{s}": v for s, v in self.contact.items()})
        return out


def log_kind(paths: list[Path]) -> str:
    """"bag" or "table" for the given log paths (all of one kind)."""
    kinds = set()
    for p in paths:
        if not p.exists():
            raise LogImportError(f"--log {p}: no such file or folder")
        if p.is_dir() and (p / "metadata.yaml").is_file():
            kinds.add("bag")
        elif p.is_file() and p.suffix.lower() in BAG_SUFFIXES:
            kinds.add("bag")
        elif p.is_file() and p.suffix.lower() in TABLE_SUFFIXES:
            kinds.add("table")
        else:
            raise LogImportError(f"--log {p}: not a log this reader knows: a ROS 2 bag (a folder with metadata.yaml, "
                                 f"or a .mcap/.db3 file), a ROS 1 .bag, a .csv or a .parquet table")
    if len(kinds) > 1:
        raise LogImportError("--log: give either bags or tables, not both (import them separately)")
    return kinds.pop()


def read_log(paths: list[Path], mapping: LogMapping, joint_names: list[str]) -> Streams:
    paths = [Path(p) for p in paths]
    if log_kind(paths) == "bag":
        return _read_bags(paths, mapping, joint_names)
    return _read_tables(paths, mapping, joint_names)


# ------------------------------------------------------------------------ bags
def _typestore(mapping: LogMapping):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.LATEST)
    types = {}
    for name, path in mapping.messages.items():
        try:
            types.update(get_types_from_msg(path.read_text(encoding="utf-8"), name))
        except Exception as e:  # noqa: BLE001 - rosbags' parser raises its own and generic errors
            raise LogImportError(f"{mapping.path}: field 'messages.{name}': {path} is not a valid .msg "
                                 f"definition ({e})") from None
    if types:
        try:
            store.register(types)
        except Exception as e:  # noqa: BLE001
            raise LogImportError(f"{mapping.path}: field 'messages': the definitions do not register ({e}); "
                                 "give every nested type's .msg too") from None
    return store


def _get(msg, path: str, where: str):
    """The value at a dot path in a message; an array of messages maps the rest of the path."""
    parts = path.split(".")
    value = msg
    for i, part in enumerate(parts):
        if isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray) and value.dtype == object):
            rest = ".".join(parts[i:])
            return [_get(v, rest, where) for v in value]
        if not hasattr(value, part):
            have = [k for k in getattr(value, "__dataclass_fields__", {})] or dir(value)
            raise LogImportError(f"{where}: the message has no field '{part}' (path '{path}'); its fields: "
                                 f"{[h for h in have if not h.startswith('_')]}")
        value = getattr(value, part)
    return value


def _vector(v, where: str, n: int) -> np.ndarray:
    if all(hasattr(v, c) for c in "xyz") and n == 3:
        return np.array([v.x, v.y, v.z], dtype=float)
    try:
        a = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise LogImportError(f"{where}: not numbers ({type(v).__name__})") from None
    if a.shape != (n,):
        raise LogImportError(f"{where}: expected {n} numbers, got {a.size}")
    return a


def _stamp_ns(msg, receive_ns: int, mapping: LogMapping, where: str) -> int:
    if mapping.time_source == "receive":
        return int(receive_ns)
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is None:
        raise LogImportError(f"{mapping.path}: field 'time_source' is header, but {where} has no header.stamp: "
                             "use `time_source: receive` (the bag's receive times)")
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _read_bags(paths: list[Path], mapping: LogMapping, joint_names: list[str]) -> Streams:
    from rosbags.highlevel import AnyReader

    wanted = {"joints": mapping.joints.topic, "imu": mapping.imu.topic}
    wanted.update({f"ft_{s}": st.topic for s, st in mapping.ft.items()})
    wanted.update({f"contact_{s}": st.topic for s, st in mapping.contact.items()})
    raw: dict[str, list] = {k: [] for k in wanted}
    try:
        reader = AnyReader(paths, default_typestore=_typestore(mapping))
        reader.open()
    except LogImportError:
        raise
    except Exception as e:  # noqa: BLE001 - rosbags raises several reader errors
        raise LogImportError(f"--log {', '.join(map(str, paths))}: cannot be read as a bag ({e})") from None
    try:
        topics = {c.topic for c in reader.connections}
        for key, topic in wanted.items():
            if topic not in topics:
                field = {"joints": "joints.topic", "imu": "imu.topic"}.get(key, key.replace("_", ".") + ".topic")
                raise LogImportError(f"{mapping.path}: field '{field}' is {topic!r}, which is not in the log; its "
                                     f"topics: {sorted(topics)}")
        conns = [c for c in reader.connections if c.topic in set(wanted.values())]
        keys_of = {}  # one topic may feed several streams (e.g. a vendor's state message)
        for k, t in wanted.items():
            keys_of.setdefault(t, []).append(k)
        from rosbags.rosbag2.errors import ReaderError
        from tqdm import tqdm

        _check_bag_size(reader, conns, mapping, paths)
        total = sum(c.msgcount for c in conns)

        def read(messages) -> None:
            for conn, receive_ns, data in tqdm(messages, total=total, unit="msg", desc="reading",
                                               disable=total < 20000, leave=False):
                try:
                    msg = reader.deserialize(data, conn.msgtype)
                except Exception as e:  # noqa: BLE001
                    raise LogImportError(f"topic {conn.topic} ({conn.msgtype}): a message cannot be decoded ({e}); "
                                         "if it is a custom type, give its .msg under 'messages'") from None
                for k in keys_of[conn.topic]:
                    raw[k].append((_stamp_ns(msg, receive_ns, mapping, f"topic {conn.topic} ({conn.msgtype})"),
                                   msg))

        try:
            read(reader.messages(connections=conns))
        except ReaderError as e:
            if "not in timestamp order" not in str(e):
                raise LogImportError(f"--log {', '.join(map(str, paths))}: cannot be read as a bag ({e})") from None
            # An unindexed MCAP (a streaming writer's: no summary or index section) whose
            # messages are not in log-time order: read it front to back, sorted by log time.
            for v in raw.values():
                v.clear()
            read(_unindexed_messages(reader, conns, paths, e))
    finally:
        reader.close()
    return _assemble_bag(raw, mapping, joint_names)


def _check_bag_size(reader, conns, mapping: LogMapping, paths: list[Path]) -> None:
    """Refuse, from the bag's own counts and span (before any message is read), a log whose
    streams or clock would exceed MAX_FRAMES."""
    logs = ", ".join(map(str, paths))
    for c in conns:
        if c.msgcount > MAX_FRAMES:
            raise too_many(c.msgcount, f"--log {logs}: topic {c.topic} ({c.msgcount:,} messages)",
                           "cut the log into parts (e.g. `ros2 bag convert` or `mcap filter` with start and end "
                           "times) and import each")
    if mapping.clock != "joints":
        span_s = max(int(reader.duration), 0) * 1e-9  # receive times: the header stamps come with the messages
        n = int(span_s * float(mapping.clock)) + 1
        if n > MAX_FRAMES:
            raise too_many(n, f"{mapping.path}: field 'clock' {mapping.clock:g} Hz over the log's {span_s:.1f} s",
                           "give a lower rate, or cut the log into parts")


def _unindexed_messages(reader, conns, paths: list[Path], error: Exception):
    """The messages of unindexed MCAP files, read linearly (rosbags' own scan of the data
    section) and sorted by log (receive) time; a bag this cannot read is refused, named."""
    from rosbags.rosbag2.storage_mcap import McapReader

    logs = ", ".join(map(str, paths))

    def refuse(why: str) -> LogImportError:
        return LogImportError(
            f"--log {logs}: an unindexed MCAP (no summary or index section: a streaming writer's, or a recording "
            f"cut short) whose messages are not in log-time order ({error}), and {why}; rebuild its index with "
            "`mcap recover IN.mcap -o OUT.mcap` (the mcap CLI) and import OUT.mcap")

    want = {(c.topic, c.msgtype): c for c in conns}
    out = []
    for r in getattr(reader, "readers", []):
        storage = getattr(r, "storage", None)
        storages = getattr(storage, "storages", None) or [storage]
        if getattr(getattr(storage, "metadata", None), "compression_mode", None) == "message":
            raise refuse("its messages are compressed one by one, which this reader does not scan")
        for st in storages:
            if not isinstance(st, McapReader) or not hasattr(st, "messages_scan"):
                raise refuse(f"{type(st).__name__} storage cannot be read front to back here")
            mine = [c for c in st.connections if (c.topic, c.msgtype) in want]
            try:
                out += [(want[(c.topic, c.msgtype)], ts, data) for c, ts, data in st.messages_scan(mine)]
            except Exception as e:  # noqa: BLE001 - rosbags' ReaderError and decompression errors
                raise refuse(f"reading it front to back failed too ({e})") from None
    out.sort(key=lambda m: m[1])  # stable: messages of one log time keep their file order
    return out


def _assemble_bag(raw: dict, mapping: LogMapping, joint_names: list[str]) -> Streams:
    for k, msgs in raw.items():
        if not msgs:
            raise LogImportError(f"{mapping.path}: the topic of stream '{k}' has no messages in the log")
    t0 = min(m[0][0] for m in raw.values())

    def times(msgs):
        return (np.array([s for s, _ in msgs], dtype=np.int64) - t0) * 1e-9

    # Joints: by name (any order, extra joints ignored; the order may change per message) or by index.
    jm, cache = mapping.joint_map, {}
    pos_path, names_path = mapping.joints.fields["position"], mapping.joints.fields["names"]
    where = f"topic {mapping.joints.topic}"
    q = np.empty((len(raw["joints"]), len(joint_names)))
    for row, (_, msg) in enumerate(raw["joints"]):
        pos = np.asarray(_get(msg, pos_path, where + f", field '{pos_path}'"), dtype=float).reshape(-1)
        if names_path is None:
            idx = [jm[n].source for n in joint_names]
            if max(idx) >= pos.size:
                raise LogImportError(f"{mapping.path}: field 'joints.map': index {max(idx)} is beyond the "
                                     f"{pos.size} positions of {where}")
        else:
            names = tuple(_get(msg, names_path, where))
            idx = cache.get(names)
            if idx is None:
                lookup = {n: i for i, n in enumerate(names)}
                twice = [(n, jm[n].source) for n in joint_names if names.count(jm[n].source) > 1]
                if twice:
                    leg, src = twice[0]
                    at = [i for i, n in enumerate(names) if n == src]
                    raise LogImportError(
                        f"{where}: joint name {src!r} (field 'joints.map.{leg}.source' in {mapping.path}) appears "
                        f"{len(at)} times in one message, at positions {at} of field '{names_path}': which position "
                        f"is the joint cannot be told; fix the logger's joint names, or map by index (`names: null` "
                        f"and each source the joint's position): {list(names)}")
                missing = [(n, jm[n].source) for n in joint_names if jm[n].source not in lookup]
                if missing:
                    raise LogImportError(
                        f"{mapping.path}: field 'joints.map.{missing[0][0]}.source' is {missing[0][1]!r}, which is "
                        f"not among the joint names of {where}: {list(names)}")
                if len(names) != pos.size:
                    raise LogImportError(f"{where}: a message has {len(names)} names but {pos.size} positions")
                idx = cache[names] = [lookup[jm[n].source] for n in joint_names]
        q[row] = pos[idx]
    q = _joint_units(q, mapping, joint_names)

    def triples(msgs, stream, names, n=3):
        out = np.empty((len(msgs), n * len(names)))
        for row, (_, msg) in enumerate(msgs):
            out[row] = np.concatenate([_vector(_get(msg, stream.fields[f], f"topic {stream.topic}"),
                                               f"topic {stream.topic}, field '{stream.fields[f]}'", n)
                                       for f in names])
        return out

    imu = triples(raw["imu"], mapping.imu, ("acc", "gyro"))
    streams = Streams(t0, (times(raw["joints"]), q), (times(raw["imu"]), _imu_units(imu, mapping)), {}, {},
                      {"joints": mapping.joints.topic, "imu": mapping.imu.topic})
    for side, st in mapping.ft.items():
        w = triples(raw[f"ft_{side}"], st, ("force", "torque"))
        streams.ft[side] = (times(raw[f"ft_{side}"]), _rotate_pairs(w, st.rotation))
        streams.sources[f"ft_{side}"] = st.topic
    for side, st in mapping.contact.items():
        c = np.array([[float(np.asarray(_get(m, st.fields["field"], f"topic {st.topic}"), dtype=float))]
                      for _, m in raw[f"contact_{side}"]])
        streams.contact[side] = (times(raw[f"contact_{side}"]), c)
        streams.sources[f"contact_{side}"] = st.topic
    return streams


def _joint_units(q: np.ndarray, mapping: LogMapping, joint_names: list[str]) -> np.ndarray:
    sign = np.array([mapping.joint_map[n].sign * mapping.joint_map[n].scale for n in joint_names])
    return q * sign


def _imu_units(imu: np.ndarray, mapping: LogMapping) -> np.ndarray:
    R = mapping.imu.rotation
    return np.hstack([imu[:, :3] @ R.T * mapping.acc_scale, imu[:, 3:] @ R.T * mapping.gyro_scale])


def _rotate_pairs(w: np.ndarray, R: np.ndarray) -> np.ndarray:
    return np.hstack([w[:, :3] @ R.T, w[:, 3:] @ R.T])


# ---------------------------------------------------------------------- tables
def _read_table(path: Path) -> dict[str, np.ndarray]:
    try:
        if path.suffix.lower() == ".parquet":
            import pyarrow.parquet as pq

            table = pq.read_table(path)
        else:
            import pyarrow.csv as pcsv

            table = pcsv.read_csv(path)
    except Exception as e:  # noqa: BLE001 - pyarrow raises ArrowInvalid, OSError, ...
        raise LogImportError(f"--log {path}: cannot be read as a {path.suffix[1:]} table ({e})") from None
    return {name: table.column(name) for name in table.column_names}


def _read_tables(paths: list[Path], mapping: LogMapping, joint_names: list[str]) -> Streams:
    """One or more tables (joined by the time column, rows sorted by time). A stream's rows
    are those where all its columns are present (multi-rate logs leave the others empty)."""
    cols: dict[str, list] = {}
    for p in paths:
        for name, c in _read_table(p).items():
            cols.setdefault(name, []).append((p, c))
    names = set(cols)

    def need(column: str, field: str) -> None:
        if column not in names:
            raise LogImportError(f"{mapping.path}: field '{field}' names column {column!r}, which is not in the "
                                 f"log; its columns: {sorted(names)}")

    need(mapping.time_column, "time.column")
    if any(len(v) != len(paths) for v in cols.values()):
        raise LogImportError("--log: several tables must have the same columns (one log cut into files)")

    def column(name: str) -> np.ndarray:
        parts = []
        for _, c in cols[name]:
            try:
                parts.append(np.asarray(c.to_numpy(zero_copy_only=False), dtype=float))
            except (TypeError, ValueError):
                raise LogImportError(f"column {name!r} is not numeric") from None
        return np.concatenate(parts)

    t_int = [c for _, c in cols[mapping.time_column]]
    if all(str(c.type).startswith(("int", "uint")) and c.null_count == 0 for c in t_int):
        # Integer stamps (e.g. nanoseconds since the epoch): differences in integers, no precision lost.
        t_raw = np.concatenate([np.asarray(c.to_numpy(), dtype=np.int64) for c in t_int])
        t0_raw = int(t_raw.min())
        t = (t_raw - t0_raw).astype(float) * mapping.time_scale
    else:
        t_raw = column(mapping.time_column)
        if not np.isfinite(t_raw).all():
            raise LogImportError(f"column {mapping.time_column!r} (field 'time.column') has empty or non-numeric "
                                 "rows")
        t0_raw = float(t_raw.min())
        t = (t_raw - t0_raw) * mapping.time_scale
    t0_ns = int(round(t0_raw * mapping.time_scale * 1e9))
    if t.size > MAX_FRAMES:
        raise too_many(t.size, f"--log {', '.join(map(str, paths))}: {t.size:,} rows",
                       "cut the table into parts by time and import each")

    def stream(columns: list[str], field: str):
        for c in columns:
            need(c, field)
        v = np.column_stack([column(c) for c in columns])
        keep = np.isfinite(v).all(axis=1)
        order = np.argsort(t[keep], kind="stable")
        return t[keep][order], v[keep][order]

    for n in joint_names:
        need(mapping.joint_map[n].source, f"joints.map.{n}.source")
    tj, q = stream([mapping.joint_map[n].source for n in joint_names], "joints.map")
    ti, imu = stream(mapping.imu.fields["acc"] + mapping.imu.fields["gyro"], "imu")
    streams = Streams(t0_ns, (tj, _joint_units(q, mapping, joint_names)), (ti, _imu_units(imu, mapping)), {}, {},
                      {"joints": "columns " + ", ".join(mapping.joint_map[n].source for n in joint_names),
                       "imu": "columns " + ", ".join(mapping.imu.fields["acc"] + mapping.imu.fields["gyro"])})
    for side in SIDES:
        if side in mapping.ft:
            st = mapping.ft[side]
            tf, w = stream(st.fields["force"] + st.fields["torque"], f"ft.{side}")
            streams.ft[side] = (tf, _rotate_pairs(w, st.rotation))
            streams.sources[f"ft_{side}"] = "columns " + ", ".join(st.fields["force"] + st.fields["torque"])
        if side in mapping.contact:
            st = mapping.contact[side]
            streams.contact[side] = stream([st.fields["field"]], f"contact.{side}.field")
            streams.sources[f"contact_{side}"] = "column " + st.fields["field"]
    return streams
