"""Scoring a calibration result against the simulator's ground truth.

recovery: signed per-joint error e_i = dq_hat_i - dq_inject_i, its RMS and maximum,
    and the errors of the pitch sums s_L, s_R, s_R - s_L. With the result's
    `imu_tilt_response` (how its estimate moves per rad of IMU tilt) and the truth's
    realized IMU errors: `imu_tilt_mrad` (the IMU's true vertical error about the pelvis
    x, y axes), `imu_share_rms_deg` (the offsets it moves, which no static level-ground
    data can separate) and `vs_imu_vertical` (the errors with that share removed: what
    the method and the data determine).
heldout: on the held-out recordings, before (dq = 0) and after (dq_hat) correction:
    foot_height_rms_mm: the flat-ground row p_Lz - p_Rz in the IMU-levelled frame
        (the paper's held-out validation; computed from the logged, noisy sensors);
    sole_normal_rms_deg: angle between each sole normal and the IMU vertical;
    and the same two on the simulator's true held-out postures (`*_true_*`: true
    joint angles minus the injected offsets, true gravity direction, no noise), which
    separate methods that the noisy version cannot (it sits at the sensor floor).
    The held-out recordings' motion is measured and resolved first (`resolve_motion`);
    `heldout.warnings` holds what it found against a declaration.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from legcal_bench.calibrators.base import CalibrationResult
from legcal_bench.data.recording import check_against_robot, in_joint_space, list_segments, load_recording, load_truth, truth_path
from legcal_bench.errors import CalibrationError, RecordingError
from legcal_bench.estimation.checks.datacheck import heldout_signs
from legcal_bench.estimation.checks.motion import resolve_motion
from legcal_bench.estimation.imu.imu_motion import compensate
from legcal_bench.estimation.imu.levelling import up_in_base
from legcal_bench.estimation.problem.residuals import flat_ground_errors
from legcal_bench.estimation.problem.smoothing import smooth_wrenches
from legcal_bench.evaluation.metrics import rms
from legcal_bench.geometry.poses import pos_quat_to_se3
from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics, pitch_sums
from legcal_bench.robots.legmap import LegMap
from legcal_bench.sim.sensors import ImuErrors


def _errors_at(kin: LegKinematics, q: np.ndarray, up_B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Foot-height differences (m) and sole-normal angles (rad, (N, 2)) at angles q (N, n), n the leg joints."""
    return flat_ground_errors(frame_kinematics(kin, q), up_B)


NO_TRUTH = ("no ground truth (*.truth.npz) beside the recordings: recovery needs the simulator's truth (logs "
            "from a real robot have none); the held-out scores use the recordings alone")


def _truths(paths, names: list[str]) -> dict:
    """The ground truth of each recording that has one, checked: every truth file must
    load, match its recording's frames, and all must declare the same finite offsets
    (one per leg joint of `names`)."""
    truths = {}
    n_joints = len(names)
    for p in paths:
        if not truth_path(p).is_file():
            continue
        t = load_truth(p)
        n = load_recording(p, names).n_frames
        if np.shape(t.offsets) != (n_joints,) or not np.isfinite(t.offsets).all():
            raise RecordingError(f"{truth_path(p)}: field 'offsets' must be {n_joints} finite numbers (radians), one "
                                 "per leg joint")
        if np.shape(t.q_true) != (n, n_joints) or len(t.pelvis_pose_world) != n:
            raise RecordingError(f"{truth_path(p)}: the ground truth has {len(t.q_true)} frames but its recording "
                                 f"{n}: it belongs to another recording (truncated or foreign); re-collect the set")
        truths[p] = t
    if truths:
        first = next(iter(truths.values())).offsets
        bad = [str(truth_path(p).name) for p, t in truths.items() if not np.array_equal(t.offsets, first)]
        if bad:
            raise RecordingError(f"{Path(paths[0]).parent}: ground-truth files {bad} declare other offsets than "
                                 "the rest: the folder mixes session sets; keep one set per folder")
    return truths


def _imu_share(kin: LegKinematics, result: CalibrationResult, truths: dict) -> tuple[np.ndarray, np.ndarray] | None:
    """(the IMU's true vertical error as a rotation about the pelvis x, y axes, in rad;
    the offsets it moves the estimate by), from the truth's realized IMU errors and the
    result's `imu_tilt_response`; None if either is missing."""
    V = result.diagnostics.get("imu_tilt_response")
    errors = [t.meta.get("imu_errors") for t in truths.values()]
    if V is None or any(e is None for e in errors):
        return None
    V = np.asarray(V, dtype=float)
    n_joints = kin.legmap.n_joints
    if V.shape != (n_joints, 2) or not np.isfinite(V).all():
        raise CalibrationError(f"diagnostics.imu_tilt_response must be {n_joints} x 2 finite numbers (offsets per rad "
                               "of IMU tilt about the pelvis x and y axes, one row per leg joint)")
    imu = ImuErrors.from_dict(errors[0])
    stance_up = [pos_quat_to_se3(x).rotation.T @ [0.0, 0.0, 1.0] for t in truths.values()
                 for x in t.pelvis_pose_world[::10]]
    u_B = np.mean(stance_up, axis=0)
    u_B /= np.linalg.norm(u_B)
    v_B = kin.R_BI @ imu.vertical(kin.R_BI.T @ u_B)
    tilt = np.cross(u_B, v_B)[:2]
    return tilt, V @ tilt


def vs_imu_rms_deg(kin: LegKinematics, result: CalibrationResult, truths: dict) -> float | None:
    """The offsets' RMS error (deg) with the IMU's realized tilt taken out (`score`'s
    `vs_imu_vertical`), against `truths` (recording name -> Truth) of the set `result`
    was calibrated on or of an edit of it; None where the truth or the result lacks the
    IMU's share."""
    share = _imu_share(kin, result, truths)
    if share is None:
        return None
    injected = next(iter(truths.values())).offsets
    return float(np.rad2deg(rms(result.offsets_vector(kin.legmap.joint_names) - injected - share[1])))


def score(bags: str, result: CalibrationResult, legmap: LegMap, allow_partial: bool = False) -> dict:
    kin = LegKinematics(legmap)
    names = legmap.joint_names
    dq = result.offsets_vector(names)
    result.check_robot(legmap)
    paths = list_segments(bags, allow_partial)
    recordings = in_joint_space([load_recording(p, names) for p in paths], legmap)
    check_against_robot(recordings, legmap)
    result.check_session(recordings, f"--bags {bags}")
    truths = _truths(paths, names)
    out: dict = {"calibrator": result.calibrator, "robot": legmap.name, "settings": result.settings}
    if not truths:
        out["recovery_unavailable"] = NO_TRUTH
    if truths:
        injected = next(iter(truths.values())).offsets
        e = dq - injected
        signs = kin.pitch_signs()
        ps_hat, ps_true = pitch_sums(dq, signs), pitch_sums(injected, signs)
        out["recovery"] = {
            "per_joint_error_deg": {n: float(np.rad2deg(v)) for n, v in zip(names, e)},
            "rms_error_deg": float(np.rad2deg(rms(e))),
            "max_error_deg": float(np.rad2deg(np.abs(e).max())),
            "pitch_sum_error_deg": {k: float(np.rad2deg(ps_hat[k] - ps_true[k])) for k in ps_hat},
            "injected_deg": {n: float(np.rad2deg(v)) for n, v in zip(names, injected)},
        }
        share = _imu_share(kin, result, truths)
        if share is not None:
            tilt, moved = share
            rel = e - moved
            out["recovery"]["imu_tilt_mrad"] = (tilt * 1e3).tolist()
            out["recovery"]["imu_share_rms_deg"] = float(np.rad2deg(rms(moved)))
            out["recovery"]["vs_imu_vertical"] = {
                "rms_error_deg": float(np.rad2deg(rms(rel))), "max_error_deg": float(np.rad2deg(np.abs(rel).max())),
                "pitch_sum_error_deg": {k: float(np.rad2deg(v)) for k, v in pitch_sums(rel, signs).items()}}
    R_BI = kin.R_BI
    held = [(p, r) for p, r in zip(paths, recordings) if r.kind == "heldout"]
    if held:
        h0, h1, n0, n1, ht0, ht1, nt0, nt1 = ([] for _ in range(8))
        heldout_warnings: list[str] = heldout_signs(kin, recordings, dq)  # a reversed sign scores as a poor fit
        for p, r in held:
            (rec,), found = resolve_motion(kin, [r])
            heldout_warnings += found
            acc = compensate(kin, rec.time, rec.q_enc, rec.imu_acc) if rec.motion == "continuous" else rec.imu_acc
            up = up_in_base(acc, R_BI)
            for store_h, store_n, corr in ((h0, n0, 0.0), (h1, n1, dq)):
                h, a = _errors_at(kin, rec.q_enc + corr, up)
                store_h.append(h)
                store_n.append(a.ravel())
            if p in truths:
                t = truths[p]
                q_enc_true = t.q_enc_clean if t.q_enc_clean is not None else t.q_true - t.offsets
                up_true = np.array([(pos_quat_to_se3(x).rotation.T @ [0, 0, 1.0]) for x in t.pelvis_pose_world])
                for store_h, store_n, corr in ((ht0, nt0, 0.0), (ht1, nt1, dq)):
                    h, a = _errors_at(kin, q_enc_true + corr, up_true)
                    store_h.append(h)
                    store_n.append(a.ravel())
        cat = np.concatenate
        out["heldout"] = {
            "sessions": len(held), "frames": int(sum(len(x) for x in h0)),
            "foot_height_rms_mm": {"before": rms(cat(h0)) * 1e3, "after": rms(cat(h1)) * 1e3},
            "sole_normal_rms_deg": {"before": float(np.rad2deg(rms(cat(n0)))),
                                    "after": float(np.rad2deg(rms(cat(n1))))},
            "foot_height_residuals_mm": {"before": (cat(h0) * 1e3).tolist(), "after": (cat(h1) * 1e3).tolist()},
        }
        if heldout_warnings:
            out["heldout"]["warnings"] = heldout_warnings
        if ht0:
            out["heldout"]["foot_height_rms_true_mm"] = {"before": rms(cat(ht0)) * 1e3, "after": rms(cat(ht1)) * 1e3}
            out["heldout"]["sole_normal_rms_true_deg"] = {"before": float(np.rad2deg(rms(cat(nt0)))),
                                                          "after": float(np.rad2deg(rms(cat(nt1))))}
    return out


def heldout_heights(legmap: LegMap, paths, effects, estimates: dict) -> dict | None:
    """Held-out foot height RMS (mm) per estimate (label -> parameter vector x of the
    model with `effects`, names or `Effect` instances: the offsets, one per leg joint,
    then the effects' parameters): the flat-ground row p_Lz - p_Rz of the held-out recordings through the model at x. On the
    simulator's true postures and vertical where the recordings keep a ground truth
    ("true"), else on the logged encoders and the IMU-levelled vertical ("logged").
    None without held-out recordings."""
    from legcal_bench.estimation.modelgap.effects import EffectModel, EffectSegment, SegmentData, load_effects
    from legcal_bench.estimation.problem.residuals import foot_height_difference

    kin = LegKinematics(legmap)
    names = legmap.joint_names
    model = EffectModel(kin, [load_effects([e])[0] if isinstance(e, str) else e for e in effects])
    heights: dict = {k: [] for k in estimates}
    kinds = set()
    for p in paths:
        (rec,) = in_joint_space([load_recording(p, names)], legmap)
        if rec.kind != "heldout":
            continue
        if truth_path(p).is_file():
            t = load_truth(p)
            q = t.q_enc_clean if t.q_enc_clean is not None else t.q_true - t.offsets
            up = np.array([pos_quat_to_se3(x).rotation.T @ [0, 0, 1.0] for x in t.pelvis_pose_world])
            kinds.add("true")
        else:
            (rec,), _ = resolve_motion(kin, [rec])  # its warnings are `score`'s (heldout.warnings)
            acc = compensate(kin, rec.time, rec.q_enc, rec.imu_acc) if rec.motion == "continuous" else rec.imu_acc
            q, up = rec.q_enc, up_in_base(acc, kin.R_BI)
            kinds.add("logged")
        ft = None if rec.ft is None else smooth_wrenches(rec.time, rec.ft)
        for key, x in estimates.items():
            x = np.asarray(x, dtype=float)
            seg = EffectSegment(model, SegmentData(q, ft, up, q_ref=q + x[:model.n_offsets],
                                                   time=np.asarray(rec.time, dtype=float)))
            heights[key].append(foot_height_difference(seg.state(model.values(x)), up))
    if not kinds:
        return None
    return {"postures": "+".join(sorted(kinds)),
            **{k: float(1e3 * rms(np.concatenate(v))) for k, v in heights.items()}}


def heldout_scores(report: dict, legmap, bags: Path) -> dict | None:
    """Held-out foot height RMS (mm) with the offsets-only estimate ("before"), the
    recommended one ("after") and every candidate model at its fitted values
    (`legcal_bench.evaluation.scoring.heldout_heights`). Scored after the choice: the
    held-out sessions never pick the estimate."""
    names = legmap.joint_names
    paths = list_segments(bags, allow_partial=True)
    out = heldout_heights(legmap, paths, [], {"before": [report["offsets_only_rad"][n] for n in names]})
    if out is None:
        return None
    per = {}
    for name, (effects, x) in report.get("_candidate_models", {}).items():
        per[name] = heldout_heights(legmap, paths, effects, {"x": x})["x"]
    rec = report.get("recommended")
    out["after"] = per[rec] if rec in per else out["before"]
    out["candidates"] = per
    return out
