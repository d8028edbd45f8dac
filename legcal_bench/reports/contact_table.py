"""The per-stance contact check measured (issue #16): clean data, a wedge under one sole
in one stance, and the contact floor, on each robot over seeds.

Cases (weld unless named; `calibrated-imu` sensors unless the case ends in `realistic`,
the paper's injection unless the case names `random:3`):
  clean        no effect: every flag is a false alarm;
  kinematic    the same in kinematic mode;
  wedge 0.3    `shim:side=S,roll=0.3,stance=T`, S and T alternating with the seed: the
               stance T must be flagged, its sole named S (`pitch=` on legs without
               an ankle roll, which cannot stand on a roll wedge);
  wedge 0.05   the same at 0.05 deg (near the check's size floor);
  contact      the contact floor, no effect: the soles really do sit off one plane there
               (they rock and sink under the load); the truth says by how much;
  <case> random:3  any case above with the offsets random:3@seed (3 deg RMS);
  <case> [random:3] realistic  any case above with realistic sensors (an uncalibrated
               IMU: `legcal_bench.sim.sensors`), e.g. `contact random:3 realistic`
               (issue #60).
Each set is calibrated with `interfoot` (operating setting) with `contact_check=flag`
(the offsets of `off`) and `contact_check=drop`; a set the robot does not hold
(HoldError) is counted as failed. Scored: the stances flagged against the
truth's own departure from one plane (the simulator's sole poses: a stance is truly off
one plane when its mean relative tilt exceeds the check's size floor), the estimated
departure against the true one, the offsets' RMS error with and without the drop.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from legcal_bench.files.scratch import scratch_dir

CASES = ("clean", "wedge 0.3", "wedge 0.05", "contact")
EXTRA_CASES = ("kinematic",)  # clean, kinematic mode
REALISTIC = " realistic"  # a case's suffix: realistic sensors instead of calibrated-imu
RANDOM = " random:3"  # before it: the offsets random:3@seed instead of the paper's
KNOWN_CASES = tuple(c + o + r for c in CASES + EXTRA_CASES for o in ("", RANDOM) for r in ("", REALISTIC))


def case_sensors(case: str) -> str:
    """The sensor preset of `case`."""
    return "realistic" if case.endswith(REALISTIC) else "calibrated-imu"


def case_offsets(case: str, seed: int) -> str:
    """The injected offsets of `case` for `seed`: the paper's, or random:3@seed."""
    return f"random:3@{seed}" if case.removesuffix(REALISTIC).endswith(RANDOM) else "paper"


def case_spec(case: str, seed: int) -> tuple[str, tuple[str, ...], str | None, str | None]:
    """(mode, effect specs, the wedge's stance, its side) of `case` for `seed`."""
    case = case.removesuffix(REALISTIC).removesuffix(RANDOM)
    side, stance = ("left", "right")[seed % 2], ("II", "III")[(seed // 2) % 2]
    if case.startswith("wedge"):
        deg = case.split()[1]
        return "weld", (f"shim:side={side},roll={deg},stance={stance}",), f"stance_{stance}", side
    return {"contact": "contact", "kinematic": "kinematic"}.get(case, "weld"), (), None, None


def true_departures(paths) -> dict[str, np.ndarray]:
    """Per stance recording, the truth's mean (tilt x, tilt y, height) of the right sole
    in the left sole's frame (`legcal_bench.estimation.checks.coplanarity.coplanarity`)."""
    from legcal_bench.data.recording import load_truth
    from legcal_bench.estimation.checks.coplanarity import coplanarity
    from legcal_bench.geometry.poses import pos_quat_to_homogeneous

    out = {}
    for p in paths:
        name = Path(p).stem
        if not name.startswith("stance_"):
            continue
        poses = np.asarray(load_truth(p).sole_poses_world)
        C = np.linalg.inv(pos_quat_to_homogeneous(poses[:, 0])) @ pos_quat_to_homogeneous(poses[:, 1])
        c = [coplanarity(M)[0] for M in C]
        out[name] = np.mean(c, axis=0)
    return out


def run_case(robot: str, case: str, seed: int) -> dict:
    from legcal_bench.calibrators.base import calibrate_training
    from legcal_bench.calibrators.registry import get_calibrator
    from legcal_bench.data.recording import list_segments, load_session, load_truth
    from legcal_bench.errors import HoldError, IKError
    from legcal_bench.estimation.checks.coplanarity import MIN_HEIGHT_M, MIN_TILT_RAD
    from legcal_bench.evaluation.metrics import rms
    from legcal_bench.protocol.collect import CollectConfig, collect
    from legcal_bench.robots import load_robot

    legmap = load_robot(robot)
    mode, effects, stance, side = case_spec(case, seed)
    if "ankle_roll" not in legmap.joint_roles:  # no ankle roll to stand on a roll wedge: the wedge in pitch
        effects = tuple(e.replace(",roll=", ",pitch=") for e in effects)
    with scratch_dir("contact") as work:
        try:
            collect(CollectConfig(robot=robot, mode=mode, sensors=case_sensors(case), seed=seed, effects=effects,
                                  offsets=case_offsets(case, seed), heldout=0), Path(work) / "set", progress=False)
        except (HoldError, IKError) as e:  # a set the robot cannot hold or reach is a failed case, counted
            return {"robot": legmap.name, "robot_spec": robot, "case": case, "seed": seed, "mode": mode,
                    "failed": str(e)}
        recs = load_session(Path(work) / "set", robot=legmap)
        paths = list_segments(Path(work) / "set")
        injected = np.asarray(load_truth(paths[0]).offsets)
        truth = true_departures(paths)
        fits = {o: calibrate_training(get_calibrator("interfoot", setting="operating", contact_check=o), legmap, recs)
                for o in ("flag", "drop")}
    check = fits["flag"].diagnostics["contact_check"]["stances"]
    truly_off = sorted(n for n, c in truth.items() if np.hypot(*c[:2]) > MIN_TILT_RAD or abs(c[2]) > MIN_HEIGHT_M)
    stances = []
    for c in check:
        t = truth[c["recording"]]
        stances.append({"recording": c["recording"], "flagged": c["flagged"], "sole": c["sole"],
                        "chi2": c["chi2"], "dof": c["dof"], "estimate": [*c["tilt_rad"], c["height_m"]], "truth": t.tolist(),
                        "tilt_error_deg": float(np.rad2deg(np.hypot(*(np.subtract(c["tilt_rad"], t[:2]))))),
                        "height_error_mm": float(1e3 * (c["height_m"] - t[2]))})
    err = {o: float(np.rad2deg(rms(np.array([r.offsets_rad[n] for n in legmap.joint_names]) - injected)))
           for o, r in fits.items()}
    return {"robot": legmap.name, "robot_spec": robot, "case": case, "seed": seed, "mode": mode,
            "effects": list(effects), "wedge_stance": stance, "wedge_side": side, "truly_off": truly_off,
            "flagged": [s["recording"] for s in stances if s["flagged"]], "stances": stances,
            "dropped": fits["drop"].diagnostics["contact_check"]["dropped"], "offsets_rms_deg": err}


def _case(args):
    return run_case(*args)


def build(robots, cases=CASES, seeds: int = 5, workers: int = 2, progress: bool = True) -> dict:
    """`robots`: built-in names, leg-map paths, or the names of the generated robots
    (`legcal_bench.robots.design.GENERATED_DESIGNS`: written for the run)."""
    from legcal_bench.reports.robot_cases import map_robot_cases

    rows = map_robot_cases(_case, robots, cases, seeds, workers, "contact-table", progress)
    return {"rows": rows, "summary": summarize(rows)}


def summarize(rows: list[dict]) -> list[dict]:
    from legcal_bench.evaluation.metrics import rms

    out = []
    for robot in dict.fromkeys(r["robot"] for r in rows):
        for case in dict.fromkeys(r["case"] for r in rows if r["robot"] == robot):
            rs = [r for r in rows if r["robot"] == robot and r["case"] == case and "failed" not in r]
            failed = sum(1 for r in rows if r["robot"] == robot and r["case"] == case and "failed" in r)
            if not rs:
                out.append({"robot": robot, "case": case, "sets": 0, "failed": failed})
                continue
            n_st = sum(len(r["stances"]) for r in rs)
            tp = sum(len(set(r["flagged"]) & set(r["truly_off"])) for r in rs)
            fp = sum(len(set(r["flagged"]) - set(r["truly_off"])) for r in rs)
            off = sum(len(r["truly_off"]) for r in rs)
            wedge = [r for r in rs if r["wedge_stance"]]
            named = [s["sole"] == r["wedge_side"] for r in wedge for s in r["stances"]
                     if s["recording"] == r["wedge_stance"] and s["flagged"]]
            flagged_st = [s for r in rs for s in r["stances"] if s["flagged"] and s["recording"] in r["truly_off"]]
            out.append({
                "robot": robot, "case": case, "sets": len(rs), "failed": failed, "stances": n_st, "truly_off": off,
                "flagged_truly_off": tp, "flagged_not_off": fp,
                # sets: any stance flagged that is not truly off (an alarm on clean data);
                # the wedge's stance flagged (caught)
                "sets_alarmed": sum(bool(set(r["flagged"]) - set(r["truly_off"])) for r in rs),
                "sets_flagged": sum(bool(r["flagged"]) for r in rs),
                "wedge_caught": sum(r["wedge_stance"] in r["flagged"] for r in wedge) if wedge else None,
                "wedge_sole_named": f"{sum(named)}/{len(wedge)}" if wedge else "–",
                "median_tilt_error_deg": float(np.median([s["tilt_error_deg"] for s in flagged_st]))
                if flagged_st else None,
                "median_abs_height_error_mm": float(np.median([abs(s["height_error_mm"]) for s in flagged_st]))
                if flagged_st else None,
                # The test's calibration: its chi2 per dof over the stances (1 where its noise
                # model holds), and the truth's departure from one plane (RMS over stances).
                "median_chi2_per_dof": float(np.median([st["chi2"] / st.get("dof", 3) for r in rs
                                                         for st in r["stances"]])),
                "true_tilt_rms_deg": float(np.rad2deg(rms(np.array([st["truth"][:2] for r in rs
                                                                    for st in r["stances"]])))),
                "true_height_rms_mm": float(1e3 * rms(np.array([st["truth"][2] for r in rs for st in r["stances"]]))),
                "offsets_rms_deg_flag": float(np.mean([r["offsets_rms_deg"]["flag"] for r in rs])),
                "offsets_rms_deg_drop": float(np.mean([r["offsets_rms_deg"]["drop"] for r in rs])),
            })
    return out


def markdown(data: dict, made_by: str, code: str) -> str:
    from legcal_bench.estimation.checks.coplanarity import MIN_HEIGHT_M, MIN_TILT_RAD

    lines = ["# The per-stance contact check", "",
             f"Made by `{made_by}` ({code}). `calibrated-imu` sensors (`realistic` where the case says so), the "
             "paper's injection (random:3@seed where the case says so), `interfoot` "
             "(operating setting). Truly off one plane: the simulator's own sole poses put the stance's mean relative "
             f"tilt above {np.rad2deg(MIN_TILT_RAD):.2f} deg or its height above {MIN_HEIGHT_M * 1e3:.1f} mm (the "
             "check's size floor). Errors: the flagged stances' estimated departure against the truth's. Offsets: "
             "RMS error (deg) of the fit with every stance (`contact_check=flag`) and without the flagged ones "
             "(`drop`), mean over sets. chi2/dof: the test's median over the stances (about 1 where its noise model "
             "holds); true departure: the truth's RMS per tilt axis and of the height over the stances. Sets alarmed: "
             "sets with a stance flagged that the truth does not put off one plane (a false alarm); wedge caught: "
             "sets whose wedged stance is flagged. Not held: sets the robot could not hold or reach (a wedge in "
             "pitch on legs without an ankle roll).", "", *rates_lines(data["summary"]), "",
             "| robot | case | sets | stances | truly off | flagged, truly off | flagged, not off | sets alarmed "
             "| wedge caught | wedge's sole named "
             "| median tilt error (deg) | median height error (mm) | chi2/dof | true departure (deg, mm) "
             "| offsets flag | offsets drop |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in data["summary"]:
        if not s["sets"]:
            lines.append(f"| {s['robot']} | {s['case']} | 0 ({s['failed']} not held) |" + " – |" * 13)
            continue
        sets = f"{s['sets']}" + (f" (+{s['failed']} not held)" if s["failed"] else "")
        te = "–" if s["median_tilt_error_deg"] is None else f"{s['median_tilt_error_deg']:.4f}"
        he = "–" if s["median_abs_height_error_mm"] is None else f"{s['median_abs_height_error_mm']:.3f}"
        lines.append(f"| {s['robot']} | {s['case']} | {sets} | {s['stances']} | {s['truly_off']} | "
                     f"{s['flagged_truly_off']} | {s['flagged_not_off']} | {s.get('sets_alarmed', '–')} | "
                     f"{'–' if s.get('wedge_caught') is None else s['wedge_caught']} | {s['wedge_sole_named']} | {te} | {he} | "
                     f"{s['median_chi2_per_dof']:.2f} | {s['true_tilt_rms_deg']:.4f}, {s['true_height_rms_mm']:.3f} | "
                     f"{s['offsets_rms_deg_flag']:.4f} | {s['offsets_rms_deg_drop']:.4f} |")
    return "\n".join(lines) + "\n"


def rates_lines(summary: list[dict]) -> list[str]:
    """The check's rates over every robot: false alarms on the sets without a planted
    defect (per kind: kinematic, weld, contact), the wedges caught per size."""
    def share(a: int, n: int) -> str:
        return f"{a / n:.1%}" if n else "–"

    def kind(case: str) -> str:
        base = case.removesuffix(REALISTIC).removesuffix(RANDOM)
        return "wedge " + base.split()[1] if base.startswith("wedge") else {"clean": "weld"}.get(base, base)

    clean, wedge = {}, {}
    for s in summary:
        if not s["sets"]:
            continue
        k = kind(s["case"])
        if k.startswith("wedge"):
            w = wedge.setdefault(k, [0, 0])
            w[0], w[1] = w[0] + s["wedge_caught"], w[1] + s["sets"]
        else:
            c = clean.setdefault(k, [0, 0, 0])
            c[0], c[1], c[2] = c[0] + s["sets_alarmed"], c[1] + s["sets"], c[2] + s["sets_flagged"]
    out = []
    if clean:
        a, n = sum(v[0] for v in clean.values()), sum(v[1] for v in clean.values())
        out.append(f"- Sets without a planted defect alarmed (a stance flagged the truth does not put off one plane): "
                   f"{a}/{n} ({share(a, n)}): " + ", ".join(f"{k} {v[0]}/{v[1]} (any stance flagged: {v[2]})"
                                                           for k, v in clean.items()) + ".")
    for k, (c, n) in wedge.items():
        out.append(f"- {k.split()[1]} deg wedges caught: {c}/{n} ({share(c, n)}).")
    return out
