"""Warnings derived from the data (issue #10): each defect a real log can carry is named
with its stance, channel and likely cause by both calibrators, and clean recordings of
every kind get none."""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import numpy as np
import pytest

from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import load_session
from legcal_bench.estimation.checks.datacheck import data_warnings
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.reports.robots_check import _cols, _edit_legs_swapped, _edit_roll_yaw_swapped
from legcal_bench.reports.robots_check import _role_col as _role
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics

G1 = str(Path(__file__).resolve().parents[2] / "examples" / "unitree_g1.legmap.yaml")
# The tests share the recordings `sessions` collects: one process runs them all.
pytestmark = pytest.mark.xdist_group("datacheck")


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    """Clean weld recordings (realistic sensors, the paper's offsets) by robot, cached."""
    cache = {}

    def get(robot, **kw):
        key = (robot, tuple(sorted(kw.items())))
        if key not in cache:
            out = tmp_path_factory.mktemp("clean") / "set"
            collect(CollectConfig(robot=robot, heldout=0, standing_s=0.0, **kw), out, progress=False)
            lm = load_robot(robot)
            recs = load_session(out, robot=lm)
            truth = np.load(out / "stance_I.truth.npz")["offsets"]
            cache[key] = (lm, recs, truth)
        return cache[key]
    return get




def _move_left_sole(lm, recs, truth, twist):
    """Encoders of a left sole that moves by `twist` (local [v, w], growing linearly over
    stance II) while the pelvis holds: the leg's joints follow the sole Jacobian."""
    kin = LegKinematics(lm)
    r = recs[1]
    J = frame_kinematics(kin, r.q_enc + truth).J_L
    s = np.linspace(0.0, 1.0, r.n_frames)
    for k in range(r.n_frames):
        r.q_enc[k, _cols(lm, "left")] += np.linalg.lstsq(J[k], twist * s[k], rcond=None)[0]


def _swap_legs(lm, recs, truth):
    _edit_legs_swapped(lm, recs)


def _swap_roll_yaw(lm, recs, truth):
    _edit_roll_yaw_swapped(lm, recs)


def _reverse_knee(lm, recs, truth):
    for r in recs:
        r.q_enc[:, _role(lm, "right", "knee")] *= -1


def _imu_axes(order):
    def edit(lm, recs, truth):
        for r in recs:
            r.imu_acc = r.imu_acc[:, order]
    return edit


def _imu_flip_x(lm, recs, truth):
    for r in recs:
        r.imu_acc[:, 0] *= -1


def _imu_stuck(lm, recs, truth):
    r = recs[1]
    r.imu_acc[200:400], r.imu_gyro[200:400] = r.imu_acc[200], r.imu_gyro[200]


def _encoder_frozen(lm, recs, truth):
    j = _role(lm, "left", "knee")
    recs[2].q_enc[100:250, j] = recs[2].q_enc[100, j]


def _heel_lifts(lm, recs, truth):
    recs[1].q_enc[300:, _role(lm, "left", "ankle_pitch")] += np.deg2rad(2.0)


def _slide(lm, recs, truth):
    _move_left_sole(lm, recs, truth, np.array([0.006, 0, 0, 0, 0, 0]))


def _yaw_creep(lm, recs, truth):
    _move_left_sole(lm, recs, truth, np.array([0, 0, 0, 0, 0, np.deg2rad(0.8)]))


# (defect, edit, the warning it must produce)
DEFECTS = [
    ("legs swapped", _swap_legs, r"stance_I, stance_II, stance_III, stance_IV: the inter-foot transform varies .*"
                                 r"likely the left and right legs' columns are exchanged"),
    ("hip roll/yaw swapped", _swap_roll_yaw, r"stance_I, .*likely the hip_roll and hip_yaw columns are exchanged "
                                             r"on both legs"),
    ("knee reversed", _reverse_knee, r"likely right_knee_joint reads with the opposite sign"),
    ("IMU x<->z", _imu_axes([2, 1, 0]), r"stance_I, .*IMU's vertical .*likely permuted or flipped IMU axes .*"
                                        r"x = \+logged z, y = \+logged y, z = \+logged x"),
    ("IMU x<->y", _imu_axes([1, 0, 2]), r"likely permuted or flipped IMU axes .*x = \+logged y, y = \+logged x"),
    ("IMU x reversed", _imu_flip_x, r"likely permuted or flipped IMU axes .*x = -logged x, y = \+logged y"),
    ("IMU stuck", _imu_stuck, r"stance_II: IMU accelerometer x, IMU accelerometer y, IMU accelerometer z, IMU gyro x, "
                              r"IMU gyro y, IMU gyro z read one unchanging value from t = 4.0\d to 8.00 s"),
    ("encoder frozen", _encoder_frozen, r"stance_III: encoder left_knee_joint reads one unchanging value from "
                                        r"t = 2.0\d to 5.00 s .*frozen or disconnected encoder"),
    ("heel lifts", _heel_lifts, r"stance_II: the left sole's tilt against the IMU's vertical changed 1.\d\d deg "
                                r"\(pitch\).*likely its heel lifted"),
    ("gradual slide", _slide, r"stance_II: the feet moved [4-6].\d mm relative to each other.*left sole's x.*"
                              r"sliding gradually"),
    ("yaw creep", _yaw_creep, r"stance_II: the inter-foot yaw changed -0.[5-8]\d deg.*creeping in yaw"),
]


def defects_on_another_robot(slow: tuple[str, ...]):
    """DEFECTS as test parameters, the named ones `slow`: on a robot other than the
    A3-like one, the defects that robot's kinematics do not bear on (a knee read
    reversed where the knee is as the A3-like robot's; the IMU's axes where it is
    mounted unrotated, as the A3-like robot's) run in `make test-slow`; the test command
    runs them on the A3-like robot with both calibrators."""
    return [pytest.param(*d, id=d[0], marks=[pytest.mark.slow] if d[0] in slow else []) for d in DEFECTS]


# The G1's cases are in test_datacheck_g1.py: a group of their own, so the two robots'
# cases run side by side under pytest-xdist, each robot's recordings collected once.
@pytest.mark.parametrize("calibrator", ["interfoot", "yamane"])
@pytest.mark.parametrize("defect, edit, expected", DEFECTS, ids=[d[0] for d in DEFECTS])
def test_each_defect_is_named_by_both_calibrators(sessions, calibrator, defect, edit, expected):
    check_defect(sessions, "a3", calibrator, edit, expected)


def check_defect(sessions, robot, calibrator, edit, expected):
    """The planted defect `edit` in `robot`'s clean recordings is named (`expected`), once,
    by the data checks `calibrator` runs."""
    lm, clean, truth = sessions(robot)
    recs = copy.deepcopy(clean)
    edit(lm, recs, truth)
    res = get_calibrator(calibrator).calibrate(lm, recs)
    kin = LegKinematics(lm)
    found = data_warnings(kin, recs, res.offsets_vector(lm.joint_names))
    assert found and set(found) <= set(res.warnings)
    assert [w for w in found if re.search(expected, w)], found
    # The root cause hides its consequences: one finding per defect (the frozen IMU
    # and encoder are per stance too).
    assert len(found) == 1, found


@pytest.mark.parametrize("robot, kw", [
    ("a3", {}), ("a2", {}), ("pair_pry", {"sensors": "zero"}), ("a3", {"mode": "contact"}),
    ("a2", {"mode": "contact"}), ("a3", {"mode": "kinematic", "sensors": "zero"}),
    ("a3", {"offsets": "random:3", "seed": 5}), ("a2", {"offsets": "random:3", "seed": 5}),
], ids=["a3", "a2", "pair-ideal", "a3-contact", "a2-contact", "a3-kinematic", "a3-random3", "a2-random3"])
@pytest.mark.parametrize("calibrator", ["interfoot", "yamane"])
def test_clean_recordings_get_no_data_warning(sessions, robot, kw, calibrator):
    check_clean(sessions, robot, kw, calibrator)


def check_clean(sessions, robot, kw, calibrator):
    lm, recs, truth = sessions(robot, **kw)
    res = get_calibrator(calibrator).calibrate(lm, recs)
    assert data_warnings(LegKinematics(lm), recs, res.offsets_vector(lm.joint_names)) == []


def test_a_five_frame_glitch_costs_five_frames(sessions):
    """The contact filter's local mean is a median: a glitch removes itself only (a
    moving average let 5 glitching frames push 127 of 300 over the thresholds)."""
    lm, clean, truth = sessions("a3")
    recs = copy.deepcopy(clean)
    recs[1].q_enc[300:305, _role(lm, "left", "knee")] += 0.3
    res = get_calibrator("interfoot").calibrate(lm, recs)
    rep = res.diagnostics["filter"][1]
    assert rep["rotation"] + rep["translation"] == 5 and rep["slip_splits"] == 0
    assert not data_warnings(LegKinematics(lm), recs, res.offsets_vector(lm.joint_names))


def test_a_quiet_encoder_holding_one_count_while_the_robot_stands_still_is_not_frozen(sessions):
    """Frozen means unchanged while another encoder moves by more than 2 mrad: an encoder
    whose noise is below one count reads one value through a still phase, legitimately."""
    lm, clean, truth = sessions("a3")
    recs = copy.deepcopy(clean)
    still = recs[0]
    k = _role(lm, "left", "knee")
    hold = slice(0, 60)
    still.q_enc[hold] = still.q_enc[0] + 1e-4 * np.sin(np.arange(60))[:, None]  # the others: noise only
    still.q_enc[hold, k] = still.q_enc[0, k]
    kin = LegKinematics(lm)
    assert not data_warnings(kin, recs, truth)
    # The same constant channel while the others sweep is a frozen encoder.
    recs[0].q_enc[hold] = clean[0].q_enc[hold]
    recs[0].q_enc[hold, k] = clean[0].q_enc[0, k]
    assert re.search(r"stance_I: encoder left_knee_joint reads one unchanging value", "\n".join(
        data_warnings(kin, recs, truth)))


def test_a_joint_the_motion_leaves_still_is_not_frozen_but_a_channel_that_froze_is(sessions):
    """A channel that reads one value through the whole recording is still, not frozen
    (a five-joint leg's hip roll in sagittal stances, read without noise); and an IMU
    declared noiseless reads one value on an axis the motion leaves still. The same
    channel moving before it stops is frozen, and so is an IMU axis that never changes
    where noise is declared."""
    from dataclasses import replace

    lm, clean, truth = sessions("a3")
    kin = LegKinematics(lm)
    k = _role(lm, "left", "hip_roll")
    recs = copy.deepcopy(clean)
    recs[0].q_enc[:, k] = recs[0].q_enc[0, k]  # still through the recording
    assert not any("unchanging" in w for w in data_warnings(kin, recs, truth))
    recs[0].q_enc[:300, k] = clean[0].q_enc[:300, k]  # moved, then stopped for good
    assert re.search(r"stance_I: encoder left_hip_roll_joint reads one unchanging value", "\n".join(
        data_warnings(kin, recs, truth)))
    recs = copy.deepcopy(clean)
    recs[0].imu_gyro[:, 0] = 0.0  # one gyro axis reads nothing at all
    assert re.search(r"stance_I: IMU gyro x reads one unchanging value", "\n".join(data_warnings(kin, recs, truth)))
    recs[0] = replace(recs[0], sensor_model=replace(recs[0].sensor_model, gyro_noise_std=0.0))
    assert not any("unchanging" in w for w in data_warnings(kin, recs, truth))


def test_check_command_prints_what_each_check_measures(sessions, tmp_path, capsys):
    from legcal_bench.cli import main

    out = tmp_path / "set"
    collect(CollectConfig(robot="a3", heldout=0, stance_s=6.0), out, progress=False)
    assert main(["check", "--robot", "a3", "--bags", str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in d["recordings"]] == ["standing", "stance_I", "stance_II", "stance_III", "stance_IV"]
    assert d["warnings"] == [] and d["offsets_from"].startswith("offsets profiled out")
    assert max(r["dispersion_mm"] for r in d["recordings"]) < 1.0
    res = tmp_path / "r.json"
    assert main(["calibrate", "--robot", "a3", "--bags", str(out), "--out", str(res)]) == 0
    capsys.readouterr()
    assert main(["check", "--robot", "a3", "--bags", str(out), "--result", str(res)]) == 0
    text = capsys.readouterr().out
    assert "disp mm" in text and "limits: identical run 10 frames" in text and "no data warnings" in text


def test_without_an_estimate_the_checks_judge_at_profiled_offsets_and_raise_no_false_alarm(tmp_path, capsys):
    """Clean data with +-3 deg offsets: judged on the raw encoders alone, the soles look
    off one plane (tens of mm); at the profiled offsets nothing is flagged."""
    from legcal_bench.estimation.checks.profile import profiled_offsets

    lm = load_robot("a3")
    collect(CollectConfig(robot="a3", mode="kinematic", offsets="random:3", seed=0, heldout=0), tmp_path,
            progress=False)
    recs = load_session(tmp_path, lm.joint_names)
    kin = LegKinematics(lm)
    assert any("not on one plane" in w for w in data_warnings(kin, recs))
    dq, note = profiled_offsets(lm, recs)
    assert note.startswith("offsets profiled out") and data_warnings(kin, recs, dq) == []
    truth = np.load(tmp_path / "stance_I.truth.npz")["offsets"]
    assert np.degrees(np.abs(dq - truth)).max() < 0.5  # realistic sensors: the IMU tilt's share, not the offsets
    none, why = profiled_offsets(lm, [r for r in recs if r.kind == "standing"])
    assert none is None and "not profiled out" in why and "--result" in why
    from legcal_bench.cli import main  # the command without --result: the same

    capsys.readouterr()
    assert main(["check", "--robot", "a3", "--bags", str(tmp_path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["warnings"] == []
