"""Legs of five joints (no ankle roll), declared in the leg map: the kinematics take the
robot's own joint count, and a commanded pelvis pose becomes the nearest one both legs
reach with their soles where they are."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from legcal_bench.errors import LegMapError
from legcal_bench.geometry.lie import Log, inverse
from legcal_bench.geometry.poses import posture_pose, posture_poses
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import write_robot, write_urdf_robot
from legcal_bench.robots.design import VARIATIONS
from legcal_bench.robots.kinematics import (
    LegKinematics, _pose_metric, frame_kinematics, reachable_postures, solve_standing,
)
from legcal_bench.robots.legmap import load_legmap

FIVE = next(d for d in VARIATIONS if d.name == "five_joint")


@pytest.fixture(scope="module")
def kin(tmp_path_factory) -> LegKinematics:
    return LegKinematics(load_robot(str(write_robot(FIVE, tmp_path_factory.mktemp("five")))))


def _chain_error(kin, posture, q, left, right) -> float:
    T = posture_pose(posture)
    sl, sr = kin.sole_poses(q)
    return max(np.linalg.norm(pin.log6((T * sl).actInv(left)).vector),
               np.linalg.norm(pin.log6((T * sr).actInv(right)).vector))


def test_the_leg_map_declares_the_absent_ankle_roll_and_counts_come_from_it(kin, tmp_path):
    lm = kin.legmap
    assert (lm.leg_joints, lm.n_joints, lm.absent_roles) == (5, 10, ("ankle_roll",))
    assert lm.joint_roles[:5] == ["hip_pitch", "hip_roll", "hip_yaw", "knee", "ankle_pitch"]
    assert lm.to_dict()["absent_roles"] == ["ankle_roll"]
    assert (lm.leg_slice("right"), lm.side_of(4), lm.side_of(5)) == (slice(5, 10), "left", "right")
    # The robot's mass is A3-like's: the ankle link's mass went into the foot.
    a3 = LegKinematics(load_robot("a3"))
    assert pin.computeTotalMass(kin.model) == pytest.approx(pin.computeTotalMass(a3.model), abs=1e-9)
    # Without the declaration, five joints are refused with the fix named.
    d = lm.to_dict()
    d.pop("absent_roles")
    d["mjcf"] = str(lm.mjcf)
    import yaml

    path = tmp_path / "undeclared.legmap.yaml"
    path.write_text(yaml.safe_dump(d))
    with pytest.raises(LegMapError, match=r"5 joints listed; .* declares it with absent_roles: \[ankle_roll\]"):
        load_legmap(path)


def test_batched_kinematics_match_pinocchio_on_five_joint_legs(kin):
    rng = np.random.default_rng(0)
    Q = rng.uniform(-0.4, 0.4, (7, 10)) + kin.q_init()
    fk = frame_kinematics(kin, Q)
    assert fk.G.shape == (7, 6, 10) and fk.J_L.shape == (7, 6, 5)
    for k, q in enumerate(Q):
        left, right = kin.sole_poses(q)
        assert np.abs(fk.C[k] - left.actInv(right).homogeneous).max() < 1e-12
        assert np.abs(fk.J_L[k] - kin.sole_jacobian("left", q)).max() < 1e-12
        assert np.abs(fk.J_R[k] - kin.sole_jacobian("right", q)).max() < 1e-12


def test_a_reachable_posture_comes_back_as_commanded_and_an_unreachable_one_as_a_near_one(kin):
    left, right = kin.sole_poses(kin.q_init())  # soles in the stance frame of a pelvis at the origin
    commanded = np.array([[0.01, 0.0, -0.02, 0.0, 0.05, 0.0],  # fore-aft, down, pitch: reachable
                          [0.0, 0.02, 0.0, 0.0, 0.0, 0.0],  # a sideways sway needs ankle roll
                          [0.0, 0.03, 0.0, 0.05, 0.0, 0.02]])
    postures, Q = reachable_postures(kin, left, right, commanded)
    for p, q in zip(postures, Q):
        assert _chain_error(kin, p, q, left, right) < 1e-11
    assert np.abs(postures[0] - commanded[0]).max() < 1e-9
    W = _pose_metric(kin)
    for c, p in zip(commanded[1:], postures[1:]):
        dist = np.linalg.norm(W * Log(inverse(posture_poses(c)[0]) @ posture_poses(p)[0]))
        to_zero = np.linalg.norm(W * Log(inverse(posture_poses(c)[0])))  # the zero posture is reachable
        # No farther than a reachable posture we know, to 0.1 % (here the nearest is about
        # the zero posture itself; the least squares stop once a step gains < 1e-6 of the cost).
        assert dist <= to_zero * (1 + 1e-3)
        assert dist > 0.5 * to_zero  # and far from reached: the sway is not a posture of these legs


def test_six_joint_legs_keep_every_commanded_posture():
    a3 = LegKinematics(load_robot("a3"))
    left, right = a3.sole_poses(a3.q_init())
    commanded = np.array([[0.0, 0.03, 0.0, 0.05, 0.0, 0.02], [0.01, -0.02, -0.03, 0.0, 0.04, -0.03]])
    postures, _ = reachable_postures(a3, left, right, commanded)
    assert np.abs(postures - commanded).max() < 1e-12


def test_straight_leg_standing_on_five_joint_legs(kin):
    left, right = kin.sole_poses(np.zeros(10))
    posture, q = solve_standing(kin, left, right, np.zeros(6), (0.005, 0.005))
    assert _chain_error(kin, posture, q, left, right) < 1e-10
    assert q[3] == q[8] == 0.005


def test_the_urdf_twin_of_a_five_joint_robot_has_the_same_kinematics(kin, tmp_path):
    twin = LegKinematics(load_robot(str(write_urdf_robot(FIVE, tmp_path))))
    Q = np.random.default_rng(2).uniform(-0.3, 0.3, (5, 10))
    a, b = frame_kinematics(kin, Q), frame_kinematics(twin, Q)
    assert np.abs(a.C - b.C).max() < 1e-12 and np.abs(a.G - b.G).max() < 1e-12
