"""Ankles in either order (issue #59): a leg whose ankle roll comes before its ankle
pitch is listed in chain order with each joint's own role, collects and calibrates;
a listing out of chain order is refused naming the chain; presets map by role."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from legcal_bench.calibrators.base import calibrate_training
from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import list_segments, load_session, load_truth
from legcal_bench.errors import LegMapError
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import ROLL_FIRST_ANKLE
from legcal_bench.robots.kinematics import LegKinematics


@pytest.fixture(scope="module")
def robot(tmp_path_factory):
    return write_robot(ROLL_FIRST_ANKLE, tmp_path_factory.mktemp("roll_first"))


def test_a_roll_first_ankle_calibrates_exactly_and_collects_on_the_weld_floor(robot, tmp_path):
    lm = load_robot(str(robot))
    assert [j.role for j in lm.legs["left"].joints][3:] == ["knee", "ankle_roll", "ankle_pitch"]
    collect(CollectConfig(robot=str(robot), mode="kinematic", sensors="zero", heldout=0, stance_s=2.0,
                          standing_s=1.0), tmp_path / "kinematic", progress=False)
    truth = load_truth(list_segments(tmp_path / "kinematic")[0]).offsets
    # the paper's preset by role: each ankle joint gets its role's offset, wherever it sits
    a3 = load_robot("a3")
    a3_truth = dict(zip(a3.joint_names, _paper(a3)))
    for name, value in zip(lm.joint_names, truth):
        assert value == pytest.approx(a3_truth[name], abs=1e-12), name
    got = calibrate_training(get_calibrator("interfoot"), lm, load_session(tmp_path / "kinematic", robot=lm))
    assert np.rad2deg(np.abs(got.offsets_vector(lm.joint_names) - truth)).max() < 1e-9
    s = collect(CollectConfig(robot=str(robot), mode="weld", stances=("I",), heldout=0, stance_s=2.0,
                              standing_s=1.0), tmp_path / "weld", progress=False)
    assert len(s.segments) == 2


def _paper(legmap) -> np.ndarray:
    from legcal_bench.sim.offsets import resolve_offsets

    return np.asarray(resolve_offsets("paper", legmap, np.random.default_rng(0)))


def test_a_listing_out_of_chain_order_is_refused_naming_the_chain(robot, tmp_path):
    d = yaml.safe_load(robot.read_text())
    d["mjcf"] = str(robot.parent / d["mjcf"])
    for side in ("left", "right"):  # the built-ins' order, pitch then roll: not this robot's chain
        j = d["legs"][side]["joints"]
        j[4], j[5] = j[5], j[4]
    (tmp_path / "wrong.legmap.yaml").write_text(yaml.safe_dump(d))
    with pytest.raises(LegMapError, match=r"legs.left.joints are listed \[.*'left_ankle_pitch_joint', "
                                          r"'left_ankle_roll_joint'\], but the model's chain from pelvis to foot is "
                                          r"\[.*'left_ankle_roll_joint', 'left_ankle_pitch_joint'\]: list the leg's "
                                          r"joints in chain order"):
        LegKinematics(load_robot(str(tmp_path / "wrong.legmap.yaml")))


def test_legs_with_different_ankle_orders_are_refused(robot, tmp_path):
    d = yaml.safe_load(robot.read_text())
    d["mjcf"] = str(robot.parent / d["mjcf"])
    j = d["legs"]["right"]["joints"]
    j[4]["role"], j[5]["role"] = j[5]["role"], j[4]["role"]
    (tmp_path / "mixed.legmap.yaml").write_text(yaml.safe_dump(d))
    with pytest.raises(LegMapError, match="left and right legs have different ankle orders"):
        load_robot(str(tmp_path / "mixed.legmap.yaml"))


def test_hips_listed_out_of_chain_order_are_refused(tmp_path):
    """A pitch-first hip listed roll first: the leg map's hip order (the paper's table,
    the IMU tilt's pitch-sum direction) would not be the robot's."""
    from legcal_bench.robots import ASSETS

    d = yaml.safe_load((ASSETS / "a3.legmap.yaml").read_text())
    d["mjcf"] = str(ASSETS / d["mjcf"])
    for side in ("left", "right"):
        j = d["legs"][side]["joints"]
        j[0], j[1] = j[1], j[0]
    (tmp_path / "hips.legmap.yaml").write_text(yaml.safe_dump(d))
    with pytest.raises(LegMapError, match=r"but the model's chain from pelvis to foot is \['left_hip_pitch_joint', "
                                          r"'left_hip_roll_joint'"):
        LegKinematics(load_robot(str(tmp_path / "hips.legmap.yaml")))
