"""Smoothing of slowly varying signals logged at a (nearly) uniform rate: a
Savitzky-Golay fit over a window given in seconds, on a uniform grid resampled from the
logged times (dropped or jittered samples are interpolated over, then the result is read
back at the logged times).

Two users:
  the IMU's acceleration from the leg angles (`imu_motion`, a second derivative);
  the ankle wrenches behind the compliance effect's loads (`smooth_wrenches`). A
  regressor measured with noise biases its fitted coefficient towards zero by
  var(signal) / (var(signal) + var(noise)) (errors in variables): loads computed from
  each frame's raw wrench (2 N, 0.2 N m noise) fitted knee compliances 5-6 % low on the
  A3-like robot, 3 posterior standard deviations. The load follows the posture, which
  moves on a ~10 s scale; a quadratic fit over FT_WINDOW_S passes it and cuts white
  noise's variance ~20x at 50 Hz (more at higher rates).
"""

from __future__ import annotations

import math

import numpy as np

FT_WINDOW_S = 1.0  # the wrenches' smoothing window (s)
FT_POLYORDER = 2


# The Savitzky-Golay filter itself, as `scipy.signal.savgol_coeffs` / `savgol_filter`
# (mode "interp") compute it, in numpy: importing scipy.signal costs a process ~0.6 s at
# scipy 1.17 (each of its functions' docstrings parsed at import, for its array-API
# notes), and every calibration's first call paid it for these two functions.
# tests/estimation/test_smoothing.py holds them to scipy.signal's to 1e-12.
def savgol_coeffs(window: int, polyorder: int, deriv: int = 0, delta: float = 1.0) -> np.ndarray:
    """(window,) the filter's weights as `scipy.signal.savgol_coeffs` returns them (its
    default `use="conv"`: reversed against the samples they weigh; the filter's output
    at a sample is their convolution with the samples around it). `window` odd."""
    half = window // 2
    x = np.arange(-half, half + 1, dtype=float)
    vander = x[:, None] ** np.arange(polyorder + 1)  # (window, polyorder + 1)
    # The least-squares polynomial's `deriv`-th coefficient as weights on the samples.
    weights = np.linalg.pinv(vander)[deriv] * (math.factorial(deriv) / delta**deriv)
    return weights[::-1].copy()


def savgol_filter(x: np.ndarray, window: int, polyorder: int, deriv: int = 0, delta: float = 1.0,
                  axis: int = 0) -> np.ndarray:
    """`scipy.signal.savgol_filter(x, window, polyorder, deriv, delta, axis, mode="interp")`:
    inside, each sample's window fitted by a polynomial of `polyorder` and its
    `deriv`-th derivative read at the centre; within half a window of either end, the
    polynomial fitted to the first (last) `window` samples read there."""
    x = np.moveaxis(np.asarray(x, dtype=float), axis, 0)
    n, half = x.shape[0], window // 2
    if window > n:
        raise ValueError(f"savgol_filter: window {window} is longer than the {n} samples")
    flat = x.reshape(n, -1)
    y = np.empty_like(flat)
    windows = np.lib.stride_tricks.sliding_window_view(flat, window, axis=0)  # (n - window + 1, m, window)
    y[half:n - half] = windows @ savgol_coeffs(window, polyorder, deriv, delta)[::-1]
    t = np.arange(window, dtype=float)
    vander = t[:, None] ** np.arange(polyorder + 1)
    powers = np.arange(polyorder + 1)
    # d^deriv/dt^deriv of t^p = p!/(p - deriv)! t^(p - deriv)
    scale = np.array([math.perm(p, deriv) for p in powers], dtype=float) / delta**deriv
    for rows, at in ((slice(0, window), np.arange(half)), (slice(n - window, n), np.arange(window - half, window))):
        coef = np.linalg.lstsq(vander, flat[rows], rcond=None)[0]  # (polyorder + 1, m)
        basis = np.where(powers >= deriv, at[:, None].astype(float) ** np.maximum(powers - deriv, 0), 0.0) * scale
        y[rows][at] = basis @ coef
    return np.moveaxis(y.reshape(x.shape), 0, axis)


def savgol_resampled(time: np.ndarray, values: np.ndarray, window_s: float, polyorder: int, deriv: int = 0
                     ) -> np.ndarray | None:
    """(N, ...) the Savitzky-Golay fit (or its `deriv`-th time derivative) of `values`
    (N, ...) logged at `time` (N,), over a window of `window_s` seconds (the odd number of
    samples nearest it, at most N); None when the recording is too short for a window
    longer than `polyorder`. `values` must be finite."""
    time = np.asarray(time, dtype=float)
    values = np.asarray(values, dtype=float)
    n = len(time)
    if n < polyorder + 2 or time[-1] <= time[0]:
        return None
    dt = (time[-1] - time[0]) / (n - 1)
    width = int(round(window_s / dt)) | 1  # odd
    width = min(width, n if n % 2 else n - 1)
    if width <= polyorder:
        return None
    grid = time[0] + dt * np.arange(n)
    flat = values.reshape(n, -1)
    uniform = np.column_stack([np.interp(grid, time, flat[:, i]) for i in range(flat.shape[1])])
    fitted = savgol_filter(uniform, width, polyorder, deriv=deriv, delta=dt, axis=0)
    back = np.column_stack([np.interp(time, grid, fitted[:, i]) for i in range(flat.shape[1])])
    return back.reshape(values.shape)


def smooth_wrenches(time: np.ndarray, ft: np.ndarray, window_s: float = FT_WINDOW_S) -> np.ndarray:
    """(N, 2, 6) the ankle wrenches `ft` (N, 2, 6) of one contact segment logged at `time`,
    smoothed over `window_s` (a quadratic Savitzky-Golay fit): the loads' noise is what
    biases a fitted compliance low. Non-finite samples are filled from their finite
    neighbours; a segment too short to smooth (or with fewer than two finite samples)
    comes back unchanged."""
    time = np.asarray(time, dtype=float)
    ft = np.asarray(ft, dtype=float)
    ok = np.isfinite(ft).reshape(len(ft), -1).all(axis=1) & np.isfinite(time)
    if ok.sum() < 2:
        return ft.copy()
    out = savgol_resampled(time[ok], ft[ok], window_s, FT_POLYORDER)
    if out is None:
        return ft.copy()
    if ok.all():
        return out
    flat = out.reshape(len(out), -1)
    filled = np.column_stack([np.interp(time, time[ok], flat[:, i]) for i in range(flat.shape[1])])
    return np.where(np.isfinite(time)[:, None, None], filled.reshape(ft.shape), ft)
