"""`legcal-bench robots-check`: robots as they come, measured.

For the built-in robots, the G1 example, the generated test robots (every hip order,
soft servos, narrow ankles; `legcal_bench.robots.design.GENERATED`) and the variations
third parties build (mirrored pitch servos, canted hips, a kid-size robot;
`legcal_bench.robots.design.VARIATIONS`, no stiff twin), each through its
leg map alone: the servo gains in use and their source, how much each stance had to
shrink to fit, the hold check's largest excursions in weld and contact mode over the
seeds (against its limits), and the weld-mode recovery of the default inter-foot
calibration next to the robot's stiff-servo twin (the same robot with the A3-like
robot's servos), and what the data checks measure on these clean sets against their
warning limits, with every warning they raise (false alarms). Writes `report.md` and
`report.json`.
"""

from __future__ import annotations

import tempfile
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from legcal_bench.calibrators.base import calibrate_training

from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import load_session
from legcal_bench.errors import LegcalError
from legcal_bench.estimation.checks.datacheck import LIMITS, data_warnings, statistics
from legcal_bench.evaluation.scoring import score
from legcal_bench.files.reports import write_report
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.protocol.servos import servo_gains
from legcal_bench.protocol.stances import STANCES, fit_stance
from legcal_bench.provenance import code_version, describe
from legcal_bench.robots import BUILTIN, available, load_robot, robot_label
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import GENERATED, VARIATIONS, stiff_twin
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.sim.hold import HOLD_LIMITS


CHECKED = ("longest_run_encoder", "longest_run_imu", "dispersion_mm", "soles_height_mm", "soles_tilt_deg",
           "gravity_deg", "gravity_motion_deg", "slide_mm", "yaw_deg", "left_tilt_change_deg", "right_tilt_change_deg")


def _data_check(lm, recs, res) -> dict:
    """The data checks on a clean session set with the calibrator's estimate: the
    largest |statistic| over the recordings, and the warnings raised (false alarms)."""
    kin = LegKinematics(lm)
    dq = res.offsets_vector(lm.joint_names)
    stats = [statistics(kin, r, dq) for r in recs]
    worst = {k: max(abs(st[k]) for st in stats if k in st) for k in CHECKED}
    return {"worst": worst, "warnings": data_warnings(kin, recs, dq)}


def _session(robot: str, mode: str, seed: int, folder: Path) -> tuple[dict, float | None, dict]:
    """(hold maxima over the segments, weld recovery RMS in deg or None, data checks)."""
    out = folder / f"{robot_label(robot)}_{mode}_{seed}"
    s = collect(CollectConfig(robot=robot, mode=mode, seed=seed), out, progress=False)
    holds = [g.hold for g in s.segments]
    hold = {"pelvis_mm": max(h["pelvis_mm"] for h in holds), "pelvis_limit_mm": holds[0]["pelvis_limit_mm"],
            "sole_move_mm": max(max(h["sole_move_mm"]) for h in holds),
            "sole_tilt_deg": max(max(h["sole_tilt_deg"]) for h in holds)}
    lm = load_robot(robot)
    recs = load_session(out, lm.joint_names)
    res = calibrate_training(get_calibrator("interfoot", setting="operating"), lm, recs)
    recovery = score(str(out), res, lm)["recovery"]["rms_error_deg"] if mode == "weld" else None
    return hold, recovery, _data_check(lm, recs, res)


def run_robots_check(out: str | Path, seeds: int = 2, progress: bool = True, extra: list[str] | None = None) -> str:
    rows, skipped = [], []
    provenance = code_version()  # the code this run starts with
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        robots: list[tuple[str, str | None]] = [(r, None) for r in BUILTIN]
        robots += [(r, None) for r in (extra or [])]
        for d in GENERATED:
            twin = str(write_robot(stiff_twin(d), tmp / "robots"))
            robots.append((str(write_robot(d, tmp / "robots")), twin))
        robots += [(str(write_robot(d, tmp / "robots")), None) for d in VARIATIONS]
        bar = tqdm(total=len(robots) * seeds * 2 + sum(t is not None for _, t in robots) * seeds,
                   desc="robots-check", unit="set", disable=not progress)
        for robot, twin in robots:
            missing = available(robot)
            if missing is not None:
                skipped.append(f"{robot} skipped: {missing}")
                continue
            lm = load_robot(robot)
            kin = LegKinematics(lm)
            g = servo_gains(lm)
            row = {"robot": robot_label(robot), "hip_order": "-".join(r[len("hip_")].upper() for r in lm.hip_order),
                   "servo_source": sorted(set(g.source)), "servo_note": g.note,
                   "kp_knee": g.kp[lm.joint_roles.index("knee")],
                   "stance_scale": {s: fit_stance(st, kin).scale for s, st in STANCES.items()},
                   "modes": {}, "recovery_deg": [], "twin_recovery_deg": [], "data_checks": {}}
            for mode in ("weld", "contact"):
                holds, checks = [], []
                for seed in range(seeds):
                    try:
                        hold, rec, check = _session(robot, mode, seed, tmp)
                        checks.append(check)
                    except LegcalError as e:
                        hold, rec = {"error": str(e)}, None
                    holds.append(hold)
                    if rec is not None:
                        row["recovery_deg"].append(rec)
                    bar.update(1)
                ok = [h for h in holds if "error" not in h]
                row["modes"][mode] = {
                    "failed": [h["error"] for h in holds if "error" in h],
                    **({k: max(h[k] for h in ok) for k in ("pelvis_mm", "sole_move_mm", "sole_tilt_deg")}
                       if ok else {}),
                    "pelvis_limit_mm": HOLD_LIMITS.pelvis_leg_fraction * kin.dims.leg_length * 1e3}
                if checks:
                    row["data_checks"][mode] = {
                        "sets": len(checks), "worst": {k: max(c["worst"][k] for c in checks) for k in CHECKED},
                        "warnings": [w for c in checks for w in c["warnings"]]}
            if twin is not None:
                for seed in range(seeds):
                    row["twin_recovery_deg"].append(_session(twin, "weld", seed, tmp)[1])
                    bar.update(1)
            rows.append(row)
        bar.close()
    command = f"legcal-bench robots-check --seeds {seeds}" + (f" --extra {' '.join(extra)}" if extra else "")
    meta = {"command": command, "provenance": provenance, "skipped": skipped, "seeds": seeds,
            "hold_limits": asdict(HOLD_LIMITS), "config": asdict(CollectConfig())}
    lines = [
        "# Robots as they come: servo gains, stance fit, hold check, recovery",
        "",
        f"Generated by `{command}` ({describe(meta['provenance'])}).",
        f"Default session sets (standing, stances I-IV, 3 held-out; paper offsets, realistic sensors), seeds 0-{seeds - 1}.",
        "Hold: the largest excursion over every segment and seed (pelvis from its commanded pose; soles from",
        f"their settled pose), limits: pelvis {100 * HOLD_LIMITS.pelvis_leg_fraction:g} % of the leg length, "
        f"soles {HOLD_LIMITS.sole_move_m * 1e3:g} mm and {np.rad2deg(HOLD_LIMITS.sole_tilt_rad):g} deg. Recovery:",
        "weld mode, default inter-foot calibration, RMS over the 12 offsets, mean over seeds; twin: the same",
        "robot with the A3-like robot's stiff servos.",
        "",
        "| robot | hip order | gains (source) | knee kp | stance fit I/II/III/IV | weld pelvis (limit) mm "
        "| contact pelvis mm | contact sole mm / deg | weld recovery (deg) | twin (deg) |",
        "|---|---|---|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        w, c = r["modes"]["weld"], r["modes"]["contact"]

        def cell(m, k, fmt):
            return "FAILED" if m["failed"] and k not in m else (fmt.format(m[k]) + (" (1 failed)" if m["failed"] else ""))

        lines.append(
            f"| {r['robot']} | {r['hip_order']} | {', '.join(r['servo_source'])} | {r['kp_knee']:.0f} | "
            + "/".join(f"{v:g}" for v in r["stance_scale"].values())
            + f" | {cell(w, 'pelvis_mm', '{:.1f}')} ({w['pelvis_limit_mm']:.0f}) | {cell(c, 'pelvis_mm', '{:.1f}')} | "
            + (f"{c['sole_move_mm']:.2f} / {c['sole_tilt_deg']:.3f}" if "sole_move_mm" in c else "FAILED")
            + f" | {np.mean(r['recovery_deg']):.3f} | "
            + (f"{np.mean(r['twin_recovery_deg']):.3f}" if r["twin_recovery_deg"] else "–") + " |")
    lines += [
        "",
        "## Data checks on clean data (false alarms)",
        "",
        "The data checks (`legcal_bench.estimation.checks.datacheck`, run by every built-in calibrator) on the same clean",
        "sets, with the default inter-foot calibration's estimate: the largest |figure| over every recording and",
        "seed next to its warning limit, and the warnings raised (each one a false alarm).",
        "",
        "| robot | mode | sets | identical run enc / imu (frames) | dispersion mm | soles mm / deg | gravity deg "
        "/ moving | slide mm | yaw deg | sole tilt change deg | warnings |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
        f"| limit | | | {LIMITS.frozen_frames} / {LIMITS.frozen_frames} | {LIMITS.dispersion_m * 1e3:g} | "
        f"{LIMITS.coplanar_m * 1e3:g} / {np.degrees(LIMITS.coplanar_rad):g} | {np.degrees(LIMITS.gravity_rad):g} / "
        f"{np.degrees(LIMITS.gravity_motion_rad):g} | {LIMITS.slide_m * 1e3:g} | {np.degrees(LIMITS.yaw_rad):g} | "
        f"{np.degrees(LIMITS.sole_tilt_rad):g} | |",
    ]
    for r in rows:
        for mode, d in r["data_checks"].items():
            w = d["worst"]
            lines.append(
                f"| {r['robot']} | {mode} | {d['sets']} | {w['longest_run_encoder']} / {w['longest_run_imu']} | "
                f"{w['dispersion_mm']:.2f} | {w['soles_height_mm']:.1f} / {w['soles_tilt_deg']:.2f} | "
                f"{w['gravity_deg']:.2f} / {w['gravity_motion_deg']:.2f} | {w['slide_mm']:.2f} | {w['yaw_deg']:.3f} | "
                f"{max(w['left_tilt_change_deg'], w['right_tilt_change_deg']):.3f} | {len(d['warnings'])} |")
    alarms = [(r["robot"], m, w) for r in rows for m, d in r["data_checks"].items() for w in d["warnings"]]
    if alarms:
        lines += ["", "False alarms:", ""] + [f"- {r} ({m}): {w}" for r, m, w in alarms]
    failures = [(r["robot"], m, e) for r in rows for m, v in r["modes"].items() for e in v["failed"]]
    if failures:
        lines += ["", "## Failed collections", ""] + [f"- {r} ({m}): {e}" for r, m, e in failures]
    lines += ["", "Servo gains:", ""] + [f"- {r['robot']}: {r['servo_note']}" for r in rows]
    if skipped:
        lines += ["", *skipped]
    text = "\n".join(lines) + "\n"
    write_report(out, text, {"meta": meta, "rows": rows})
    return text
