"""The mapping file: how a robot's log becomes recordings (schema `legcal-log-map/1`).

It names, for each stream the calibration needs, where it is in the log (a topic and
field paths into its messages for bags; columns for CSV/Parquet tables), how the log's
joints map onto the leg map's (name, sign, unit), the IMU's and the F/T sensors' frame
rotations, the time source, the gap tolerance and the sensor model. Every field is
checked here, before any log is opened, and every error names the field and the fix.
The schema is documented in docs/log-import.md; `example_mapping` writes a commented one.

Field paths (bags): dot-separated attribute names into the message, e.g.
`wrench.force` or `imu_state.accelerometer`. A path that reaches an array of messages
maps the rest of the path over its elements (`motor_state.q`: each motor's `q`).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from legcal_bench.data.recording import MAX_RATE_HZ, MIN_RATE_HZ
from legcal_bench.errors import ConfigError, LogImportError, SensorModelError
from legcal_bench.inputs import is_finite_number, read_text, shown
from legcal_bench.robots.legmap import LegMap
from legcal_bench.sim.sensors import REALIZED_FIELDS, SensorModel

SCHEMA = "legcal-log-map/1"
TIME_SOURCES = ("header", "receive")
JOINT_UNITS = {"rad": 1.0, "deg": np.pi / 180.0}
ACC_UNITS = {"m/s^2": 1.0, "g": 9.80665}
GYRO_UNITS = {"rad/s": 1.0, "deg/s": np.pi / 180.0}
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
MOTIONS = ("static", "continuous")
SIDES = ("left", "right")
# The most frames an import aligns onto one clock, and the most samples it reads per
# stream: the import holds about 1.6-1.9 kB per frame at its peak (measured on the A3,
# clock 2000-4000 Hz, no F/T) and takes about 55 us per frame, so 2 million frames is
# about 3.8 GB and 2 minutes: 11 h at 50 Hz, 33 min at 1 kHz. A longer log is refused
# before it is read or aligned (a lower `clock`, or the log cut into parts, fits).
MAX_FRAMES = 2_000_000


def too_many(n: int, what: str, fix: str) -> LogImportError:
    """The refusal of a log that would give `n` frames or samples (> MAX_FRAMES)."""
    return LogImportError(f"{what} would give {n:,} frames, more than this import holds ({MAX_FRAMES:,}: about "
                          f"1.9 kB each at its peak, so {MAX_FRAMES * 1.9e3 / 1e9:.1f} GB): {fix}")


@dataclass(frozen=True)
class Detection:
    """Thresholds of static double-support detection (`legcal_bench.logs.detect`)."""

    min_duration_s: float = 3.0  # a shorter still run is not a segment (double support inside a gait is ~0.2 s)
    trim_s: float = 0.25  # frames dropped at each end of a segment (settling)
    window_s: float = 0.5  # smoothing window of the stillness rates
    still_speed: float = 0.01  # m/s: the inter-foot transform's translation rate below which the soles are still
    still_turn: float = 0.05  # rad/s: its rotation rate below which the soles are still
    spread_m: float = 0.02  # m: largest inter-foot translation spread across one segment
    load_fraction: float = 0.1  # with F/T: each foot carries at least this fraction of the total force
    level_rad: float = 0.07  # without F/T or contact: angle between the two soles' normals (offsets included)
    height_m: float = 0.03  # without F/T or contact: sole height difference along gravity (offsets included)
    gyro_max: float = 0.3  # rad/s: the pelvis turns slower than this in a stance (walking turns it faster)
    acc_band: float = 1.0  # m/s^2: |specific force| within g +- this
    cluster_m: float = 0.02  # segments whose inter-foot transforms agree this well are one stance
    cluster_rad: float = 0.05
    posture_m: float = 0.01  # a segment whose pelvis moves less than this (p5-p95) is held still
    posture_rad: float = 0.017


@dataclass(frozen=True)
class Stream:
    """Where one stream is: a topic (bags) or none (tables), and its fields' paths or columns."""

    topic: str | None
    fields: dict  # quantity -> field path (bags) or list of columns (tables)
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))  # log frame -> leg map frame


@dataclass(frozen=True)
class JointSource:
    source: str | int  # name in the log's joint-name field, column, or index into the position array
    sign: float = 1.0
    scale: float = 1.0  # to radians


@dataclass(frozen=True)
class LogMapping:
    path: Path
    robot: str | None
    time_source: str
    time_column: str
    time_scale: float
    gap_tolerance_s: float
    clock: str | float  # "joints", or an output rate in Hz
    sensor_model: SensorModel | None  # None: declared `unknown`
    motion: str | None
    messages: dict[str, Path]
    joints: Stream
    joint_map: dict[str, JointSource]
    acc_scale: float
    gyro_scale: float
    imu: Stream
    ft: dict[str, Stream] = field(default_factory=dict)
    contact: dict[str, Stream] = field(default_factory=dict)
    contact_threshold: float = 0.5
    detection: Detection = Detection()

    @property
    def sensor_declared(self) -> bool:
        return self.sensor_model is not None


class _Where:
    """Names a field of the mapping file in every error."""

    def __init__(self, path: Path):
        self.path = path

    def err(self, key: str, msg: str) -> LogImportError:
        return LogImportError(f"{self.path}: field '{key}' {msg}")

    def table(self, d, key: str, known: dict[str, bool]) -> dict:
        """`d` as a mapping with only `known` keys (name -> required)."""
        if not isinstance(d, dict):
            if key:
                raise self.err(key, f"must be a mapping of {', '.join(known)}, got {shown(d)}")
            raise LogImportError(f"{self.path}: the mapping file must be a YAML mapping (see docs/log-import.md), "
                                 f"got {'an empty file' if d is None else type(d).__name__}")
        unknown = [k for k in d if k not in known]
        if unknown:
            close = difflib.get_close_matches(str(unknown[0]), list(known), n=1)
            raise self.err(_join(key, unknown[0]), "is not a mapping-file field here" + (
                f" (did you mean {close[0]!r}?)" if close else " (misspelt?)") + f"; known: {sorted(known)}")
        for k, required in known.items():
            if required and d.get(k) is None:
                raise self.err(_join(key, k), "is required (see docs/log-import.md)")
        return d

    def string(self, v, key: str) -> str:
        if not isinstance(v, str) or not v.strip():
            raise self.err(key, f"must be a non-empty string, got {shown(v)}")
        return v

    def choice(self, v, key: str, choices) -> str:
        if not isinstance(v, str) or v not in choices:
            raise self.err(key, f"is {shown(v)}; use one of {list(choices)}")
        return v

    def number(self, v, key: str, low: float = 0.0, open_low: bool = True) -> float:
        ok = is_finite_number(v) and (v > low if open_low else v >= low)
        if not ok:
            raise self.err(key, f"must be a number {'>' if open_low else '>='} {low:g}, got {shown(v)}")
        return float(v)

    def rotation(self, v, key: str) -> np.ndarray:
        if v is None:
            return np.eye(3)
        d = self.table(v, key, {"rpy_deg": False, "matrix": False})
        if ("rpy_deg" in d) == ("matrix" in d):
            raise self.err(key, "must give exactly one of rpy_deg: [roll, pitch, yaw] (degrees, fixed axes x-y-z) "
                           "or matrix: [[...], [...], [...]] (rows), rotating the log's frame into the leg map's")
        try:
            a = np.asarray(d.get("rpy_deg", d.get("matrix")), dtype=float)
        except (TypeError, ValueError, OverflowError):
            a = np.full(1, np.nan)
        if "rpy_deg" in d:
            if a.shape != (3,) or not np.isfinite(a).all():
                raise self.err(key + ".rpy_deg", f"must be 3 numbers in degrees, got {shown(d['rpy_deg'])}")
            return Rotation.from_euler("xyz", np.deg2rad(a)).as_matrix()
        if a.shape != (3, 3) or not np.isfinite(a).all():
            raise self.err(key + ".matrix", f"must be a 3x3 matrix (3 rows of 3 numbers), got {shown(d['matrix'])}")
        if np.abs(a @ a.T - np.eye(3)).max() > 1e-6 or np.linalg.det(a) < 0:
            raise self.err(key + ".matrix", "is not a rotation (rows orthonormal to 1e-6, determinant +1): a "
                           "mirrored axis is a sign, not a rotation; fix the matrix")
        return a


def _join(key: str, k) -> str:
    return f"{key}.{k}" if key else str(k)


def _paths(w: _Where, d: dict, key: str, name: str, default, table: bool, n: int | None = None):
    """A quantity's field path (bags: a string) or its columns (tables: `n` strings, or one)."""
    v = d.get(name, default)
    k = _join(key, name)
    if table:
        if n is None:
            return w.string(v, k)
        if not (isinstance(v, list) and len(v) == n and all(isinstance(c, str) and c for c in v)):
            raise w.err(k, f"must list {n} column names (a CSV/Parquet log), got {shown(v)}")
        return list(v)
    if v is None:
        raise w.err(k, "is required: the field path into the topic's messages (e.g. 'linear_acceleration')")
    return w.string(v, k)


def load_mapping(path: str | Path, legmap: LegMap, table: bool) -> LogMapping:
    """Read and check the mapping file for `legmap`; `table`: the log is CSV/Parquet
    (columns) rather than bags (topics and field paths)."""
    from legcal_bench.files.packaged import packaged

    path = packaged(path)  # the one rule for a file a user names
    if not path.exists():
        raise LogImportError(f"--map {path}: no such file; write one from docs/log-import.md "
                             "(`legcal-bench import --example-map` prints a commented example)")
    try:
        text = read_text("--map", path, "mapping file")  # a folder, unreadable or not UTF-8: named
    except ConfigError as e:
        raise LogImportError(str(e)) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise LogImportError(f"{path}: not a readable YAML file ({e})") from None
    except RecursionError:
        raise LogImportError(f"{path}: not a readable YAML file (nested too deeply)") from None
    w = _Where(path)
    d = w.table(data, "", {"format": True, "robot": False, "time_source": False, "time": False,
                           "gap_tolerance_s": False, "clock": False, "sensor_model": True, "motion": False,
                           "messages": False, "joints": True, "imu": True, "ft": False, "contact": False,
                           "detection": False})
    if d["format"] != SCHEMA:
        raise w.err("format", f"is {shown(d['format'])}; this reader takes {SCHEMA!r}")
    robot = d.get("robot")
    if robot is not None and robot != legmap.name:
        raise w.err("robot", f"is {shown(robot)} but --robot is {legmap.name!r}: a log mapped for one robot and "
                    "calibrated as another gives wrong offsets; pass the right --robot or fix the field")
    time_source = w.choice(d.get("time_source", "header"), "time_source", TIME_SOURCES)
    t = w.table(d.get("time", {}), "time", {"column": False, "unit": False})
    time_column = w.string(t.get("column", "time"), "time.column")
    time_scale = TIME_UNITS[w.choice(t.get("unit", "s"), "time.unit", TIME_UNITS)]
    gap = w.number(d.get("gap_tolerance_s", 0.1), "gap_tolerance_s")
    clock = d.get("clock", "joints")
    if clock != "joints":
        clock = w.number(clock, "clock")
        if not MIN_RATE_HZ < clock < MAX_RATE_HZ:  # the recordings' rule (legcal_bench.data.recording)
            raise w.err("clock", f"is {clock:g} Hz, outside {MIN_RATE_HZ:g}-{MAX_RATE_HZ:g} Hz (exclusive), "
                        "the rates a recording takes: give `joints` (the joint states' own stamps) or a rate "
                        "such as 100 (the calibration needs no more)")
    sensor = _sensor_model(w, d["sensor_model"])
    motion = d.get("motion")
    if motion is not None:
        w.choice(motion, "motion", MOTIONS)
    messages = _messages(w, d.get("messages") or {})

    j = w.table(d["joints"], "joints", {"topic": not table, "position": False, "names": False, "map": True})
    topic = None if table else w.string(j["topic"], "joints.topic")
    names_field = None if table else j.get("names", "name")
    if names_field is not None:
        names_field = w.string(names_field, "joints.names")
    joints = Stream(topic, {"position": None if table else w.string(j.get("position", "position"),
                                                                     "joints.position"),
                            "names": names_field})
    joint_map = _joint_map(w, j["map"], legmap, table, names_field)

    i = w.table(d["imu"], "imu", {"topic": not table, "acc": table, "gyro": table, "acc_unit": False,
                                  "gyro_unit": False, "rotation": False})
    imu = Stream(None if table else w.string(i["topic"], "imu.topic"),
                 {"acc": _paths(w, i, "imu", "acc", "linear_acceleration", table, 3 if table else None),
                  "gyro": _paths(w, i, "imu", "gyro", "angular_velocity", table, 3 if table else None)},
                 w.rotation(i.get("rotation"), "imu.rotation"))
    acc_scale = ACC_UNITS[w.choice(i.get("acc_unit", "m/s^2"), "imu.acc_unit", ACC_UNITS)]
    gyro_scale = GYRO_UNITS[w.choice(i.get("gyro_unit", "rad/s"), "imu.gyro_unit", GYRO_UNITS)]

    ft = {}
    if d.get("ft") is not None:
        f = w.table(d["ft"], "ft", {"left": True, "right": True})
        for side in SIDES:
            key = f"ft.{side}"
            s = w.table(f[side], key, {"topic": not table, "force": table, "torque": table, "rotation": False})
            ft[side] = Stream(None if table else w.string(s["topic"], key + ".topic"),
                              {"force": _paths(w, s, key, "force", "wrench.force", table, 3 if table else None),
                               "torque": _paths(w, s, key, "torque", "wrench.torque", table, 3 if table else None)},
                              w.rotation(s.get("rotation"), key + ".rotation"))
    contact, threshold = {}, 0.5
    if d.get("contact") is not None:
        c = w.table(d["contact"], "contact", {"left": True, "right": True, "threshold": False})
        if c.get("threshold") is not None:
            threshold = w.number(c["threshold"], "contact.threshold", open_low=False)
        for side in SIDES:
            key = f"contact.{side}"
            s = w.table(c[side], key, {"topic": not table, "field": True})
            contact[side] = Stream(None if table else w.string(s["topic"], key + ".topic"),
                                   {"field": w.string(s["field"], key + ".field")})
    detection = _detection(w, d.get("detection") or {})
    return LogMapping(path=path, robot=robot, time_source=time_source, time_column=time_column,
                      time_scale=time_scale, gap_tolerance_s=gap, clock=clock, sensor_model=sensor, motion=motion,
                      messages=messages, joints=joints, joint_map=joint_map, acc_scale=acc_scale,
                      gyro_scale=gyro_scale, imu=imu, ft=ft, contact=contact, contact_threshold=threshold,
                      detection=detection)


def _sensor_model(w: _Where, v) -> SensorModel | None:
    if v == "unknown":
        return None
    fields_ = list(SensorModel.__dataclass_fields__)
    if not isinstance(v, dict):
        raise w.err("sensor_model", f"must be the sensors' datasheet values ({', '.join(fields_)}; SI units) or "
                    f"the word unknown (conservative bounds, said in every result), got {shown(v)}")
    for k, x in v.items():
        if k not in fields_ and k not in REALIZED_FIELDS:  # (realized values: SensorModel.from_dict says why not)
            close = difflib.get_close_matches(str(k), fields_, n=1)
            raise w.err(f"sensor_model.{k}", "is not a sensor-model field" + (
                f" (did you mean {close[0]!r}?)" if close else "") + f"; the fields: {fields_}")
        if any(isinstance(e, int) and not is_finite_number(e) for e in (x if isinstance(x, list) else [x])):
            raise w.err(f"sensor_model.{k}", f"is {shown(x)}: a number too large for a float; give the datasheet "
                        "value in SI units")
    missing = [k for k in fields_ if k not in v]
    if missing:
        raise w.err("sensor_model", f"is missing {missing}: declare each from the datasheet (0 only if the "
                    "sensor truly has none), or write `sensor_model: unknown`")
    try:
        return SensorModel.from_dict(v)
    except SensorModelError as e:
        raise w.err("sensor_model", f"is invalid ({e})") from None


def _messages(w: _Where, v) -> dict[str, Path]:
    if not isinstance(v, dict):
        raise w.err("messages", f"must map message type names to .msg files, e.g. "
                    f"'my_robot_msgs/msg/LowState: msgs/LowState.msg', got {shown(v)}")
    out = {}
    for name, file in v.items():
        key = f"messages.{name}"
        if not isinstance(name, str) or name.count("/") != 2 or "/msg/" not in name:
            raise w.err(key, "must be a full message type name, package/msg/Type")
        p = Path(w.string(file, key))
        p = p if p.is_absolute() else w.path.parent / p
        if not p.is_file():
            raise w.err(key, f"names {p}, which does not exist (paths are relative to the mapping file)")
        out[name] = p
    return out


def _joint_map(w: _Where, v, legmap: LegMap, table: bool, names_field) -> dict[str, JointSource]:
    if not isinstance(v, dict):
        raise w.err("joints.map", "must map each leg-map joint to its source in the log: "
                    "{source: <name or column or index>, sign: 1 or -1, unit: rad or deg}")
    unknown = [k for k in v if k not in legmap.joint_names]
    if unknown:
        raise w.err(f"joints.map.{unknown[0]}", f"is not a leg joint of {legmap.name} (its leg joints: "
                    f"{legmap.joint_names})")
    missing = [n for n in legmap.joint_names if n not in v]
    if missing:
        raise w.err("joints.map", f"has no entry for leg joints {missing}: every leg joint of {legmap.name} "
                    "must come from the log")
    out, seen = {}, {}
    for name in legmap.joint_names:
        key = f"joints.map.{name}"
        e = v[name]
        e = e if isinstance(e, dict) else {"source": e}
        e = w.table(e, key, {"source": True, "sign": False, "unit": False})
        src = e["source"]
        if names_field is None and not table:
            if not isinstance(src, int) or isinstance(src, bool) or src < 0:
                raise w.err(key + ".source", f"must be an index (>= 0) into the position array: joints.names is "
                            f"null, so the log has no joint names, got {shown(src)}")
        elif not isinstance(src, str) or not src:
            raise w.err(key + ".source", f"must be the joint's {'column' if table else 'name in the log'}, "
                        f"got {shown(src)}")
        if src in seen:
            raise w.err(key + ".source", f"{src!r} is already the source of {seen[src]}: two leg joints from one "
                        "log joint")
        seen[src] = name
        sign = e.get("sign", 1)
        if sign not in (1, -1) or isinstance(sign, bool):
            raise w.err(key + ".sign", "must be 1 or -1 (-1: the log's axis is the leg map's reversed), got "
                        f"{shown(sign)}")
        unit = w.choice(e.get("unit", "rad"), key + ".unit", JOINT_UNITS)
        out[name] = JointSource(src, float(sign), JOINT_UNITS[unit])
    return out


def _detection(w: _Where, v) -> Detection:
    known = {k: False for k in Detection.__dataclass_fields__}
    d = w.table(v, "detection", known)
    return Detection(**{k: w.number(x, f"detection.{k}", open_low=k in ("min_duration_s", "window_s"))
                        for k, x in d.items()})


EXAMPLE = """\
# legcal-bench log mapping (docs/log-import.md). Paths are relative to this file.
format: legcal-log-map/1
robot: {robot}                    # the leg map's name (checked against --robot)
time_source: header           # header: the messages' header.stamp; receive: when the bag recorded them
gap_tolerance_s: 0.1          # a longer gap in any stream splits a segment (and is reported)
clock: joints                 # output frames at the joint states' stamps (or a rate in Hz)
sensor_model:                 # from the datasheets (SI units), or the word: unknown
  encoder_noise_std: 1.0e-4       # rad
  encoder_resolution: 4.8e-5      # rad per count (0: none)
  accel_noise_std: 0.01           # m/s^2 per sample
  gyro_noise_std: 0.003           # rad/s per sample
  ft_force_noise_std: 2.0         # N
  ft_torque_noise_std: 0.2        # N m
  accel_bias_bound: 0.03          # m/s^2 per axis
  gyro_bias_bound: 0.002          # rad/s per axis
  imu_mount_bound: 0.002          # rad, mounting tilt per axis
# motion: static              # optional; measured from the data either way
joints:
  topic: /joint_states        # sensor_msgs/JointState (any order, extra joints ignored)
  map:                        # leg-map joint: {{source: name in the log, sign: 1|-1, unit: rad|deg}}
{joints}
imu:
  topic: /imu                 # sensor_msgs/Imu
  rotation: {{rpy_deg: [0, 0, 0]}}   # the log's IMU frame into the leg map's IMU frame
# ft:                         # optional: ankle force/torque (geometry_msgs/WrenchStamped)
#   left: {{topic: /ft/left}}
#   right: {{topic: /ft/right}}
"""


def example_mapping(legmap: LegMap) -> str:
    joints = "\n".join(f"    {n}: {{source: {n}, sign: 1, unit: rad}}" for n in legmap.joint_names)
    return EXAMPLE.format(robot=legmap.name, joints=joints)
