from pathlib import Path

import numpy as np
import pytest

from legcal_bench.calibrators.base import CalibrationResult

from legcal_bench.calibrators.registry import available_calibrators, get_calibrator
from legcal_bench.data.recording import load_session
from legcal_bench.errors import CalibrationError
from legcal_bench.robots import load_robot
from legcal_bench.sim.offsets import paper_injection

G1_LEGMAP = str(Path(__file__).resolve().parents[2] / "examples" / "unitree_g1.legmap.yaml")
SMALL = dict(stance_s=4.0, heldout_s=2.0, standing_s=1.0, heldout=1)


def _session(collected, robot, **kw):
    """A set collected once per test process (`collected`), loaded afresh: tests edit
    the arrays they get, never the files."""
    out = collected(robot=robot, **{**SMALL, **kw})
    lm = load_robot(robot)
    return lm, load_session(out, lm.joint_names), out


@pytest.mark.parametrize("robot", ["a2", "a3", G1_LEGMAP])
def test_zero_noise_kinematic_matched_recovers_to_1e_10_deg(collected, robot):
    lm, recs, _ = _session(collected, robot, mode="kinematic", sensors="zero")
    res = get_calibrator("interfoot", setting="matched").calibrate(lm, recs)
    err = np.rad2deg(res.offsets_vector(lm.joint_names) - paper_injection(lm))
    assert np.abs(err).max() < 1e-10, err
    assert res.warnings == []
    assert res.diagnostics["frames_used"] == 4 * 180  # 200 per stance, 10 % trimmed


def test_paper_alternation_stops_short_of_the_optimum_the_projected_solve_reaches(collected):
    lm, recs, _ = _session(collected, "a3", mode="kinematic", sensors="zero")
    truth = paper_injection(lm)
    alt = get_calibrator("interfoot", setting="matched", solver="alternating", trim_fraction=0.0).calibrate(lm, recs)
    hist = np.array(alt.diagnostics["history_first_solve"])
    errs = np.abs(hist - truth).max(axis=1)
    # Fifteen outer iterations (the paper's cap), each better than the last, none at the optimum.
    assert len(hist) == 15 and np.all(np.diff(errs) < 0)
    assert 1e-6 < np.abs(alt.offsets_vector(lm.joint_names) - truth).max() < np.abs(truth).max()
    # The projected solve on the same data reaches it.
    proj = get_calibrator("interfoot", setting="matched", trim_fraction=0.0).calibrate(lm, recs)
    assert np.rad2deg(np.abs(proj.offsets_vector(lm.joint_names) - truth).max()) < 1e-10


def test_result_json_round_trip_and_required_fields(collected, tmp_path):
    lm, recs, _ = _session(collected, "a3", mode="kinematic")
    res = get_calibrator("interfoot", setting="operating").calibrate(lm, recs)
    back = CalibrationResult.load(res.save(tmp_path / "r.json"))
    assert back.offsets_rad == res.offsets_rad
    assert set(back.conditioning) >= {"kappa_J_data", "kappa_H_data", "kappa_H_reg", "eigenvalues_H_data"}
    assert set(back.pitch_sums_rad) == {"left", "right", "right_minus_left"}
    assert back.diagnostics["setting"] == "a3_operating" and back.diagnostics["knee_prior_rad"] is not None
    assert "interfoot" in available_calibrators()


def test_a_single_static_posture_is_refused_with_the_combinations(collected):
    lm, recs, _ = _session(collected, "a3", mode="kinematic", stances=("I",))
    still = [r for r in recs if r.kind == "stance"][0]
    still.q_enc[:] = still.q_enc[0]  # the robot never moved
    with pytest.raises(CalibrationError, match="not determined by the data or any prior: .*hip"):
        get_calibrator("interfoot", setting="matched").calibrate(lm, [still])


def test_regularised_but_unobservable_gets_a_warning(collected):
    lm, recs, _ = _session(collected, "a3", mode="kinematic", stances=("I",))
    res = get_calibrator("interfoot", setting="matched", lambda_g=0.0, lambda_q=1.0).calibrate(lm, recs)
    assert any("do not determine" in w and "hip_pitch" in w for w in res.warnings)


def test_too_few_frames_and_no_stance(collected):
    lm, recs, _ = _session(collected, "a3", mode="kinematic", stances=("I",))
    stance = [r for r in recs if r.kind == "stance"][0]
    for k in ("time", "q_enc", "imu_acc", "imu_gyro"):
        setattr(stance, k, getattr(stance, k)[:10])
    with pytest.raises(CalibrationError, match="no usable frames .*10 raw"):
        get_calibrator("interfoot").calibrate(lm, [stance])
    with pytest.raises(CalibrationError, match="no stance recordings"):
        get_calibrator("interfoot").calibrate(lm, [r for r in recs if r.kind != "stance"])


def test_nan_frames_slip_and_lifted_foot_are_filtered_and_counted(collected):
    lm, recs, _ = _session(collected, "a3", mode="kinematic", sensors="zero", stances=("I", "II"))
    s1, s2 = [r for r in recs if r.kind == "stance"]
    s1.q_enc[5:8, 2] = np.nan
    # A sudden slip halfway through stance II: the left ankle pitch reading jumps by
    # 2 degrees (the foot rotated and stayed there).
    s2.q_enc[120:, 4] += np.deg2rad(2.0)
    # A lifted/tilted foot for a burst of stance I: ankle roll off by 8 degrees.
    s1.q_enc[60:70, 5] += np.deg2rad(8.0)
    res = get_calibrator("interfoot", setting="matched").calibrate(lm, [s1, s2])
    f1, f2 = res.diagnostics["filter"]
    assert f1["non_finite"] == 3 and f1["rotation"] == 10
    assert f2["slip_splits"] == 1 and f2["pieces"] == ["stance_II#1", "stance_II#2"]
    assert any("stance_I:" in w and "3 non-finite" in w for w in res.warnings)


def test_the_sensor_setting_ends_with_the_generalized_least_squares_and_its_posterior_holds(collected):
    """The "sensor" fit whitens every frame by its declared covariance: its error is well
    below the row-weighted solution it starts from (the last iterate before the refinement,
    the fit of commit c30118a and before), and its posterior predicts that error."""
    lm = load_robot("a3")
    z2, sq_gls, sq_rows = [], 0.0, 0.0
    for seed in range(3):
        _, recs, _ = _session(collected, "a3", mode="kinematic", sensors="calibrated-imu", seed=seed)
        res = get_calibrator("interfoot", setting="sensor").calibrate(lm, recs)
        truth = paper_injection(lm)
        err = res.offsets_vector(lm.joint_names) - truth
        rows = np.asarray(res.diagnostics["history_after_trim"][-1]) - truth
        std = np.array([res.diagnostics["posterior"]["std_rad"][n] for n in lm.joint_names])
        assert res.diagnostics["generalized_least_squares"]["converged"]
        z2 += list((err / std) ** 2)
        sq_gls, sq_rows = sq_gls + err @ err, sq_rows + rows @ rows
    # 36 offsets: the mean z^2 of a right posterior lies in [0.54, 1.57] 95 % of the time.
    assert 0.4 < np.mean(z2) < 2.0, np.mean(z2)
    assert sq_gls < 0.5 * sq_rows, (sq_gls, sq_rows)


def test_the_generalized_least_squares_is_not_used_where_the_declared_noise_is_rejected(collected):
    """Frames weighed by a noise model the data reject: the fit keeps the row-weighted
    solution and says why. Here the recordings declare half their true noise (chi2/dof
    about 4); declared right, the same data give chi2/dof about 1 and the whitened fit."""
    from dataclasses import replace

    lm, recs, _ = _session(collected, "a3", mode="kinematic", sensors="calibrated-imu", seed=0)
    right = get_calibrator("interfoot", setting="sensor").calibrate(lm, recs)
    gls = right.diagnostics["generalized_least_squares"]
    assert gls["used"] and 0.9 < gls["chi2_per_dof"] < 1.1, gls
    for r in recs:
        m = r.sensor_model
        r.sensor_model = replace(m, encoder_noise_std=m.encoder_noise_std / 2, encoder_resolution=m.encoder_resolution / 2,
                                 accel_noise_std=m.accel_noise_std / 2)
    wrong = get_calibrator("interfoot", setting="sensor").calibrate(lm, recs)
    gls = wrong.diagnostics["generalized_least_squares"]
    assert not gls["used"] and 3.5 < gls["chi2_per_dof"] < 4.5, gls
    assert np.allclose(wrong.offsets_vector(lm.joint_names), wrong.diagnostics["history_after_trim"][-1])
    assert any("generalized least squares: not used" in w and "chi2/dof" in w for w in wrong.warnings)
