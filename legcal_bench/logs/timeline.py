"""The import's timeline: what was taken, and why the rest was not (text and plot)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from legcal_bench.files.plots import pyplot, save_figure
from legcal_bench.logs.detect import REASONS, Detected, _runs

MERGE_S = 0.2  # refusals shorter than this are folded into their neighbour in the text


def intervals(time: np.ndarray, found: Detected) -> list[dict]:
    """The timeline as consecutive intervals: {t0, t1, taken, segment, kind, reason}."""
    label = np.array(found.reason, dtype=object)
    for s in found.segments:
        label[s.start:s.stop] = "@" + s.name
    kinds = {s.name: s.kind for s in found.segments}
    out = []
    i, n = 0, len(time)
    while i < n:
        j = i + 1
        while j < n and label[j] == label[i]:
            j += 1
        lab = label[i]
        taken = lab.startswith("@")
        out.append({"t0": float(time[i]), "t1": float(time[j - 1]), "taken": taken,
                    "segment": lab[1:] if taken else None, "kind": kinds.get(lab[1:]) if taken else None,
                    "reason": "" if taken else REASONS.get(lab, lab)})
        i = j
    merged: list[dict] = []
    for iv in out:  # fold flickers of refusal reasons into the previous refused interval
        if (merged and not iv["taken"] and not merged[-1]["taken"]
                and (iv["t1"] - iv["t0"] < MERGE_S or iv["reason"] == merged[-1]["reason"])):
            merged[-1]["t1"] = iv["t1"]
            continue
        merged.append(dict(iv))
    return merged


def format_timeline(summary) -> str:
    lines = [f"{summary.robot}: {summary.duration_s:.1f} s, {summary.frames} frames on one clock"]
    for name, st in summary.streams.items():
        lines.append(f"  stream {name:<14} {st['samples']:>8} samples  {st['rate_hz']:8.1f} Hz  jitter "
                     f"{st['jitter_ms']:.2f} ms  ({st['from']})")
    lines.append("timeline (s):")
    for iv in summary.intervals:
        what = f"TAKEN  {iv['segment']} ({iv['kind']})" if iv["taken"] else f"-      {iv['reason']}"
        lines.append(f"  {iv['t0']:8.2f} - {iv['t1']:8.2f}  {what}")
    lines.append(f"segments: {len(summary.segments)}")
    for s in summary.segments:
        lines.append(f"  {s['name']:<14} {s['kind']:<9} {s['stance']:<9} {s['t0']:7.2f}-{s['t1']:7.2f} s "
                     f"{s['frames']:>6} frames  pelvis moves {s['posture_range_m'] * 1e3:5.1f} mm / "
                     f"{np.rad2deg(s['posture_range_rad']):4.1f} deg  motion {s.get('motion') or 'unclear'}  "
                     f"({s['found_by']})")
    for w in summary.warnings:
        lines.append(f"warning: {w}")
    return "\n".join(lines)


_COLORS = {"gap": "#000000", "unloaded": "#d62728", "not_flat": "#ff7f0e", "feet_moving": "#9467bd",
           "imu_motion": "#8c564b", "short": "#bcbd22", "trim": "#c7c7c7", "spread": "#e377c2",
           "excluded": "#dddddd"}
_KIND_COLORS = {"standing": "#1f77b4", "stance": "#2ca02c", "heldout": "#17becf"}


def plot_timeline(found: Detected, aligned, path: Path, title: str, spans: list[dict] | None = None) -> Path:
    """The timeline's figure; `spans`: `intervals(aligned.time, found)` if already made."""
    plt = pyplot()
    s, t = found.traces, aligned.time
    step = max(1, len(t) // 4000)  # enough points for the eye
    panels = 4
    fig, ax = plt.subplots(panels, 1, figsize=(11, 8), sharex=True,
                           gridspec_kw={"height_ratios": [1, 1, 1, 0.6]})
    ax[0].semilogy(t[::step], np.maximum(s["speed"][::step], 1e-5), lw=0.8, label="inter-foot speed (m/s)")
    ax[0].semilogy(t[::step], np.maximum(s["turn"][::step], 1e-5), lw=0.8, label="inter-foot turn rate (rad/s)")
    ax[0].set_ylabel("feet relative\nmotion")
    ax[0].legend(loc="upper right", fontsize=7)
    if "load" in s:
        ax[1].plot(t[::step], s["load"][::step, 0], lw=0.8, label="left foot's share of force")
        ax[1].plot(t[::step], s["load"][::step, 1], lw=0.8, label="right foot's share")
        ax[1].set_ylabel("F/T load share")
    elif "contact" in s:
        ax[1].plot(t[::step], s["contact"][::step].astype(float) + [0, 0.05], lw=0.8)
        ax[1].set_ylabel("contact")
    else:
        ax[1].plot(t[::step], s["height"][::step] * 1e3, lw=0.8, label="right sole above left, along gravity (mm)")
        ax[1].plot(t[::step], np.rad2deg(s["tilt"][::step]) * 10, lw=0.8, label="angle between soles (0.1 deg)")
        ax[1].set_ylabel("flat ground\n(no F/T)")
    ax[1].legend(loc="upper right", fontsize=7)
    ax[2].plot(t[::step], s["gyro"][::step], lw=0.8, label="|gyro| (rad/s)")
    ax[2].plot(t[::step], s["acc_dev"][::step], lw=0.8, label="| |f| - g | (m/s^2)")
    ax[2].set_ylabel("pelvis IMU")
    ax[2].legend(loc="upper right", fontsize=7)
    for iv in spans if spans is not None else intervals(t, found):
        if iv["taken"]:
            c = _KIND_COLORS.get(iv["kind"], "#2ca02c")
            ax[3].axvspan(iv["t0"], iv["t1"], color=c, lw=0)
            ax[3].text((iv["t0"] + iv["t1"]) / 2, 0.5, iv["segment"], ha="center", va="center", fontsize=7,
                       rotation=90, color="white")
            for a in ax[:3]:
                a.axvspan(iv["t0"], iv["t1"], color=c, alpha=0.12, lw=0)
    for key, color in _COLORS.items():
        m = found.reason == key
        if m.any():
            for i, j in _runs(m):
                ax[3].axvspan(t[i], t[j - 1], ymin=0.0, ymax=0.35, color=color, lw=0)
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in _KIND_COLORS.values()]
    names = list(_KIND_COLORS)
    for key, color in _COLORS.items():
        if (found.reason == key).any():
            handles.append(plt.Rectangle((0, 0), 1, 1, color=color))
            names.append(REASONS[key])
    ax[3].set_yticks([])
    ax[3].set_ylabel("taken")
    ax[3].set_xlabel("time from the log's start (s)")
    fig.legend(handles, names, loc="lower center", ncol=3, fontsize=7, frameon=False)
    fig.suptitle(title[:110], fontsize=10)
    fig.tight_layout(rect=(0, 0.08, 1, 0.97))
    return save_figure(fig, path)

