"""A channel read with the opposite sign in the straight-leg standing phase (issue #42).

Measured before: the right knee's sign flipped in the standing recording only (within
its joint limits) moved the knee prior by twice its reading, the operating calibration
came out 2.3 deg off, and neither the calibrators nor `legcal-bench check` warned: the
column search only looked at the stances, whose inter-foot transform varies with the
posture, and the standing phase holds one posture. It is now judged against the
stances' calibration (`datacheck.standing_signs`): the flipped channel is named, on the
A3-like robot and on one whose pitch axes are mirrored between the legs by design, and
clean sets of both and of the G1 raise nothing."""

from __future__ import annotations

import copy
import re
import shutil

import numpy as np
import pytest

from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import load_session, training
from legcal_bench.estimation.checks.datacheck import data_warnings, standing_signs
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import VARIATIONS
from legcal_bench.robots.kinematics import LegKinematics
from tests.conftest import G1_LEGMAP

pytestmark = pytest.mark.xdist_group("sign_flip_standing")
MIRRORED = next(d for d in VARIATIONS if d.name == "a3_mirrored_pitch")  # right pitch axes reversed in the leg map
CALIBRATORS = {"interfoot": {}, "operating": {"setting": "operating"}, "yamane": {}}


@pytest.fixture(scope="module")
def sets(tmp_path_factory):
    """Clean weld sets with the standing phase (realistic sensors, the paper's offsets),
    by robot: (leg map, recordings, folder, true offsets), collected once."""
    cache = {}
    robots = tmp_path_factory.mktemp("robots")

    def get(robot):
        if robot not in cache:
            path = str(write_robot(MIRRORED, robots)) if robot == MIRRORED.name else robot
            out = tmp_path_factory.mktemp(MIRRORED.name if robot == MIRRORED.name else "set") / "set"
            collect(CollectConfig(robot=path, heldout=1), out, progress=False)
            lm = load_robot(path)
            recs = load_session(out, robot=lm)
            assert [r.kind for r in recs] == ["standing"] + ["stance"] * 4 + ["heldout"]
            cache[robot] = (lm, recs, out, np.load(out / "stance_I.truth.npz")["offsets"])
        return cache[robot]
    return get


def _calibrate(lm, recs, calibrator):
    name = "interfoot" if calibrator == "operating" else calibrator
    return get_calibrator(name, **CALIBRATORS[calibrator]).calibrate(lm, training(recs))


def _flipped(lm, recs, joint, kind="standing"):
    out = copy.deepcopy(recs)
    next(r for r in out if r.kind == kind).q_enc[:, lm.joint_names.index(joint)] *= -1  # that recording only
    return out


@pytest.mark.parametrize("robot, joint, calibrator", [
    ("a3", "right_knee_joint", "operating"),  # the measured case: the knee prior takes it
    ("a3", "left_knee_joint", "yamane"),
    ("a3", "left_hip_roll_joint", "interfoot"),  # alone it also put the soles 24 mm apart: one finding
    ("a3", "right_hip_pitch_joint", "interfoot"),
    (MIRRORED.name, "right_knee_joint", "operating"),
    (MIRRORED.name, "left_hip_pitch_joint", "interfoot"),
])
def test_a_channel_flipped_in_the_standing_phase_is_named(sets, robot, joint, calibrator):
    lm, clean, _, truth = sets(robot)
    recs = _flipped(lm, clean, joint)
    res = _calibrate(lm, recs, calibrator)
    dq = res.offsets_vector(lm.joint_names)
    found = data_warnings(LegKinematics(lm), recs, dq)
    assert len(found) == 1, found
    assert re.match(rf"standing: the straight-leg standing posture does not fit the stances' calibration \(.*\): "
                    rf"likely {joint} reads with the opposite sign in this recording \(with it undone", found[0]), found
    assert found[0] in res.warnings  # the calibrators' warnings carry it, as the stances' column search
    if calibrator == "operating":  # why it matters: the knee prior took the flipped reading
        assert np.degrees(np.abs(dq - truth)).max() > 1.5


def test_the_check_command_names_it(sets, tmp_path, capsys):
    """`legcal-bench check` on the files (it profiles the offsets out, the standing phase
    does not enter that fit), which said "no data warnings" before."""
    from legcal_bench.cli import main

    lm, clean, out, _ = sets("a3")
    folder = tmp_path / "set"
    shutil.copytree(out, folder)
    _flipped(lm, clean, "right_knee_joint")[0].save(folder / "standing.npz")
    assert main(["check", "--robot", "a3", "--bags", str(folder)]) == 0
    text = capsys.readouterr().out
    assert "likely right_knee_joint reads with the opposite sign in this recording" in text
    assert "no data warnings" not in text


@pytest.mark.parametrize("robot", ["a3", MIRRORED.name, str(G1_LEGMAP)], ids=["a3", "mirrored", "g1"])
def test_clean_sets_raise_no_warning(sets, robot):
    """Each calibrator's estimate, and the raw encoders (the check then fits the stances
    alone): no finding on clean data, mirrored axes included."""
    lm, recs, _, _ = sets(robot)
    kin = LegKinematics(lm)
    for calibrator in CALIBRATORS:
        res = _calibrate(lm, recs, calibrator)
        assert data_warnings(kin, recs, res.offsets_vector(lm.joint_names)) == [], calibrator
    standing = [r for r in recs if r.kind == "standing"]
    assert standing_signs(kin, standing, [r for r in recs if r.kind == "stance"], np.zeros(lm.n_joints)) == ([], set())


def test_a_flip_the_standing_posture_cannot_show_is_not_named(sets):
    """A hip yaw read reversed in the standing phase leaves the soles' relative tilt and
    height, the IMU's vertical and the knees as they were: nothing to see, and nothing
    the calibration takes from the standing phase is wrong."""
    lm, clean, _, truth = sets("a3")
    recs = _flipped(lm, clean, "left_hip_yaw_joint")
    res = _calibrate(lm, recs, "operating")
    assert data_warnings(LegKinematics(lm), recs, res.offsets_vector(lm.joint_names)) == []
    assert np.degrees(np.abs(res.offsets_vector(lm.joint_names) - truth)).max() < 0.5


@pytest.mark.parametrize("robot, joint", [("a3", "right_ankle_pitch_joint"), ("a3", "left_hip_pitch_joint"),
                                          (MIRRORED.name, "right_hip_pitch_joint")])
def test_a_channel_flipped_in_a_held_out_session_is_named_by_check_and_score(sets, tmp_path, robot, joint):
    """Held-out sessions score the calibration by their foot height; one read with a
    reversed sign would score the reversal as a poor calibration, silently. Its posture
    (knees free) must fit the stances' calibration as the standing phase's does. (A bent knee
    read reversed leaves its joint limits: the recording is refused on loading.)"""
    from legcal_bench.evaluation.scoring import score

    lm, clean, out, _ = sets(robot)
    recs = _flipped(lm, clean, joint, "heldout")
    res = _calibrate(lm, recs, "interfoot")
    found = data_warnings(LegKinematics(lm), recs, res.offsets_vector(lm.joint_names))
    assert len(found) == 1, found
    assert re.match(rf"heldout_1: the held-out posture does not fit the stances' calibration \(.*\): likely {joint} "
                    "reads with the opposite sign in this recording .*its held-out foot height would score the "
                    "reversed sign, not the calibration$", found[0]), found
    assert "knees within" not in found[0]
    folder = tmp_path / "set"
    shutil.copytree(out, folder)
    recs[-1].save(folder / "heldout_1.npz")
    assert found[0] in score(str(folder), res, lm)["heldout"]["warnings"]
    assert "warnings" not in score(str(out), res, lm)["heldout"]  # the clean set: no alarm
