"""Every joint the leg map does not list is held: at the leg map's angle, the model's
first keyframe's or its reference; rigidly, or on a servo with the leg map's gains (its
sag reported); `info` and the session say which."""

import json
import re

import numpy as np
import pytest
import yaml

from legcal_bench.errors import LegMapError
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots.holds import joint_holds
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots.legmap import load_legmap
from legcal_bench.sim.hold import RIGID_HOLD_LIMIT_RAD


def _variant(testbot_legmap, tmp_path, edit_legmap=None, keyframe: dict | None = None):
    """A copy of the test robot (waist yaw, shoulders, elbows: none a leg joint) with its
    leg map edited, and optionally a keyframe giving some of its joints' angles."""
    src = testbot_legmap.parent
    xml = (src / "testbot.xml").read_text()
    if keyframe is not None:
        import mujoco

        m = mujoco.MjModel.from_xml_string(xml)
        qpos = m.qpos0.copy()
        for name, v in keyframe.items():
            qpos[m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)]] = v
        key = f'<keyframe><key name="stand" qpos="{" ".join(repr(float(x)) for x in qpos)}"/></keyframe>'
        xml = re.sub(r"</mujoco>\s*$", key + "\n</mujoco>\n", xml)
    (tmp_path / "testbot.xml").write_text(xml)
    d = yaml.safe_load(testbot_legmap.read_text())
    if edit_legmap:
        edit_legmap(d)
    p = tmp_path / "testbot.legmap.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def _drop(*names):
    def edit(d):
        for n in names:
            d["held_joints_rad"].pop(n)
    return edit


def test_unlisted_joints_are_held_at_the_keyframe_or_the_reference(testbot_legmap, tmp_path):
    lm = load_legmap(_variant(testbot_legmap, tmp_path, _drop("left_elbow_joint", "right_elbow_joint"),
                              keyframe={"left_elbow_joint": -0.4}))
    holds = {h.joint: h for h in joint_holds(lm)}
    assert set(holds) == {"waist_yaw_joint", "left_shoulder_pitch_joint", "right_shoulder_pitch_joint",
                          "left_elbow_joint", "right_elbow_joint"}
    assert (holds["waist_yaw_joint"].angle_rad, holds["waist_yaw_joint"].source) == (0.1, "leg map")
    assert (holds["left_elbow_joint"].angle_rad, holds["left_elbow_joint"].source) == (-0.4, "keyframe 'stand'")
    # the keyframe gives every joint: one it does not change is at the model's reference there
    assert holds["right_elbow_joint"].angle_rad == 0.0
    assert all(h.how == "rigid" for h in holds.values())
    # the kinematics stands the joints where the simulator holds them
    kin = LegKinematics(lm)
    j = kin.model.joints[kin.model.getJointId("left_elbow_joint")]
    assert kin.q_neutral[j.idx_q] == -0.4

    lm = load_legmap(_variant(testbot_legmap, tmp_path, _drop("left_elbow_joint")))
    h = {h.joint: h for h in joint_holds(lm)}["left_elbow_joint"]
    assert (h.angle_rad, h.source) == (0.0, "model's reference (qpos0)")


def test_servo_gains_name_held_joints_by_name_or_pattern(testbot_legmap, tmp_path):
    def edit(d):
        d["servo_gains"] = {"*_elbow_joint": [40.0, 1.0], "waist_yaw_joint": [300.0, 5.0]}
    holds = {h.joint: h for h in joint_holds(load_legmap(_variant(testbot_legmap, tmp_path, edit)))}
    assert (holds["left_elbow_joint"].how, holds["left_elbow_joint"].kp, holds["left_elbow_joint"].kd) == (
        "servo", 40.0, 1.0)
    assert (holds["waist_yaw_joint"].how, holds["waist_yaw_joint"].kp) == ("servo", 300.0)
    assert holds["left_shoulder_pitch_joint"].how == "rigid"


@pytest.mark.parametrize("gains, message", [
    ({"waist": [1.0, 2.0]}, r"servo_gains\.waist: no joint of that name .*\(waist_yaw_joint"),
    ({"*_knee_*": [1.0, 2.0]}, r"servo_gains\.'\*_knee_\*' matches no non-leg joint"),
])
def test_servo_gains_for_no_joint_are_refused(testbot_legmap, tmp_path, gains, message):
    lm = load_legmap(_variant(testbot_legmap, tmp_path, lambda d: d.update(servo_gains=gains)))
    with pytest.raises(LegMapError, match=message):
        joint_holds(lm)


def test_held_joints_rad_for_no_joint_is_refused(testbot_legmap, tmp_path):
    lm = load_legmap(_variant(testbot_legmap, tmp_path, lambda d: d["held_joints_rad"].update(neck=0.2)))
    with pytest.raises(LegMapError, match=r"held_joints_rad\.neck: no joint of that name"):
        joint_holds(lm)


def test_weld_collection_holds_every_joint_and_reports_servo_sag(testbot_legmap, tmp_path):
    """Elbows left out of the leg map (before: loose) are held rigidly at their reference
    within RIGID_HOLD_LIMIT_RAD; shoulders on soft servos sag, and the session says by how much."""
    def edit(d):
        _drop("left_elbow_joint", "right_elbow_joint")(d)
        d["servo_gains"] = {"*_shoulder_pitch_joint": [30.0, 1.0]}
    lm = _variant(testbot_legmap, tmp_path, edit)
    out = tmp_path / "weld"
    summary = collect(CollectConfig(robot=str(lm), mode="weld", offsets="paper", sensors="zero", seed=0,
                                    stance_s=1.0, heldout=0, standing_s=0.0), out, progress=False)
    table = {h["joint"]: h for h in summary.held_joints}
    assert json.loads((out / "session.json").read_text())["held_joints"] == summary.held_joints
    for name in ("waist_yaw_joint", "left_elbow_joint", "right_elbow_joint"):
        assert table[name]["how"] == "rigid" and table[name]["within_limit"], table[name]
        assert table[name]["error_deg"] < np.rad2deg(RIGID_HOLD_LIMIT_RAD)
    for name in ("left_shoulder_pitch_joint", "right_shoulder_pitch_joint"):
        h = table[name]
        assert h["how"] == "servo" and h["kp"] == 30.0
        # the arm (2 kg at 0.15 m, 1.2 kg at ~0.4 m below the shoulder, held 0.3 rad forward) pulls
        # against kp 30 N m/rad: a sag of degrees, far beyond the rigid holds' hundredths
        assert h["sag_deg"] > 1.0, h


def test_a_joint_with_a_reference_is_held_at_it_and_unnamed_or_following_joints_are_not_held(testbot_legmap,
                                                                                              tmp_path):
    """MuJoCo measures a joint equality from the joint's reference (`ref`, its qpos0): the hold
    is at the angle, not at ref + angle. A joint without a name cannot be held (free); a
    joint the model couples to another (joint1 of an equality) follows that one."""
    lm_path = _variant(testbot_legmap, tmp_path, _drop("left_elbow_joint"))
    xml = (tmp_path / "testbot.xml").read_text()
    xml = re.sub(r'(<joint name="left_elbow_joint")', r'\1 ref="-0.2"', xml, count=1)  # in its range [-2.5, 0.1]
    xml = re.sub(r'(<joint name="right_elbow_joint"[^>]*?)/>',
                 r'\1/><body name="right_hand" pos="0 0 -0.25"><joint type="hinge" axis="1 0 0"/>'
                 r'<inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/></body>', xml, count=1)
    xml = xml.replace("</mujoco>", '<equality><joint joint1="right_shoulder_pitch_joint" '
                      'joint2="left_shoulder_pitch_joint" polycoef="0 1 0 0 0"/></equality>\n</mujoco>')
    (tmp_path / "testbot.xml").write_text(xml)
    lm = load_legmap(lm_path)
    holds = {h.joint: h for h in joint_holds(lm)}
    assert (holds["left_elbow_joint"].angle_rad, holds["left_elbow_joint"].ref) == (-0.2, -0.2)
    assert holds["(unnamed)"].how == "free"
    assert "right_shoulder_pitch_joint" not in holds  # it follows the left one
    LegKinematics(lm)  # an unnamed joint does not stop the kinematics
    summary = collect(CollectConfig(robot=str(lm_path), mode="weld", offsets="paper", sensors="zero", seed=0,
                                    stance_s=1.0, heldout=0, standing_s=0.0), tmp_path / "weld", progress=False)
    elbow = {h["joint"]: h for h in summary.held_joints}["left_elbow_joint"]
    assert elbow["within_limit"] and abs(elbow["angle_deg"] - np.rad2deg(-0.2)) < 1e-12, str(elbow)


def test_a_hold_outside_the_joints_range_is_refused(testbot_legmap, tmp_path):
    lm = load_legmap(_variant(testbot_legmap, tmp_path, lambda d: d["held_joints_rad"].update(left_elbow_joint=0.3)))
    with pytest.raises(LegMapError, match=r"held_joints_rad\.left_elbow_joint = \+0\.3000 is outside the joint's "
                                          r"range \[-2\.5000, \+0\.1000\]"):
        joint_holds(lm)
