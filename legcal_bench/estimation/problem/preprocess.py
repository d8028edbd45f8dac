"""Frame selection before the inter-foot solve (the paper's Data Preprocessing).

Per contact segment, on the raw encoders (filtering is not repeated after correction):
  0. beyond the paper, IMU motion compensation (`imu="compensated"`, the default): the
     IMU's acceleration predicted from the leg angles is removed from the accelerometer
     (`legcal_bench.estimation.imu.imu_motion`) in recordings logged while moving (not in
     those declared `motion: static`); `imu="raw"` is the paper's setting;
  1. drop frames with a non-finite value;
  2. gyro guard: drop frames whose IMU rate exceeds 0.5 rad/s; beyond the paper, an
     accelerometer guard: drop frames whose specific force is not within 50 % of g
     (a static robot reads g; 0 is a dropped sample, and has no direction);
  3. contact-consistency filter: the local mean of the inter-foot transform over a 2.5 s
     window; drop frames whose rotation residual exceeds 5 deg (the paper's local mean
     is a Frechet mean; ours is a median in its Log coordinates, robust to glitches);
  beyond the paper, because a rotation-only filter misses them:
  4. translation residual against the same local mean above 5 mm (a foot sliding
     without rotating);
  5. a sudden slip splits the segment: a frame-to-frame jump of the inter-foot
     translation above max(1 mm, 10x the segment's median step) starts a new contact
     segment (each keeps its own mean); pieces shorter than `min_frames` are dropped;
  6. joint-angle clustering (k-means on the leg joints' encoder angles) and subsampling
     to at most N_max = 500 distinct configurations per segment.
The largest-residual trimming (10 %) happens after the first solve, in the calibrator.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.cluster.vq import kmeans2
from scipy.spatial import cKDTree

from legcal_bench.estimation.imu.imu_motion import IMU_WINDOW_S, compensate
from legcal_bench.geometry.lie import Exp, Log, frechet_mean, inverse
from legcal_bench.paper import (GYRO_GUARD_RAD_S, LOCAL_MEAN_WINDOW_S, N_MAX_PER_STANCE,
                                ROTATION_RESIDUAL_MAX_DEG)
from legcal_bench.estimation.verdict import HARMLESS, LIMITS, Finding
from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics


@dataclass
class PreprocessConfig:
    gyro_max: float = GYRO_GUARD_RAD_S  # rad/s
    accel_band: tuple[float, float] = (0.5 * 9.81, 1.5 * 9.81)  # m/s^2, |specific force| of a static IMU
    window_s: float = LOCAL_MEAN_WINDOW_S
    max_rotation_residual: float = np.deg2rad(ROTATION_RESIDUAL_MAX_DEG)
    max_translation_residual: float = 0.005  # m
    slip_jump_min: float = 0.001  # m
    slip_jump_factor: float = 10.0
    n_max: int = N_MAX_PER_STANCE
    min_frames: int = 30
    imu: str = "compensated"  # or "raw" (the paper's)
    imu_window_s: float = IMU_WINDOW_S


@dataclass
class Segment:
    """Frames of one contact segment chosen for the solve."""

    name: str
    q_enc: np.ndarray  # (N, n), n the leg joints
    imu_acc: np.ndarray  # (N, 3)
    frames: np.ndarray  # indices into the source recording


GYRO_UNITS_SHARE = 0.5  # the gyro guard dropping this share of a stance's frames or more: its units are asked about


@dataclass
class FilterReport:
    name: str
    raw: int
    non_finite: int = 0
    gyro: int = 0
    accel: int = 0
    rotation: int = 0
    translation: int = 0
    slip_splits: int = 0
    short_pieces: int = 0
    clustered_out: int = 0
    kept: int = 0
    pieces: list[str] = field(default_factory=list)

    def text(self) -> str:
        units = ""
        if self.raw and self.gyro >= GYRO_UNITS_SHARE * self.raw:  # a static stance turning fast throughout
            units = (f" (the IMU's rate is above the {GYRO_GUARD_RAD_S:g} rad/s guard in most frames of a static "
                     "stance: is imu_gyro in deg/s? It must be rad/s, numpy.deg2rad)")
        return (f"{self.raw} raw, {self.non_finite} non-finite, {self.gyro} gyro > guard{units}, {self.accel} "
                f"accelerometer off g, {self.rotation} rotation residual, {self.translation} translation residual, "
                f"{self.slip_splits} slip split(s), {self.short_pieces} in short pieces, {self.clustered_out} "
                f"clustered out, {self.kept} kept")


def filter_warnings(reports: list[FilterReport]) -> list[str]:
    """One warning per stance whose frames the filter removed or skipped (any calibrator
    using `select_frames`)."""
    out = []
    for rep in reports:
        if rep.kept == 0:
            out.append(Finding(f"{rep.name}: no usable frames left ({rep.text()}); segment skipped", LIMITS))
        elif rep.non_finite + rep.accel + rep.rotation + rep.translation + rep.slip_splits + rep.short_pieces:
            out.append(Finding(f"{rep.name}: contact filter removed frames ({rep.text()})", HARMLESS))
    return out


def _local_residuals(C: np.ndarray, times: np.ndarray, window_s: float) -> np.ndarray:
    """Log(C_local^-1 C_k) with C_local the local mean of C over [t_k - w/2, t_k + w/2].

    The local mean is the component-wise median of the Log coordinates about the
    segment's Frechet mean, so a short glitch moves it by nothing (a moving average let
    a 5-frame glitch push 127 of 300 frames over the thresholds). Medians are taken at
    centres w/25 apart (or every frame, if sparser) and interpolated between them: the
    local mean changes on the scale of the window, and this keeps the cost O(N w / 25)."""
    M = frechet_mean(C, tol=1e-12)
    tau = Log(inverse(M) @ C)
    step = window_s / 25
    n_centres = int(np.floor((times[-1] - times[0]) / step)) + 1
    if n_centres >= len(times):
        centres = times
    else:
        centres = np.append(times[0] + step * np.arange(n_centres), times[-1])
    lo = np.searchsorted(times, centres - window_s / 2, side="left")
    hi = np.searchsorted(times, centres + window_s / 2, side="right")
    med = np.empty((len(lo), 6))
    width = hi - lo
    for w in np.unique(width):  # windows of one width at once (all but those at the ends)
        at = np.flatnonzero(width == w)
        med[at] = np.median(tau[lo[at, None] + np.arange(w)], axis=1)
    if centres is not times:
        med = np.column_stack([np.interp(times, centres, med[:, i]) for i in range(6)])
    local = M @ Exp(med)
    return Log(inverse(local) @ C)


def select_frames(kin: LegKinematics, name: str, time: np.ndarray, q_enc: np.ndarray, imu_acc: np.ndarray,
                  imu_gyro: np.ndarray, cfg: PreprocessConfig, motion: str = "continuous"
                  ) -> tuple[list[Segment], FilterReport]:
    """The frames of one recording chosen for the solve. `motion` is the recording's:
    frames logged at rest ("static") need no IMU motion compensation."""
    rep = FilterReport(name=name, raw=len(time))
    if cfg.imu == "compensated" and motion == "continuous":
        imu_acc = compensate(kin, time, q_enc, imu_acc, cfg.imu_window_s)
    idx = np.arange(len(time))
    finite = np.all(np.isfinite(q_enc), axis=1) & np.all(np.isfinite(imu_acc), axis=1) & np.all(
        np.isfinite(imu_gyro), axis=1)
    rep.non_finite = int((~finite).sum())
    idx = idx[finite]
    still = np.linalg.norm(imu_gyro[idx], axis=1) <= cfg.gyro_max
    rep.gyro = int((~still).sum())
    idx = idx[still]
    f = np.linalg.norm(imu_acc[idx], axis=1)
    level = (f >= cfg.accel_band[0]) & (f <= cfg.accel_band[1])
    rep.accel = int((~level).sum())
    idx = idx[level]
    if len(idx) < cfg.min_frames:
        return [], rep
    C = frame_kinematics(kin, q_enc[idx]).C
    res = _local_residuals(C, time[idx], cfg.window_s)
    rot_bad = np.linalg.norm(res[:, 3:], axis=1) > cfg.max_rotation_residual
    trans_bad = (np.linalg.norm(res[:, :3], axis=1) > cfg.max_translation_residual) & ~rot_bad
    rep.rotation, rep.translation = int(rot_bad.sum()), int(trans_bad.sum())
    ok = ~(rot_bad | trans_bad)
    idx, C = idx[ok], C[ok]
    # Sudden slips: jumps in the inter-foot translation between consecutive kept frames.
    pieces = [idx]
    if len(idx) > 2:
        trans = C[:, :3, 3]
        step = np.linalg.norm(np.diff(trans, axis=0), axis=1)
        thresh = max(cfg.slip_jump_min, cfg.slip_jump_factor * float(np.median(step)))
        cuts = np.flatnonzero(step > thresh) + 1
        rep.slip_splits = len(cuts)
        pieces = np.split(idx, cuts)
    segments = []
    for p_i, piece in enumerate(pieces):
        if len(piece) < cfg.min_frames:
            rep.short_pieces += len(piece)
            continue
        chosen = _cluster(q_enc[piece], cfg.n_max)
        rep.clustered_out += len(piece) - len(chosen)
        frames = piece[chosen]
        seg_name = name if len(pieces) == 1 else f"{name}#{p_i + 1}"
        segments.append(Segment(seg_name, q_enc[frames], imu_acc[frames], frames))
        rep.pieces.append(seg_name)
    rep.kept = sum(len(s.frames) for s in segments)
    return segments, rep


def _cluster(Q: np.ndarray, n_max: int) -> np.ndarray:
    """Indices of at most n_max distinct configurations: the frame nearest each k-means
    centroid in joint space (deterministic seed)."""
    if len(Q) <= n_max:
        return np.arange(len(Q))
    centroids, _ = kmeans2(Q, n_max, seed=0, minit="points")
    return np.unique(nearest_rows(Q, centroids))


def nearest_rows(Q: np.ndarray, points: np.ndarray) -> np.ndarray:
    """For each of `points`, the index of the nearest row of `Q` (the first on a tie of
    the squared distance sum((q - p)^2)): a k-d tree finds the candidates, every row
    within 1e-9 relative of its distance (duplicate frames, ties) is compared exactly."""
    tree = cKDTree(Q)
    dist, nearest = tree.query(points)
    for i, ball in enumerate(tree.query_ball_point(points, dist * (1 + 1e-9))):
        if len(ball) > 1:
            ball = np.sort(ball)
            nearest[i] = ball[np.argmin(((Q[ball] - points[i]) ** 2).sum(-1))]
    return nearest
