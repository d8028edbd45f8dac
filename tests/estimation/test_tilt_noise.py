"""The IMU vertical's noise measured from the data (issue #17): white accelerometer noise
reads as itself (the smoothing's passed share corrected for), a slow tilt course and a
fixed mount tilt do not read as noise, a 2 Hz error does."""

from types import SimpleNamespace

import numpy as np
from scipy.signal import savgol_coeffs

from legcal_bench.estimation.imu.tilt_noise import measured_tilt_noise, vertical_scatter

G = 9.81
RATE = 50.0


def _recording(sigma_acc: float, n: int = 50_000, seed: int = 0, mount=(0.0, 0.0), wobble=0.0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    roll = 0.05 * np.sin(2 * np.pi * t / 10) + mount[0] + wobble * np.sin(2 * np.pi * 2.0 * t)
    pitch = 0.04 * np.cos(2 * np.pi * t / 13) + mount[1]
    up = np.stack([np.sin(pitch), -np.sin(roll) * np.cos(pitch), np.cos(roll) * np.cos(pitch)], axis=1)
    acc = G * up + sigma_acc * rng.standard_normal((n, 3))
    return SimpleNamespace(time=t, imu_acc=acc, q_enc=np.zeros((n, 12)), motion="static")


def test_white_accelerometer_noise_reads_as_its_declared_tilt():
    sigma = 0.02  # m/s^2: 2.04 mrad of tilt
    s, n = vertical_scatter(None, _recording(sigma))
    # 1e5 samples: the estimate's relative std ~0.3 %; without the passed share (1 - h0)
    # corrected it would read ~2.3 % low.
    assert abs(s / (sigma / G) - 1) < 0.01, s / (sigma / G)
    assert n > 0.99 * 50_000 - 2 * 51


def test_a_fixed_mount_tilt_is_not_noise_and_a_2_hz_error_is():
    sigma = 0.02
    base = vertical_scatter(None, _recording(sigma))[0]
    mounted = vertical_scatter(None, _recording(sigma, mount=(0.01, -0.008)))[0]
    assert abs(mounted / base - 1) < 0.005
    wobbly = vertical_scatter(None, _recording(sigma, wobble=1e-3))[0]
    # + a 1 mrad 2 Hz sine on the roll axis: the smoothing leaves |1 - H(2 Hz)| of it,
    # variance (1e-3 |1 - H|)^2 / 2 on one of the two axes, over the passed share.
    c = savgol_coeffs(51, 2)
    H = np.sum(c * np.exp(-2j * np.pi * 2.0 / RATE * (np.arange(51) - 25)))
    excess = (1e-3 * abs(1 - H)) ** 2 / 2 / 2 / (1 - c[25])
    expected = np.sqrt(base**2 + excess)
    assert abs(wobbly / expected - 1) < 0.005, (wobbly, expected)
    assert wobbly / base > 1.03


def test_pooled_over_recordings_and_none_when_too_short():
    a, b = _recording(0.02, 20_000, seed=1), _recording(0.04, 20_000, seed=2)
    pooled = measured_tilt_noise(None, [a, b])
    assert abs(pooled / (np.sqrt((0.02**2 + 0.04**2) / 2) / G) - 1) < 0.015
    assert measured_tilt_noise(None, [_recording(0.02, 100)]) is None
    gap = _recording(0.02, 5000)
    gap.imu_acc[100] = np.nan
    assert vertical_scatter(None, gap)[1] == 0
