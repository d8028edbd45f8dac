"""Streams at their own rates, with jitter and gaps, onto one clock.

The clock is the joint states' own stamps (`clock: joints`, the default: encoder
angles are never interpolated) or a uniform grid at a given rate. Every other stream is
interpolated linearly at the clock's times. A frame is kept only where every stream has
samples on both sides no farther apart than the gap tolerance: a longer gap in any
stream drops the frames inside it, which splits a segment there, and is reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from legcal_bench.errors import LogImportError
from legcal_bench.logs.mapping import SIDES, LogMapping
from legcal_bench.logs.read import Streams


@dataclass
class Aligned:
    time: np.ndarray  # (N,) s from the log's first stamp
    q_enc: np.ndarray  # (N, n) rad
    imu_acc: np.ndarray  # (N, 3)
    imu_gyro: np.ndarray  # (N, 3)
    ft: np.ndarray | None  # (N, 2, 6) or None
    contact: np.ndarray | None  # (N, 2) bool or None
    valid: np.ndarray  # (N,) bool: False inside a gap of some stream
    gaps: list[dict] = field(default_factory=list)  # {stream, t0, t1, seconds}
    stats: dict = field(default_factory=dict)  # stream -> {samples, rate_hz, jitter_ms, duplicates}


def _clean(name: str, t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Sorted by time, repeated stamps dropped (the first kept): (t, v, dropped)."""
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    keep = np.ones(len(t), bool)
    keep[1:] = np.diff(t) > 0
    if not np.isfinite(v[keep]).all():
        bad = int((~np.isfinite(v[keep]).all(axis=1)).sum())
        raise LogImportError(f"stream '{name}': {bad} sample(s) hold NaN or inf; drop them from the log")
    return t[keep], v[keep], int((~keep).sum())


DROP_FACTOR = 1.5  # an interval this many times the stream's median period is a dropped message (or more)
MAX_LISTED = 20  # dropped-message intervals listed per stream (the count is always whole)


def _stats(t: np.ndarray, duplicates: int) -> dict:
    """Rate (from the median period), jitter (the periods' spread, dropped messages
    left out), repeated stamps, and the intervals where messages were dropped."""
    dt = np.diff(t)
    med = float(np.median(dt)) if dt.size else float("nan")
    late = np.flatnonzero(dt > DROP_FACTOR * med) if dt.size else np.zeros(0, int)
    regular = np.delete(dt, late)
    return {"samples": int(t.size), "rate_hz": 1.0 / med if dt.size and med > 0 else 0.0,
            "jitter_ms": float(np.std(regular) * 1e3) if regular.size else 0.0, "duplicates": duplicates,
            "dropped_count": int(late.size),
            "dropped": [{"t0": float(t[i]), "t1": float(t[i + 1]), "missing": int(round(dt[i] / med)) - 1}
                        for i in late[:MAX_LISTED]]}


def align(streams: Streams, mapping: LogMapping) -> Aligned:
    tol = mapping.gap_tolerance_s
    named = streams.named()
    clean, stats = {}, {}
    for name, (t, v) in named.items():
        t, v, dropped = _clean(name, np.asarray(t, float), np.asarray(v, float))
        if t.size < 2:
            raise LogImportError(f"stream '{name}' ({streams.sources.get(name, '')}) has {t.size} sample(s): "
                                 "nothing to calibrate from")
        clean[name] = (t, v)
        stats[name] = _stats(t, dropped)
    tj, qj = clean["joints"]
    if mapping.clock == "joints":
        clock = tj
    else:
        clock = np.arange(tj[0], tj[-1], 1.0 / float(mapping.clock))
    valid = np.ones(clock.size, bool)
    jump = np.flatnonzero(np.diff(clock) > tol)  # the clock's own gaps: both frames beside one are left out
    valid[jump] = valid[jump + 1] = False
    gaps = []
    out = {}
    for name, (t, v) in clean.items():
        # Frames outside the stream's span, or between two samples farther apart than tol, are invalid.
        k = np.searchsorted(t, clock, side="right")  # t[k-1] <= clock < t[k]
        inside = (k > 0) & (k < t.size)
        kk = np.clip(k, 1, t.size - 1)
        exact = (k > 0) & (t[np.clip(k - 1, 0, t.size - 1)] == clock)
        span = t[kk] - t[kk - 1]
        ok = exact | (inside & (span <= tol))
        valid &= ok
        if name == "joints" and mapping.clock == "joints":
            out[name] = v
        else:
            out[name] = np.column_stack([np.interp(clock, t, v[:, c]) for c in range(v.shape[1])])
        big = np.flatnonzero(np.diff(t) > tol)
        gaps += [{"stream": name, "t0": float(t[i]), "t1": float(t[i + 1]), "seconds": float(t[i + 1] - t[i])}
                 for i in big]
    ft = None
    if streams.ft:
        ft = np.stack([out[f"ft_{s}"] for s in SIDES], axis=1)
    contact = None
    if streams.contact:
        contact = np.stack([out[f"contact_{s}"][:, 0] > mapping.contact_threshold for s in SIDES], axis=1)
    imu = out["imu"]
    gaps.sort(key=lambda g: g["t0"])
    return Aligned(time=clock, q_enc=out["joints"], imu_acc=imu[:, :3], imu_gyro=imu[:, 3:], ft=ft, contact=contact,
                   valid=valid, gaps=gaps, stats=stats)
