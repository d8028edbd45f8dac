"""Issue #60's stand-ins for robots unlike ours on a contact floor
(`legcal_bench.robots.design.STAND_INS`): what each is, and that each holds a stance on
the contact floor with the default standing controller at offsets of a real robot."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from legcal_bench.robots import load_robot
from legcal_bench.robots.build import build_urdf, write_designs
from legcal_bench.robots.design import A3, GENERATED_DESIGNS, STAND_INS
from legcal_bench.robots.kinematics import LegKinematics

NAMES = [d.name for d in STAND_INS]


@pytest.fixture(scope="module")
def robots(tmp_path_factory):
    return dict(zip(NAMES, write_designs(NAMES, tmp_path_factory.mktemp("stand_ins"))))


def _model(path: str) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_path(path.replace(".legmap.yaml", ".xml"))


def test_the_stand_ins_are_what_they_say(robots):
    assert set(NAMES) == {"five_joint_capsule_heel", "heavy_full_size", "ryp_canted_hips"}
    assert all(GENERATED_DESIGNS[n] is d for n, d in zip(NAMES, STAND_INS))
    # The heavy robot: ~90 kg, legs 1.2x the A3-like's, servos 1.65x (its mass) against a load 1.98x.
    heavy, a3 = _model(robots["heavy_full_size"]), mujoco.MjModel.from_xml_path(str(load_robot("a3").mjcf))
    assert heavy.body_mass.sum() == pytest.approx(90.0, abs=0.5)
    assert LegKinematics(load_robot(robots["heavy_full_size"])).dims.leg_length == pytest.approx(
        1.2 * LegKinematics(load_robot("a3")).dims.leg_length, rel=1e-6)
    assert heavy.actuator_gainprm[:, 0].max() == pytest.approx(1.65 * a3.actuator_gainprm[:, 0].max())
    # Roll-yaw-pitch with the roll and yaw axes canted 45 degrees.
    ryp = load_robot(robots["ryp_canted_hips"])
    assert tuple(ryp.joint_roles[:3]) == ("hip_roll", "hip_yaw", "hip_pitch")
    assert np.degrees(LegKinematics(ryp).role_axes()[1]).max() == pytest.approx(45.0)


def test_the_capsule_heel_touches_along_the_feet_centre_line(robots):
    lm = load_robot(robots["five_joint_capsule_heel"])
    assert lm.absent_roles == ("ankle_roll",)
    m = _model(robots["five_joint_capsule_heel"])
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    for side in ("left", "right"):
        heel = m.geom(f"{side}_heel_geom")
        toe = m.geom(f"{side}_sole_geom")
        sole = d.site(f"{side}_sole")
        assert heel.type[0] == mujoco.mjtGeom.mjGEOM_CAPSULE
        # In the sole's frame: the capsule lies along x, on the sole's centre line, its bottom on the sole plane,
        # behind the toe box, which covers the sole's front half.
        R, p = sole.xmat.reshape(3, 3), sole.xpos
        axis = R.T @ d.geom(f"{side}_heel_geom").xmat.reshape(3, 3)[:, 2]
        centre = R.T @ (d.geom(f"{side}_heel_geom").xpos - p)
        toe_c = R.T @ (d.geom(f"{side}_sole_geom").xpos - p)
        assert abs(abs(axis[0]) - 1) < 1e-9 and abs(centre[1]) < 1e-9
        assert centre[2] - heel.size[0] == pytest.approx(0.0, abs=1e-9)
        assert centre[0] + heel.size[1] + heel.size[0] == pytest.approx(0.0, abs=1e-9)  # ends at the sole centre
        assert toe_c[0] - toe.size[0] == pytest.approx(0.0, abs=1e-9)
        assert toe_c[2] - toe.size[2] == pytest.approx(0.0, abs=1e-9)
        assert toe.size[0] * 2 == pytest.approx(A3.sole_half[0])


def test_a_capsule_heel_has_no_urdf_twin():
    with pytest.raises(ValueError, match="heel='capsule' has no URDF twin"):
        build_urdf(GENERATED_DESIGNS["five_joint_capsule_heel"])
