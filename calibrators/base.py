"""The calibrator interface, its result type and the registry (`legcal_bench.calibrators.base`).

A calibrator gets the nominal robot (its leg map) and the training recordings'
observable part (stances and standing: never the held-out sessions that score it, never
the ground truth; `calibrate_training` is the framework's one door) and returns a
`CalibrationResult`. Calibrators are found
through the package entry-point group `legcal_bench.calibrators`: legcal-bench's own
register there exactly as a third-party package does, so a researcher adds a method
with one class and one line in their pyproject:

    [project.entry-points."legcal_bench.calibrators"]
    my_method = "my_package.module:MyCalibrator"
"""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from legcal_bench.data.recording import Recording, session_identity, training
from legcal_bench.errors import CalibrationError
from legcal_bench.estimation.checks.motion import resolve_motion
from legcal_bench.estimation.imu.imu_motion import IMU_MODES
from legcal_bench.estimation.problem.preprocess import PreprocessConfig
from legcal_bench.estimation.verdict import LIMITS, Finding, check_verdict, judge
from legcal_bench.files.atomic import atomic_write_json
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots.legmap import LegMap
from legcal_bench.robots.linkage import linkage_offsets
from legcal_bench.robots.transmission import motor_offsets, transmissions
from legcal_bench.sim.sensors import SensorModel

ENTRY_POINT_GROUP = "legcal_bench.calibrators"
RESULT_FORMAT = "legcal-calibration-result"


@dataclass
class CalibrationResult:
    calibrator: str
    robot: str
    offsets_rad: dict[str, float]  # joint name -> dq, in the convention q = q_enc + dq
    pitch_sums_rad: dict[str, float] = field(default_factory=dict)  # left, right, right_minus_left
    conditioning: dict[str, Any] = field(default_factory=dict)
    diagnostics: dict[str, Any] = field(default_factory=dict)
    timing_s: dict[str, float] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    # Whether to apply the offsets (`legcal_bench.estimation.verdict`): {"verdict": apply |
    # review | do-not-apply, "reasons": each warning with its meaning, "counts"}; set by
    # the framework (`calibrate_training`), kept as written when read back.
    verdict: dict[str, Any] = field(default_factory=dict)
    # The session set it was calibrated on (`session_identity`): sessions, recordings, sha256.
    session: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        if not self.verdict:
            self.judge()

    def judge(self) -> dict:
        """The verdict of the result's warnings, set and returned (their classes are
        the checks'; a warning no check classed is a doubt)."""
        self.verdict = judge(self.warnings)
        return self.verdict

    @property
    def decision(self) -> str:
        """"apply", "review" or "do-not-apply" (`verdict`'s reasons say why)."""
        return self.verdict["verdict"]

    def to_dict(self) -> dict:
        return {"format": RESULT_FORMAT, "version": 1, **asdict(self)}

    def save(self, path: str | Path) -> Path:
        return atomic_write_json(path, self.to_dict())

    @classmethod
    def load(cls, path: str | Path) -> "CalibrationResult":
        path = Path(path)
        try:
            d = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
            raise CalibrationError(f"{path}: not a readable result JSON ({e})") from None
        if not isinstance(d, dict) or d.get("format") != RESULT_FORMAT:
            raise CalibrationError(f"{path}: field 'format' must be {RESULT_FORMAT!r} (a result written by "
                                   "legcal-bench calibrate)")
        d.pop("format"), d.pop("version", None)
        missing = [k for k in ("calibrator", "robot", "offsets_rad") if k not in d]
        if missing:
            raise CalibrationError(f"{path}: missing fields {missing}")
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(d) - known)
        if unknown:
            raise CalibrationError(f"{path}: unknown fields {unknown}; a result has {sorted(known)}")
        offsets = d["offsets_rad"]
        if not isinstance(offsets, dict) or not offsets:
            raise CalibrationError(f"{path}: field 'offsets_rad' must map joint names to offsets in radians")
        for k, v in offsets.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise CalibrationError(f"{path}: offsets_rad.{k} must be a finite number of radians, got {v!r}")
        for k, want in (("pitch_sums_rad", dict), ("conditioning", dict), ("diagnostics", dict),
                        ("timing_s", dict), ("settings", dict), ("warnings", list), ("verdict", dict),
                        ("session", dict)):
            if k in d and not isinstance(d[k], want):
                raise CalibrationError(f"{path}: field '{k}' must be a JSON {'object' if want is dict else 'list'}")
        if d.get("verdict"):
            try:
                check_verdict(d["verdict"], str(path))
            except ValueError as e:
                raise CalibrationError(str(e)) from None
        return cls(**d)  # a result written before verdicts is judged now, its warnings unclassed

    def check_robot(self, legmap: LegMap, source: str = "the result") -> None:
        """A result used on a robot (scored, a correction, a start) must have been
        calibrated for it: another robot's offsets, even under the same joint names, are
        that robot's. CalibrationError naming both robots and `source` (the option and
        file it came from)."""
        if self.robot != legmap.name:
            spec = self.settings.get("robot_spec", self.robot)
            raise CalibrationError(
                f"{source}: calibrated for robot {self.robot!r}, but the robot here is {legmap.name!r}: its offsets "
                f"are {self.robot}'s; give a result calibrated for {legmap.name}, or --robot {spec}")

    def check_session(self, recordings: list[Recording], source: str) -> None:
        """A result scored, reported or exported against a session set must have been
        calibrated on it: CalibrationError naming `source` (the option and folder) when
        the set's training recordings are not the ones the result records. A result
        without a recorded session (written before they were recorded) passes."""
        if not self.session.get("sha256"):
            return
        here = session_identity(recordings)
        if here["sha256"] != self.session["sha256"]:
            def shown(ident):
                return (", ".join(ident.get("sessions") or []) or "unlabelled") + \
                    f" ({len(ident.get('recordings', []))} recordings, sha256 {ident['sha256'][:12]})"
            raise CalibrationError(
                f"{source}: the result was calibrated on session set {shown(self.session)}, but these are other "
                f"recordings: {shown(here)}; give the session set it was calibrated on, or calibrate this one "
                "(legcal-bench calibrate --bags ...)")

    def offsets_vector(self, joint_names: list[str]) -> np.ndarray:
        missing = [n for n in joint_names if n not in self.offsets_rad]
        if missing:
            raise CalibrationError(f"result has no offsets for {missing} (it was calibrated for another robot? "
                                   f"its joints: {sorted(self.offsets_rad)[:4]}...)")
        return np.array([self.offsets_rad[n] for n in joint_names], dtype=float)


class Calibrator(ABC):
    """One calibration method. Subclasses set `name` and implement `calibrate`.

    Options come as keyword arguments to the constructor (the CLI passes
    `--option key=value`); `settings()` reports them in every result.
    """

    name: ClassVar[str] = ""

    def __init__(self, **options: Any):
        if options:
            raise CalibrationError(f"calibrator {self.name!r} takes no options, got {sorted(options)}")

    @abstractmethod
    def calibrate(self, robot: LegMap, recordings: list[Recording]) -> CalibrationResult:
        ...

    def settings(self) -> dict[str, Any]:
        return {}

    @classmethod
    def benchmark_variants(cls) -> dict[str, dict[str, Any]]:
        """The variants `bench` runs, each a leaderboard row: variant name -> constructor
        options. Default: one, "default", with the constructor's defaults."""
        return {"default": {}}


def calibrate_training(calibrator: Calibrator, robot: LegMap, recordings: list[Recording]) -> CalibrationResult:
    """The one door through which the framework calls a calibrator (`calibrate`, `bench`,
    `sweep`, `walk-eval`, `diagnose`, the model-gap suite, the Python API): it gets the
    training recordings only (stances and standing, `training`); the held-out sessions
    that score its result never reach it.

    The declarations are settled here, before the calibrator reads them (issue #39):
    each recording's motion is measured and resolved (`resolve_motion`: a declaration
    the data contradict is replaced, with a warning; the evidence in
    `diagnostics["motion"]`), and a result calibrated on recordings without a declared
    sensor model says so in its warnings. The result records the set it was calibrated
    on (`session_identity`) and gets its verdict (`CalibrationResult.judge`) here."""
    recs = training(recordings)
    evidence: dict = {}
    kin = LegKinematics(robot)
    recs, motion_warnings = resolve_motion(kin, recs, evidence)
    result = calibrator.calibrate(robot, recs)
    result.warnings = [*result.warnings, *motion_warnings, *undeclared_sensor_warnings(recs)]
    result.diagnostics.setdefault("motion", evidence)
    drives = transmissions(robot)
    if drives:  # the encoders' own offsets, where a transmission puts them (`legcal_bench.robots.transmission`)
        result.diagnostics["offsets_motor_rad"] = motor_offsets(result.offsets_rad, robot)
        result.diagnostics["transmissions"] = {n: {"c0": t.c0, "c1": t.c1, "kind": t.kind} for n, t in drives.items()}
    if kin.linkages:  # a linkage ankle's columns are its motors' offsets; the joints' errors they make
        result.diagnostics["linkages"] = linkage_offsets(result.offsets_rad, kin)
    result.session = session_identity(recs)
    result.judge()
    return result


def undeclared_sensor_warnings(recordings: list[Recording]) -> list[str]:
    """The warning every result calibrated on recordings that declare no sensor model
    (`"sensor_model": "unknown"`) carries: which ones, the conservative bounds applied,
    and the fix."""
    names = [r.name for r in recordings if not r.sensor_declared]
    if not names:
        return []
    return [Finding(f"sensor model not declared in {len(names)} recording(s) ({', '.join(names)}): calibrated with "
                    f"conservative bounds ({SensorModel.unknown().describe()}; SI units), which widen the uncertainty "
                    "and the IMU-tilt bound; declare the sensors' datasheet values in the recordings' sensor_model "
                    "(docs/recording-format.md) for a calibration as tight as the sensors allow", LIMITS)]


def number_option(name: str, value: Any, low: float | None = None, high: float | None = None, *,
                  low_open: bool = False, high_open: bool = False, integer: bool = False) -> float | int:
    """An option's value as a finite number within its range, or a CalibrationError
    naming the option and the range (for calibrators checking their constructor's
    arguments; the CLI passes `--option name=value`)."""
    kind = "an integer" if integer else "a number"
    rng = (("(" if low_open else "[") + ("-inf" if low is None else f"{low:g}") + ", "
           + ("inf" if high is None else f"{high:g}") + (")" if high_open else "]"))
    try:
        if isinstance(value, bool) or (integer and isinstance(value, float) and not value.is_integer()):
            raise ValueError
        v = int(value) if integer else float(value)
    except (TypeError, ValueError, OverflowError):
        raise CalibrationError(f"option {name}={value!r}: expected {kind} in {rng}, e.g. --option {name}="
                               f"{low if low is not None and not low_open else 1}") from None
    bad = (not np.isfinite(v) or (low is not None and (v <= low if low_open else v < low))
           or (high is not None and (v >= high if high_open else v > high)))
    if bad:  # --option trim_fraction=1 arrives typed as 1.0; the message shows it as written
        shown = repr(value).removesuffix(".0") if isinstance(value, float) else repr(value)
        raise CalibrationError(f"option {name}={shown}: must be {kind} in {rng}")
    return v


def preprocess_options(n_max: Any, imu: Any, imu_window_s: Any) -> PreprocessConfig:
    """The shared preprocessing options of calibrators built on `select_frames`, checked:
    `n_max` configurations per stance, `imu` "compensated" (the IMU's acceleration
    predicted from the leg angles removed; default) or "raw" (the paper's), and the
    compensation's smoothing window in seconds."""
    if imu not in IMU_MODES:
        raise CalibrationError(f"option imu={imu!r}: use one of {', '.join(IMU_MODES)} (compensated: the IMU's "
                               "motion acceleration removed; raw: the paper's setting)")
    return PreprocessConfig(n_max=number_option("n_max", n_max, 1, integer=True), imu=imu,
                            imu_window_s=number_option("imu_window_s", imu_window_s, 0.05, 10.0))
