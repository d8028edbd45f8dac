"""Sensors: what a recording declares, and what the simulator realizes.

`SensorModel` is the declaration stored in every recording: what a robot team knows
from datasheets and their own characterization (noise levels, encoder resolution, and
*bounds* on the IMU's bias and mounting tilt), never the realized bias or tilt, which
no real log could know. `ImuErrors` holds the realized bias and mounting tilt; they live
in the simulator (`SimSensors`) and in the ground truth only.

A declaration read from user data (`SensorModel.from_dict`: a recording, a sensor spec)
must give every field: a field left out is not a perfect sensor but an undeclared one.
A team that does not know its sensors writes `unknown` instead: `SensorModel.unknown()`,
conservative bounds that every calibration result then names (issue #39).

Encoders: Gaussian noise, then quantization to the encoder resolution. IMU: the true
specific force and angular rate in the nominal IMU frame, rotated into the actual
(mounting-tilted) sensor frame, plus the realized constant bias and Gaussian noise.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from functools import cached_property

import numpy as np
from scipy.spatial.transform import Rotation

from legcal_bench.errors import SensorModelError
from legcal_bench.sim.names import SENSOR_PRESET_NAMES

G = 9.81  # m/s^2
# Realized values that older recordings declared; a robot cannot know them.
REALIZED_FIELDS = {"accel_bias": "accel_bias_bound", "gyro_bias": "gyro_bias_bound",
                   "imu_mount_rpy": "imu_mount_bound"}


def _numbers(cls, d: dict, what: str) -> dict:
    """The fields of dataclass `cls` from `d`, checked: scalars finite and >= 0,
    3-vectors finite."""
    if not isinstance(d, dict):
        raise SensorModelError(f"{what} must be a JSON object of its fields, got {d!r}")
    known = {f.name for f in fields(cls)}
    unknown = set(d) - known
    if unknown:
        raise SensorModelError(f"{what}: unknown fields {sorted(unknown)}; known: {sorted(known)}")
    out = {}
    for k, v in d.items():
        vector = isinstance(getattr(cls, k), tuple)
        try:
            if isinstance(v, (bool, str)) or (isinstance(v, (list, tuple)) and any(isinstance(x, (bool, str))
                                                                                   for x in v)):
                raise ValueError
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError, OverflowError):  # OverflowError: an integer beyond any float
            a = None
        if vector and (a is None or a.shape != (3,) or not np.isfinite(a).all()):
            raise SensorModelError(f"{what}: field '{k}' must be 3 finite numbers [x, y, z], got {v!r}")
        if not vector and (a is None or a.shape != () or not np.isfinite(a) or a < 0):
            raise SensorModelError(f"{what}: field '{k}' must be one finite number >= 0 (a standard deviation, "
                                   f"resolution or bound in SI units), got {v!r}")
        out[k] = tuple(float(x) for x in a) if vector else float(a)
    return out


@dataclass(frozen=True)
class SensorModel:
    """The declaration: what a robot team knows about its sensors."""

    encoder_noise_std: float = 0.0  # rad
    encoder_resolution: float = 0.0  # rad per count; 0 = no quantization
    accel_noise_std: float = 0.0  # m/s^2
    gyro_noise_std: float = 0.0  # rad/s
    ft_force_noise_std: float = 0.0  # N, ankle force/torque sensors
    ft_torque_noise_std: float = 0.0  # N m
    accel_bias_bound: float = 0.0  # m/s^2, per axis (datasheet)
    gyro_bias_bound: float = 0.0  # rad/s, per axis
    imu_mount_bound: float = 0.0  # rad, mounting tilt per axis (drawing tolerance or an IMU calibration)

    def to_dict(self) -> dict:
        return asdict(self)

    @cached_property
    def ft_std(self) -> np.ndarray:
        """(6,) the force/torque sensor's noise per axis [force x3, torque x3]."""
        return np.array([self.ft_force_noise_std] * 3 + [self.ft_torque_noise_std] * 3)

    @property
    def tilt_bound(self) -> float:
        """Bound on the IMU's static vertical error (rad) near level: mounting tilt plus
        the horizontal accelerometer bias over g. (A z bias b adds b/g sin(tilt): a scale
        error of the tilt reading, not an offset.)"""
        return self.imu_mount_bound + self.accel_bias_bound / G

    @classmethod
    def from_dict(cls, d: dict, complete: bool = True) -> "SensorModel":
        """The declaration in `d`, checked. With `complete` (the default: a declaration
        from user data) every field must be there: a missing one is an error naming it,
        never a silent 0 (a perfect sensor). `complete=False` fills missing fields with
        0, for code that builds a model from a few known fields on purpose."""
        if isinstance(d, dict):
            realized = sorted(set(d) & set(REALIZED_FIELDS))
            if realized:
                raise SensorModelError(
                    f"sensor model: fields {realized} are realized values (the IMU's actual bias or mounting tilt) "
                    f"that a robot's log cannot know; declare bounds instead ({', '.join(REALIZED_FIELDS[k] for k in realized)}). "
                    "Recordings collected before issue #11 carry them: re-collect them")
        values = _numbers(cls, d, "sensor model")
        missing = [f.name for f in fields(cls) if f.name not in values]
        if complete and missing:
            raise SensorModelError(
                f"sensor model: missing fields {missing}: a field left out would read as a perfect sensor (0); "
                "declare it from the datasheet (0 only if the sensor truly has none), or write "
                "\"sensor_model\": \"unknown\" (conservative bounds, named in every result; "
                "docs/recording-format.md)")
        return cls(**values)

    @classmethod
    def unknown(cls) -> "SensorModel":
        """The model applied when a recording declares `"sensor_model": "unknown"`:
        `UNKNOWN_SENSORS`, conservative bounds (see there)."""
        return UNKNOWN_SENSORS

    def describe(self) -> str:
        """The fields as 'name value' pairs, for messages."""
        return ", ".join(f"{k} {v:g}" for k, v in self.to_dict().items())


# What a recording that declares `"sensor_model": "unknown"` is calibrated with: bounds
# larger than any plausible humanoid's sensors, so the posterior, the contact check and
# the IMU-tilt warning err on the safe side (wider uncertainty, fewer soles flagged, the
# tilt warning on). Every calibration result names the recordings that use them.
UNKNOWN_SENSORS = SensorModel(
    # 1 mrad (0.057 deg): 10x a 17-bit absolute encoder's electrical noise (1e-4 rad), and
    # above a 12-bit magnetic encoder's quantization (2 pi / 2^12 / sqrt(12) = 0.44 mrad).
    encoder_noise_std=1e-3,
    # Quantization is folded into encoder_noise_std above (0 = none declared separately).
    encoder_resolution=0.0,
    # 0.05 m/s^2 (5 mg) per sample: a consumer MEMS accelerometer (~400 ug/sqrt(Hz), e.g.
    # MPU-6050) at ~100 Hz bandwidth reads ~4 mg; industrial parts read well under 1 mg.
    accel_noise_std=0.05,
    # 0.01 rad/s (0.57 deg/s) per sample: ~10x a consumer MEMS gyro at 100 Hz bandwidth
    # (0.005 deg/s/sqrt(Hz) -> 0.05 deg/s), room for a leg's vibration.
    gyro_noise_std=0.01,
    # 5 N, 0.5 N m: above six-axis ankle force/torque sensors' noise (0.5-2 N, 0.05-0.2 N m)
    # with a strain gauge's drift over a segment.
    ft_force_noise_std=5.0,
    ft_torque_noise_std=0.5,
    # 0.2 m/s^2 (~20 mg) per axis: a trimmed MEMS accelerometer's zero-g offset over
    # temperature (BMI088, ICM-42688: +-20 mg); a factory-calibrated IMU module reads < 5 mg.
    accel_bias_bound=0.2,
    # 0.05 rad/s (~3 deg/s) per axis: a trimmed MEMS gyro's zero-rate offset (+-1-3 deg/s).
    gyro_bias_bound=0.05,
    # 1 deg: an IMU board screwed into a machined bracket, without an IMU calibration
    # (drawing tolerances give 0.1-0.5 deg).
    imu_mount_bound=float(np.deg2rad(1.0)),
)


@dataclass(frozen=True)
class ImuErrors:
    """The realized IMU errors: in the simulator and the ground truth only."""

    accel_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m/s^2
    gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)  # rad/s
    imu_mount_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)  # rad, mounting tilt

    def to_dict(self) -> dict:
        return {k: list(v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict) -> "ImuErrors":
        return cls(**_numbers(cls, d, "IMU errors"))

    @cached_property
    def mount_rotation(self) -> np.ndarray:
        """Rotation of the actual IMU frame in the nominal IMU frame (computed once)."""
        return Rotation.from_euler("xyz", self.imu_mount_rpy).as_matrix()

    @cached_property
    def biases(self) -> tuple[np.ndarray, np.ndarray]:
        """(accelerometer, gyro) bias as arrays (made once: the IMU reads them every sample)."""
        return np.asarray(self.accel_bias), np.asarray(self.gyro_bias)

    def vertical(self, up_I: np.ndarray) -> np.ndarray:
        """The up direction a static accelerometer reports, in the nominal IMU frame,
        when the true one is `up_I` (noise-free): tilted by the mount, pulled by the bias."""
        f = self.mount_rotation.T @ (G * np.asarray(up_I, dtype=float)) + np.asarray(self.accel_bias)
        return f / np.linalg.norm(f)


@dataclass(frozen=True)
class SimSensors:
    """The simulator's sensors: the declared model's noise with the realized errors."""

    model: SensorModel = SensorModel()
    errors: ImuErrors = ImuErrors()
    # Realized encoder scale errors (one per leg joint, leg-map order; empty = none): an encoder reads
    # (q - offset) / (1 + scale), so q = q_enc + scale q_enc + offset (issue #16's effect).
    encoder_scale: tuple[float, ...] = ()
    # Reading laws (effect plug-ins that change how an encoder reads, through
    # `ModelEdit.sensors`; e.g. a backlash): each `law(e, time) -> e` maps a whole series'
    # noise-free readings e (N, n) (encoder space, after the scale error) at its
    # timestamps `time` (N,) to what the encoders read before their noise. The ground
    # truth's clean readings (`Truth.q_enc_clean`) go through them too.
    reading_laws: tuple = ()

    def clean_readings(self, q_true_minus_offset: np.ndarray, time: np.ndarray | None = None) -> np.ndarray:
        """The encoders' noise-free readings of a series: the scale error, then the
        reading laws (which need the series' `time`)."""
        e = q_true_minus_offset
        if self.encoder_scale:
            e = e / (1.0 + np.asarray(self.encoder_scale))
        if self.reading_laws and time is None:
            raise SensorModelError("an effect that changes the encoders' reading law (a reading law of "
                                   "`SimSensors.reading_laws`) needs a whole series with its timestamps: it is "
                                   "simulated in static collection (`legcal-bench collect`), not frame by frame")
        for law in self.reading_laws:
            e = np.asarray(law(np.asarray(e, dtype=float), np.asarray(time, dtype=float)), dtype=float)
        return e

    def encoders(self, q_true_minus_offset: np.ndarray, rng: np.random.Generator,
                 noise: np.ndarray | None = None, time: np.ndarray | None = None) -> np.ndarray:
        """Encoder readings; `noise`: standard normal draws to use instead of drawing
        from `rng` (the same numbers give the same readings, whatever the batch); `time`:
        the series' timestamps, for the reading laws (`clean_readings`)."""
        m = self.model
        q_true_minus_offset = self.clean_readings(q_true_minus_offset, time)
        if noise is None:
            noise = rng.standard_normal(q_true_minus_offset.shape)
        q = q_true_minus_offset + m.encoder_noise_std * noise
        if m.encoder_resolution > 0:
            q = np.rint(q / m.encoder_resolution) * m.encoder_resolution  # np.round with 0 decimals is rint
        return q

    def imu(self, specific_force: np.ndarray, gyro: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        R, (acc_bias, gyro_bias), m = self.errors.mount_rotation, self.errors.biases, self.model
        acc = R.T @ specific_force + acc_bias + m.accel_noise_std * rng.standard_normal(3)
        gyr = R.T @ gyro + gyro_bias + m.gyro_noise_std * rng.standard_normal(3)
        return acc, gyr

    def imu_samples(self, samples: np.ndarray, noise: np.ndarray) -> np.ndarray:
        """`imu` of many samples in one call: `samples` (N, 2, 3) or (2N, 3), [specific
        force, angular rate] per sample (IMU frame), `noise` the same shape of standard
        normal draws (per sample: accelerometer's, then gyro's, as `imu` draws them).
        The same products and sums as one sample at a time (a broadcast matmul: a
        matrix-vector product per row)."""
        pairs = samples.reshape(-1, 2, 3)
        bias, std = self._imu_rows
        out = np.matmul(self.errors.mount_rotation.T, pairs[..., None])[..., 0] + bias + std * noise.reshape(pairs.shape)
        return out.reshape(samples.shape)

    @cached_property
    def _imu_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """Bias (2, 3) and noise level (2, 1) of [accelerometer, gyro]."""
        m = self.model
        return np.stack(self.errors.biases), np.array([[m.accel_noise_std], [m.gyro_noise_std]])

    def force_torque(self, wrench: np.ndarray, rng: np.random.Generator, noise: np.ndarray | None = None) -> np.ndarray:
        """(..., 2, 6) ankle wrenches [force, torque] with noise (`noise`: standard normal
        draws of that shape, instead of drawing from `rng`)."""
        return wrench + self.model.ft_std * (rng.standard_normal(wrench.shape) if noise is None else noise)


# A typical full-size humanoid: 17-bit absolute joint encoders with a little electrical
# noise, a MEMS IMU (about 1 mrad of gravity-direction noise per sample).
_NOISE = dict(encoder_noise_std=1e-4, encoder_resolution=2 * np.pi / 2**17, accel_noise_std=0.01,
              gyro_noise_std=0.003, ft_force_noise_std=2.0, ft_torque_noise_std=0.2)
ZERO, REALISTIC, CALIBRATED_IMU = SENSOR_PRESET_NAMES  # their names, which the command shows
SENSOR_PRESETS: dict[str, SimSensors] = {
    # Every effect off: encoders read q_true - offset exactly, the IMU reads the truth.
    ZERO: SimSensors(),
    # An uncalibrated IMU: a few mg of bias, mounted to within a tenth of a degree
    # (realized: 2.04 mrad of x bias over g plus 1.0 mrad of mounting pitch).
    REALISTIC: SimSensors(
        SensorModel(**_NOISE, accel_bias_bound=0.03, gyro_bias_bound=0.002, imu_mount_bound=0.002),
        ImuErrors(accel_bias=(0.02, -0.015, 0.01), gyro_bias=(0.001, -0.0015, 0.0005),
                  imu_mount_rpy=(0.0015, -0.001, 0.0))),
    # The same IMU after an IMU calibration (bias and mounting estimated on a level
    # reference): about 0.1 mrad of residual vertical error. Every axis's bias is within
    # the declared bound, z too: off level, a z bias b reads a tilt theta short by
    # (b/g) sin theta, so 1 mg of it scales the stances' pelvis pitch by -0.1 % and
    # biases a fitted encoder scale (issue #16; it was 0.01 m/s^2 before, 10x the bound).
    CALIBRATED_IMU: SimSensors(
        SensorModel(**_NOISE, accel_bias_bound=0.001, gyro_bias_bound=0.002, imu_mount_bound=0.0001),
        ImuErrors(accel_bias=(0.0006, -0.0004, 0.0008), gyro_bias=(0.001, -0.0015, 0.0005),
                  imu_mount_rpy=(0.00005, -0.00004, 0.0))),
}


def sim_sensors(spec: str | SimSensors | SensorModel | dict) -> SimSensors:
    """A preset by name, or a declared model (as an object or dict) with no IMU errors."""
    if isinstance(spec, SimSensors):
        return spec
    if isinstance(spec, SensorModel):
        return SimSensors(spec)
    if isinstance(spec, dict):
        return SimSensors(SensorModel.from_dict(spec))
    if spec not in SENSOR_PRESETS:
        raise SensorModelError(f"unknown sensor preset {spec!r}; use one of {list(SENSOR_PRESETS)}")
    return SENSOR_PRESETS[spec]


def sensor_model(spec: str | SimSensors | SensorModel | dict) -> SensorModel:
    """The declared model of a preset or spec."""
    return sim_sensors(spec).model
