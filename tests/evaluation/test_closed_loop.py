"""The closed-loop evaluation (issue #15): one short trial end to end on the G1."""

from __future__ import annotations

import pytest

from tests.conftest import G1_LEGMAP
from tests.envs.test_walking import G1_POLICY, needs_g1

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


@needs_g1
def test_one_trial_calibrates_then_walks_four_conditions(tmp_path, capsys):
    from legcal_bench.cli import main

    assert main(["walk-eval", "--robot", str(G1_LEGMAP), "--policy", str(G1_POLICY), "--offsets", "paper@3",
                 "--trials", "1", "--seconds", "4", "--workers", "1", "--out", str(tmp_path), "--quiet"]) == 0
    import json

    d = json.loads((tmp_path / "report.json").read_text())
    s, [t] = d["summaries"][0], d["trials"][0]
    c = s["conditions"]
    assert all(c[k]["upright"] == 1 for k in ("nominal", "uncorrected", "corrected", "oracle"))
    unc, cor, ora = (c[k]["pelvis_rms_mm"]["mean"] for k in ("uncorrected", "corrected", "oracle"))
    # 3 deg on every joint moves the walk by decimetres in 4 s; the static calibration
    # (0.01-0.02 deg) leaves millimetres; the true correction repeats the nominal walk.
    assert unc > 300 and cor < 0.05 * unc and ora < 1.0
    assert t["recovery_rms_deg"] < 0.05 and s["config"]["options"] == {"setting": "sensor"}
    # Wall-clock times beside the report, not in it (a resumed run's report is an uninterrupted one's).
    assert json.loads((tmp_path / "timings.json").read_text())["evaluations"][0]["trials"][0]["static_s"] > 0
    assert s["nominal_spread"]["pelvis_rms_mm"]["n"] == 1
    assert (tmp_path / "paths.png").stat().st_size > 10_000  # a fixed name, nothing of the offsets in it
    assert "| corrected | 1/1 |" in (tmp_path / "report.md").read_text()


@needs_g1
def test_leg_odometry_follows_the_walk_and_a_hip_pitch_offset_tilts_it():
    import numpy as np

    from legcal_bench.envs.walking import WalkingEnv
    from legcal_bench.evaluation.odometry import (centre_of_pressure, imu_orientation, leg_odometry, odometry_errors,
                                                  pitch_sensitivity, pose_matrices, sole_from_ft)
    from legcal_bench.evaluation.walk import walk
    from legcal_bench.policies.runner import PolicyRunner
    from legcal_bench.robots.kinematics import LegKinematics

    env = WalkingEnv(robot=str(G1_LEGMAP), policy=str(G1_POLICY))
    w = walk(env, PolicyRunner(env.policy_spec, env.legmap), 6.0, seed=2, options={"offsets": "none"}, log=True)
    kin, truth = LegKinematics(env.legmap), pose_matrices(w.pelvis)
    R = imu_orientation(w.gravity, w.ang_vel, env.dt, truth[0, :3, :3])
    cop = centre_of_pressure(w.ft, sole_from_ft(env.legmap))
    # Centres of pressure stay on the sole (G1: 0.17 m long, 0.06 m wide), give or take light loads.
    loaded = w.loads > 100
    assert np.percentile(np.abs(cop[..., 0][loaded]), 95) < 0.1 and np.percentile(np.abs(cop[..., 1][loaded]), 95) < 0.05
    e = odometry_errors(leg_odometry(kin, w.q_enc, w.loads, R, truth[0, :3, 3], cop), truth)
    moved = np.linalg.norm(truth[-1, :2, 3] - truth[0, :2, 3])
    assert moved > 2.0 and e["total_mm"] < 0.02 * 1e3 * moved  # within 2 % of the distance walked
    # Anchoring the sole's origin instead drifts more: a rolling foot's origin leaves the floor.
    e0 = odometry_errors(leg_odometry(kin, w.q_enc, w.loads, R, truth[0, :3, 3]), truth)
    assert e0["vertical_mm"] > 1.5 * e["vertical_mm"]
    # A symmetric hip-pitch offset tilts the kinematic base: height drifts by about the
    # offset's tangent times the distance.
    s = pitch_sensitivity(kin, w.q_enc, w.loads, R, truth, cop)
    assert s["m_per_deg"] == pytest.approx(np.tan(np.deg2rad(1)) * moved, rel=0.15)


@needs_g1
def test_the_closed_loop_suite_gives_every_variant_a_row_and_resumes(tmp_path, capsys, monkeypatch):
    from dataclasses import replace

    import legcal_bench.benchmark.closed_loop as suite
    from legcal_bench.benchmark.plan import plan
    from legcal_bench.cli import main
    from legcal_bench.errors import ConfigError

    # 4 s walks instead of the suite's 20 s: the rows and the resume are what this tests.
    configs = suite.suite_configs
    monkeypatch.setattr(suite, "suite_configs", lambda *a, **k: [replace(c, seconds=4.0) for c in configs(*a, **k)])

    with pytest.raises(ConfigError, match="walks, it has no static cells"):
        plan("closed-loop")
    args = ["bench", "--suite", "closed-loop", "--robots", "a3", "--seeds", "1", "--workers", "1", "--out",
            str(tmp_path), "--quiet"]
    assert main(args) == 0
    files = sorted((tmp_path / "closed_loop").glob("*.json"))
    assert [f.name for f in files] == ["a3_paper3.json", "a3_random3.json"]  # our policy walks the A3-like robot
    text = (tmp_path / "README.md").read_text()
    section = text[text.index("## Closed loop"):]
    for row in ("interfoot-sensor", "interfoot-operating", "yamane-sensor", "zero-default", "*uncorrected*"):
        assert f"| {row} | 1/1 |" in section
    # zero-default corrects nothing: its walk is the uncorrected one.
    assert "| zero-default | 1/1 | 3.0000 ± 0.0000 |" in section and "100.00 %" in section
    stamp = files[0].stat().st_mtime_ns
    capsys.readouterr()
    assert main(args) == 0 and files[0].stat().st_mtime_ns == stamp  # kept: same key


def test_a_trial_whose_static_set_cannot_be_held_walks_without_a_correction(monkeypatch, tmp_path):
    """The robot cannot hold the static sessions with some offsets: that trial gets no
    estimate and no corrected walk, is counted and named, and the others go on."""
    import legcal_bench.protocol.collect as collect_module
    from legcal_bench.errors import HoldError
    from legcal_bench.evaluation.closed_loop import ClosedLoopConfig, run_trial, summarize
    from legcal_bench.reports.closed_loop import write

    def cannot_hold(*args, **kwargs):
        raise HoldError("segment stance_I: the robot did not hold the posture. Fix: stiffer gains")

    monkeypatch.setattr(collect_module, "collect", cannot_hold)
    cfg = ClosedLoopConfig(robot="a3", policy="a3", offsets="paper@3", trials=1, seconds=1.0, calibrator="interfoot",
                           variants=(("zero-default", "zero", ()),))
    t = run_trial(cfg, 0)
    assert t["static_failed"].startswith("segment stance_I") and t["estimate_rad"] is None
    assert t["corrected"] == {"skipped": t["static_failed"]} and "skipped" in t["variants"]["zero-default"]
    assert t["uncorrected"]["upright"] and t["oracle"]["upright"] and t["odometry"] is None
    s = summarize(cfg, [t])
    assert s["static_failed"]["count"] == 1 and s["static_failed"]["seeds"] == [0]
    assert s["conditions"]["corrected"]["trials"] == 0 and s["conditions"]["uncorrected"]["trials"] == 1
    write(tmp_path, [s], [[t]], "test", "test")
    assert "1 trial(s) without a calibration** (seeds [0])" in (tmp_path / "report.md").read_text()


def test_trials_as_separate_tasks_give_the_rows_of_whole_trials():
    """`evaluate` through an executor runs each trial's static estimate, walks and
    odometry as tasks of their own (threads here: each keeps its own walker); the rows
    are `run_trial`'s, number for number."""
    from concurrent.futures import ThreadPoolExecutor

    from legcal_bench.evaluation.closed_loop import ClosedLoopConfig, evaluate, run_trial

    cfg = ClosedLoopConfig(robot="a3", policy="a3", offsets="random:3", trials=2, seconds=1.0,
                           options={"setting": "sensor"}, variants=(("zero", "zero", ()),))
    with ThreadPoolExecutor(2) as ex:
        summary, rows = evaluate(cfg, ex, progress=False)
    timing = ("static_s", "wall_s")

    def numbers(v):  # the row without its timings, NaN comparable
        if isinstance(v, dict):
            return {k: numbers(x) for k, x in v.items() if k not in timing}
        if isinstance(v, list):
            return [numbers(x) for x in v]
        return "nan" if isinstance(v, float) and v != v else v

    assert [numbers(r) for r in rows] == [numbers(run_trial(cfg, s)) for s in (0, 1)]
    assert summary["variants"]["zero"]["trials"] == 2 and summary["odometry"]["after"]["total_mm"]["n"] == 2


def test_a_trial_whose_static_set_failed_walks_without_a_correction_either_way(monkeypatch):
    from concurrent.futures import ThreadPoolExecutor

    from legcal_bench.evaluation import closed_loop
    from legcal_bench.evaluation.walk import trial_offsets
    from legcal_bench.robots import load_robot

    cfg = closed_loop.ClosedLoopConfig(robot="a3", policy="a3", trials=2, seconds=0.5, variants=(("zero", "zero", ()),))
    failed = lambda cfg, seed: {"dq": trial_offsets(cfg.offsets, load_robot("a3"), seed), "dq_hat": None,  # noqa: E731
                                "others": {}, "failed": "did not hold", "warnings": [], "static_s": 0.0}
    monkeypatch.setattr(closed_loop, "static_estimate", failed)
    with ThreadPoolExecutor(2) as ex:
        summary, rows = closed_loop.evaluate(cfg, ex, progress=False)
    assert summary["static_failed"]["count"] == 2 and summary["conditions"]["corrected"]["trials"] == 0
    alone = closed_loop.run_trial(cfg, 1)
    assert rows[1]["corrected"] == alone["corrected"] == {"skipped": "did not hold"}
    assert rows[1]["variants"] == alone["variants"] and rows[1]["odometry"] is alone["odometry"] is None
    assert rows[1]["uncorrected"]["path"] == alone["uncorrected"]["path"]
