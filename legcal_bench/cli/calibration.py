"""`legcal-bench calibrate`, `check`, `score`, `design`, `excite` and `export`."""

from __future__ import annotations

import argparse
import json
from functools import partial
from pathlib import Path

from legcal_bench import inputs
from legcal_bench.cli.robots import COUNT0, door, frame_count, robot_args
from legcal_bench.errors import ConfigError

CALIBRATE_OUT = "runs/calibrate/result.json"
EXPORT_OUT = "runs/export/offsets.yaml"


def writable_parent(path: str, option: str) -> None:
    """Create `path`'s folder now, so an unwritable output fails before the work (and
    refuse a folder given as the file)."""
    parent = Path(path).parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError(f"{option} {path}: cannot create its folder {parent} ({e.strerror}); give a path in a "
                          "folder you can write") from None
    inputs.output_file(option, path)


def cmd_calibrate(a: argparse.Namespace) -> int:
    door(a, plots=inputs.output_folder)
    from legcal_bench.calibrators.base import calibrate_training
    from legcal_bench.calibrators.registry import get_calibrator, parse_options
    from legcal_bench.data.recording import load_session
    from legcal_bench.robots import load_robot, resolve_robot

    options = parse_options(a.calibrator, a.option)
    if a.setting is not None:
        options["setting"] = a.setting
    if a.solver is not None:
        options["solver"] = a.solver
    if a.with_effects:
        options["effects"] = " ".join(a.with_effects)
    calibrator = get_calibrator(a.calibrator, **options)  # a bad name or option fails before any data is read
    writable_parent(a.out, "--out")
    legmap = load_robot(a.robot, a.mjcf)
    recordings = load_session(a.bags, allow_partial=a.allow_partial, robot=legmap)
    result = calibrate_training(calibrator, legmap, recordings)
    result.settings["robot_spec"] = resolve_robot(a.robot)
    result.save(a.out)
    if a.plots and result.conditioning.get("eigenvalues_H_reg"):
        from legcal_bench.estimation.information.observability import plot_observability

        plot_observability(result.conditioning, legmap.joint_names, Path(a.plots) / "observability.png",
                           title=f"{legmap.name} {result.calibrator}")
    print(format_result(result, legmap.joint_names))
    print(f"wrote {a.out}")
    return 0


def format_result(result, names: list[str]) -> str:
    import numpy as np

    from legcal_bench.estimation.verdict import headline

    c = result.conditioning
    lines = [headline(result.verdict), f"{result.calibrator} on {result.robot}: offsets (deg)"]
    motor, drives = result.diagnostics.get("offsets_motor_rad"), result.diagnostics.get("transmissions", {})
    linked = {n: (side, lk) for side, lk in result.diagnostics.get("linkages", {}).items() for n in lk["motors"]}
    for n in names:
        lines.append(f"  {n:<28} {np.rad2deg(result.offsets_rad[n]):+8.4f}" + (
            f"   at its encoder (motor side, {drives[n]['kind']}): {np.rad2deg(motor[n]):+8.4f}"
            if motor and n in drives else
            f"   {linked[n][1]['motors'][n]} of the {linked[n][0]} linkage ankle; the joint at the ankle's zero "
            f"{np.rad2deg(linked[n][1]['joint_offsets_at_zero_rad'][n]):+8.4f}" if n in linked else ""))
    if result.pitch_sums_rad:
        ps = result.pitch_sums_rad
        lines.append("pitch sums (deg): " + ", ".join(f"{k} {np.rad2deg(v):+.4f}" for k, v in ps.items()))
    kappas = [(label, c[key]) for label, key in (("kappa(J_data)", "kappa_J_data"), ("kappa(H_data)", "kappa_H_data"),
                                                 ("kappa(H_reg)", "kappa_H_reg")) if key in c]
    if kappas:
        lines.append("conditioning: " + ", ".join(f"{label} {v:.4g}" for label, v in kappas))
    eff = result.diagnostics.get("effects")
    if eff:
        lines.append(f"with effects {', '.join(eff['effects'])} ({eff['seconds']:.1f} s): offsets (deg) offsets-only "
                     "-> with effects (1 sigma)")
        for n in names:
            lines.append(f"  {n:<28} {np.rad2deg(eff['offsets_only_rad'][n]):+8.4f} -> "
                         f"{np.rad2deg(eff['offsets_rad'][n]):+8.4f} (±{np.rad2deg(eff['offsets_std_rad'][n]):.4f})")
        lines.append("effect parameters (SI units, 1 sigma):")
        for n, p in eff["parameters"].items():
            lines.append(f"  {n:<28} {p['value']:+.4e} ± {p['std']:.1e} {p['unit']}"
                         + ("  (held at zero: not estimable from these data)" if p["held"] else ""))
    lines.append("time (s): " + ", ".join(f"{k} {v:.3f}" for k, v in result.timing_s.items()))
    lines += [f"WARNING ({r['meaning']}): {r['text']}" for r in result.verdict["reasons"]]
    return "\n".join(lines)


def cmd_score(a: argparse.Namespace) -> int:
    import sys
    import warnings

    from legcal_bench.calibrators.base import CalibrationResult
    from legcal_bench.data.recording import UncheckedTruthWarning
    from legcal_bench.evaluation.scoring import score
    from legcal_bench.robots import load_robot

    result = CalibrationResult.load(a.result)
    legmap = load_robot(a.robot or result.settings.get("robot_spec", result.robot))
    with warnings.catch_warnings(record=True) as caught:  # ground truth that cannot be checked: said, once
        warnings.simplefilter("always", UncheckedTruthWarning)
        s = score(a.bags, result, legmap, allow_partial=a.allow_partial)
    for w in caught:
        if not issubclass(w.category, UncheckedTruthWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    for text in dict.fromkeys(str(w.message) for w in caught if issubclass(w.category, UncheckedTruthWarning)):
        print(f"legcal-bench score: warning: {text}", file=sys.stderr)
    if not a.residuals:
        s.get("heldout", {}).pop("foot_height_residuals_mm", None)
    if a.json:
        print(json.dumps(s, indent=2))
        return 0
    if "recovery_unavailable" in s:
        print(f"recovery: not scored: {s['recovery_unavailable']}")
    if "recovery" in s:
        r = s["recovery"]
        print(f"recovery: RMS {r['rms_error_deg']:.4g} deg, max {r['max_error_deg']:.4g} deg; pitch-sum errors (deg) "
              + ", ".join(f"{k} {v:+.4g}" for k, v in r["pitch_sum_error_deg"].items()))
    if "heldout" in s:
        h = s["heldout"]
        print(f"held-out ({h['frames']} frames): foot height RMS {h['foot_height_rms_mm']['before']:.3f} -> "
              f"{h['foot_height_rms_mm']['after']:.3f} mm, sole normal RMS {h['sole_normal_rms_deg']['before']:.3f} -> "
              f"{h['sole_normal_rms_deg']['after']:.3f} deg")
        if "foot_height_rms_true_mm" in h:
            t = h["foot_height_rms_true_mm"]
            print(f"  on the true held-out postures (noise-free): foot height RMS {t['before']:.4f} -> {t['after']:.4f} mm")
    return 0


def cmd_check(a: argparse.Namespace) -> int:
    """Check a session set before (or after) calibrating: what each data check measures,
    per recording, and the warnings it raises."""
    import numpy as np

    from legcal_bench.calibrators.base import CalibrationResult
    from legcal_bench.data.recording import load_session
    from legcal_bench.estimation.checks.datacheck import LIMITS, data_warnings, statistics
    from legcal_bench.robots import load_robot
    from legcal_bench.robots.kinematics import LegKinematics

    legmap = load_robot(a.robot, a.mjcf)
    result = None
    if a.result:
        result = CalibrationResult.load(a.result)
        result.check_robot(legmap, f"--result {a.result}")
    recs = load_session(a.bags, allow_partial=a.allow_partial, robot=legmap)
    if result is not None:
        dq, offsets_from = result.offsets_vector(legmap.joint_names), a.result
    else:  # offsets of a few degrees would read as defects: profiled out by the framework's fit
        from legcal_bench.estimation.checks.profile import profiled_offsets

        dq, offsets_from = profiled_offsets(legmap, recs)
    kin = LegKinematics(legmap)
    stats = [statistics(kin, r, dq) for r in recs]
    found = data_warnings(kin, recs, dq)
    contacts, contact_note = _contact_test(legmap, recs, dq)
    found += [c.text() for c in contacts or [] if c.flagged]
    if a.json:
        print(json.dumps({"robot": legmap.name, "offsets_from": offsets_from, "recordings": stats,
                          "contact_check": None if contacts is None else [c.to_dict() for c in contacts],
                          "contact_check_note": contact_note, "warnings": found}, indent=2))
        return 0
    cols = [("longest_run_encoder", "enc run", "{:d}"), ("longest_run_imu", "imu run", "{:d}"),
            ("dispersion_mm", "disp mm", "{:.2f}"), ("soles_height_mm", "soles mm", "{:+.1f}"),
            ("soles_tilt_deg", "soles °", "{:.2f}"), ("gravity_deg", "grav °", "{:.2f}"),
            ("gravity_motion_deg", "grav mov °", "{:.3f}"), ("slide_mm", "slide mm", "{:.2f}"),
            ("yaw_deg", "yaw °", "{:+.3f}"), ("left_tilt_change_deg", "L tilt Δ°", "{:.3f}"),
            ("right_tilt_change_deg", "R tilt Δ°", "{:.3f}")]
    print(f"{'recording':12s} {'kind':9s} {'frames':>6s} " + " ".join(f"{h:>10s}" for _, h, _ in cols))
    for st in stats:
        print(f"{st['name'][:12]:12s} {st['kind']:9s} {st['frames']:6d} "
              + " ".join(f"{f.format(st[k]) if k in st else '-':>10s}" for k, _, f in cols))
    print(f"limits: identical run {LIMITS.frozen_frames} frames and {LIMITS.frozen_s} s; dispersion "
          f"{LIMITS.dispersion_m * 1e3:g} mm; soles {LIMITS.coplanar_m * 1e3:g} mm, "
          f"{np.degrees(LIMITS.coplanar_rad):g}°; gravity {np.degrees(LIMITS.gravity_rad):g}°, moving "
          f"{np.degrees(LIMITS.gravity_motion_rad):g}°; slide {LIMITS.slide_m * 1e3:g} mm; yaw "
          f"{np.degrees(LIMITS.yaw_rad):g}°; sole tilt change {np.degrees(LIMITS.sole_tilt_rad):g}° "
          f"({'raw encoders and ' + a.result + ', the better fit' if a.result else offsets_from})")
    print(f"contact check: {contact_note}")
    print("\n".join(["warnings:"] + [f"  - {w}" for w in found]) if found else "no data warnings")
    return 0


def _contact_test(legmap, recs, dq) -> tuple[list | None, str]:
    """(the per-stance contact test of `recs`, the calibrator's own, or None; a line on
    what it judged)."""
    from legcal_bench.errors import CalibrationError
    from legcal_bench.estimation.checks.contact import recordings_contact_check

    try:
        contacts = recordings_contact_check(legmap, recs, dq)
    except CalibrationError as e:
        return None, f"not run: the recordings cannot be fitted ({e})"
    if contacts is None:
        return None, "not run: the recordings declare no sensor noise to judge it against, or hold one stance"
    flagged = sum(c.flagged for c in contacts)
    return contacts, (f"{len(contacts)} stances tested against the others on the declared noise (the calibrator's "
                      f"test), {flagged} off one plane")


def cmd_design(a: argparse.Namespace) -> int:
    """Predicted information of the default stances against a greedy E-optimal choice
    of sampled stances, each screened in simulation for the hold check (weld, contact)."""
    door(a, count=inputs.count, frames=frame_count, candidates=inputs.count, seed=inputs.seed,
         margin=partial(inputs.number, low=0.0, low_open=True, high=1.0,
                        fix="a fraction of the pelvis hold limit"),
         contact_seeds=COUNT0, weld_seeds=COUNT0, budget=inputs.number, out=inputs.output_file, plot=inputs.output_file)
    from legcal_bench.estimation.information.design import design
    from legcal_bench.protocol.stances import STANCES, stances_for
    from legcal_bench.robots import load_robot
    from legcal_bench.robots.kinematics import LegKinematics

    if a.count < 1 or a.candidates < a.count:
        raise ConfigError(f"--count {a.count} / --candidates {a.candidates}: need 1 <= count <= candidates")
    if a.frames < 50 * a.count:
        raise ConfigError(f"--frames {a.frames}: give at least 50 frames (1 s at 50 Hz) per stance, "
                          f"{50 * a.count} for --count {a.count}")
    kin = LegKinematics(load_robot(a.robot, a.mjcf))
    frames = a.frames
    screen = None
    if not a.no_screen:
        from legcal_bench.benchmark.plan import NATIVE
        from legcal_bench.protocol.screen import HoldScreen

        screen = HoldScreen(kin.legmap, NATIVE, contact_seeds=a.contact_seeds, weld_seeds=a.weld_seeds,
                            margin=a.margin, duration_s=frames / a.count / 50)
    catalog, default, left_out = stances_for(kin, STANCES, tuple(STANCES))  # the default protocol it stands in
    d = design(kin, [catalog[n] for n in default], k=a.count, candidates=a.candidates, frames=frames, seed=a.seed,
               sensors=a.sensors, ranges=a.ranges, screen=screen, progress=not a.json,
               budget_s=a.budget if a.budget > 0 else None)
    if a.json:
        from dataclasses import asdict

        print(json.dumps({**d, "designed_stances": [asdict(s) for s in d["designed_stances"]]}, indent=2))
        return 0
    for note in left_out:
        print(f"{kin.legmap.name}: default protocol: {note}")
    print(f"{kin.legmap.name}: {d['frames']} frames in all; {d['candidates_fitting']} of {a.candidates} sampled "
          f"stances fit the robot (predicted from the kinematics, {a.sensors} sensor noise)")
    if screen is not None:
        held = sum(r["held"] for r in d["screened"].values())
        print(f"  hold screen ({screen.describe()}): "
              f"{held} of {len(d['screened'])} screened stances held; the default stances: "
              + ", ".join(f"{n} {'held' if r['held'] else 'failed'}" for n, r in d["default_screen"].items()))
    for name in ("default", "designed"):
        s = d[name]
        print(f"  {name:8s} smallest eigenvalues {', '.join(f'{v:.3g}' for v in s['eigenvalues'])}; "
              f"kappa {s['kappa']:.3g}; worst offset std {max(s['std_deg'].values()):.4f} deg; pitch-sum std "
              + ", ".join(f"{k} {v:.4f}" for k, v in s["pitch_sum_std_deg"].items()) + " deg")
    if a.plot:
        from legcal_bench.reports.design import plot_design

        print(f"wrote {plot_design(d, kin.legmap.name, a.plot)}")
    if a.out:
        from legcal_bench.protocol.stances import write_protocol
        from legcal_bench.provenance import code_version, describe

        path = write_protocol(a.out, d["designed_stances"], {
            "robot": kin.legmap.name, "frames": d["frames"], "stance_s": d["frames"] / len(d["designed_stances"]) / 50,
            "made_by": f"legcal-bench design --robot {a.robot} --count {a.count} --frames {a.frames} "
                       f"--candidates {a.candidates} "
                       f"--ranges {a.ranges} --seed {a.seed}"
                       + (" --no-screen" if a.no_screen else
                          f" --margin {a.margin:g} --contact-seeds {a.contact_seeds} --weld-seeds {a.weld_seeds}"),
            "code": describe(code_version()),
            "predicted": {"default": d["default"], "designed": d["designed"]},
            "hold_screen": {st.name: d["screened"].get(st.name) for st in d["designed_stances"]}})
        print(f"wrote {path}: collect it with legcal-bench collect --protocol {path} --stance-seconds "
              f"{d['frames'] / len(d['designed_stances']) / 50:g}")
    for st, scale in zip(d["designed_stances"], d["motion_scales"]):
        print(f"  designed: left_x {st.left_x:+.3f}, right_x {st.right_x:+.3f}, extra_width {st.extra_width:+.3f} "
              f"(leg lengths), toe_out {st.toe_out:+.3f} rad, depth {st.depth:.3f}, motion scale {scale:.2f}")
    return 0


def cmd_excite(a: argparse.Namespace) -> int:
    """A learned open-loop excitation policy on the static env's information-gain reward,
    against no motion and the protocol's motion."""
    door(a, frames=frame_count, iterations=inputs.count, population=inputs.count, elite=inputs.count,
         seed=inputs.seed, out=inputs.output_file)
    from legcal_bench.evaluation.excitation import learn_excitation
    from legcal_bench.provenance import code_version, describe

    r = learn_excitation(a.robot, a.stance, a.mode, a.frames, a.iterations, a.population, a.elite, a.seed,
                         progress=not a.json, mjcf=a.mjcf)
    doc = {**r.to_dict(), "code": describe(code_version()),
           "made_by": f"legcal-bench excite --robot {a.robot} --stance {a.stance} --mode {a.mode} --frames {a.frames} "
                      f"--iterations {a.iterations} --population {a.population} --elite {a.elite} --seed {a.seed}"}
    if a.out:
        from legcal_bench.files.atomic import atomic_write_json

        atomic_write_json(a.out, doc)
    if a.json:
        print(json.dumps(doc, indent=2))
        return 0
    print(f"{r.robot}, stance {r.stance}, {r.mode} mode, {r.frames} frames, paper offsets, realistic sensors "
          f"({doc['code']})")
    print(f"  {'motion':9s} {'return':>8s} {'lambda_min':>11s} {'pelvis mm':>10s}  held  amplitude factors (x y z roll pitch yaw)")
    for name, e in (("none", r.still), ("protocol", r.protocol), ("learned", r.learned)):
        print(f"  {name:9s} {e.episode_return:8.2f} {e.lambda_min:11.3g} {e.pelvis_mm:10.1f}  {'yes' if e.held else 'no ':3s}  "
              + " ".join(f"{f:.2f}" for f in e.factors))
    print("  return = log det(H_data + I) gained; lambda_min in (mm, mrad)^-2 units of the env's information")
    if a.out:
        print(f"wrote {a.out}")
    return 0


def cmd_export(a: argparse.Namespace) -> int:
    door(a, out=inputs.output_file, ros2_params=inputs.output_file, urdf_out=inputs.output_file,
         mjcf_out=inputs.output_folder)
    from legcal_bench.calibrators.base import CalibrationResult
    from legcal_bench.robots import load_robot
    from legcal_bench.robots.export import (FK_TOL, check_urdf_fold, fold_into_mjcf, fold_into_urdf,
                                            write_offsets_yaml, write_ros2_params)

    from legcal_bench.estimation.verdict import DO_NOT_APPLY, INVALIDATES

    result = CalibrationResult.load(a.result)
    legmap = load_robot(a.robot or result.settings.get("robot_spec", result.robot), a.mjcf)
    result.check_robot(legmap, f"--result {a.result}")
    if result.decision == DO_NOT_APPLY and not a.force:
        why = [r["text"] for r in result.verdict["reasons"] if r["meaning"] == INVALIDATES]
        raise ConfigError(f"--result {a.result}: its verdict is do-not-apply ({len(why)} finding(s) invalidate it; "
                          f"first: {why[0]}); fix the data or the robot and calibrate again, or give --force to "
                          "write it all the same")
    if a.bags:
        from legcal_bench.data.recording import load_session

        result.check_session(load_session(a.bags, robot=legmap), f"--bags {a.bags}")
    if a.urdf_out:  # refused before anything is written
        if legmap.urdf is None:
            raise ConfigError(f"--urdf-out: robot {legmap.name} is described by an MJCF ({legmap.mjcf}), not a URDF "
                              "(its leg map has no field 'urdf'" + (", and --mjcf replaces it" if a.mjcf else "")
                              + "); use --mjcf-out NEW_FOLDER for a corrected copy of its MJCF")
        if Path(a.urdf_out).exists():
            raise ConfigError(f"--urdf-out {a.urdf_out} exists: give a new file name (an existing file is not "
                              "replaced)")
    if a.mjcf_out and Path(a.mjcf_out).exists():
        raise ConfigError(f"--mjcf-out {a.mjcf_out} exists: give a new folder (the corrected model is written whole)")
    source = str(Path(a.result).resolve())
    if result.decision != "apply":
        print(f"legcal-bench export: {'--force: ' if result.decision == DO_NOT_APPLY else ''}writing a result whose "
              f"verdict is {result.decision}: {result.verdict['reasons'][0]['text']}")
    path = write_offsets_yaml(a.out, legmap, result.offsets_rad, source=source)
    print(f"wrote {path}: {len(legmap.joint_names)} offsets of {legmap.name} in its joint names (q = q_enc + offset)")
    if a.ros2_params:
        path = write_ros2_params(a.ros2_params, legmap, result.offsets_rad, node=a.ros2_node, source=source)
        print(f"wrote {path}: ROS 2 parameter file for node {a.ros2_node} (joint_names, offsets in rad; "
              "q = q_enc + offset)")
    if a.mjcf_out:
        model = fold_into_mjcf(legmap, result.offsets_rad, a.mjcf_out)
        print(f"wrote {model}: {legmap.mjcf.name} with each leg joint's ref lowered by its offset, so the model fed "
              "raw encoder readings has the calibrated kinematics")
    if a.urdf_out:
        model = fold_into_urdf(legmap, result.offsets_rad, a.urdf_out)
        err = check_urdf_fold(legmap, result.offsets_rad, model)  # measured again on the file as written
        print(f"wrote {model}: {legmap.urdf.name} with each leg joint's origin folding its offset in and its limits "
              f"moved by -offset; Pinocchio check, every frame at random encoder readings against the original at "
              f"q_enc + offset: max difference {err:.2e} (tolerance {FK_TOL:g})")
    return 0


def cmd_diagnose(a: argparse.Namespace) -> int:
    """The model-gap loop on a set of recordings: verdict, effects, tracing (markdown, JSON, plot)."""
    from legcal_bench.calibrators.base import CalibrationResult, calibrate_training
    from legcal_bench.calibrators.registry import get_calibrator, parse_options
    from legcal_bench.data.recording import load_session
    from legcal_bench.errors import CalibrationError
    from legcal_bench.evaluation.modelgap import diagnose
    from legcal_bench.evaluation.scoring import heldout_scores
    from legcal_bench.files.reports import write_report
    from legcal_bench.provenance import code_version, describe
    from legcal_bench.reports.diagnose import (diagnosis_walks, json_ready, markdown, plot,
                                               truth_scores, walks_line)
    from legcal_bench.robots import load_robot

    if a.walk_trials < 1:
        raise ConfigError(f"--walk-trials {a.walk_trials}: give at least 1")
    door(a, out=inputs.output_folder)
    res, cal = None, None
    if a.result:
        if a.option:
            raise ConfigError("--option: give it with --calibrator; --result's offsets are already made")
        try:
            res = CalibrationResult.load(a.result)
        except CalibrationError as e:
            raise ConfigError(f"--result: {e}; give the file legcal-bench calibrate --out wrote") from None
    else:  # a bad name or option fails before any data is read
        cal = get_calibrator(a.calibrator, **parse_options(a.calibrator, a.option))
    legmap = load_robot(a.robot, a.mjcf)
    if res is not None:
        res.check_robot(legmap, f"--result {a.result}")
    if a.walk:
        from legcal_bench.policies.runner import PolicyRunner

        PolicyRunner(a.walk, legmap)  # a bad spec fails here, before the diagnosis
    recordings = load_session(a.bags, allow_partial=a.allow_partial, robot=legmap)
    if res is None:
        res = calibrate_training(cal, legmap, recordings)
    effects = a.effects or None
    report = diagnose(legmap, recordings, start=res.offsets_vector(legmap.joint_names), effects=effects,
                      progress=None if a.quiet else (lambda m: print(f"  diagnose: {m}", flush=True)))
    report["start"] = {"calibrator": res.calibrator, "settings": res.settings, "offsets_rad": res.offsets_rad}
    truth = truth_scores(report, Path(a.bags), legmap.joint_names)
    report["heldout_foot_height_mm"] = heldout_scores(report, legmap, Path(a.bags))
    made_by = (f"legcal-bench diagnose --robot {a.robot} --bags {a.bags}"
               + (f" --result {a.result}" if a.result else f" --calibrator {a.calibrator}"
                  + "".join(f" --option {kv}" for kv in a.option))
               + (f" --walk {a.walk} --walk-trials {a.walk_trials}" if a.walk else ""))
    walks = None
    if a.walk:
        walks = diagnosis_walks(report, legmap, Path(a.bags), a.walk, a.walk_trials, progress=not a.quiet)
    code = code_version()
    data = {**json_ready(report), "truth": truth, "walks": walks, "made_by": made_by, "code": code}
    md = markdown(report, made_by, describe(code), truth, walks)
    write_report(a.out, md, data, name="diagnosis")
    plot(report, Path(a.out) / "trace.png")
    print(report["verdict_line"])
    print(report["summary"])
    if truth:
        print(f"offsets RMS error vs truth: {truth['before']:.4f} deg -> {truth['after']:.4f} deg")
    hh = report["heldout_foot_height_mm"]
    if hh:
        print(f"held-out foot height RMS ({hh['postures']} postures): {hh['before']:.4f} mm -> {hh['after']:.4f} mm")
    if walks:
        print(walks_line(walks))
    print(f"wrote {a.out}/diagnosis.md, .json, trace.png")
    return 0


def add_commands(sub) -> None:
    dg = sub.add_parser("diagnose", help="model gap: does the offsets-only model explain the recordings; where the "
                                         "residual lives; which library effect is missing, or 'unexplained'",
                        description="Fit the offsets-only model to the training recordings, starting from a "
                                    "calibrator's offsets (--result, or --calibrator run now); test whether the "
                                    "residual is the declared noise (whitened chi-square, leave-one-stance-out "
                                    "gap); trace it to channels, stances and legs; and, when it is not noise, "
                                    "select library effects (BIC, cross-validation) to a verdict: explained, "
                                    "selected, ambiguous or unexplained. Writes diagnosis.md, diagnosis.json and "
                                    "trace.png into --out.")
    robot_args(dg)
    dg.add_argument("--bags", required=True, help="directory of recordings (collect --out or import --out)")
    dg.add_argument("--allow-partial", action="store_true", help="read a folder without session.json (every *.npz "
                                                                 "in it; default: refused)")
    dg.add_argument("--result", default=None, help="a calibrate result JSON of any calibrator, for this robot: the "
                                                   "diagnosis's fit starts from its offsets (default: run "
                                                   "--calibrator now)")
    dg.add_argument("--calibrator", default="interfoot", help="registered calibrator whose offsets the diagnosis "
                                                              "starts from, when no --result (default interfoot)")
    dg.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                    help="an option of --calibrator, typed from its constructor (repeatable)")
    dg.add_argument("--effects", nargs="+", default=None, metavar="EFFECT",
                    help="candidate library effects (default: all registered)")
    dg.add_argument("--out", required=True, help="report folder: diagnosis.md, diagnosis.json, trace.png (checked "
                                                 "writable before the diagnosis)")
    dg.add_argument("--walk", default=None, metavar="POLICY",
                    help="closed loop before/after: walk this policy (a built-in walker name or a spec YAML) with the "
                         "true offsets (the recordings' ground truth; for real logs, the diagnosis's final estimate) "
                         "corrected by the offsets-only estimate and by the estimate after the diagnosis (default: "
                         "no walks)")
    dg.add_argument("--walk-trials", type=int, default=5, help="seeds of the --walk comparison, at least 1 "
                                                               "(default 5)")
    dg.add_argument("--quiet", action="store_true", help="no progress output (default: progress lines)")
    dg.set_defaults(func=cmd_diagnose)

    k = sub.add_parser("calibrate", help="estimate the offsets from a directory of recordings",
                       description="Read a session folder's training recordings (stances and standing; held-out "
                                   "sessions never reach a calibrator), run a registered calibrator and write its "
                                   "result JSON: offsets (rad), pitch sums, conditioning, diagnostics, timings and "
                                   "warnings. `score`, `check`, `diagnose`, `report`, `export` and `walk "
                                   "--correction` read that file.")
    robot_args(k)
    k.add_argument("--bags", required=True, help="directory of recordings (legcal-bench collect --out, or your own)")
    k.add_argument("--allow-partial", action="store_true",
                    help="read a folder without session.json (every *.npz in it), e.g. your own logs; "
                         "otherwise refused, as a collection that may have stopped half-way")
    k.add_argument("--calibrator", default="interfoot", help="registered calibrator name (default interfoot)")
    k.add_argument("--setting", default=None, help="interfoot: sensor (default: the declared noise's weights, then "
                                                   "the generalized least squares), matched, operating (the paper's "
                                                   "weights and priors, biased on perfect data), a3_operating, "
                                                   "a2_operating")
    k.add_argument("--solver", default=None, help="interfoot's solver: projected or alternating (the paper's) "
                                                  "(default: the calibrator's, projected)")
    k.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="a calibrator option, typed by its constructor, e.g. --option lambda_q=0.1 "
                        "(repeatable; an unknown key lists the calibrator's options, types and defaults)")
    k.add_argument("--with-effects", nargs="+", default=None, metavar="EFFECT",
                   help="interfoot: also fit these model-gap effects (plug-ins of the entry-point group "
                        "legcal_bench.effects; built in: leg_length, encoder_scale, compliance, imu_tilt, hip_axis): "
                        "the result holds the offsets before and after, each parameter with its posterior standard "
                        "deviation, and what the data confound it with (default: offsets only)")
    k.add_argument("--out", default=CALIBRATE_OUT, help=f"result JSON to write, its folder made if needed (default "
                                                        f"{CALIBRATE_OUT})")
    k.add_argument("--plots", default=None, help="directory for the observability plot (default: none drawn)")
    k.set_defaults(func=cmd_calibrate)

    sc = sub.add_parser("score", help="score a result against the ground truth kept with simulated recordings",
                        description="Compare a calibration result with the injected offsets the simulated "
                                    "recordings keep (recovery RMS and max error, deg; pitch-sum errors) and "
                                    "score it on the held-out sessions (foot height, mm, and sole normal, deg, RMS "
                                    "before and after the correction). Writes nothing; prints text or JSON.")
    sc.add_argument("--bags", required=True, help="directory of recordings with their ground truth (collect --out); "
                                                  "truth files of another session set are refused")
    sc.add_argument("--allow-partial", action="store_true",
                    help="read a folder without session.json (every *.npz in it), e.g. your own logs; "
                         "otherwise refused, as a collection that may have stopped half-way")
    sc.add_argument("--result", required=True, help="result JSON (legcal-bench calibrate --out)")
    sc.add_argument("--robot", default=None, help="robot (default: the one the result was calibrated for)")
    sc.add_argument("--json", action="store_true", help="print the scores as JSON (default: text)")
    sc.add_argument("--residuals", action="store_true", help="include per-frame held-out foot-height residuals "
                                                             "(mm) in the JSON (default: left out)")
    sc.set_defaults(func=cmd_score)

    ck = sub.add_parser("check", help="check a session set's data: frozen channels, swapped columns, IMU axes, "
                                      "soles apart, slides, yaw creep, lifted heels, soles off one plane "
                                      "(no calibration)",
                        description="Measure each recording of a session set against the data checks' limits "
                                    "(identical-value runs, inter-foot dispersion, the soles' plane, the IMU's "
                                    "vertical against the posture, slide, yaw creep, sole tilt change), run the "
                                    "calibrator's per-stance contact test (each stance's soles on one plane at the "
                                    "offsets of the others, against the declared noise) and print the warnings, "
                                    "naming stance, channel and likely cause. Judged at --result's offsets, or at "
                                    "the offsets the framework's own fit profiles out. Writes nothing.")
    robot_args(ck)
    ck.add_argument("--bags", required=True, help="directory of recordings (collect --out or import --out)")
    ck.add_argument("--allow-partial", action="store_true", help="read a folder without session.json (every *.npz "
                                                                 "in it; default: refused)")
    ck.add_argument("--result", default=None, help="also judge the data corrected by this result's (this robot's) "
                                                   "offsets "
                                                   "(the calibrators do this with their own); default: the "
                                                   "offsets profiled out by the framework's own fit of the data")
    ck.add_argument("--json", action="store_true", help="print the statistics and warnings as JSON (default: a "
                                                        "table)")
    ck.set_defaults(func=cmd_check)

    de = sub.add_parser("design", help="stance design: the default stances' predicted information against a "
                                       "greedy E-optimal choice of sampled stances the robot holds in simulation "
                                       "(same frame count)",
                        description="Predict the information (the Fisher information's smallest eigenvalues, the "
                                    "offsets' standard deviations) of the default stances and of a greedy "
                                    "E-optimal choice among sampled candidate stances with the same frame budget, "
                                    "each candidate screened in simulation for the hold check (weld and contact "
                                    "floors). Optionally writes the designed stances as a protocol file (--out) "
                                    "and a plot (--plot).")
    robot_args(de)
    de.add_argument("--count", type=int, default=4, help="stances to choose, at least 1 (default 4)")
    de.add_argument("--frames", type=int, default=2400, help="frame budget of the stances in all, at 50 Hz (default "
                                                             "2400: the default protocol's four 12 s stances); "
                                                             "both protocols get it")
    de.add_argument("--candidates", type=int, default=120, help="sampled candidate stances, at least --count "
                                                                "(default 120)")
    de.add_argument("--seed", type=int, default=0, help="candidate sampling seed: an integer in [0, 2^32 - 1] "
                                                        "(default 0)")
    de.add_argument("--ranges", default="default", choices=["default", "wide"],
                    help="candidate ranges: near the paper's stances (default) or wider, up to 3x stance I's motion")
    de.add_argument("--sensors", default="realistic", help="sensor preset whose declared noise whitens the "
                                                           "information's rows")
    de.add_argument("--margin", type=float, default=0.75, help="hold screen, weld: the fraction (0 to 1] of the "
                                                               "pelvis hold limit a chosen stance must stay within "
                                                               "(default 0.75)")
    de.add_argument("--contact-seeds", type=int, default=4, help="hold screen: contact-mode seeds, at the hold limits "
                                                                  "(default 4; 0 skips contact)")
    de.add_argument("--weld-seeds", type=int, default=8, help="hold screen: weld-mode seeds (placement jitter, motion "
                                                               "phases, factory offsets; default 8), plus two cases "
                                                               "with the factory offsets at their bound")
    de.add_argument("--no-screen", action="store_true", help="skip the hold screen (kinematics only; the collected "
                                                             "protocol may then fail the hold check; default: "
                                                             "screened)")
    de.add_argument("--budget", type=float, default=600.0,
                    help="seconds after which no further stance is screened: the design then stops saying how far "
                         "it got (default 600; 0 or less: no limit)")
    de.add_argument("--out", default=None, help="write the designed stances as a protocol file (YAML) for "
                                                "collect/bench --protocol (default: none written)")
    de.add_argument("--plot", default=None, help="write a PNG: smallest eigenvalues and per-offset predicted std, "
                                                 "the default stances against the designed (default: none drawn)")
    de.add_argument("--json", action="store_true", help="print the design as JSON (default: text)")
    de.set_defaults(func=cmd_design)

    xc = sub.add_parser("excite", help="learn an open-loop excitation motion on the static env's information-gain "
                                       "reward (cross-entropy method), against no motion and the protocol's",
                        description="Learn the amplitudes of an open-loop pelvis motion in one stance by the "
                                    "cross-entropy method on the static env's information-gain reward (log det of "
                                    "the information gained), with the paper's offsets and realistic sensors, and "
                                    "compare it with no motion and the protocol's motion (return, smallest "
                                    "eigenvalue, pelvis excursion, hold check). Optionally writes the result as "
                                    "JSON (--out).")
    robot_args(xc)
    xc.add_argument("--stance", default="I", help="the stance to excite: I, II, III or IV (default I)")
    xc.add_argument("--mode", default="weld", choices=["kinematic", "weld", "contact"], help="floor model "
                                                                                          "(default weld)")
    xc.add_argument("--frames", type=int, default=600, help="frames per episode (default 600 = 12 s at 50 Hz)")
    xc.add_argument("--iterations", type=int, default=6, help="cross-entropy iterations, at least 1 (default 6)")
    xc.add_argument("--population", type=int, default=12, help="episodes per iteration, at least 1 (default 12)")
    xc.add_argument("--elite", type=int, default=3, help="best episodes the next iteration is fitted to, at least 1 "
                                                         "(default 3)")
    xc.add_argument("--seed", type=int, default=0, help="sampling seed: an integer in [0, 2^32 - 1] (default 0)")
    xc.add_argument("--out", default=None, help="write the result as JSON (a file; default: none written)")
    xc.add_argument("--json", action="store_true", help="print the result as JSON (default: a table)")
    xc.set_defaults(func=cmd_excite)

    ex = sub.add_parser("export", help="write a result's offsets for the robot (YAML in its joint names), and "
                                       "optionally a ROS 2 parameter file and a copy of its MJCF or URDF with the "
                                       "correction folded in",
                        description="Apply a calibration result on the robot: its offsets as YAML in the robot's "
                                    "own joint names (q = q_enc + offset), optionally a ROS 2 parameter file, a "
                                    "copy of its URDF whose joint origins fold the offsets in (checked with "
                                    "Pinocchio before it is written) and a copy of its MJCF whose leg joints' ref "
                                    "is lowered by them.")
    ex.add_argument("--result", required=True, help="result JSON (legcal-bench calibrate --out); required")
    ex.add_argument("--robot", default=None, help="robot (default: the one the result was calibrated for)")
    ex.add_argument("--mjcf", default=None, help="use this MJCF instead of the one the leg map names "
                                                 "(default: the leg map's)")
    ex.add_argument("--out", default=EXPORT_OUT, help=f"offsets YAML to write, its folder made if needed (default "
                                                     f"{EXPORT_OUT}; replaced if it exists)")
    ex.add_argument("--mjcf-out", default=None, help="new folder for the corrected MJCF and its assets "
                                                     "(default: none written)")
    ex.add_argument("--ros2-params", default=None, metavar="PATH",
                    help="also write a ROS 2 parameter file: <node>: ros__parameters: joint_names, offsets (rad), "
                         "robot, units, convention (default: none written; replaced if it exists)")
    ex.add_argument("--ros2-node", default="joint_offsets", metavar="NODE",
                    help="node name the ROS 2 parameter file addresses, e.g. /ns/node or /** (default joint_offsets)")
    ex.add_argument("--force", action="store_true",
                    help="write a result whose verdict is do-not-apply (default: refused, naming the finding that "
                         "invalidates it)")
    ex.add_argument("--bags", default=None, metavar="SESSION",
                    help="the session set the result was calibrated on: refused unless its training recordings are "
                         "the ones the result records (default: not checked)")
    ex.add_argument("--urdf-out", default=None, metavar="PATH",
                    help="new file for a copy of the robot's URDF with each leg joint's origin folding its offset in "
                         "and its limits moved, checked with Pinocchio before it is written; only for a robot whose "
                         "leg map names a URDF (default: none written)")
    ex.set_defaults(func=cmd_export)
