"""Recordings: the on-disk format shared by simulation and real robots.

One `.npz` file per segment (a stance, the straight-leg standing phase, or a held-out
session) holds what a real robot logs; the simulator's ground truth for that segment,
which calibrators never receive, sits beside it in `<name>.truth.npz`. A directory of
segments (a "session set") has a `session.json` manifest. The schema is in
docs/recording-format.md; `load_recording` validates everything it reads.

Version 2 (issue #39) makes the declarations impossible to get silently wrong: the
sensor model is complete (every field) or the string "unknown" (conservative bounds,
`SensorModel.unknown()`, named in every result), and `motion` is optional: absent means
not declared, and the motion is measured from the data before any estimator reads it
(`legcal_bench.estimation.checks.motion.resolve_motion`). Version 1 files load with the
same checks (this tool always wrote them with a complete model and a motion).
"""

from __future__ import annotations

import difflib
import io
import json
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from legcal_bench.errors import LegcalError, RecordingError
from legcal_bench.files.atomic import atomic_write, atomic_write_json
from legcal_bench.robots.kinematics import LegKinematics, joint_limits
from legcal_bench.robots.legmap import LegMap
from legcal_bench.robots.transmission import encoder_map, to_joint_space
from legcal_bench.sim.sensors import SensorModel

FORMAT = "legcal-recording"
VERSION = 2  # written; READ_VERSIONS are read
READ_VERSIONS = (1, 2)
KINDS = ("standing", "stance", "heldout")
# What a calibrator may see: the stances and the straight-leg standing phase. Held-out
# sessions score a result and never feed it (`training`).
TRAINING_KINDS = ("standing", "stance")
MOTIONS = ("continuous", "static")
UNKNOWN = "unknown"  # meta "sensor_model": "unknown": not declared, conservative bounds applied
MANIFEST = "session.json"


@dataclass
class Recording:
    """The observable part of one segment: what a real robot logs."""

    name: str
    kind: str  # standing | stance | heldout
    stance: str  # I, II, III, IV, standing, or a free label for real logs
    robot: str
    joint_names: list[str]
    time: np.ndarray  # (N,) s, strictly increasing
    q_enc: np.ndarray  # (N, n) rad, encoder angles in joint_names order (n leg joints)
    imu_acc: np.ndarray  # (N, 3) m/s^2, specific force in the IMU frame
    imu_gyro: np.ndarray  # (N, 3) rad/s, angular rate in the IMU frame
    # The declared sensor model: the datasheet's (every field), or with
    # sensor_declared=False the conservative `SensorModel.unknown()` (the default then).
    sensor_model: SensorModel | None = None
    ft: np.ndarray | None = None  # (N, 2, 6) ankle [force, torque], left then right
    source: str = "robot"  # "robot", or "sim:<mode>" for simulated data
    session: str = ""
    # "continuous": logged while the posture moves (the accelerometer also reads the
    # IMU's acceleration); "static": every frame logged at rest (it reads gravity alone);
    # None: not declared. Measured from the data either way (`resolve_motion`, which the
    # framework runs before any estimator: `calibrate_training`, the scoring).
    motion: str | None = None
    # False: the team did not declare its sensors ("sensor_model": "unknown" on disk).
    sensor_declared: bool = True

    def __post_init__(self):
        if self.sensor_model is None:
            if self.sensor_declared:
                raise RecordingError(
                    f"{self.name}: no sensor_model: declare it from the datasheet (SensorModel with every field), "
                    "or pass sensor_declared=False for conservative bounds (SensorModel.unknown(), named in every "
                    "result)")
            self.sensor_model = SensorModel.unknown()
        elif not isinstance(self.sensor_model, SensorModel):
            raise RecordingError(f"{self.name}: sensor_model must be a SensorModel, got {self.sensor_model!r}")
        elif not self.sensor_declared and self.sensor_model != SensorModel.unknown():
            raise RecordingError(
                f"{self.name}: sensor_declared=False with a sensor model other than SensorModel.unknown(): an "
                "undeclared model is the conservative bounds; declare the model (sensor_declared=True) or drop it")
        if self.motion is not None and self.motion not in MOTIONS:
            raise RecordingError(f"{self.name}: motion {self.motion!r}; use 'continuous', 'static' or None (not "
                                 "declared: measured from the data)")

    @property
    def n_frames(self) -> int:
        return int(self.time.shape[0])

    @property
    def rate_hz(self) -> float:
        return float((self.n_frames - 1) / (self.time[-1] - self.time[0])) if self.n_frames > 1 else 0.0

    def meta(self) -> dict:
        meta = {
            "format": FORMAT, "version": VERSION, "name": self.name, "kind": self.kind,
            "stance": self.stance, "robot": self.robot, "joint_names": list(self.joint_names),
            "sensor_model": self.sensor_model.to_dict() if self.sensor_declared else UNKNOWN,
            "source": self.source, "session": self.session,
        }
        if self.motion is not None:
            meta["motion"] = self.motion
        return meta

    def save(self, path: str | Path, version: int = VERSION) -> Path:
        """Write the recording (validated first). `version=1`: the previous format, for a
        reader of it (`bench-speed`'s baseline); only a recording that declares its
        sensor model and motion has one."""
        arrays = {"time": self.time, "q_enc": self.q_enc, "imu_acc": self.imu_acc, "imu_gyro": self.imu_gyro}
        if self.ft is not None:
            arrays["ft"] = self.ft
        meta = self.meta()
        if version != VERSION:
            if version != 1 or not self.sensor_declared or self.motion is None:
                raise RecordingError(f"{path}: version {version} cannot hold this recording (version 1 needs a "
                                     "declared sensor model and motion)")
            meta["version"] = version
        validate(arrays, meta, str(path))
        return _save_npz(path, arrays, meta)


@dataclass
class Truth:
    """The simulator's ground truth for one segment (never given to calibrators)."""

    q_true: np.ndarray  # (N, n), n leg joints
    offsets: np.ndarray  # (n,) injected, q_enc = q_true - offsets (+ noise)
    sole_poses_world: np.ndarray  # (N, 2, 7) [x y z qw qx qy qz], left then right
    pelvis_pose_world: np.ndarray  # (N, 7)
    posture: np.ndarray  # (N, 6) commanded pelvis posture actually applied
    posture_reachable: np.ndarray  # (N,) bool
    imu_true_acc: np.ndarray  # (N, 3)
    imu_true_gyro: np.ndarray  # (N, 3)
    meta: dict = field(default_factory=dict)
    # (N, n) what the encoders read without noise (q_true - offsets unless a reality
    # effect, e.g. an encoder scale or a series spring, says otherwise); optional.
    q_enc_clean: np.ndarray | None = None

    def save(self, path: str | Path) -> Path:
        arrays = {k: getattr(self, k) for k in self.__dataclass_fields__
                  if k != "meta" and getattr(self, k) is not None}
        return _save_npz(path, arrays, {"format": FORMAT + "-truth", "version": VERSION, **self.meta})


def _save_npz(path: str | Path, arrays: dict, meta: dict) -> Path:
    buf = io.BytesIO()
    np.savez_compressed(buf, meta=np.array(json.dumps(meta, sort_keys=True)),
                        **{k: np.asarray(v) for k, v in arrays.items()})
    return atomic_write(path, lambda f: f.write(buf.getvalue()), mode="wb")


def truth_path(path: str | Path) -> Path:
    path = Path(path)
    return path.with_name(path.stem + ".truth.npz")


# -------------------------------------------------------------------- validation
# A logging rate outside this range means 'time' is not in seconds (ms or ns read as s).
MIN_RATE_HZ, MAX_RATE_HZ = 1.0, 5000.0
# q_enc: (N, n) with n the robot's leg joints (`LegMap.n_joints`), checked in `validate`.
_SHAPES = {"time": (None,), "q_enc": (None, None), "imu_acc": (None, 3), "imu_gyro": (None, 3), "ft": (None, 2, 6)}
_META_KEYS = ("format", "version", "name", "kind", "stance", "robot", "joint_names", "sensor_model")


def validate(arrays: dict, meta: dict, where: str, joint_names: list[str] | None = None,
             robot: str | None = None) -> None:
    """Refuse a recording that breaks the format (docs/recording-format.md). With
    `joint_names` (and `robot`, the leg map's name), it must hold those leg joints, in
    that order, of that robot."""
    if not isinstance(meta, dict):
        raise RecordingError(f"{where}: field 'meta' must be a JSON object (see docs/recording-format.md)")
    for key in _META_KEYS:
        if key not in meta:
            raise RecordingError(f"{where}: missing metadata field '{key}' (see docs/recording-format.md)")
    for key in ("name", "kind", "stance", "robot"):
        if not isinstance(meta[key], str):
            raise RecordingError(f"{where}: metadata field '{key}' must be a string, got {meta[key]!r}")
    if not isinstance(meta["joint_names"], list) or not all(isinstance(n, str) for n in meta["joint_names"]):
        raise RecordingError(f"{where}: field 'joint_names' must be a list of the robot's leg joint names (strings), "
                             f"got {meta['joint_names']!r}")
    if not isinstance(meta["sensor_model"], dict) and meta["sensor_model"] != UNKNOWN:
        raise RecordingError(f"{where}: field 'sensor_model' must be a JSON object of sensor-model fields, every "
                             f"one declared from the datasheet, or the string \"unknown\" (conservative bounds; see "
                             f"docs/recording-format.md), got {meta['sensor_model']!r}")
    if meta["format"] != FORMAT:
        raise RecordingError(f"{where}: field 'format' is {meta['format']!r}, expected {FORMAT!r}")
    if isinstance(meta["version"], bool) or meta["version"] not in READ_VERSIONS:
        raise RecordingError(f"{where}: format version {meta['version']} is not supported (this reader: "
                             f"{', '.join(map(str, READ_VERSIONS))})")
    for key in ("source", "session"):
        if key in meta and not isinstance(meta[key], str):
            raise RecordingError(f"{where}: metadata field '{key}' must be a string, got {meta[key]!r}")
    if meta.get("motion") is not None and meta["motion"] not in MOTIONS:
        raise RecordingError(f"{where}: field 'motion' is {meta['motion']!r}; use 'continuous' (logged while the "
                             "posture moves) or 'static' (every frame logged at rest), or leave it out (measured "
                             "from the data)")
    if meta["kind"] not in KINDS:
        raise RecordingError(f"{where}: field 'kind' is {meta['kind']!r}; use one of {KINDS}")
    names = list(meta["joint_names"])
    if robot is not None and meta["robot"] != robot and (joint_names is None or names != list(joint_names)):
        raise RecordingError(robot_mismatch(where, meta["robot"], robot, names, joint_names))
    if joint_names is not None and len(names) != len(joint_names):
        raise RecordingError(f"{where}: field 'joint_names' must list the robot's {len(joint_names)} leg joints, "
                             f"got {len(names)}")
    if not names or len(names) % 2:
        raise RecordingError(f"{where}: field 'joint_names' must list the robot's leg joints, left leg then right "
                             f"(the same number per leg), got {len(names)}")
    if joint_names is not None and names != list(joint_names):
        raise RecordingError(_joints_mismatch(where, meta["robot"], names, list(joint_names), robot))
    for key in ("time", "q_enc", "imu_acc", "imu_gyro"):
        if key not in arrays:
            raise RecordingError(f"{where}: missing field '{key}' (see docs/recording-format.md)")
    n = None
    shapes = {**_SHAPES, "q_enc": (None, len(names))}  # one column per leg joint, in joint_names order
    for key, shape in shapes.items():
        if key not in arrays:
            continue
        a = np.asarray(arrays[key])
        if a.dtype.kind not in "fi":
            raise RecordingError(f"{where}: field '{key}' must be numeric, got dtype {a.dtype}")
        if a.dtype.kind == "i" and key in ("q_enc", "imu_acc", "imu_gyro", "time"):
            raise RecordingError(f"{where}: field '{key}' is an integer array ({a.dtype}): raw counts or truncated "
                                 "values? Save it as floats in SI units (radians, m/s^2, rad/s, seconds)")
        if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
            want = "(N, " + ", ".join(str(s) for s in shape[1:]) + ")" if len(shape) > 1 else "(N,)"
            raise RecordingError(f"{where}: field '{key}' has shape {a.shape}, expected {want}" + (
                f": one column per leg joint, the robot's {len(names)} in joint_names order" if key == "q_enc" else ""))
        if n is None:
            n = a.shape[0]
        elif a.shape[0] != n:
            raise RecordingError(f"{where}: field '{key}' has {a.shape[0]} frames but 'time' has {n}")
        bad = ~np.isfinite(a)
        if bad.any():
            frames = np.unique(np.nonzero(bad)[0])
            raise RecordingError(f"{where}: field '{key}' has NaN/inf in {frames.size} frame(s), first at frame "
                                 f"{frames[0]}; drop those frames (or interpolate) before saving")
    if n == 0:
        raise RecordingError(f"{where}: the recording has no frames")
    t = np.asarray(arrays["time"], dtype=float)
    dt = np.diff(t)
    if (dt <= 0).any():
        k = int(np.flatnonzero(dt <= 0)[0])
        raise RecordingError(f"{where}: field 'time' is not strictly increasing (frame {k + 1}: {t[k + 1]} after "
                             f"{t[k]}); sort the frames by time and drop duplicates")
    if n > 1:
        rate = (n - 1) / (t[-1] - t[0])
        if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
            unit = "milliseconds or nanoseconds" if rate < MIN_RATE_HZ else "minutes or hours"
            raise RecordingError(
                f"{where}: field 'time' gives a logging rate of {rate:.3g} Hz, outside {MIN_RATE_HZ:g}-{MAX_RATE_HZ:g} "
                f"Hz: it looks like {unit}; 'time' must be in seconds (divide ms by 1e3, ns by 1e9)")
    q = np.asarray(arrays["q_enc"], dtype=float)
    if np.abs(q).max() > 2 * np.pi:
        raise RecordingError(f"{where}: field 'q_enc' {_beyond_turn(q, list(meta['joint_names']))}")
    acc_norm = np.linalg.norm(np.asarray(arrays["imu_acc"], dtype=float), axis=1).mean()
    if not 3.0 < acc_norm < 30.0:
        raise RecordingError(f"{where}: field 'imu_acc' has mean norm {acc_norm:.3g}; expected specific force in "
                             "m/s^2 (about 9.81 at rest). Convert from g (x 9.81) if needed")


SPIKE_SHARE = 0.05  # frames beyond a turn: under this share of a column, spikes; over it, the column's units


def _beyond_turn(q: np.ndarray, names: list[str]) -> str:
    """What an encoder column beyond a full turn (|angle| > 2 pi) most likely is, with
    its fix: jumps of a whole turn between frames (a wrapped angle); a few frames out
    (spikes, a glitch); else the column's unit (degrees, or a whole turn added)."""
    out = np.abs(q) > 2 * np.pi
    j = int(np.argmax(out.sum(axis=0)))
    col, bad = q[:, j], np.flatnonzero(out[:, j])
    name = names[j] if j < len(names) else f"column {j}"
    where = (f"joint {name}: {bad.size} of {len(col)} frame(s) (first {bad[0]}) beyond a full turn, up to "
             f"{np.abs(col).max():.4g}")
    step = np.diff(col)
    turns = np.abs(step) > np.pi
    if turns.any() and np.all(np.abs(np.abs(step[turns]) - 2 * np.pi) < 0.5):  # one turn up or down
        return (f"{where}, jumping by whole turns (2 pi) between frames: a wrapped angle; unwrap it "
                "(numpy.unwrap) before saving")
    if bad.size <= SPIKE_SHARE * len(col):
        return (f"{where}, while the others stay within {np.abs(np.delete(col, bad)).max(initial=0.0):.3g} rad: "
                "spikes (a glitch of the log); drop or repair those frames")
    return (f"{where}, which looks like degrees (or a whole turn added); encoder angles must be radians "
            "(numpy.deg2rad), within a turn of the joint's zero")


def robot_mismatch(where: str, recorded: str, robot: str, names: list[str] | None = None,
                   joint_names: list[str] | None = None) -> str:
    """The message for recordings of robot `recorded` read with the leg map of `robot`:
    the robot chosen is blamed (--robot), not the recording."""
    differ = ""
    if names is not None and joint_names is not None and names != list(joint_names):
        differ = (" (their leg joints differ too: the same names in another order)" if sorted(names) ==
                  sorted(joint_names) else " (their leg joints differ too)")
    return (f"{where}: field 'robot' is {recorded!r} but the leg map is {robot!r}{differ}: recordings of one robot "
            f"calibrated as another give wrong offsets; pass that robot's leg map (--robot {recorded}, or its "
            "leg-map file), or fix the recording's 'robot' field if it is the same robot")


def _joints_mismatch(where: str, recorded: str, names: list[str], joint_names: list[str],
                     robot: str | None) -> str:
    """The message for a recording whose joint names are not the leg map's: which side
    to fix depends on what differs. The recording names the robot it was logged on; with
    the leg map's name `robot` the same, a name that differs is the leg map's or the
    recording's spelling, and an order that differs the leg map's joint order or the
    recording's columns."""
    missing = [n for n in joint_names if n not in names]
    extra = [n for n in names if n not in joint_names]
    if missing or extra:
        pairs = [f"leg map {m!r} where the recording has {close[0]!r}" for m in missing
                 for close in [difflib.get_close_matches(m, extra, n=1)] if close]
        what = f"missing {missing}, unexpected {extra}" + (f"; {'; '.join(pairs)}" if pairs else "")
        fix = ("check the leg map's joint names (legs.<side>.joints[].name, as the MJCF names them): a misspelt "
               "one is the leg map's to fix; if the recording's are wrong, rename them in its 'joint_names'")
    else:
        what = "same names in another order"
        fix = ("reorder the q_enc columns to the leg map's order, or, if the recording's order is the robot's, fix "
               "the leg map's joint order (legs.<side>.joints)")
    if robot is None:
        fix += f"; the recording names robot {recorded!r}: if that is not the robot given, pass it (--robot)"
    return f"{where}: joint_names do not match the robot's leg joints ({what}: {fix})"


def _read_npz(path: Path) -> tuple[dict, dict]:
    if path.is_dir():
        raise RecordingError(f"{path}: is a folder, not a recording file; give a recording (.npz), or pass the folder "
                             "where a session folder is asked for")
    if not path.is_file():
        raise RecordingError(f"{path}: no such recording")
    try:
        loaded = np.load(path, allow_pickle=False)
    except Exception as e:  # noqa: BLE001 - numpy raises many types for bad files
        raise RecordingError(f"{path}: not a readable .npz file ({e})") from None
    if not isinstance(loaded, np.lib.npyio.NpzFile):
        raise RecordingError(f"{path}: holds one array (a .npy file), not a .npz archive of named fields; save the "
                             "recording with numpy.savez (see docs/recording-format.md)")
    try:
        with loaded as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as e:  # noqa: BLE001
        raise RecordingError(f"{path}: not a readable .npz file ({e})") from None
    if "meta" not in arrays:
        raise RecordingError(f"{path}: missing field 'meta' (the JSON header; see docs/recording-format.md)")
    try:
        meta = json.loads(str(arrays.pop("meta")))
    except json.JSONDecodeError as e:
        raise RecordingError(f"{path}: field 'meta' is not valid JSON ({e})") from None
    return arrays, meta


def load_recording(path: str | Path, joint_names: list[str] | None = None, robot: str | None = None) -> Recording:
    """Read and validate one recording (never its ground truth); with `robot` (the leg
    map's name), a recording of another robot is refused naming both."""
    path = Path(path)
    arrays, meta = _read_npz(path)
    validate(arrays, meta, str(path), joint_names, robot)
    declared = meta["sensor_model"] != UNKNOWN
    try:
        sensor = SensorModel.from_dict(meta["sensor_model"]) if declared else SensorModel.unknown()
    except (TypeError, ValueError, LegcalError) as e:
        raise RecordingError(f"{path}: field 'sensor_model' is invalid ({e})") from None
    return Recording(
        name=meta["name"], kind=meta["kind"], stance=meta["stance"], robot=meta["robot"],
        joint_names=list(meta["joint_names"]),
        time=arrays["time"].astype(float), q_enc=arrays["q_enc"].astype(float),
        imu_acc=arrays["imu_acc"].astype(float), imu_gyro=arrays["imu_gyro"].astype(float),
        sensor_model=sensor, ft=arrays["ft"].astype(float) if "ft" in arrays else None,
        source=meta.get("source", "robot"), session=meta.get("session", ""),
        motion=meta.get("motion"), sensor_declared=declared,
    )


class UncheckedTruthWarning(UserWarning):
    """A ground-truth file without its session's identity (written before collect
    recorded one): it cannot be checked against its recording."""


def load_truth(path: str | Path) -> Truth:
    """The simulator's ground truth for the recording at `path` (scoring only). It must
    be that recording's: the truth names its session set (meta 'session', written by
    collect into the recording's field 'session' too), and a truth file from another
    session set, which would score against that set's offsets, is refused naming both.
    A truth file without the identity (written before it was recorded) is read with an
    `UncheckedTruthWarning`."""
    tp = truth_path(path)
    arrays, meta = _read_npz(tp)
    optional = ("q_enc_clean",)
    fields_ = [k for k in Truth.__dataclass_fields__ if k != "meta"]
    missing = [k for k in fields_ if k not in arrays and k not in optional]
    if missing:
        raise RecordingError(f"{tp}: missing ground-truth fields {missing}")
    _check_identity(Path(path), tp, meta)
    return Truth(**{k: arrays[k] for k in fields_ if k in arrays}, meta=meta)


def _check_identity(path: Path, tp: Path, meta: dict) -> None:
    session = meta.get("session")
    if session is None:
        warnings.warn(f"{tp.parent}: the ground-truth files name no session set (written before legcal-bench "
                      "recorded one in each): they cannot be checked against their recordings, and truth copied from "
                      "another session set would score against its offsets; re-collect the set to have them checked",
                      UncheckedTruthWarning, stacklevel=3)
        return
    if not path.is_file():
        return  # the truth alone (its recording checks it when both are read)
    try:
        with np.load(path, allow_pickle=False) as z:
            recorded = json.loads(str(z["meta"])).get("session")
    except Exception:  # noqa: BLE001 - an unreadable recording is refused when it is read
        return
    if recorded != session:
        raise RecordingError(
            f"{tp}: the ground truth is of session {session!r} but its recording {path.name} is of session "
            f"{recorded!r}: truth files from another session set score a result against that set's offsets; put "
            "the truth files collected with these recordings beside them (or re-collect the set)")


def write_manifest(out_dir: str | Path, manifest: dict) -> Path:
    return atomic_write_json(Path(out_dir) / MANIFEST, {"format": FORMAT + "-session", "version": VERSION, **manifest})


# Beside the recordings: the manifest, and the timeline plot of an imported log.
SESSION_FILES = (MANIFEST, "timeline.png")


def is_session_dir(directory: str | Path) -> bool:
    """True for a folder that holds only a session set (recordings, their ground truth,
    a manifest, an import's timeline plot): one that a new collection or import may replace."""
    directory = Path(directory)
    return directory.is_dir() and all(
        p.is_file() and (p.name in SESSION_FILES or p.suffix == ".npz") for p in directory.iterdir())


def list_segments(directory: str | Path, allow_partial: bool = False) -> list[Path]:
    """Recording files of a session set, in its manifest's order. A folder without a
    manifest may be a collection that stopped half-way: refused unless `allow_partial`
    (then every *.npz recording in it, sorted)."""
    directory = Path(directory)
    if not directory.is_dir():
        raise RecordingError(f"{directory}: not a directory of recordings")
    man = directory / MANIFEST
    if man.is_file():
        try:
            d = json.loads(man.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise RecordingError(f"{man}: not valid JSON ({e}); rewrite it or remove it and pass --allow-partial "
                                 "to read every recording in the folder") from None
        files = d.get("files") if isinstance(d, dict) else None
        if not isinstance(files, list) or not files or not all(isinstance(f, str) for f in files):
            raise RecordingError(f"{man}: field 'files' must list the session's recording files (a JSON object "
                                 "with \"files\": [\"stance_I.npz\", ...]; see docs/recording-format.md)")
        missing = [f for f in files if not (directory / f).is_file()]
        if missing:
            raise RecordingError(f"{man}: field 'files' names recordings that are not in the folder: {missing}")
        return [directory / f for f in files]
    paths = sorted(p for p in directory.glob("*.npz") if not p.name.endswith(".truth.npz"))
    if not paths:
        raise RecordingError(f"{directory}: no recordings (*.npz) found")
    if not allow_partial:
        raise RecordingError(f"{directory}: no {MANIFEST}: this may be a session set whose collection stopped "
                             f"half-way; write a {MANIFEST} listing its files (docs/recording-format.md), or pass "
                             "--allow-partial to use every recording in the folder")
    return paths


def training(recordings: list["Recording"]) -> list["Recording"]:
    """The recordings a calibrator, a diagnosis or a model selection may read: the
    training kinds (`TRAINING_KINDS`); the held-out sessions are kept for scoring."""
    return [r for r in recordings if r.kind in TRAINING_KINDS]


def session_identity(recordings: list[Recording]) -> dict:
    """What a result records of the session set it was calibrated on: the training
    recordings' names, their sessions' labels (`meta.session`: a log's file stem, not
    unique) and a SHA-256 over their content (names, kinds, stances, joint names and
    every sample), which two different sets share only by being the same data."""
    import hashlib

    recs = sorted(training(recordings), key=lambda r: r.name)
    h = hashlib.sha256()
    for r in recs:
        h.update(json.dumps([r.name, r.kind, r.stance, r.robot, r.joint_names]).encode())
        for a in (r.time, r.q_enc, r.imu_acc, r.imu_gyro):
            h.update(np.ascontiguousarray(a, dtype="<f8").tobytes())
    return {"sessions": sorted({r.session for r in recs if r.session}), "recordings": [r.name for r in recs],
            "sha256": h.hexdigest()}


def load_session(directory: str | Path, joint_names: list[str] | None = None,
                 allow_partial: bool = False, robot: LegMap | None = None) -> list[Recording]:
    """The session set's recordings. With `robot` (the leg map they are calibrated
    with), each must name that robot and keep its encoder angles within the robot's
    joint limits (± `LIMIT_SLACK_RAD`, room for the offsets)."""
    if robot is not None:
        joint_names = robot.joint_names
    name = robot.name if robot is not None else None
    recs = [load_recording(p, joint_names, name) for p in list_segments(directory, allow_partial)]
    if robot is not None:
        recs = in_joint_space(recs, robot)
        check_against_robot(recs, robot)
    return recs


def in_joint_space(recordings: list[Recording], robot: LegMap) -> list[Recording]:
    """The recordings with their encoder columns as the joints' angles: a column whose
    encoder reads a motor through a transmission (`legcal_bench.robots.transmission`) is
    converted, q = c0 + c1 e; the others, and robots without transmissions, unchanged."""
    emap = encoder_map(robot)
    return recordings if emap is None else [replace(r, q_enc=to_joint_space(r.q_enc, emap)) for r in recordings]


# Encoder angles may pass a joint limit by an offset's size; beyond this they are not radians of that joint.
LIMIT_SLACK_RAD = 0.15


def check_against_robot(recordings: list[Recording], robot: LegMap) -> None:
    """Refuse recordings of another robot, or angles no joint of this robot can reach."""
    for r in recordings:
        if r.robot != robot.name:
            raise RecordingError(robot_mismatch(r.name, r.robot, robot.name))
    lower, upper = joint_limits(robot)
    kin = LegKinematics(robot) if any(leg.linkage is not None for leg in robot.legs.values()) else None
    linkage_cols = {c: list(lk.cols) for lk in (kin.linkages if kin else ()) for c in lk.cols}
    for r in recordings:
        q = r.q_enc if kin is None else kin.joint_angles(r.q_enc)  # a linkage ankle's motors, as its joints
        unreached = ~np.isfinite(q).all(axis=0) & np.isfinite(r.q_enc).all(axis=0)
        if unreached.any():
            j = int(np.flatnonzero(unreached)[0])
            frames = np.flatnonzero(~np.isfinite(q[:, j]))
            cols = linkage_cols[j]
            raise RecordingError(
                f"{r.name}: field 'q_enc', the {robot.side_of(j)} linkage ankle's motors (columns "
                f"{', '.join(robot.joint_names[c] for c in cols)}): {frames.size} frame(s) (first {frames[0]}) at "
                f"{np.round(r.q_enc[frames[0], cols], 4).tolist()} rad, which the leg map's linkage cannot reach: "
                "the motors' columns swapped, degrees, or the linkage's geometry?")
        out = (q < lower - LIMIT_SLACK_RAD) | (q > upper + LIMIT_SLACK_RAD)
        if out.any():
            j = int(np.flatnonzero(out.any(axis=0))[0])
            frames = np.flatnonzero(out[:, j])
            raise RecordingError(
                f"{r.name}: field 'q_enc', joint {robot.joint_names[j]}: {frames.size} frame(s) (first {frames[0]}) "
                f"at {q[frames[0], j]:+.3f} rad{' (its motors through the linkage)' if j in linkage_cols else ''}, beyond "
                f"its limits [{lower[j]:+.3f}, {upper[j]:+.3f}] rad by more "
                f"than {LIMIT_SLACK_RAD} rad: degrees, a wrapped angle (±2π) or another joint's column? Encoder "
                "angles must be radians, in the leg map's joint order")
