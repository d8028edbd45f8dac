"""Joint axes read physically (issue #37): a robot whose right-leg pitch axes point the
other way gets the same physical offsets pattern under the paper's presets and its
pitch sums in one frame; a hip axis canted far from its role is named."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from legcal_bench.paper import INJECTION_RAD
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import A3, PITCH_ROLES
from legcal_bench.robots.kinematics import LegKinematics, axis_warnings, pitch_sums
from legcal_bench.sim.offsets import resolve_offsets


@pytest.fixture(scope="module")
def twins(tmp_path_factory):
    """A3-like and its twin with mirrored right-leg pitch servos (same geometry)."""
    out = tmp_path_factory.mktemp("twins")
    a = load_robot(str(write_robot(A3, out)))
    b = load_robot(str(write_robot(replace(A3, name="a3_mirrored_pitch", flipped_axes=PITCH_ROLES), out)))
    return LegKinematics(a), LegKinematics(b)


def _posture(kin: LegKinematics) -> np.ndarray:
    """A squat with some roll and yaw on each leg (A3-like angles)."""
    by_role = {"hip_pitch": -0.35, "hip_roll": 0.05, "hip_yaw": 0.08, "knee": 0.7, "ankle_pitch": -0.33,
               "ankle_roll": -0.04}
    return np.array([by_role[r] for r in kin.legmap.joint_roles])


def test_the_mirrored_twin_has_the_same_geometry_at_the_opposite_right_pitch_angles(twins):
    a, b = twins
    signs = b.physical_signs()
    right_pitch = [i for i, r in enumerate(b.legmap.joint_roles) if i >= 6 and r in PITCH_ROLES]
    assert np.array_equal(np.flatnonzero(signs < 0), right_pitch)
    assert np.array_equal(a.physical_signs(), np.ones(12))
    q = _posture(a)
    np.testing.assert_allclose(b.inter_foot(signs * q).homogeneous, a.inter_foot(q).homogeneous, atol=1e-12)


@pytest.mark.parametrize("preset", ["paper", "paper@3", "paper-base"])
def test_paper_presets_give_a_robot_and_its_mirrored_twin_identical_inter_foot_transforms(twins, preset):
    a, b = twins
    q = _posture(a)
    q_b = b.physical_signs() * q  # the same physical posture on the twin
    dq_a, dq_b = resolve_offsets(preset, a.legmap), resolve_offsets(preset, b.legmap)
    # What each robot's encoders read (q_enc = q_true - dq) seen through its own kinematics.
    C_a = a.inter_foot(q - dq_a).homogeneous
    C_b = b.inter_foot(q_b - dq_b).homogeneous
    np.testing.assert_allclose(C_b, C_a, atol=1e-12)
    # By role alone (the sign of the axis ignored) the twin's feet would disagree.
    by_role = np.abs(dq_b) * np.sign(dq_a)
    R = (b.inter_foot(q_b - by_role).rotation.T @ a.inter_foot(q - dq_a).rotation)
    assert math.degrees(np.arccos((np.trace(R) - 1) / 2)) > 1.0


def test_pitch_sums_read_a_common_pelvis_pitch_alike_on_both_legs_of_the_mirrored_twin(twins):
    a, b = twins
    eps = 0.004  # rad about the pelvis y axis, on each leg's hip pitch: what an IMU pitch tilt looks like
    dq = np.array([eps if r == "hip_pitch" else 0.0 for r in a.legmap.joint_roles])
    for kin in (a, b):
        s = pitch_sums(kin.physical_signs() * dq, kin.pitch_signs())
        assert s["left"] == pytest.approx(eps) and s["right"] == pytest.approx(eps)
        assert s["right_minus_left"] == pytest.approx(0.0, abs=1e-15)


def test_paper_injection_keeps_the_papers_values_on_the_built_ins():
    for name in ("a2", "a3", "pair_ryp", "pair_pry"):
        lm = load_robot(name)
        assert np.array_equal(resolve_offsets("paper", lm), [INJECTION_RAD[r] for r in lm.joint_roles])


def test_a_hip_canted_far_from_its_role_is_named_and_a_small_cant_is_not(tmp_path):
    canted = LegKinematics(load_robot(str(write_robot(replace(A3, name="a3_cant45", hip_cant=math.radians(45)),
                                                      tmp_path))))
    signs, angles = canted.role_axes()
    roles = canted.legmap.joint_roles
    hip = [i for i, r in enumerate(roles) if r in ("hip_roll", "hip_yaw")]
    np.testing.assert_allclose(np.degrees(angles[hip]), 45.0, atol=1e-9)
    assert np.array_equal(signs, np.ones(12))
    warnings = axis_warnings(canted)
    assert len(warnings) == 4
    assert all("45 deg" in w and "check the leg map's role" in w for w in warnings)
    assert {w.split(":")[0] for w in warnings} == {f"joint {canted.legmap.joint_names[i]}" for i in hip}
    slight = LegKinematics(load_robot(str(write_robot(replace(A3, name="a3_cant10", hip_cant=math.radians(10)),
                                                      tmp_path))))
    assert axis_warnings(slight) == [] and axis_warnings(LegKinematics(load_robot("a3"))) == []
