"""The simulated sensors: each preset's realized IMU errors stay within the bounds it
declares (a robot team's datasheet), and why the z axis matters too."""

import numpy as np
import pytest

from legcal_bench.sim.sensors import G, SENSOR_PRESETS, ImuErrors


@pytest.mark.parametrize("name", sorted(SENSOR_PRESETS))
def test_every_preset_realizes_errors_within_its_declared_bounds(name):
    s = SENSOR_PRESETS[name]
    for field, bound in (("accel_bias", s.model.accel_bias_bound), ("gyro_bias", s.model.gyro_bias_bound),
                         ("imu_mount_rpy", s.model.imu_mount_bound)):
        realized = np.abs(getattr(s.errors, field))
        assert np.all(realized <= bound), f"{name}: {field} {realized.tolist()} beyond the declared bound {bound}"


def test_a_z_bias_scales_an_off_level_tilt_reading():
    b, tilt = 0.01, 0.2
    up = np.array([np.sin(tilt), 0.0, np.cos(tilt)])
    read = ImuErrors(accel_bias=(0.0, 0.0, b)).vertical(up)
    read_tilt = np.arctan2(read[0], read[2])
    # atan(g sin t / (g cos t + b)) - t = -(b/g) sin t to first order in b/g: a tilt read
    # about b/g short, 0.2 mrad at 0.2 rad for the 1 mg the calibrated-imu preset once had
    assert read_tilt - tilt == pytest.approx(-(b / G) * np.sin(tilt), rel=0.01)


@pytest.mark.parametrize("name", sorted(SENSOR_PRESETS))
def test_many_samples_read_at_once_are_the_samples_read_one_at_a_time(name):
    """The simulators read the IMU and encoders of many samples in one call (a walk's
    step, a recorded segment) with the random draws of one sample at a time, in order."""
    s, rng = SENSOR_PRESETS[name], np.random.default_rng(7)
    f, w, q = rng.normal(0, 9.81, (50, 3)), rng.normal(0, 0.5, (50, 3)), rng.normal(0, 1, (50, 12))
    a, b = np.random.default_rng(1), np.random.default_rng(1)
    one = [(s.imu(f[i], w[i], a), s.encoders(q[i], a)) for i in range(50)]
    noise = b.standard_normal((50, 18))
    imu = s.imu_samples(np.stack([f, w], axis=1), noise[:, :6])
    assert np.array_equal(imu, np.array([[acc, gyr] for (acc, gyr), _ in one]))
    assert np.array_equal(s.encoders(q, None, noise[:, 6:]), np.array([e for _, e in one]))
    assert a.random() == b.random()  # the same stream, left in the same place


def test_a_reading_law_changes_the_readings_and_the_clean_ones_alike():
    """Issue #61: an effect that changes how the encoders read (a reading law) reaches the
    noisy readings and the truth's clean ones the same way; without the series' timestamps
    it refuses instead of reading around the law."""
    import dataclasses

    from legcal_bench.errors import SensorModelError
    def late(e, time):  # reads the angle half a second late
        return np.stack([np.interp(time - 0.5, time, col) for col in e.T], axis=1)

    base = SENSOR_PRESETS["realistic"]
    law = dataclasses.replace(base, encoder_scale=(0.01, 0.0), reading_laws=(late,))
    time = np.arange(100) * 0.02
    e = np.stack([np.sin(time), np.cos(time)], axis=1)
    clean = law.clean_readings(e, time)
    assert np.allclose(clean, late(e / [1.01, 1.0], time))
    noise = np.random.default_rng(0).standard_normal(e.shape)
    rng = np.random.default_rng(1)
    m = base.model
    assert np.abs(law.encoders(e, rng, noise, time) - (clean + m.encoder_noise_std * noise)).max() <= m.encoder_resolution
    with pytest.raises(SensorModelError, match="timestamps"):
        law.encoders(e, rng, noise)
    assert np.array_equal(base.clean_readings(e), e)  # no law, no scale: the angle as it is
