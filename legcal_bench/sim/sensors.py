"""The declared sensor model: one object, stored in every recording.

Encoders: Gaussian noise, then quantization to the encoder resolution. IMU: the true
specific force and angular rate in the nominal IMU frame, rotated into the actual
(mounting-tilted) sensor frame, plus a constant bias and Gaussian noise.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from functools import cached_property

import numpy as np
from scipy.spatial.transform import Rotation

from legcal_bench.errors import SensorModelError


@dataclass(frozen=True)
class SensorModel:
    encoder_noise_std: float = 0.0  # rad
    encoder_resolution: float = 0.0  # rad per count; 0 = no quantization
    accel_noise_std: float = 0.0  # m/s^2
    accel_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m/s^2
    gyro_noise_std: float = 0.0  # rad/s
    gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)  # rad/s
    imu_mount_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)  # rad, mounting tilt
    ft_force_noise_std: float = 0.0  # N, ankle force/torque sensors
    ft_torque_noise_std: float = 0.0  # N m

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, d: dict) -> "SensorModel":
        known = {f.name for f in fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise SensorModelError(f"sensor model: unknown fields {sorted(unknown)}; known: {sorted(known)}")
        out = {}
        for k, v in d.items():
            vector = isinstance(getattr(cls, k), tuple)
            try:
                if isinstance(v, (bool, str)) or (isinstance(v, (list, tuple)) and
                                                  any(isinstance(x, (bool, str)) for x in v)):
                    raise ValueError
                a = np.asarray(v, dtype=float)
            except (TypeError, ValueError):
                a = None
            if vector and (a is None or a.shape != (3,) or not np.isfinite(a).all()):
                raise SensorModelError(f"sensor model: field '{k}' must be 3 finite numbers [x, y, z], got {v!r}")
            if not vector and (a is None or a.shape != () or not np.isfinite(a) or a < 0):
                raise SensorModelError(f"sensor model: field '{k}' must be one finite number >= 0 (a standard "
                                       f"deviation or resolution in SI units), got {v!r}")
            out[k] = tuple(float(x) for x in a) if vector else float(a)
        return cls(**out)

    @cached_property
    def mount_rotation(self) -> np.ndarray:
        """Rotation of the actual IMU frame in the nominal IMU frame (computed once)."""
        return Rotation.from_euler("xyz", self.imu_mount_rpy).as_matrix()

    def encoders(self, q_true_minus_offset: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        q = q_true_minus_offset + self.encoder_noise_std * rng.standard_normal(q_true_minus_offset.shape)
        if self.encoder_resolution > 0:
            q = np.round(q / self.encoder_resolution) * self.encoder_resolution
        return q

    def imu(self, specific_force: np.ndarray, gyro: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        R = self.mount_rotation
        acc = R.T @ specific_force + np.asarray(self.accel_bias) + self.accel_noise_std * rng.standard_normal(3)
        gyr = R.T @ gyro + np.asarray(self.gyro_bias) + self.gyro_noise_std * rng.standard_normal(3)
        return acc, gyr

    def force_torque(self, wrench: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """(2, 6) ankle wrenches [force, torque] with noise."""
        std = np.array([self.ft_force_noise_std] * 3 + [self.ft_torque_noise_std] * 3)
        return wrench + std * rng.standard_normal(wrench.shape)


SENSOR_PRESETS: dict[str, SensorModel] = {
    # Every effect off: encoders read q_true - offset exactly, the IMU reads the truth.
    "zero": SensorModel(),
    # A typical full-size humanoid: 17-bit absolute joint encoders with a little
    # electrical noise, a MEMS IMU (about 1 mrad of gravity-direction noise per sample,
    # a few mg of bias) mounted to within a tenth of a degree.
    "realistic": SensorModel(
        encoder_noise_std=1e-4,
        encoder_resolution=2 * np.pi / 2**17,
        accel_noise_std=0.01,
        accel_bias=(0.02, -0.015, 0.01),
        gyro_noise_std=0.003,
        gyro_bias=(0.001, -0.0015, 0.0005),
        imu_mount_rpy=(0.0015, -0.001, 0.0),
        ft_force_noise_std=2.0,
        ft_torque_noise_std=0.2,
    ),
}


def sensor_model(spec: str | SensorModel | dict) -> SensorModel:
    if isinstance(spec, SensorModel):
        return spec
    if isinstance(spec, dict):
        return SensorModel.from_dict(spec)
    if spec not in SENSOR_PRESETS:
        raise SensorModelError(f"unknown sensor preset {spec!r}; use one of {list(SENSOR_PRESETS)}")
    return SENSOR_PRESETS[spec]
