"""`legcal-bench robots-check`: robots as they come, measured.

For the built-in robots, the G1 example and the generated test robots (every hip order,
soft servos, narrow ankles; `legcal_bench.robots.design.GENERATED`), each through its
leg map alone: the servo gains in use and their source, how much each stance had to
shrink to fit, the hold check's largest excursions in weld and contact mode over the
seeds (against its limits), and the weld-mode recovery of the default inter-foot
calibration next to the robot's stiff-servo twin (the same robot with the A3-like
robot's servos). Writes `report.md` and `report.json`.
"""

from __future__ import annotations

import tempfile
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from legcal_bench.calibrators.base import get_calibrator
from legcal_bench.data.recording import load_session
from legcal_bench.errors import LegcalError
from legcal_bench.evaluation.scoring import score
from legcal_bench.files.reports import write_report
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.protocol.servos import servo_gains
from legcal_bench.protocol.stances import STANCES, fit_stance
from legcal_bench.provenance import code_version, describe
from legcal_bench.robots import BUILTIN, available, load_robot, robot_label
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import GENERATED, stiff_twin
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.sim.hold import HOLD_LIMITS


def _session(robot: str, mode: str, seed: int, folder: Path) -> tuple[dict, float | None]:
    """(hold maxima over the segments, weld recovery RMS in deg or None)."""
    out = folder / f"{robot_label(robot)}_{mode}_{seed}"
    s = collect(CollectConfig(robot=robot, mode=mode, seed=seed), out, progress=False)
    holds = [g.hold for g in s.segments]
    hold = {"pelvis_mm": max(h["pelvis_mm"] for h in holds), "pelvis_limit_mm": holds[0]["pelvis_limit_mm"],
            "sole_move_mm": max(max(h["sole_move_mm"]) for h in holds),
            "sole_tilt_deg": max(max(h["sole_tilt_deg"]) for h in holds)}
    recovery = None
    if mode == "weld":
        lm = load_robot(robot)
        res = get_calibrator("interfoot").calibrate(lm, load_session(out, lm.joint_names))
        recovery = score(str(out), res, lm)["recovery"]["rms_error_deg"]
    return hold, recovery


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
                   "modes": {}, "recovery_deg": [], "twin_recovery_deg": []}
            for mode in ("weld", "contact"):
                holds = []
                for seed in range(seeds):
                    try:
                        hold, rec = _session(robot, mode, seed, tmp)
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
    failures = [(r["robot"], m, e) for r in rows for m, v in r["modes"].items() for e in v["failed"]]
    if failures:
        lines += ["", "## Failed collections", ""] + [f"- {r} ({m}): {e}" for r, m, e in failures]
    lines += ["", "Servo gains:", ""] + [f"- {r['robot']}: {r['servo_note']}" for r in rows]
    if skipped:
        lines += ["", *skipped]
    text = "\n".join(lines) + "\n"
    write_report(out, text, {"meta": meta, "rows": rows})
    return text
