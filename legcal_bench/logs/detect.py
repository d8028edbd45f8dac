"""Finding static double support in a long log, and what each found segment is.

A frame is in static double support when:
- no stream has a gap there (`align`);
- both soles are still relative to each other: the inter-foot transform from forward
  kinematics of the encoder angles changes slower than `still_speed` / `still_turn`
  (its rate over a `window_s` window). Offsets make that transform wrong by a constant
  plus a few millimetres across postures, never by a rate;
- both feet are loaded: from the ankle F/T (each foot carries at least
  `load_fraction` of the total force) or a contact topic where the robot has them;
  without either, from the flat-ground geometry: the two soles' normals agree within
  `level_rad` and their heights along gravity (the accelerometer's up direction) within
  `height_m` — a foot held up in the air fails that;
- the pelvis is not being swung or jolted: the gyro below `gyro_max` and the specific
  force within `acc_band` of g.
Runs of such frames shorter than `min_duration_s` are left out (double support inside
a gait lasts tenths of a second); `trim_s` is cut from each end of a run.

Each segment is then classified: held still with the knees straight → "standing" (the
straight-leg phase that gives the knee prior), otherwise a "stance". Segments whose
inter-foot transforms agree (same foot placement) get one stance label (S1, S2, ...).
Every frame not taken carries the first reason it was refused, for the timeline.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from legcal_bench.errors import LogImportError
from legcal_bench.logs.align import Aligned
from legcal_bench.logs.mapping import Detection
from legcal_bench.robots.kinematics import LegKinematics

G = 9.81
# Reasons a frame was not taken, in the order they are checked (the first that applies is shown).
REASONS = {
    "gap": "a gap in a stream",
    "unloaded": "one foot unloaded (single support, a step)",
    "not_flat": "soles not level or not at one height (a foot lifted)",
    "feet_moving": "the feet move relative to each other",
    "imu_motion": "the pelvis swings or jolts (gyro / accelerometer)",
    "short": "still, but shorter than the minimum duration",
    "trim": "settling at a segment's ends (trimmed)",
    "spread": "the feet crept during the run (inter-foot spread too large)",
    "excluded": "outside the user's time ranges",
}
KNEE_STRAIGHT_TOL_RAD = 0.1  # a held posture whose knees read within this of straight is the standing phase
RANGE_SLACK_S = 1e-6  # a user's range includes frames stamped this close outside it (stamps in ns, ranges in s)


@dataclass
class Segment:
    name: str
    kind: str  # standing | stance | heldout
    stance: str  # "standing" or S1, S2, ...
    start: int  # frame index, inclusive
    stop: int  # exclusive
    t0: float
    t1: float
    posture_range_m: float
    posture_range_rad: float
    spread_m: float
    reason: str = ""  # how it was found ("detected" or "user range")

    @property
    def frames(self) -> int:
        return self.stop - self.start

    def to_dict(self) -> dict:
        return {"name": self.name, "kind": self.kind, "stance": self.stance, "t0": self.t0, "t1": self.t1,
                "frames": self.frames, "posture_range_m": self.posture_range_m,
                "posture_range_rad": self.posture_range_rad, "spread_m": self.spread_m, "found_by": self.reason}


@dataclass
class Detected:
    segments: list[Segment]
    reason: np.ndarray  # (N,) str: "" for taken frames, else a key of REASONS
    traces: dict  # per-frame signals for the timeline: speed, turn, load, height, tilt, gyro


def _window_rate(t: np.ndarray, x: np.ndarray, w: float, diff) -> np.ndarray:
    """|x(t + w/2) - x(t - w/2)| / span per frame (nearest frames), with `diff` the
    difference of two stacks of samples."""
    a = np.searchsorted(t, t - w / 2, side="left")
    b = np.clip(np.searchsorted(t, t + w / 2, side="right") - 1, 0, len(t) - 1)
    span = np.maximum(t[b] - t[a], 1e-9)
    return diff(x[b], x[a]) / span


def _angle(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    c = (np.einsum("nij,nij->n", Ra, Rb) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def _smooth(t: np.ndarray, x: np.ndarray, w: float) -> np.ndarray:
    """Mean over a window of `w` seconds (cumulative sums; x (N, k))."""
    a = np.searchsorted(t, t - w / 2, side="left")
    b = np.searchsorted(t, t + w / 2, side="right")
    c = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    return (c[b] - c[a]) / (b - a)[:, None]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def frame_signals(a: Aligned, kin: LegKinematics, det: Detection) -> dict:
    """Per-frame quantities the detection thresholds: the inter-foot transform's rates,
    the feet's loads or the flat-ground geometry, and the IMU's motion."""
    t = a.time
    TL, TR = kin.sole_poses_batch(kin.joint_angles(a.q_enc))
    C = np.linalg.inv(TL) @ TR
    p, R = C[:, :3, 3], C[:, :3, :3]
    speed = _window_rate(t, p, det.window_s, lambda x, y: np.linalg.norm(x - y, axis=1))
    turn = _window_rate(t, R, det.window_s, _angle)
    acc = _smooth(t, a.imu_acc, det.window_s)
    gyro = np.linalg.norm(_smooth(t, a.imu_gyro, det.window_s), axis=1)
    up_B = acc @ kin.R_BI.T  # the specific force at rest points up; in the pelvis frame
    up_B /= np.maximum(np.linalg.norm(up_B, axis=1, keepdims=True), 1e-9)
    # Angle between the two soles' normals (a toe-out turns the soles about the normal: not counted).
    tilt = np.arccos(np.clip(np.einsum("ni,ni->n", TL[:, :3, 2], TR[:, :3, 2]), -1.0, 1.0))
    height = np.einsum("ni,ni->n", TR[:, :3, 3] - TL[:, :3, 3], up_B)
    out = {"time": t, "speed": speed, "turn": turn, "gyro": gyro, "acc_dev": np.abs(np.linalg.norm(acc, axis=1) - G),
           "tilt": tilt, "height": height, "p_interfoot": p, "T_left": TL}
    if a.ft is not None:
        f = np.linalg.norm(a.ft[:, :, :3], axis=2)
        out["load"] = f / np.maximum(f.sum(axis=1, keepdims=True), 1e-9)
    if a.contact is not None:
        out["contact"] = a.contact
    return out


def refusals(s: dict, a: Aligned, det: Detection) -> np.ndarray:
    """(N,) the first reason each frame is not static double support ("" if it is)."""
    n = len(a.time)
    reason = np.full(n, "", dtype=object)

    def mark(mask, key):
        reason[(reason == "") & mask] = key

    mark(~a.valid, "gap")
    if "load" in s:
        mark(s["load"].min(axis=1) < det.load_fraction, "unloaded")
    elif "contact" in s:
        mark(~s["contact"].all(axis=1), "unloaded")
    else:
        mark((s["tilt"] > det.level_rad) | (np.abs(s["height"]) > det.height_m), "not_flat")
    mark((s["speed"] > det.still_speed) | (s["turn"] > det.still_turn), "feet_moving")
    mark((s["gyro"] > det.gyro_max) | (s["acc_dev"] > det.acc_band), "imu_motion")
    return reason


def _posture_range(TL: np.ndarray) -> tuple[float, float]:
    """How far the pelvis moves over a segment (the left sole's poses in the pelvis frame, (N, 4, 4))."""
    T = np.linalg.inv(TL)  # the pelvis in the left sole's frame
    ang = _angle(T[:, :3, :3], np.broadcast_to(T[len(T) // 2, :3, :3], T[:, :3, :3].shape))
    return _spread(T[:, :3, 3]), float(np.percentile(ang, 95) * 2)


def _spread(p: np.ndarray) -> float:
    lo, hi = np.percentile(p, [5, 95], axis=0)
    return float(np.linalg.norm(hi - lo))


def detect(a: Aligned, kin: LegKinematics, det: Detection, knee_idx: list[int], knee_straight: float,
           ranges: list[tuple[float, float]] | None = None) -> Detected:
    """The static double-support segments of an aligned log. With `ranges` (seconds from
    the log's start), those time ranges are the segments (frames in gaps still left
    out), and the checks only inform."""
    s = frame_signals(a, kin, det)
    reason = refusals(s, a, det)
    t = a.time
    candidates = []
    if ranges:
        inside = np.zeros(len(t), bool)
        for t0, t1 in ranges:  # each range is its own segment (split where a stream has a gap)
            m = (t >= t0 - RANGE_SLACK_S) & (t <= t1 + RANGE_SLACK_S)
            if not m.any():
                raise LogImportError(f"--ranges {t0:g}:{t1:g}: no frame of the log in that range (the log spans "
                                     f"0-{t[-1]:.1f} s)")
            if (inside & m).any():
                raise LogImportError(f"--ranges {t0:g}:{t1:g} overlaps another range: give disjoint ranges")
            inside |= m
            candidates += [(i, j, "user range") for i, j in _runs(m & a.valid)]
        reason = np.where(inside, np.where(a.valid, "", "gap"), "excluded").astype(object)
    else:
        for i, j in _runs(reason == ""):
            if t[j - 1] - t[i] < det.min_duration_s:
                reason[i:j] = "short"
                continue
            k0 = np.searchsorted(t, t[i] + det.trim_s)
            k1 = np.searchsorted(t, t[j - 1] - det.trim_s, side="right")
            reason[i:k0] = "trim"
            reason[k1:j] = "trim"
            if _spread(s["p_interfoot"][k0:k1]) > det.spread_m:
                reason[k0:k1] = "spread"
                continue
            candidates.append((k0, k1, "detected"))
    segments = []
    for i, j, how in candidates:
        q = a.q_enc[i:j]
        pm, pr = _posture_range(s["T_left"][i:j])
        held = pm < det.posture_m and pr < det.posture_rad
        straight = knee_idx and np.abs(np.median(q[:, knee_idx], axis=0) - knee_straight).max() < KNEE_STRAIGHT_TOL_RAD
        kind = "standing" if held and straight else "stance"
        segments.append(Segment("", kind, "standing" if kind == "standing" else "", int(i), int(j), float(t[i]),
                                float(t[j - 1]), pm, pr, _spread(s["p_interfoot"][i:j]), how))
    _label(segments, s["p_interfoot"], a.q_enc, kin, det)
    return Detected(segments, reason, s)


def _label(segments: list[Segment], p: np.ndarray, q: np.ndarray, kin: LegKinematics, det: Detection) -> None:
    """Stance labels by foot placement (the median inter-foot transform), names by order."""
    placements: list[tuple[np.ndarray, np.ndarray]] = []
    counts: dict[str, int] = {}
    for seg in segments:
        if seg.kind == "stance":
            qm = np.median(q[seg.start:seg.stop], axis=0)
            TL, TR = kin.sole_poses_batch(kin.joint_angles(qm[None]))
            C = np.linalg.inv(TL[0]) @ TR[0]
            for k, (pc, Rc) in enumerate(placements):
                if (np.linalg.norm(C[:3, 3] - pc) < det.cluster_m
                        and _angle(C[None, :3, :3], Rc[None])[0] < det.cluster_rad):
                    seg.stance = f"S{k + 1}"
                    break
            else:
                placements.append((C[:3, 3], C[:3, :3]))
                seg.stance = f"S{len(placements)}"
        base = "standing" if seg.kind == "standing" else f"stance_{seg.stance}"
        counts[base] = counts.get(base, 0) + 1
        seg.name = base if counts[base] == 1 else f"{base}_{counts[base]}"
