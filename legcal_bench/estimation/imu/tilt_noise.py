"""The IMU vertical's noise measured from the recordings themselves (issue #17).

The declared tilt noise is the accelerometer's white noise over g. On a moving posture
the motion compensation (`imu_motion.compensate`) leaves an error of its own at 1-3 Hz
(on the G1's weld sets 1.03-1.06x the declared sigma: `reports/modelgap/tilt_scatter.md`),
which the declared noise does not hold and which a chi-square test over ~10^4 degrees
of freedom sees. No truth is needed to measure it: the pelvis tilts on a ~10 s scale, so
the compensated vertical's scatter about its own smooth course (a quadratic
Savitzky-Golay fit over `WINDOW_S`) is noise. Per axis,

    sigma^2 = mean |u x s|^2_xy / (1 - h0),

u the unit vertical, s its smoothed course, h0 the fit's weight on its own sample (the
share of white noise the fit passes). A static effect (an IMU mount tilt, a leg
length) is smooth in the posture and stays in s: it is not mistaken for noise.
"""

from __future__ import annotations

import numpy as np

from legcal_bench.estimation.imu.imu_motion import compensate
from legcal_bench.estimation.problem.smoothing import savgol_coeffs, savgol_filter
from legcal_bench.robots.kinematics import LegKinematics

WINDOW_S = 1.0  # with 0.3 s the G1's excess hardly shows (1.01x): most of it lies at 1-3 Hz
POLYORDER = 2


def _window(time: np.ndarray, window_s: float) -> int:
    return int(round(window_s / np.median(np.diff(time)))) | 1


def vertical_scatter(kin: LegKinematics, rec, window_s: float = WINDOW_S) -> tuple[float, int]:
    """(per-axis sigma (rad), samples used) of one recording's IMU vertical about its
    smooth course: compensated for the posture's motion unless the recording is
    declared static. (nan, 0) when the recording is shorter than three windows or
    holds non-finite samples (a gap would read as scatter)."""
    n = len(rec.time)
    acc = np.asarray(rec.imu_acc, dtype=float)
    if n < 2 or not (np.isfinite(acc).all() and np.isfinite(rec.q_enc).all()):
        return float("nan"), 0
    w = _window(rec.time, window_s)
    if n < 3 * w:
        return float("nan"), 0
    f = acc if rec.motion == "static" else compensate(kin, rec.time, rec.q_enc, acc)
    u = f / np.linalg.norm(f, axis=1, keepdims=True)
    s = savgol_filter(u, w, POLYORDER, axis=0)
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    e = np.cross(s, u)[w:-w, :2]  # interior: the fit's ends differ
    h0 = savgol_coeffs(w, POLYORDER)[w // 2]
    return float(np.sqrt((e**2).mean() / (1 - h0))), len(e)


def measured_tilt_noise(kin: LegKinematics, recordings, window_s: float = WINDOW_S) -> float | None:
    """Per-axis tilt sigma (rad) pooled over `recordings` (their samples weighted
    equally); None when none is long enough."""
    parts = [vertical_scatter(kin, r, window_s) for r in recordings]
    parts = [(s, n) for s, n in parts if n > 0]
    if not parts:
        return None
    return float(np.sqrt(sum(s**2 * n for s, n in parts) / sum(n for _, n in parts)))
