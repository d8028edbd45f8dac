"""Smoothing on the logged time grid (`legcal_bench.estimation.problem.smoothing`): a slow signal
passes, white noise's variance drops by the quadratic Savitzky-Golay factor, gaps and
short segments are handled."""

import numpy as np
import pytest

from legcal_bench.estimation.problem.smoothing import FT_WINDOW_S, savgol_resampled, smooth_wrenches

RATE = 50.0


def _wrenches(seconds=12.0, noise=(2.0, 0.2), seed=0):
    t = np.arange(0, seconds, 1 / RATE)
    slow = np.zeros((len(t), 2, 6))
    slow[:, :, 2] = 200 + 30 * np.sin(2 * np.pi * t / 10)[:, None]  # a posture cycle of 10 s
    slow[:, :, 4] = 5 * np.cos(2 * np.pi * t / 8)[:, None]
    rng = np.random.default_rng(seed)
    std = np.array([noise[0]] * 3 + [noise[1]] * 3)
    return t, slow, slow + rng.normal(size=slow.shape) * std


def test_a_slow_load_passes_and_white_noise_drops_by_the_quadratic_fit_s_factor():
    t, slow, noisy = _wrenches()
    assert np.abs(smooth_wrenches(t, slow) - slow).max() < 0.01 * 30  # < 1 % of the posture swing
    n = int(round(FT_WINDOW_S * RATE)) | 1
    factor = 3 * (3 * n**2 - 7) / (4 * n * (n**2 - 4))  # a centred quadratic fit's variance ratio (~1/23)
    inner = slice(n, len(t) - n)
    ratio = np.var((smooth_wrenches(t, noisy) - slow)[inner]) / np.var((noisy - slow)[inner])
    assert ratio == pytest.approx(factor, rel=0.25)


def test_dropped_and_non_finite_samples_are_bridged():
    t, slow, noisy = _wrenches(noise=(0.0, 0.0))
    keep = np.ones(len(t), bool)
    keep[100:110] = False  # a gap in the log
    noisy = noisy.copy()
    noisy[300, 1, 3] = np.nan  # a dropped channel
    out = smooth_wrenches(t[keep], noisy[keep])
    assert np.isfinite(out).all()
    assert np.abs(out - slow[keep]).max() < 0.01 * 30


def test_a_segment_too_short_to_smooth_comes_back_unchanged():
    t, _, noisy = _wrenches(seconds=0.05)
    assert savgol_resampled(t, noisy, FT_WINDOW_S, 2) is None or len(t) >= 4
    np.testing.assert_array_equal(smooth_wrenches(t[:3], noisy[:3]), noisy[:3])


@pytest.mark.parametrize("window,polyorder,deriv,n,axis", [(5, 2, 0, 9, 0), (51, 2, 0, 400, 0), (25, 3, 1, 300, 1),
                                                           (11, 2, 2, 11, 0), (101, 2, 2, 1000, 0), (7, 4, 3, 50, 2)])
def test_our_savitzky_golay_is_scipy_signals(window, polyorder, deriv, n, axis):
    # Ours in numpy (scipy.signal's import costs a process ~0.6 s), held to scipy.signal's:
    # the interior, both edges (mode "interp"), derivatives with a sample spacing, any axis.
    from scipy import signal

    from legcal_bench.estimation.problem import smoothing

    rng = np.random.default_rng(window + n)
    shape = [3, 4, 2]
    shape.insert(axis, n)
    x = rng.normal(size=shape) + np.linspace(0, 5, n).reshape([-1 if k == axis else 1 for k in range(4)]) ** 2
    theirs = signal.savgol_coeffs(window, polyorder, deriv, delta=0.02)
    np.testing.assert_allclose(smoothing.savgol_coeffs(window, polyorder, deriv, delta=0.02), theirs,
                               rtol=0, atol=1e-12 * np.abs(theirs).max())
    ours = smoothing.savgol_filter(x, window, polyorder, deriv=deriv, delta=0.02, axis=axis)
    theirs = signal.savgol_filter(x, window, polyorder, deriv=deriv, delta=0.02, axis=axis, mode="interp")
    np.testing.assert_allclose(ours, theirs, rtol=1e-9, atol=1e-9 * np.abs(theirs).max())
    assert ours.shape == x.shape


def test_the_calibration_path_imports_neither_scipy_signal_nor_scipy_stats():
    # Their imports cost a process ~0.6 s and ~0.4 s (scipy 1.17) for two filters and a
    # few distribution tails: a calibration or a diagnosis in a fresh process loads neither.
    import subprocess
    import sys

    code = ("import sys; import legcal_bench.calibrators.base, legcal_bench.calibrators.interfoot, "
            "legcal_bench.calibrators.yamane, legcal_bench.data.recording, legcal_bench.evaluation.modelgap; "
            "print(sorted(m for m in sys.modules if m in ('scipy.signal', 'scipy.stats')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
