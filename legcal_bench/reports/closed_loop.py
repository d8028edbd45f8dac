"""The closed-loop evaluation's report: a markdown table beside the paper's numbers,
the JSON it was made from, and a plot of the pelvis paths."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from legcal_bench.evaluation.closed_loop import CONDITIONS
from legcal_bench.evaluation.metrics import format_mean_std
from legcal_bench.files.plots import pyplot, save_figure
from legcal_bench.files.reports import write_report
from legcal_bench.paper import (CLOSED_LOOP_FOOT_STRIKE_MM, CLOSED_LOOP_OFFSET_DEG, CLOSED_LOOP_PELVIS_MM,
                                CLOSED_LOOP_TRIALS, LIDAR_RMS_MM, LIDAR_VERTICAL_DRIFT_M_PER_DEG)

COLOURS = {"nominal": "black", "uncorrected": "tab:red", "corrected": "tab:blue", "oracle": "tab:green"}


def table(summary: dict) -> list[str]:
    c = summary["conditions"]
    L = ["| condition | upright | foot-strike RMS dev (mm) | pelvis RMS dev (mm) | time to fall (s) | mean torque (N m) | "
         "mean power (W) |", "|---|---:|---:|---:|---:|---:|---:|"]
    for name in CONDITIONS:
        r = c[name]
        L.append(f"| {name} | {r['upright']}/{r['trials']} | {format_mean_std(r.get('foot_strike_rms_mm'), 1)} | "
                 f"{format_mean_std(r.get('pelvis_rms_mm'), 1)} | {format_mean_std(r['time_to_fall_s'], 2)} | {format_mean_std(r['torque_mean'], 2)} | "
                 f"{format_mean_std(r['power_mean'], 1)} |")
    return L


def static_failures(summary: dict) -> list[str]:
    """The trials whose static session set the robot could not hold: no estimate, so no
    corrected walk (they count in the other conditions)."""
    f = summary.get("static_failed") or {}
    if not f.get("count"):
        return []
    return [f"**{f['count']} trial(s) without a calibration** (seeds {f['seeds']}): the static session set with the "
            f"trial's offsets could not be collected, so there is no corrected walk; the first reason: "
            f"{f['first_reason'].split('. Fix:')[0]}.", ""]


def odometry_table(summary: dict) -> list[str]:
    o = summary["odometry"]
    L = ["Leg kinematic-inertial odometry of the nominal walks (orientation from the IMU, position from the stance "
         f"foot's contact point, its {o['contact_point']}, through forward kinematics; `legcal_bench.evaluation."
         "odometry`), the simulator's truth as the reference, the trial's offsets added to the logged encoders "
         "afterwards, before and after the trial's correction; RMS error (mm), mean ± std over trials:", "",
         "| RMS error (mm) | no offsets | before | after | reduction | paper, before → after |",
         "|---|---:|---:|---:|---:|---:|"]
    for key, label, paper in (("vertical_mm", "vertical z", LIDAR_RMS_MM["vertical"]),
                              ("forward_mm", "forward x", LIDAR_RMS_MM["forward"]),
                              ("lateral_mm", "lateral y", LIDAR_RMS_MM["lateral"]),
                              ("total_mm", "total 3-D", LIDAR_RMS_MM["total_3d"])):
        b, a = o["before"][key], o["after"][key]
        red = f"{100 * (1 - a['mean'] / b['mean']):.1f} %" if b and a else "–"
        L.append(f"| {label} | {format_mean_std(o['no_offsets'][key])} | {format_mean_std(b)} | {format_mean_std(a)} | {red} | {paper[0]} → {paper[1]} |")
    L += ["", f"Vertical drift per degree of symmetric hip-pitch offset (final height error, least squares over "
          f"-3..3 deg): {format_mean_std(o['pitch_m_per_deg'], 3)} m/deg over {format_mean_std(o['distance_m'], 1)} m walked, i.e. one "
          f"degree's tangent times the distance (paper: {LIDAR_VERTICAL_DRIFT_M_PER_DEG} m/deg over its walks)."]
    return L


def plot_paths(trial: dict, path: Path, title: str) -> Path:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 5))
    for name in (c for c in CONDITIONS if "path" in trial[c]):  # no corrected walk without a calibration
        p = np.asarray(trial[name]["path"])
        ax.plot(p[:, 0], p[:, 1], color=COLOURS[name], lw=1.5, label=name + ("" if trial[name]["upright"] else " (fell)"))
        ax.plot(p[-1, 0], p[-1, 1], "o", color=COLOURS[name], ms=4)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def write(out: str | Path, summaries: list[dict], trials: list[list[dict]], code: str, made_by: str) -> str:
    """`out/report.md`, `out/report.json`, and `out/paths_<offsets>.png` per offset."""
    out = Path(out)
    cfg = summaries[0]["config"]
    L = [f"# Closed-loop evaluation: {Path(cfg['robot']).name}, policy {Path(cfg['policy']).name}", "",
         f"Made by `{made_by}` ({code}). {cfg['trials']} paired trials of {cfg['seconds']:g} s, walking sensors "
         f"`{cfg['walk_sensors']}`; each trial's estimate from an independent static session set "
         f"({cfg['static_mode']}, `{cfg['static_sensors']}`, stances I-IV) calibrated by `{cfg['calibrator']}` "
         f"{cfg['options'] or '(defaults)'}. Deviations against the same seed's nominal walk; trials where a walk fell "
         "are left out of the RMS and counted in 'upright'."]
    if summaries[0]["privileged"]:
        L += ["", f"The policy reads privileged observation terms from the simulator: {summaries[0]['privileged']}."]
    for s, ts in zip(summaries, trials):
        c = s["config"]
        r = s["ratios"]
        name = c["offsets"].replace(":", "_").replace("@", "_")
        png = plot_paths(ts[0], out / f"paths_{name}.png",
                         f"{Path(c['robot']).name}, offsets {c['offsets']}, seed {ts[0]['seed']}")
        L += ["", f"## offsets `{c['offsets']}`", "", *table(s), "",
              f"Corrected / uncorrected: foot strike {100 * r['foot_strike_rms_mm']['corrected_over_uncorrected']:.1f} %, "
              f"pelvis {100 * r['pelvis_rms_mm']['corrected_over_uncorrected']:.1f} %; corrected / oracle: foot strike "
              f"{r['foot_strike_rms_mm']['corrected_over_oracle']:.2f}x, pelvis "
              f"{r['pelvis_rms_mm']['corrected_over_oracle']:.2f}x (the oracle repeats the nominal walk up to rounding). "
              f"Nominal seed-to-seed spread (other noise and jitter): foot strike "
              f"{format_mean_std(s['nominal_spread']['foot_strike_rms_mm'], 1)} mm, pelvis {format_mean_std(s['nominal_spread']['pelvis_rms_mm'], 1)} "
              f"mm. Static recovery RMS "
              f"{format_mean_std(s['recovery_rms_deg'], 4)} deg; per trial: static collection + calibration "
              f"{format_mean_std(s['static_s'], 2)} s, a walk {format_mean_std(s['walk_s'], 2)} s wall.", "",
              *static_failures(s), f"![pelvis paths]({png.name})"]
        L += ["", *odometry_table(s)]
    fs, pv = CLOSED_LOOP_FOOT_STRIKE_MM, CLOSED_LOOP_PELVIS_MM
    L += ["", f"Paper (real A3, {CLOSED_LOOP_TRIALS} trials at {CLOSED_LOOP_OFFSET_DEG:g} deg): foot strike "
          f"{fs[0]} -> {fs[1]} mm ({100 * fs[1] / fs[0]:.1f} %), pelvis {pv[0]} -> {pv[1]} mm "
          f"({100 * pv[1] / pv[0]:.1f} %), all upright.", ""]
    data = {"code": code, "made_by": made_by, "summaries": summaries,
            "trials": [[{k: v for k, v in t.items()} for t in ts] for ts in trials]}
    return write_report(out, "\n".join(L), data)
