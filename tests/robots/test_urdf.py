"""Robots described by a URDF (issue #37): the URDF twin of a built-in has the same
kinematics, collects on every floor and calibrates to the same answers as its MJCF
twin; leg-map mistakes about the model file are named."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from legcal_bench.calibrators.base import calibrate_training
from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import load_session
from legcal_bench.errors import LegMapError
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import write_urdf_robot
from legcal_bench.robots.design import A2, A3
from legcal_bench.robots.kinematics import LegKinematics


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    """Converted URDFs go to this test's folder."""
    monkeypatch.setenv("LEGCAL_CACHE", str(tmp_path / "cache"))


@pytest.mark.parametrize("design", [A3, A2], ids=["a3", "a2"])
def test_the_urdf_twin_has_the_mjcf_twins_kinematics(design, tmp_path):
    twin = load_robot(str(write_urdf_robot(design, tmp_path)))
    assert twin.urdf is not None and twin.model_file == twin.urdf and twin.mjcf.suffix == ".xml"
    ku, km = LegKinematics(twin), LegKinematics(load_robot(design.name))
    assert ku.dims == km.dims
    for q in np.random.default_rng(0).uniform(-0.4, 0.4, (5, 12)):
        np.testing.assert_allclose(ku.inter_foot(q).homogeneous, km.inter_foot(q).homogeneous, atol=1e-12)
        np.testing.assert_allclose(ku.imu_pose(q).homogeneous, km.imu_pose(q).homogeneous, atol=1e-12)
        np.testing.assert_allclose(ku.sole_jacobian("right", q), km.sole_jacobian("right", q), atol=1e-12)


def test_the_urdf_twin_collects_on_every_floor_and_calibrates_as_the_mjcf_twin(tmp_path):
    robot = str(write_urdf_robot(A3, tmp_path / "robot"))
    twin, mjcf = load_robot(robot), load_robot("a3")
    collect(CollectConfig(robot=robot, mode="kinematic", heldout=0), tmp_path / "kinematic", progress=False)
    same = []
    for lm in (twin, mjcf):
        recs = load_session(tmp_path / "kinematic", lm.joint_names)
        same.append(calibrate_training(get_calibrator("interfoot"), lm, recs).offsets_vector(lm.joint_names))
    assert np.abs(same[0] - same[1]).max() <= 1e-9
    for mode in ("weld", "contact"):  # the simulator runs the converted model, servos from the leg map
        s = collect(CollectConfig(robot=robot, mode=mode, stances=("I",), heldout=0, stance_s=2.0, standing_s=1.0),
                    tmp_path / mode, progress=False)
        assert set(s.servo_gains["source"]) == {"leg map"} and len(s.segments) == 2


def test_the_conversion_is_made_once_per_urdf_text(tmp_path):
    robot = write_urdf_robot(A3, tmp_path)
    first = load_robot(str(robot)).mjcf
    stamp = first.stat().st_mtime_ns
    assert load_robot(str(robot)).mjcf == first and first.stat().st_mtime_ns == stamp
    urdf = tmp_path / "a3.urdf"
    urdf.write_text(urdf.read_text().replace('damping="0.2"', 'damping="0.3"'))
    assert load_robot(str(robot)).mjcf != first


def _legmap(tmp_path: Path, **changes) -> Path:
    path = write_urdf_robot(A3, tmp_path)
    d = yaml.safe_load(path.read_text())
    for k, v in changes.items():
        if v is None:
            d.pop(k)
        else:
            d[k] = v
    path.write_text(yaml.safe_dump(d))
    return path


def test_leg_map_mistakes_about_the_model_file_are_named(tmp_path):
    with pytest.raises(LegMapError, match="exactly one of the fields 'mjcf'.*or 'urdf'.*not both"):
        load_robot(str(_legmap(tmp_path / "both", mjcf=str(load_robot("a3").mjcf))))
    with pytest.raises(LegMapError, match="exactly one of the fields"):
        load_robot(str(_legmap(tmp_path / "none", urdf=None)))
    with pytest.raises(LegMapError, match=r"imu: a URDF has no sites; give each frame as a pose relative to a link"):
        load_robot(str(_legmap(tmp_path / "site", imu={"site": "imu"})))
    with pytest.raises(LegMapError, match="is not a URDF .*root element is <mujoco>.*field 'mjcf'"):
        load_robot(str(_legmap(tmp_path / "mjcf", urdf=str(load_robot("a3").mjcf))))


def test_a_urdf_with_a_mimic_joint_converts(tmp_path):
    """MuJoCo writes a URDF <mimic> as an equality constraint, not a body's joint: it gets
    no motor (it used to crash the conversion), and the model compiles."""
    import mujoco

    from legcal_bench.robots.urdf import mjcf_of_urdf

    urdf = tmp_path / "robot" / "a3.urdf"
    write_urdf_robot(A3, tmp_path / "robot")
    urdf.write_text(urdf.read_text().replace("</robot>", (
        '<link name="linkage"><inertial><origin xyz="0 0 0" rpy="0 0 0" /><mass value="0.1" />'
        '<inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4" /></inertial></link>'
        '<joint name="linkage_joint" type="revolute"><parent link="left_knee_link" /><child link="linkage" />'
        '<origin xyz="0 0 -0.1" rpy="0 0 0" /><axis xyz="0 1 0" /><limit lower="-3" upper="3" effort="1" '
        'velocity="1" /><mimic joint="left_knee_joint" multiplier="-0.5" offset="0.1" /></joint></robot>')))
    model = mujoco.MjModel.from_xml_path(str(mjcf_of_urdf(urdf, "test")))
    assert model.neq == 1 and mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, "legcal_motor_linkage_joint") >= 0
