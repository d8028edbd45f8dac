"""Leg joints whose encoders read a motor: a drive joint coupled to the leg joint by a
joint equality in the model (a URDF mimic compiles to one), and a fixed gear ratio given
in the leg map. The recordings hold the motors' readings; calibration works in joint
space and reports the offsets where the encoders are (motor space) too."""

import numpy as np
import pytest

from legcal_bench import api
from legcal_bench.data.recording import load_recording, load_truth, list_segments
from legcal_bench.errors import ConfigError, LegMapError
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import ASSETS
from legcal_bench.robots.holds import joint_couplings, joint_holds
from legcal_bench.robots.samples import a3_with_transmissions
from legcal_bench.robots.transmission import transmissions

def a3_variant(folder, coupled: bool = False, ratio: dict | None = None):
    return a3_with_transmissions(folder, coupled, ratio)


@pytest.fixture
def coupled(tmp_path):
    return a3_variant(tmp_path / "coupled", coupled=True)


def test_the_coupling_is_read_and_the_drive_not_held(coupled):
    lm = load_robot(str(coupled))
    (c,) = joint_couplings(lm.mjcf)
    assert (c.joint, c.drive, c.polycoef[:2]) == ("left_hip_yaw_joint", "left_hip_yaw_drive", (0.0, 0.5))
    assert joint_holds(lm) == ()
    t = transmissions(lm)["left_hip_yaw_joint"]
    assert (t.c0, t.c1, t.drive) == (0.0, 0.5, "left_hip_yaw_drive")


def _calibrated(legmap, mode, sensors, out, seed=0):
    collect(CollectConfig(robot=str(legmap), mode=mode, sensors=sensors, offsets="paper", seed=seed), out,
            progress=False)
    result = api.calibrate(out, str(legmap))
    return result, api.score(out, result, str(legmap))["recovery"], load_truth(list_segments(out)[0])


@pytest.mark.parametrize("case", ["drive joint", "fixed ratio"])
def test_zero_noise_recovery_in_motor_space(tmp_path, case):
    legmap = (a3_variant(tmp_path / "r", coupled=True) if case == "drive joint" else
              a3_variant(tmp_path / "r", ratio={"left_knee_joint": 2.0, "right_ankle_pitch_joint": -1.5}))
    lm = load_robot(str(legmap))
    result, rec, truth = _calibrated(legmap, "kinematic", "zero", tmp_path / "k")
    c1 = np.array([transmissions(lm)[n].c1 if n in transmissions(lm) else 1.0 for n in lm.joint_names])
    motor = np.array([result.diagnostics["offsets_motor_rad"][n] for n in lm.joint_names])
    assert np.rad2deg(np.abs(motor - truth.offsets / c1)).max() <= 1e-9
    assert rec["max_error_deg"] <= 1e-9
    # the recording holds the motors' readings: joint angle minus offset, over c1
    r = load_recording(list_segments(tmp_path / "k")[1], lm.joint_names)
    t = load_truth(list_segments(tmp_path / "k")[1])
    assert np.allclose(r.q_enc, (t.q_true - t.offsets) / c1, atol=1e-12)


def test_a_drive_joint_collects_on_the_weld_floor_and_calibrates_as_the_a3(coupled, tmp_path):
    """Realistic weld, seed 0: the coupled robot's IMU-removed recovery within 1.5x of the
    A3-like robot's on the same seed (over seeds 0-2: `legcal-bench vendor-cases`)."""
    _, a3, _ = _calibrated(ASSETS / "a3.legmap.yaml", "weld", "realistic", tmp_path / "a3")
    result, rec, _ = _calibrated(coupled, "weld", "realistic", tmp_path / "w")
    assert rec["vs_imu_vertical"]["rms_error_deg"] <= 1.5 * a3["vs_imu_vertical"]["rms_error_deg"], (
        rec["vs_imu_vertical"], a3["vs_imu_vertical"])
    assert result.decision == "apply"
    assert result.diagnostics["transmissions"]["left_hip_yaw_joint"]["kind"] == "drive joint left_hip_yaw_drive"


def test_a_nonlinear_coupling_and_walking_a_drive_are_refused(coupled, tmp_path):
    from legcal_bench.sim.walking import WalkingConfig, build_walking_scene

    lm = load_robot(str(coupled))
    with pytest.raises(ConfigError, match="walking does not simulate drive joints yet"):
        build_walking_scene(lm, WalkingConfig(kp=(100.0,) * 12, kd=(2.0,) * 12, default_q=(0.0,) * 12))
    xml = (coupled.parent / "a3.xml").read_text().replace('polycoef="0 0.5 0 0 0"', 'polycoef="0 0.5 0.1 0 0"')
    (coupled.parent / "a3.xml").write_text(xml)
    with pytest.raises(LegMapError, match="polynomial of degree > 1"):
        transmissions(load_robot(str(coupled)))


def test_a_ratio_of_zero_is_refused(tmp_path):
    with pytest.raises(LegMapError, match=r"joints\[3\]\.ratio is 0"):
        load_robot(str(a3_variant(tmp_path, ratio={"left_knee_joint": 0.0})))


def test_a_joint_following_a_leg_joint_is_neither_held_nor_a_transmission(coupled):
    """A passive joint the model couples to a leg joint (follower = f(knee)) moves with the
    leg: not held, and the leg joint keeps its own encoder; two leg joints coupled: refused."""
    xml_path = coupled.parent / "a3.xml"
    xml = xml_path.read_text()
    follower = ('<body name="left_knee_follower" pos="0 0 0"><joint name="left_knee_follower_joint" axis="0 1 0"/>'
                '<inertial pos="0 0 0" mass="0.05" diaginertia="1e-5 1e-5 1e-5"/></body>\n')
    anchor = '<body name="left_hip_yaw_rotor"'
    xml = xml.replace(anchor, follower + anchor, 1).replace(
        "</equality>", '<joint joint1="left_knee_follower_joint" joint2="left_knee_joint" polycoef="0 2 0 0 0"/>'
        "</equality>", 1)
    xml_path.write_text(xml)
    lm = load_robot(str(coupled))
    assert set(transmissions(lm)) == {"left_hip_yaw_joint"}
    assert joint_holds(lm) == ()
    xml_path.write_text(xml.replace('joint1="left_knee_follower_joint"', 'joint1="left_ankle_pitch_joint"'))
    with pytest.raises(LegMapError, match="couples two leg joints"):
        transmissions(load_robot(str(coupled)))


def test_the_drive_starts_where_its_coupling_puts_it_and_references_fold_into_c0(coupled):
    """Every reset places the drive at (q - c0) / c1 (a drive left at 0 would be yanked by the
    equality at every settle); a coupling between joints with references: joint - ref1 =
    a0 + a1 (drive - ref2), so c0 = ref1 + a0 - a1 ref2."""
    import pinocchio as pin

    from legcal_bench.robots.holds import Coupling
    from legcal_bench.sim.double_support import DoubleSupportSim
    from legcal_bench.sim.sensors import sim_sensors

    lm = load_robot(str(coupled))
    sim = DoubleSupportSim(lm, "weld", np.zeros(12), sim_sensors("zero"))
    q = np.zeros(12)
    q[2] = 0.3  # left hip yaw
    sim._set_state(q, pin.SE3.Identity())
    sc = sim.scene
    assert sim.data.qpos[sc.act_qpos_adr[2]] == pytest.approx(0.6)
    assert Coupling("j", "d", (0.1, 0.5, 0, 0, 0), (0.2, 0.4)).linear == pytest.approx((0.1, 0.5))
