"""The closed-loop evaluation's report: a markdown table beside the paper's numbers,
the JSON it was made from, and a plot of the pelvis paths.

A run's folder (`walk-eval --out DIR`): `report.md`, `report.json`, `paths.png` (one
evaluation) or `paths_<k>.png` (the k-th of a sweep, from 1), `timings.json` (the wall
clock per trial, and which trials this run computed), `trials/` (each finished trial,
`legcal_bench.evaluation.closed_loop.TrialStore`). No file name holds anything the user
typed. The report holds no wall-clock figure, so a run resumed from its finished trials
writes the same report.md, report.json and plots, byte for byte, as an uninterrupted one.
"""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

import numpy as np

from legcal_bench.evaluation.closed_loop import CONDITIONS, TIMING_KEYS, offsets_label
from legcal_bench.evaluation.metrics import format_mean_std
from legcal_bench.files.plots import pyplot, save_figure
from legcal_bench.files.reports import write_report
from legcal_bench.paper import (CLOSED_LOOP_FOOT_STRIKE_MM, CLOSED_LOOP_OFFSET_DEG, CLOSED_LOOP_PELVIS_MM,
                                CLOSED_LOOP_TRIALS, LIDAR_RMS_MM, LIDAR_VERTICAL_DRIFT_M_PER_DEG)

COLOURS = {"nominal": "black", "uncorrected": "tab:red", "corrected": "tab:blue", "oracle": "tab:green"}
ROUNDING_MM = 1.0  # an oracle within this of the nominal walk (every trial, both metrics) repeats it "up to rounding"
PLOT_NAME = re.compile(r"paths(_[0-9]+)?\.png")  # the plots `write` names; an earlier run's extra ones are removed
FIXED_PATTERNS = ("none", "paper", "paper-base")  # offsets specs the plot's title names alone (paper@<deg> too)


def table(summary: dict) -> list[str]:
    c = summary["conditions"]
    L = ["| condition | upright | foot-strike RMS dev (mm) | pelvis RMS dev (mm) | time to fall (s) | mean torque (N m) | "
         "mean power (W) |", "|---|---:|---:|---:|---:|---:|---:|"]
    for name in CONDITIONS:
        r = c[name]
        if not r["trials"]:  # no corrected walk: no trial was calibrated
            L.append(f"| {name} | no calibrated trial | – | – | – | – | – |")
            continue
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


def verdicts(summary: dict) -> list[str]:
    """The trials' calibration verdicts in words: a do-not-apply trial is a failed
    calibration, walked as no correction; review trials are corrections, counted."""
    v, rej = summary.get("verdicts"), summary.get("rejected") or {}
    if not v or not any(v.values()):
        return []
    line = (f"Calibration verdicts: {v['apply']} apply, {v['review']} review (corrections, walked as such), "
            f"{v['do-not-apply']} do-not-apply")
    if rej.get("count"):
        line += (f" (seeds {rej['seeds']}: failed calibrations, walked and scored as no correction; the first "
                 f"reason: {rej['first_reason']})")
    return [line + ".", ""]


def _mm(x: dict | None, nd: int = 1) -> str:
    return "–" if not x else f"{x['mean']:.{nd}f} mm"


def _share(x: float | None, percent: bool) -> str:
    if x is None:
        return "–"
    return f"{100 * x:.1f} %" if percent else f"{x:.2f}x"


def comparison(summary: dict) -> str:
    """The paragraph under an evaluation's table: corrected against uncorrected, the
    oracle's distance from the nominal walk and what it makes of corrected / oracle, the
    nominal seed-to-seed spread, the static recovery; in words where a number is missing."""
    s, c = summary, summary["conditions"]
    r, sp = s["ratios"], s["nominal_spread"]
    n = s["config"]["trials"]
    calibrated = c["corrected"]["trials"] > 0
    if not calibrated:
        first = (f"No trial was calibrated: the static session set could not be collected in any of the {n} "
                 "trial(s), so there is no corrected walk and nothing to compare it with.")
    elif all(r[k]["corrected_over_uncorrected"] is None for k in r):
        first = ("Corrected / uncorrected: not available (no trial in which the uncorrected and corrected walks both "
                 "stayed upright beside the nominal one).")
    else:
        first = (f"Corrected / uncorrected: foot strike {_share(r['foot_strike_rms_mm']['corrected_over_uncorrected'], True)}, "
                 f"pelvis {_share(r['pelvis_rms_mm']['corrected_over_uncorrected'], True)}.")
    spread = ("Nominal seed-to-seed spread (other noise and jitter): "
              + ("none measured (a nominal or spread walk fell in every trial)." if not sp["pelvis_rms_mm"] else
                 f"foot strike {format_mean_std(sp['foot_strike_rms_mm'], 1)} mm, pelvis "
                 f"{format_mean_std(sp['pelvis_rms_mm'], 1)} mm."))
    recovery = (f"Static recovery RMS {format_mean_std(s['recovery_rms_deg'], 4)} deg." if s["recovery_rms_deg"]
                else "")
    return " ".join(x for x in (first, oracle_text(s, calibrated), spread, recovery) if x)


def oracle_text(summary: dict, calibrated: bool = True) -> str:
    """How far the oracle walk is from the nominal one (mean and max over trials), and
    so what corrected / oracle means: nothing where the oracle repeats the nominal walk
    up to rounding; the floor a correction can reach where it is farther than the
    nominal seed-to-seed spread."""
    od, sp, r = summary.get("oracle_distance") or {}, summary["nominal_spread"], summary["ratios"]
    pel, fs = od.get("pelvis_rms_mm"), od.get("foot_strike_rms_mm")
    policy = Path(summary["config"]["policy"]).name
    if pel is None:
        return ("No oracle walk stayed upright beside its nominal walk: the oracle's distance from the nominal walk is "
                "not known.")
    where = (f"Oracle walk (the true offsets as the correction) against the nominal walk, policy `{policy}`, "
             f"{pel['n']} trial(s): pelvis {pel['mean']:.1f} mm mean, {pel['max']:.1f} mm max"
             + (f"; foot strike {fs['mean']:.1f} mm mean, {fs['max']:.1f} mm max." if fs else "."))
    ratio = (f"Corrected / oracle: foot strike {_share(r['foot_strike_rms_mm']['corrected_over_oracle'], False)}, "
             f"pelvis {_share(r['pelvis_rms_mm']['corrected_over_oracle'], False)}") if calibrated else ""
    if max(pel["max"], fs["max"] if fs else 0.0) <= ROUNDING_MM:
        return (where + f" The oracle repeats the nominal walk up to rounding (within {ROUNDING_MM:g} mm in every "
                "trial), so it is no noise floor" + (" and corrected / oracle is no meaningful bar" if calibrated
                                                    else "") + "; the floor is the nominal seed-to-seed spread.")
    sp_p, sp_f = sp.get("pelvis_rms_mm"), sp.get("foot_strike_rms_mm")
    if sp_p is None:
        return (where + " The oracle does not repeat the nominal walk, and there is no nominal seed-to-seed spread to "
                "compare it with (a nominal or spread walk fell)." + (f" {ratio}." if ratio else ""))
    farther = pel["mean"] > sp_p["mean"] or (fs is not None and sp_f is not None and fs["mean"] > sp_f["mean"])
    if farther:
        return (where + f" The oracle is farther from the nominal walk than the nominal seed-to-seed spread (pelvis "
                f"{_mm(sp_p)}, foot strike {_mm(sp_f)} mean): with this policy the true correction does not give the "
                "nominal walk back, so the oracle, not the spread, is the floor a correction can reach."
                + (f" {ratio}." if ratio else ""))
    return (where + f" The oracle does not repeat the nominal walk up to rounding but stays within the nominal "
            f"seed-to-seed spread (pelvis {_mm(sp_p)}, foot strike {_mm(sp_f)} mean), which remains the floor."
            + (f" {ratio} (an oracle this close to nominal makes the ratio large)." if ratio else ""))


def odometry_table(summary: dict) -> list[str]:
    o = summary["odometry"]
    if not o["before"]["total_mm"]:
        return ["No leg-odometry check: it compares each nominal walk's odometry before and after the trial's "
                "correction, and no trial was calibrated."]
    L = ["Leg kinematic-inertial odometry of the nominal walks (orientation from the IMU, position from the stance "
         f"foot's contact point, its {o['contact_point']}, through forward kinematics; `legcal_bench.evaluation."
         "odometry`), the simulator's truth as the reference, the trial's offsets added to the logged encoders "
         "afterwards, before and after the trial's correction; RMS error (mm), mean ± std over trials:", "",
         "| RMS error (mm) | no offsets | before | after | reduction | paper, before → after |",
         "|---|---:|---:|---:|---:|---:|"]
    cancelled, residual = [], []  # the rows whose reduction is negative, by why
    for key, label, paper in (("vertical_mm", "vertical z", LIDAR_RMS_MM["vertical"]),
                              ("forward_mm", "forward x", LIDAR_RMS_MM["forward"]),
                              ("lateral_mm", "lateral y", LIDAR_RMS_MM["lateral"]),
                              ("total_mm", "total 3-D", LIDAR_RMS_MM["total_3d"])):
        b, a, z = o["before"][key], o["after"][key], o["no_offsets"][key]
        share = 1 - a["mean"] / b["mean"] if b and a and b["mean"] > 0 else None
        red = "–" if share is None else f"{100 * share:.1f} %"
        if share is not None and share < 0:
            nums = f"{label} (before {b['mean']:.1f}, after {a['mean']:.1f}, no offsets {z['mean']:.1f} mm)" if z else label
            (cancelled if z and b["mean"] < z["mean"] else residual).append(nums)
        L.append(f"| {label} | {format_mean_std(z)} | {format_mean_std(b)} | {format_mean_std(a)} | {red} | {paper[0]} → {paper[1]} |")
    if cancelled or residual:
        note = ("Reduction is 1 − after / before: the share of the error with the offsets that the correction removes. "
                "The correction gives the encoders back, so its floor is the 'no offsets' column (the odometry's own "
                "error with exact encoders), not zero; a negative reduction means the error after the correction is "
                "larger than before it.")
        if cancelled:
            note += (f" Negative in {', '.join(cancelled)}: there the trial's offsets happened to cancel part of the "
                     "odometry's own error (before is below no offsets), and undoing them brings that error back; the "
                     "correction working, not failing.")
        if residual:
            note += (f" Negative in {', '.join(residual)}: there the error after the correction is above both the "
                     "no-offsets floor and the error before it: along this axis the estimate's own error moves the "
                     "odometry more than the offsets did.")
        L += ["", note]
    L += ["", f"Vertical drift per degree of symmetric hip-pitch offset (final height error, least squares over "
          f"-3..3 deg): {format_mean_std(o['pitch_m_per_deg'], 3)} m/deg over {format_mean_std(o['distance_m'], 1)} m walked, i.e. one "
          f"degree's tangent times the distance (paper: {LIDAR_VERTICAL_DRIFT_M_PER_DEG} m/deg over its walks)."]
    return L


def plot_title(config: dict, trial: dict, width: int = 80) -> str:
    """The plot's title, a few lines that fit its width: robot, policy and seed; the
    offsets spec, shortened (`offsets_label`), and, for a drawn or explicit pattern, the
    trial's offsets in degrees to one decimal."""
    from legcal_bench.robots import robot_label

    def short(name: str, n: int = 40) -> str:
        return name if len(name) <= n else name[:n - 3] + "..."

    robot, policy = short(robot_label(config["robot"])), short(Path(config["policy"]).name.removesuffix(".yaml"))
    lines = textwrap.wrap(f"{robot}, policy {policy}, trial seed {trial['seed']}", width)
    spec = str(config["offsets"]).strip()
    if spec in FIXED_PATTERNS or spec.startswith("paper@"):
        lines += textwrap.wrap(f"offsets {spec}", width)
    else:
        deg = np.degrees(np.asarray(trial["offsets_rad"], dtype=float))
        pattern = ", ".join(f"{d:+.1f}" for d in deg)
        head = ("explicit offsets" if "," in spec else f"offsets {offsets_label(spec)}, this trial's")
        lines += textwrap.wrap(f"{head} (deg, leg-map order): {pattern}", width)
    return "\n".join(lines)


def plot_paths(trial: dict, path: Path, title: str) -> Path:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 5), layout="constrained")  # the axes make room for a title of a few lines
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


def _without_timings(v):
    """`v` (a summary, a trial row) without its wall-clock fields (`TIMING_KEYS`)."""
    if isinstance(v, dict):
        return {k: _without_timings(x) for k, x in v.items() if k not in TIMING_KEYS}
    if isinstance(v, list):
        return [_without_timings(x) for x in v]
    return v


def timings(summaries: list[dict], trials: list[list[dict]], computed=None) -> dict:
    """The wall clock of each evaluation's trials (static collection + calibration, each
    walk) and their means; `computed`: the (offsets, seed) run by this process, the others
    taken from an earlier run's files."""
    out = []
    for s, ts in zip(summaries, trials):
        spec = s["config"]["offsets"]
        rows = [{"seed": t["seed"], "static_s": t["static_s"],
                 "walks_s": {c: t[c]["wall_s"] for c in CONDITIONS if "wall_s" in t[c]},
                 **({"computed": "this run" if (spec, t["seed"]) in computed else "an earlier run"}
                    if computed is not None else {})} for t in ts]
        out.append({"offsets": spec, "static_s": s.get("static_s"), "walk_s": s.get("walk_s"), "trials": rows})
    return {"evaluations": out}


def write(out: str | Path, summaries: list[dict], trials: list[list[dict]], code: str, made_by: str,
          computed=None) -> str:
    """`out/report.md`, `out/report.json`, the pelvis paths of each evaluation's first
    trial (`out/paths.png`, or `out/paths_<k>.png` for the k-th of several: no file name
    from the offsets), and `out/timings.json` (`timings`; the report itself holds no wall
    clock). Returns the markdown."""
    from legcal_bench.files.atomic import atomic_write_json

    out = Path(out)
    cfg = summaries[0]["config"]
    L = [f"# Closed-loop evaluation: {Path(cfg['robot']).name}, policy {Path(cfg['policy']).name}", "",
         f"Made by `{made_by}` ({code}). {cfg['trials']} paired trials of {cfg['seconds']:g} s, walking sensors "
         f"`{cfg['walk_sensors']}`; each trial's estimate from an independent static session set "
         f"({cfg['static_mode']}, `{cfg['static_sensors']}`, stances I-IV) calibrated by `{cfg['calibrator']}` "
         f"{cfg['options'] or '(defaults)'}. Deviations against the same seed's nominal walk; trials where a walk fell "
         "are left out of the RMS and counted in 'upright'. Wall-clock times per trial are in `timings.json` beside "
         "this report, not in it: a run resumed from its finished trials (`trials/`) writes this report unchanged."]
    from legcal_bench.policies.spec import load_policy_spec

    L += ["", f"Simulation settings from the policy's spec: {load_policy_spec(cfg['policy']).settings}."]
    if summaries[0]["privileged"]:
        L += ["", f"The policy reads privileged observation terms from the simulator: {summaries[0]['privileged']}."]
    plots = []
    for k, (s, ts) in enumerate(zip(summaries, trials), 1):
        c = s["config"]
        png = plot_paths(ts[0], out / ("paths.png" if len(summaries) == 1 else f"paths_{k}.png"), plot_title(c, ts[0]))
        plots.append(png.name)
        label = offsets_label(c["offsets"], 40)
        L += ["", f"## offsets `{label}`", ""]
        if label != c["offsets"]:
            L += [f"Offsets (rad, leg-map order): `{c['offsets']}`", ""]
        L += [*table(s), "", comparison(s), "", *static_failures(s), *verdicts(s), f"![pelvis paths]({png.name})"]
        L += ["", *odometry_table(s)]
    for stale in out.iterdir():  # an earlier run's plots this one does not replace (a longer sweep's)
        if PLOT_NAME.fullmatch(stale.name) and stale.name not in plots:
            stale.unlink()
    fs, pv = CLOSED_LOOP_FOOT_STRIKE_MM, CLOSED_LOOP_PELVIS_MM
    L += ["", f"Paper (real A3, {CLOSED_LOOP_TRIALS} trials at {CLOSED_LOOP_OFFSET_DEG:g} deg): foot strike "
          f"{fs[0]} -> {fs[1]} mm ({100 * fs[1] / fs[0]:.1f} %), pelvis {pv[0]} -> {pv[1]} mm "
          f"({100 * pv[1] / pv[0]:.1f} %), all upright.", ""]
    data = {"code": code, "made_by": made_by, "summaries": _without_timings(summaries),
            "trials": _without_timings(trials)}
    atomic_write_json(out / "timings.json", {"code": code, "made_by": made_by,
                                             **timings(summaries, trials, computed)})
    return write_report(out, "\n".join(L), data)
