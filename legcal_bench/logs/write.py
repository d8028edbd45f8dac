"""Writing a log as a robot's logger would: ROS 2 bags (MCAP, sqlite3), ROS 1 bags,
CSV and Parquet tables, with standard messages (sensor_msgs/JointState, sensor_msgs/Imu,
geometry_msgs/WrenchStamped) and the mapping file that imports it.

Used to turn simulated data into logs (`legcal-bench simulate-log`, the import tests,
the guide's first step); a real robot's logs come from its own logger.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from legcal_bench.errors import LogImportError
from legcal_bench.files.atomic import atomic_write_text
from legcal_bench.logs.mapping import SCHEMA
from legcal_bench.sim.sensors import SensorModel

FORMATS = ("mcap", "sqlite3", "ros1", "csv", "parquet")
TOPICS = {"joints": "/joint_states", "imu": "/imu/data", "ft_left": "/ft/left", "ft_right": "/ft/right"}
EPOCH_NS = 1_767_225_600_000_000_000  # stamps start here (2026-01-01), as a robot's clock would


@dataclass
class LogStreams:
    """What a logger wrote, in the log's own joint names, order and signs."""

    joint_names: list[str]
    joint_time: np.ndarray  # (M,) s
    joint_pos: np.ndarray  # (M, k) in the log's units
    imu_time: np.ndarray
    imu_acc: np.ndarray  # (M, 3)
    imu_gyro: np.ndarray
    ft_time: np.ndarray | None = None
    ft: np.ndarray | None = None  # (M, 2, 6) left, right
    t0_ns: int = EPOCH_NS
    frame_ids: dict = field(default_factory=lambda: {"imu": "imu_link", "ft_left": "left_ft", "ft_right": "right_ft"})


def _ns(streams: LogStreams, t: np.ndarray) -> np.ndarray:
    return streams.t0_ns + np.rint(np.asarray(t) * 1e9).astype(np.int64)


def _messages(streams: LogStreams, store):
    """(topic, type, [(stamp_ns, message)...]) per stream."""
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    V3 = store.types["geometry_msgs/msg/Vector3"]
    Q = store.types["geometry_msgs/msg/Quaternion"]

    def header(ns: int, frame: str):
        return Header(stamp=Time(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000)), frame_id=frame)

    def v3(a):
        return V3(x=float(a[0]), y=float(a[1]), z=float(a[2]))

    JS = store.types["sensor_msgs/msg/JointState"]
    zeros = np.zeros(len(streams.joint_names))
    joints = [(ns, JS(header=header(ns, ""), name=list(streams.joint_names), position=np.ascontiguousarray(p, dtype=np.float64),
                      velocity=zeros, effort=zeros))
              for ns, p in zip(_ns(streams, streams.joint_time), streams.joint_pos)]
    Imu = store.types["sensor_msgs/msg/Imu"]
    cov = np.zeros(9)
    imu = [(ns, Imu(header=header(ns, streams.frame_ids["imu"]), orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
                    orientation_covariance=np.r_[-1.0, np.zeros(8)], angular_velocity=v3(g),
                    angular_velocity_covariance=cov, linear_acceleration=v3(a), linear_acceleration_covariance=cov))
           for ns, a, g in zip(_ns(streams, streams.imu_time), streams.imu_acc, streams.imu_gyro)]
    out = [(TOPICS["joints"], "sensor_msgs/msg/JointState", joints), (TOPICS["imu"], "sensor_msgs/msg/Imu", imu)]
    if streams.ft is not None:
        WS = store.types["geometry_msgs/msg/WrenchStamped"]
        W = store.types["geometry_msgs/msg/Wrench"]
        for side, k in (("ft_left", 0), ("ft_right", 1)):
            out.append((TOPICS[side], "geometry_msgs/msg/WrenchStamped", [
                (ns, WS(header=header(ns, streams.frame_ids[side]), wrench=W(force=v3(w[k, :3]), torque=v3(w[k, 3:]))))
                for ns, w in zip(_ns(streams, streams.ft_time), streams.ft)]))
    return out


def write_bag(path: str | Path, streams: LogStreams, storage: str) -> Path:
    """A ROS 2 bag (storage "mcap" or "sqlite3": a folder) or a ROS 1 bag ("ros1": a .bag file)."""
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    if path.exists():
        raise LogImportError(f"{path} exists: give a new path for the bag")
    if storage == "ros1":
        from rosbags.rosbag1 import Writer as Writer1

        store = get_typestore(Stores.ROS1_NOETIC)
        # ROS 1 names types without /msg/; the ROS 1 store holds the same standard messages.
        ros2 = get_typestore(Stores.ROS2_HUMBLE)
        entries = _messages(streams, ros2)
        with Writer1(path) as w:
            for topic, typ, msgs in entries:
                conn = w.add_connection(topic, typ, typestore=store)
                for ns, m in msgs:
                    w.write(conn, int(ns), store.serialize_ros1(_to_store(m, store), typ))
        return path
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2

    store = get_typestore(Stores.ROS2_HUMBLE)
    plugin = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}[storage]
    with Writer2(path, version=9, storage_plugin=plugin) as w:
        for topic, typ, msgs in _messages(streams, store):
            conn = w.add_connection(topic, typ, typestore=store)
            for ns, m in msgs:
                w.write(conn, int(ns), store.serialize_cdr(m, typ))
    return path


def _to_store(msg, store):
    """A ROS 2 message object rebuilt from `store`'s classes of the same names (ROS 1)."""
    cls = store.types[msg.__msgtype__]
    kwargs = {}
    for name in msg.__dataclass_fields__:
        if name == "__msgtype__":
            continue
        v = getattr(msg, name)
        kwargs[name] = _to_store(v, store) if hasattr(v, "__msgtype__") else v
    if msg.__msgtype__ == "std_msgs/msg/Header":
        kwargs.setdefault("seq", 0)
    fields_ = set(cls.__dataclass_fields__)
    return cls(**{k: v for k, v in kwargs.items() if k in fields_})


def write_table(path: str | Path, streams: LogStreams, fmt: str) -> Path:
    """One table with a `time` column (s, from the log's clock) and a column per quantity;
    a stream's columns are empty (NaN) on the others' rows when rates differ."""
    import pyarrow as pa

    path = Path(path)
    t_all = np.unique(np.concatenate([streams.joint_time, streams.imu_time]
                                     + ([streams.ft_time] if streams.ft is not None else [])))
    # Parquet: integer nanoseconds since the epoch; CSV: seconds from the start (text keeps them whole).
    cols = {"time": _ns(streams, t_all) if fmt == "parquet" else t_all}

    def put(names, t, v):
        idx = np.searchsorted(t_all, t)
        for c, name in enumerate(names):
            col = np.full(t_all.size, np.nan)
            col[idx] = v[:, c]
            cols[name] = col

    put([f"{n}_pos" for n in streams.joint_names], streams.joint_time, streams.joint_pos)
    put(["acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z"], streams.imu_time,
        np.hstack([streams.imu_acc, streams.imu_gyro]))
    if streams.ft is not None:
        for k, side in enumerate(("l", "r")):
            put([f"{side}_{q}{a}" for q in ("f", "t") for a in "xyz"], streams.ft_time, streams.ft[:, k])
    table = pa.table(cols)
    path.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "parquet":
        import pyarrow.parquet as pq

        pq.write_table(table, path)
    else:
        import pyarrow.csv as pcsv

        pcsv.write_csv(table, path)
    return path


def write_log(path: str | Path, streams: LogStreams, fmt: str) -> Path:
    if fmt not in FORMATS:
        raise LogImportError(f"log format {fmt!r}: use one of {FORMATS}")
    if fmt in ("csv", "parquet"):
        return write_table(path, streams, fmt)
    return write_bag(path, streams, fmt)


def mapping_document(robot: str, leg_joints: list[str], sources: list[str], signs: list[int], fmt: str,
                     sensor_model: SensorModel | None, ft: bool, motion: str | None = None) -> dict:
    """The mapping file for a log written by `write_log` (leg joint i comes from log joint
    `sources[i]` with `signs[i]`)."""
    table = fmt in ("csv", "parquet")
    doc: dict = {"format": SCHEMA, "robot": robot, "time_source": "header", "gap_tolerance_s": 0.1,
                 "sensor_model": "unknown" if sensor_model is None else sensor_model.to_dict()}
    if motion:
        doc["motion"] = motion
    if table:
        doc["time"] = {"column": "time", "unit": "ns" if fmt == "parquet" else "s"}
        doc["joints"] = {"map": {n: {"source": f"{s}_pos", "sign": int(g), "unit": "rad"}
                                 for n, s, g in zip(leg_joints, sources, signs)}}
        doc["imu"] = {"acc": ["acc_x", "acc_y", "acc_z"], "gyro": ["gyro_x", "gyro_y", "gyro_z"]}
        if ft:
            doc["ft"] = {s: {"force": [f"{c}_f{a}" for a in "xyz"], "torque": [f"{c}_t{a}" for a in "xyz"]}
                         for s, c in (("left", "l"), ("right", "r"))}
    else:
        doc["joints"] = {"topic": TOPICS["joints"], "map": {n: {"source": s, "sign": int(g), "unit": "rad"}
                                                            for n, s, g in zip(leg_joints, sources, signs)}}
        doc["imu"] = {"topic": TOPICS["imu"]}
        if ft:
            doc["ft"] = {"left": {"topic": TOPICS["ft_left"]}, "right": {"topic": TOPICS["ft_right"]}}
    return doc


def write_mapping(path: str | Path, doc: dict) -> Path:
    return atomic_write_text(path, "# legcal-bench log mapping (docs/log-import.md)\n"
                             + yaml.safe_dump(doc, sort_keys=False))
