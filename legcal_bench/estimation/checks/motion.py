"""Static or continuous: how a recording was logged, measured from its data (issue #39).

A recording is "continuous" (logged while the posture moves: the accelerometer also
reads the IMU's acceleration, which the calibrators remove with the encoder
kinematics, `imu_motion.compensate`) or "static" (every frame logged at rest, e.g.
hold-and-log, or the simulator's kinematic mode: it reads gravity alone). The
declaration used to default to "continuous"; a hold-and-log recording converted that
way had a motion acceleration that was never there removed from every frame, and all
four stances came out "soles not on one plane" (chi2 53-447). So the data decide.

With the feet fixed, the encoders give the IMU's orientation and position in each sole
frame, hence what a moving IMU reads beyond gravity. Two comparisons, each of the
hypotheses "static" (the sensor reads none of it) and "continuous" (all of it):

  accelerometer: the specific force against the acceleration `imu_acceleration`
      predicts (a), after fitting what both hypotheses share: gravity in each sole
      frame, a constant bias, and the encoders' offsets to first order (a fixed offset
      tilts the predicted gravity differently in each posture: without it the misfit is
      as large as the acceleration). With P the projection off those columns, whitened
      by sigma, the least-squares share of a the accelerometer reads is
          k = <P f, P a> / |P a|^2      (0: static, 1: continuous)
      and the two hypotheses' chi-square differ by
          dchi2 = chi2_static - chi2_continuous = S (2k - 1),   S = |P a|^2 / sigma^2,
      S being how far apart the data can tell them (the chi-square of the predicted
      signal itself).
  gyro: the angular rate against the IMU's rate in a sole frame from the encoders
      (a Savitzky-Golay derivative of its orientation, `RATE_WINDOW_S`), a constant bias
      fitted; k, dchi2 and S as above. A gyro reading ~0 (plus bias) while the encoders'
      orientation turns is a robot read at rest.

sigma per axis is the declared noise (`SensorModel`) with a floor for the prediction's
own error (`ACC_MODEL_STD`, `GYRO_MODEL_STD`), and at least the scatter the better
hypothesis leaves (noise declared too small must not make a verdict conclusive). A
comparison is conclusive when |dchi2| >= `MARGIN` and k lies within `FIT_TOLERANCE` of
the winner (0 or 1; between the two neither fits). The accelerometer decides (its
reading is what compensation changes); the gyro decides "static" alone when the
accelerometer cannot tell. A gyro that follows the encoders does not prove
"continuous": the simulator's kinematic mode reads the posture's rate with gravity
alone.

`resolve_motion` runs before any estimator (`calibrate_training`, the scoring): a
conclusive measurement replaces the declaration, with a warning when they disagree;
an inconclusive one keeps it, and an undeclared recording is taken as "continuous"
(compensation is harmless when the motion is within the noise; a warning when the
predicted acceleration is not, `QUIET`).

The comparisons use the frames where the smoothing has its full window (its ends are
noisier). The margins measured on the default sets, and the command that gives them, are
in docs/recording-format.md ("Motion: measured from the data"). Work per recording: two
batched forward-kinematics passes, two smoothings, one SVD of (frames x 21).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from functools import lru_cache
from time import perf_counter

import numpy as np

from legcal_bench.data.recording import MOTIONS, Recording
from legcal_bench.estimation.imu.imu_motion import IMU_WINDOW_S, imu_acceleration
from legcal_bench.estimation.imu.imu_motion import POLYORDER as IMU_POLYORDER
from legcal_bench.estimation.problem.smoothing import savgol_coeffs, savgol_resampled
from legcal_bench.estimation.verdict import HARMLESS, Finding
from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics

STATIC, CONTINUOUS = "static", "continuous"
assert set(MOTIONS) == {STATIC, CONTINUOUS}
# The prediction's own error per axis, added to the declared noise: the compensation
# misses ~10 % of a ~0.02 m/s^2 motion (smoothing, servo jitter; tests/estimation/
# test_imu_motion.py) and the offsets' second-order effect; the encoder rate misses
# 1.3-2.6 mrad/s per axis on noise-free A3 weld and kinematic sets. Both floors are ~2x that.
ACC_MODEL_STD = 0.005  # m/s^2
GYRO_MODEL_STD = 0.005  # rad/s
RATE_WINDOW_S = 0.3  # the orientation's derivative (quadratic Savitzky-Golay)
# A verdict needs the hypotheses' chi-square to differ by this (a likelihood ratio of
# e^12.5; 5 standard errors of k when S ~ 25) ...
MARGIN = 25.0
# ... and the share k read to lie this near the winner (0 or 1): k = 0.5 fits neither.
FIT_TOLERANCE = 0.35
# Undeclared and inconclusive: "continuous" is taken; below this separation S (the
# predicted acceleration's chi-square, less its part from the prediction's own noise)
# the choice moves nothing beyond ~2 sigma, and no warning is given.
QUIET = 4.0
# "static" also needs the predicted signal to be mostly signal: its power at least this
# many times the noise the encoders put into it (a derivative of noisy angles). Noise
# in the prediction is not in the sensor, so a still robot (the standing phase) would
# read as "static" on its prediction's noise alone; the factor leaves room for encoder
# noise up to 2x the declared. (Noise cannot fake "continuous": it lowers k.)
SNR_MIN = 4.0
MIN_FRAMES = 10  # frames with a full smoothing window


@dataclass(frozen=True)
class Comparison:
    """One sensor's reading against the two hypotheses."""

    fraction: float  # k: the share of the predicted motion signal the sensor reads (0 static, 1 continuous)
    dchi2: float  # chi2(static) - chi2(continuous), whitened: > 0 favours continuous
    separation: float  # S = |P s|^2 / sigma^2: the predicted signal's own chi-square
    sigma: float  # per-axis whitening standard deviation used
    predicted_rms: float  # RMS norm of the predicted signal (m/s^2 or rad/s)
    # The predicted signal's power over its own expected noise power (from the encoders'
    # declared noise through the derivative); None when they declare none.
    snr: float | None
    verdict: str | None  # "static", "continuous" or None (inconclusive)


@dataclass(frozen=True)
class MotionEvidence:
    """What a recording's data say about how it was logged; `motion` None when they
    cannot tell (too little motion for the noise, or neither hypothesis fits)."""

    recording: str
    motion: str | None
    frames: int
    accel: Comparison | None = None
    gyro: Comparison | None = None
    note: str = ""  # why there is no measurement at all
    seconds: float = 0.0  # what measuring it cost

    def to_dict(self) -> dict:
        return asdict(self)

    def describe(self) -> str:
        if self.accel is None and self.gyro is None:
            return self.note or "no measurement"
        parts = []
        if self.accel is not None:
            a = self.accel
            parts.append(f"the accelerometer reads {a.fraction:.2f} of the IMU acceleration the encoders predict "
                         f"({a.predicted_rms * 1e3:.1f} mm/s^2 RMS; chi2 static - continuous {a.dchi2:+.4g}, "
                         f"separation {a.separation:.4g}, sigma {a.sigma:.3g} m/s^2)")
        if self.gyro is not None:
            g = self.gyro
            parts.append(f"the gyro reads {g.fraction:.2f} of the rate the encoders predict ({g.predicted_rms * 1e3:.1f} "
                         f"mrad/s RMS; chi2 static - continuous {g.dchi2:+.4g})")
            if self.accel is not None and self.accel.verdict and g.verdict and g.verdict != self.accel.verdict:
                parts[-1] += " (the accelerometer decides)"
        return "; ".join(parts)


def measure_motion(kin: LegKinematics, rec: Recording) -> MotionEvidence:
    """How `rec` was logged, from its encoders and IMU (module docstring)."""
    t0 = perf_counter()
    n = rec.n_frames
    time, q = np.asarray(rec.time, dtype=float), np.asarray(rec.q_enc, dtype=float)
    acc, gyro = np.asarray(rec.imu_acc, dtype=float), np.asarray(rec.imu_gyro, dtype=float)
    if n < MIN_FRAMES:
        return MotionEvidence(rec.name, None, n, note=f"{n} frames: too short to tell")
    if q.ndim != 2 or q.shape[1] != kin.legmap.n_joints or acc.shape != (n, 3) or gyro.shape != (n, 3):
        return MotionEvidence(rec.name, None, n, note="arrays do not match the leg map")
    if not (np.isfinite(time).all() and np.isfinite(q).all() and np.isfinite(acc).all() and np.isfinite(gyro).all()):
        return MotionEvidence(rec.name, None, n, note="non-finite samples")
    if not time[-1] > time[0]:
        return MotionEvidence(rec.name, None, n, note="no time span")
    sm = rec.sensor_model
    sigma_q = float(np.hypot(sm.encoder_noise_std, sm.encoder_resolution / np.sqrt(12)))
    dt = (time[-1] - time[0]) / (n - 1)
    fk = frame_kinematics(kin, q)
    legs = ((fk.R_L, fk.p_L, fk.J_L), (fk.R_R, fk.p_R, fk.J_R))
    p_BI = kin.T_BI[:3, 3]

    accel = None
    w = _window(n, dt, IMU_WINDOW_S, IMU_POLYORDER)
    if w is not None and n - 2 * (w // 2) >= MIN_FRAMES:
        keep = slice(w // 2, n - w // 2)  # where the smoothing's full window is (its ends are noisier)
        # The prediction's own noise from the encoders': the IMU's position in each sole
        # frame, p_S = R^T (p_BI - p), moves by -(J_rho + J_theta x p_S) d for angles q + d.
        jp = 0.0
        for R, p, J in legs:
            p_S = np.einsum("nji,nj->ni", R[keep], p_BI - p[keep])
            J_p = J[keep, :3] - np.cross(p_S[:, :, None], J[keep, 3:], axis=1)
            jp += float((J_p**2).sum()) / 4  # each sole carries half
        noise = (sigma_q * _gain(w, IMU_POLYORDER, 2) / dt**2) ** 2 * jp
        accel = _accel_comparison(kin, fk, keep, acc, imu_acceleration(kin, time, q),
                                  float(np.hypot(sm.accel_noise_std, ACC_MODEL_STD)), noise)

    gyro_cmp = None
    w = _window(n, dt, RATE_WINDOW_S, 2)
    keep = slice(w // 2, n - w // 2) if w is not None else slice(1, n - 1)
    if w is None or n - 2 * (w // 2) >= MIN_FRAMES:
        gain = _gain(w, 2, 1) / dt if w is not None else np.sqrt(0.5) / dt  # central differences
        jt = sum(float((J[keep, 3:] ** 2).sum()) for _, _, J in legs) / 4
        rate = _predicted_rate(kin, fk, time)[keep]
        g = gyro[keep]
        gyro_cmp = _compare(g - g.mean(axis=0), rate - rate.mean(axis=0), 3,
                            float(np.hypot(sm.gyro_noise_std, GYRO_MODEL_STD)), (sigma_q * gain) ** 2 * jt)

    motion = accel.verdict if accel is not None else None
    if motion is None and gyro_cmp is not None and gyro_cmp.verdict == STATIC:
        motion = STATIC
    return MotionEvidence(rec.name, motion, n, accel, gyro_cmp, seconds=perf_counter() - t0)


def _window(n: int, dt: float, window_s: float, polyorder: int) -> int | None:
    """The Savitzky-Golay window (samples) `savgol_resampled` uses; None where it gives up."""
    if n < polyorder + 2:
        return None
    w = min(int(round(window_s / dt)) | 1, n if n % 2 else n - 1)
    return w if w > polyorder else None


@lru_cache(maxsize=64)
def _gain(window: int, polyorder: int, deriv: int) -> float:
    """White noise's gain through the Savitzky-Golay filter (unit sample spacing)."""
    return float(np.linalg.norm(savgol_coeffs(window, polyorder, deriv=deriv)))


def _compare(r: np.ndarray, s: np.ndarray, dof_used: int, sigma: float, noise: float) -> Comparison:
    """The comparison of a residual `r` (N, 3), what both hypotheses leave once their
    shared columns are fitted, with the predicted signal `s` (N, 3) projected off the
    same columns; `dof_used` those columns' count, `noise` the predicted signal's own
    expected power from the encoders' declared noise (sum of squares)."""
    r, s = r.ravel(), s.ravel()
    ss = float(s @ s)
    rms = float(np.sqrt(ss / (len(s) // 3)))
    snr = ss / noise if noise > 0 else None
    if not ss > 1e-24 * len(s):  # no predicted motion (below 1e-12 per sample: rounding)
        return Comparison(0.0, 0.0, 0.0, sigma, rms, snr, None)
    k = float(r @ s) / ss
    rss_static, rss_cont = float(r @ r), float((r - s) @ (r - s))
    dof = max(len(r) - dof_used - 1, 1)
    var = max(sigma**2, min(rss_static, rss_cont) / dof)  # no tighter than the better fit's own scatter
    dchi2, sep = (rss_static - rss_cont) / var, ss / var
    verdict = None
    if dchi2 >= MARGIN and abs(k - 1) <= FIT_TOLERANCE:
        verdict = CONTINUOUS
    elif dchi2 <= -MARGIN and abs(k) <= FIT_TOLERANCE and (snr is None or snr >= SNR_MIN):
        verdict = STATIC
    return Comparison(k, float(dchi2), float(sep), float(np.sqrt(var)), rms, snr, verdict)


def _skew(u: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])


def _accel_comparison(kin: LegKinematics, fk, keep: slice, f: np.ndarray, a: np.ndarray, sigma: float,
                      noise: float) -> Comparison:
    """The accelerometer `f` against the predicted acceleration `a` on frames `keep`,
    gravity in each sole frame, the bias and the offsets' first-order tilt fitted."""
    f, a = f[keep], a[keep]
    n = len(f)
    R_IB = kin.R_BI.T
    cols = []
    for R, J in ((fk.R_L[keep], fk.J_L[keep]), (fk.R_R[keep], fk.J_R[keep])):
        A = 0.5 * np.einsum("ij,njk->nik", R_IB, R)  # (N, 3, 3): gravity in this sole frame, read by the IMU
        # Gravity in the sole frame (A carries half of it), for the offsets' columns.
        u = 2.0 * np.einsum("nji,nj->i", A, f) / n
        # A right perturbation of the sole rotation by J_w d turns R u into R (u + J_w d x u).
        cols += [A, -np.matmul(A @ _skew(u), J[:, 3:])]
    cols.append(np.broadcast_to(np.eye(3), (n, 3, 3)))  # the accelerometer's bias
    D = np.concatenate(cols, axis=2).reshape(3 * n, -1)
    U, sv, _ = np.linalg.svd(D, full_matrices=False)
    U = U[:, sv > sv[0] * 1e-9]

    def off(x: np.ndarray) -> np.ndarray:
        x = x.ravel()
        return (x - U @ (U.T @ x)).reshape(n, 3)

    return _compare(off(f), off(a), U.shape[1], sigma, noise)


def _predicted_rate(kin: LegKinematics, fk, time: np.ndarray) -> np.ndarray:
    """(N, 3) the IMU's angular rate (IMU frame) from the encoders, feet fixed: the
    body rate of its orientation in each sole frame, averaged over the two."""
    R_SI = np.stack([np.swapaxes(fk.R_L, 1, 2), np.swapaxes(fk.R_R, 1, 2)], axis=1) @ kin.R_BI  # (N, 2, 3, 3)
    dR = savgol_resampled(time, R_SI, RATE_WINDOW_S, 2, deriv=1)
    if dR is None:  # too few samples per window (a sparse hold-and-log): central differences
        dR = np.gradient(R_SI, time, axis=0)
    W = (np.swapaxes(R_SI, 2, 3) @ dR).sum(axis=1)  # R^T dR/dt = [w]x, summed over the soles
    return 0.25 * np.stack([W[:, 2, 1] - W[:, 1, 2], W[:, 0, 2] - W[:, 2, 0], W[:, 1, 0] - W[:, 0, 1]], axis=1)


def _signal(c: Comparison) -> float:
    """The separation S less its part from the prediction's own noise."""
    return c.separation * (1.0 - 1.0 / c.snr) if c.snr else c.separation


def resolve_motion(kin: LegKinematics, recordings: list[Recording], evidence: dict | None = None
                   ) -> tuple[list[Recording], list[str]]:
    """(copies of `recordings` whose `motion` is resolved, warnings). A conclusive
    measurement is used; it replaces a declaration that says otherwise, with a warning
    giving the numbers. Inconclusive: the declaration is kept, or "continuous" for an
    undeclared recording (a warning only when the predicted acceleration stands out of
    the noise, separation >= `QUIET`). `evidence`, if given, receives each recording's
    `MotionEvidence.to_dict()` with the declared and used motion, by name."""
    out, warnings = [], []
    for r in recordings:
        ev = measure_motion(kin, r)
        declared = r.motion
        if ev.motion is None:
            used = declared or CONTINUOUS
            if declared is None and ev.accel is not None and _signal(ev.accel) >= QUIET:
                warnings.append(Finding(
                    f"{r.name}: motion not declared and the data cannot tell static from continuous "
                    f"({ev.describe()}); taken as continuous (the predicted IMU acceleration is removed): declare "
                    "\"motion\" if you know how it was logged", HARMLESS))
        else:
            used = ev.motion
            if declared is not None and declared != ev.motion:
                warnings.append(Finding(
                    f"{r.name}: motion declared {declared!r}, the data show {ev.motion!r}: {ev.describe()}; "
                    f"used as {ev.motion!r}: fix the declaration (or leave \"motion\" out: it is measured)",
                    HARMLESS))
        if evidence is not None:
            d = ev.to_dict()
            d.pop("seconds")  # a result's diagnostics stay reproducible
            evidence[r.name] = {"declared": declared, "used": used, **d}
        out.append(r if used == declared else replace(r, motion=used))
    return out, warnings
