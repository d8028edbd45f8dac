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

from legcal_bench.data.recording import MAX_RATE_HZ, MIN_RATE_HZ
from legcal_bench.errors import LogImportError
from legcal_bench.logs.mapping import MAX_FRAMES, SIDES, TIME_UNITS, LogMapping, too_many
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


def _table(mapping: LogMapping) -> bool:
    return mapping.joints.topic is None


def _too_few(name: str, given: int, t: np.ndarray, streams: Streams, mapping: LogMapping) -> str:
    """Why a stream has fewer than two distinct stamps: none or one message, or stamps never set."""
    where = f"stream '{name}' ({streams.sources.get(name, '')})"
    if given < 2:
        return f"{where} has {given} sample(s): nothing to calibrate from"
    stamp_ns = streams.t0_ns + int(round(float(t[0]) * 1e9))
    if _table(mapping):
        return (f"{where}: its {given} rows all carry one time, {stamp_ns * 1e-9:.9g} s, in column "
                f"{mapping.time_column!r}: field 'time.column' must name a column of times, one per row")
    if mapping.time_source == "header":
        what = "all zero: the logger never set header.stamp" if stamp_ns == 0 else f"all {stamp_ns} ns"
        return (f"{where}: its {given} messages carry one header stamp ({what}), so they are one instant: with "
                f"field 'time_source' header the stamps are the messages' header.stamp; use `time_source: "
                f"receive` in {mapping.path} (the bag's receive times)")
    return (f"{where}: its {given} messages were all received at one instant ({stamp_ns} ns): the bag's receive "
            f"times are not usable; use `time_source: header` in {mapping.path} if the messages carry stamps")


def _plausible_rate(name: str, t: np.ndarray, rate: float, streams: Streams, mapping: LogMapping) -> None:
    """A robot's encoders and IMU log at MIN_RATE_HZ-MAX_RATE_HZ (the recordings' range): a
    stream far slower is stamped in the wrong unit (milliseconds read as seconds: 1000 times
    too long); joints far faster, with `clock: joints`, give recordings no calibration takes."""
    span = float(t[-1] - t[0])
    unit = (f"field 'time.unit' is {next(k for k, v in TIME_UNITS.items() if v == mapping.time_scale)!r}: if "
            f"column {mapping.time_column!r} holds another unit (s, ms, us, ns), give that one"
            if _table(mapping) else
            f"field 'time_source' is {mapping.time_source!r}: the stamps must be seconds and nanoseconds (try "
            "`time_source: " + ("receive" if mapping.time_source == "header" else "header") + "`)")
    where = f"stream '{name}' ({streams.sources.get(name, '')})"
    if rate < MIN_RATE_HZ:
        raise LogImportError(
            f"{where}: {t.size} samples over {span:.6g} s, one every {1 / rate:.3g} s ({rate:.3g} Hz): the log is "
            f"implausibly long for its sample count (a robot's {name} log at {MIN_RATE_HZ:g}-{MAX_RATE_HZ:g} Hz), so "
            f"its times are likely not in seconds; {unit}")
    if name == "joints" and mapping.clock == "joints" and rate >= MAX_RATE_HZ:
        raise LogImportError(
            f"{where}: {t.size} samples over {span:.6g} s ({rate:.4g} Hz), faster than the {MAX_RATE_HZ:g} Hz a "
            f"recording takes, with field 'clock' joints (one frame per message): if the log is that fast, give "
            f"`clock: 1000` (or lower) in {mapping.path}; if not, its times are not in seconds: {unit}")


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
        given = len(t)
        t, v, dropped = _clean(name, np.asarray(t, float), np.asarray(v, float))
        if t.size < 2:
            raise LogImportError(_too_few(name, given, t, streams, mapping))
        clean[name] = (t, v)
        stats[name] = _stats(t, dropped)
        if name in ("joints", "imu"):
            _plausible_rate(name, t, stats[name]["rate_hz"], streams, mapping)
    tj, qj = clean["joints"]
    if mapping.clock == "joints":
        clock = tj
    else:
        n = int((tj[-1] - tj[0]) * float(mapping.clock)) + 1
        if n > MAX_FRAMES:
            raise too_many(n, f"{mapping.path}: field 'clock' {mapping.clock:g} Hz over the log's "
                           f"{tj[-1] - tj[0]:.1f} s", "give a lower rate, or cut the log into parts")
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
