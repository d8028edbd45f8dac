"""An MJCF with `<frame>` elements (issue #59): Pinocchio's model of it (the frames folded
by MuJoCo's compilation, `legcal_bench.robots.frames`) has the kinematics MuJoCo
simulates, and the robot calibrates through its leg map unedited."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import numpy as np

from legcal_bench.robots import ASSETS, load_robot
from legcal_bench.robots.frames import fold_frames
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots.samples import framed


def _framed(tmp_path, same_robot: bool = False):
    """The framed A3-like MJCF and its leg map (`legcal_bench.robots.samples.framed`)."""
    legmap = framed(tmp_path, same_robot)
    return tmp_path / "a3_framed.xml", load_robot(str(legmap))


def _site_pose(model, data, name):
    i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = data.site_xmat[i].reshape(3, 3), data.site_xpos[i]
    return T


def test_pinocchio_reads_the_framed_model_as_mujoco_simulates_it(tmp_path):
    xml, lm = _framed(tmp_path)
    assert "<frame" in xml.read_text()
    kin = LegKinematics(lm)
    model = mujoco.MjModel.from_xml_path(str(xml))
    data = mujoco.MjData(model)
    adr = [model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n)] for n in lm.joint_names]
    for q in np.random.default_rng(0).uniform(-0.4, 0.4, (5, lm.n_joints)):
        data.qpos[:] = model.qpos0
        data.qpos[adr] = q
        mujoco.mj_kinematics(model, data)
        left, right, imu = (_site_pose(model, data, n) for n in ("left_sole", "right_sole", "imu"))
        pelvis = np.eye(4)
        pelvis[:3, :3] = data.xmat[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "pelvis")].reshape(3, 3)
        pelvis[:3, 3] = data.xpos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "pelvis")]
        np.testing.assert_allclose(kin.inter_foot(q).homogeneous, np.linalg.inv(left) @ right, atol=1e-12)
        sole_l, sole_r = kin.sole_poses(q)
        np.testing.assert_allclose(sole_l.homogeneous, np.linalg.inv(pelvis) @ left, atol=1e-12)
        np.testing.assert_allclose(kin.imu_pose(q).homogeneous, np.linalg.inv(pelvis) @ imu, atol=1e-12)
    # the frames change the model: the unframed A3-like robot's inter-foot pose differs
    q = np.zeros(lm.n_joints)
    assert np.abs(kin.inter_foot(q).homogeneous - LegKinematics(load_robot("a3")).inter_foot(q).homogeneous).max() > 1e-3


def test_a_model_without_frames_is_left_as_it_is():
    text = (ASSETS / "a3.xml").read_text()
    assert fold_frames(text, mujoco.MjModel.from_xml_path(str(ASSETS / "a3.xml"))) is text


def test_the_framed_robot_collects_and_calibrates_through_its_leg_map(tmp_path):
    from legcal_bench.calibrators.base import calibrate_training
    from legcal_bench.calibrators.registry import get_calibrator
    from legcal_bench.data.recording import list_segments, load_session, load_truth
    from legcal_bench.protocol.collect import CollectConfig, collect

    _, lm = _framed(tmp_path, same_robot=True)
    robot = str(tmp_path / "a3_framed.legmap.yaml")
    for mode in ("kinematic", "weld"):  # the simulator builds its scene from the folded model too
        collect(CollectConfig(robot=robot, mode=mode, sensors="zero", heldout=0, stance_s=2.0, standing_s=1.0),
                tmp_path / mode, progress=False)
    recs = load_session(tmp_path / "kinematic", robot=lm)
    got = calibrate_training(get_calibrator("interfoot"), lm, recs).offsets_vector(lm.joint_names)
    truth = load_truth(list_segments(tmp_path / "kinematic")[0]).offsets
    assert np.rad2deg(np.abs(got - truth)).max() < 1e-9  # zero-noise kinematic data: exact


def test_frames_beside_includes_are_refused_with_the_fix(tmp_path):
    import pytest

    from legcal_bench.errors import LegMapError
    from legcal_bench.robots.frames import mjcf_element

    xml, _ = _framed(tmp_path)
    (tmp_path / "scene.xml").write_text(f'<mujoco><include file="{xml.name}"/><worldbody><frame pos="0 0 1">'
                                        '<site name="s"/></frame></worldbody></mujoco>')
    with pytest.raises(LegMapError, match="has both <include> and <frame> elements; fold the includes into one file"):
        mjcf_element(tmp_path / "scene.xml")
