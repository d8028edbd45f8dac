"""The simulated reality (issue #16): each effect changes the recordings as its physics
says, the recordings do not name it, the ground truth does; bad specs name the fix."""

import numpy as np
import pytest

from legcal_bench.data.recording import load_recording, load_truth
from legcal_bench.errors import ConfigError
from legcal_bench.estimation.modelgap.effects import joint_loads
from legcal_bench.estimation.imu.levelling import up_in_base
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.sim.effects import build_reality, parse_effect
from legcal_bench.sim.sensors import sim_sensors

SHORT = dict(stances=("I",), heldout=0, standing_s=0.0, stance_s=1.0)


def _reality(tmp_path, robot, *specs):
    lm = load_robot(robot)
    return lm, build_reality(lm, lm, specs, sim_sensors("zero"), tmp_path / "model")


@pytest.mark.parametrize("robot", ["a3", "a2"])
def test_a_shank_lengthened_5mm_moves_the_true_sole_5mm_and_nothing_else(tmp_path, robot):
    lm, r = _reality(tmp_path, robot, "link_length:link=left_shank,mm=5")
    nominal, real = LegKinematics(lm), LegKinematics(r.sim_legmap)
    q = nominal.q_init()
    (L0, R0), (L1, R1) = nominal.sole_poses_batch(q[None]), real.sole_poses_batch(q[None])
    assert np.linalg.norm(L1[0, :3, 3] - L0[0, :3, 3]) == pytest.approx(0.005, abs=1e-9)
    assert np.abs(L1[0, :3, :3] - L0[0, :3, :3]).max() < 1e-12 and np.abs(R1 - R0).max() < 1e-12
    assert r.truth == [{"effect": "link_length:link=left_shank,mm=5", "kind": "link_length", "link": "left_shank",
                        "length_m": 0.005}]


def test_a_hip_axis_rotated_half_a_degree_tilts_that_joint_axis_by_half_a_degree(tmp_path):
    lm, r = _reality(tmp_path, "a3", "hip_axis:joint=right_hip_pitch,about=z,deg=0.5")
    nominal, real = LegKinematics(lm), LegKinematics(r.sim_legmap)
    k = [lm.joint_roles[int(c)] for c in nominal.poe["right"].cols].index("hip_pitch")
    a0, a1 = nominal.poe["right"].S[k][3:], real.poe["right"].S[k][3:]
    assert np.degrees(np.arccos(a0 @ a1 / np.linalg.norm(a0) / np.linalg.norm(a1))) == pytest.approx(0.5, abs=1e-9)


def test_encoder_scale_and_imu_tilt_enter_the_sensor_path(tmp_path):
    cfg = CollectConfig(robot="a3", mode="kinematic", sensors="zero", offsets="paper", **SHORT,
                        effects=("encoder_scale:joint=left_knee,scale=0.005", "imu_tilt:roll=0.5"))
    collect(cfg, tmp_path / "s", progress=False)
    rec, tr = load_recording(tmp_path / "s" / "stance_I.npz"), load_truth(tmp_path / "s" / "stance_I.npz")
    j = load_robot("a3").joint_roles.index("knee")
    scale = np.ones(12)
    scale[j] = 1.005
    assert np.abs(rec.q_enc * scale + tr.offsets - tr.q_true).max() < 1e-12  # q = (1 + s) q_enc + offset
    true_up = tr.imu_true_acc / np.linalg.norm(tr.imu_true_acc, axis=1)[:, None]
    read_up = rec.imu_acc / np.linalg.norm(rec.imu_acc, axis=1)[:, None]
    angle = np.degrees(np.arccos(np.clip(np.einsum("ni,ni->n", true_up, read_up), -1, 1)))
    assert np.abs(angle - 0.5).max() < 0.02  # the roll tilt less its small share along the vertical
    assert "encoder_scale" not in str(rec.meta()) and "imu_tilt" not in str(rec.meta())  # only the truth says
    assert [e["kind"] for e in tr.meta["reality"]["effects"]] == ["encoder_scale", "imu_tilt"]
    assert np.abs(tr.q_enc_clean - rec.q_enc).max() < 1e-15  # the noise-free reading, scale included


def test_a_series_spring_deflects_by_its_load_over_k(tmp_path):
    cfg = CollectConfig(robot="a3", mode="weld", sensors="zero", offsets="paper", **SHORT,
                        effects=("compliance:joint=left_knee,k=1e4",))
    collect(cfg, tmp_path / "s", progress=False)
    rec, tr = load_recording(tmp_path / "s" / "stance_I.npz"), load_truth(tmp_path / "s" / "stance_I.npz")
    lm = load_robot("a3")
    j = lm.joint_roles.index("knee")
    deflection = tr.q_true - (rec.q_enc + tr.offsets)
    load = joint_loads(LegKinematics(lm), tr.q_true, rec.ft, up_in_base(rec.imu_acc, LegKinematics(lm).R_BI))
    assert np.abs(np.delete(deflection, j, axis=1)).max() < 1e-12  # only the compliant joint
    assert np.abs(deflection[:, j]).mean() > 2e-3  # a squat loads the knee: millirad
    assert deflection[:, j].mean() / (load[:, j].mean() / 1e4) == pytest.approx(1.0, abs=0.01)


def test_a_shim_tilts_the_true_sole_not_the_plan(tmp_path):
    cfg = CollectConfig(robot="a3", mode="weld", sensors="zero", offsets="none", **SHORT,
                        effects=("shim:side=left,roll=0.5",))
    collect(cfg, tmp_path / "s", progress=False)
    tr = load_truth(tmp_path / "s" / "stance_I.npz")
    q = tr.sole_poses_world[:, :, 3:]  # wxyz
    from scipy.spatial.transform import Rotation

    left = Rotation.from_quat(q[:, 0][:, [1, 2, 3, 0]])
    right = Rotation.from_quat(q[:, 1][:, [1, 2, 3, 0]])
    tilt = (right.inv() * left).as_rotvec(degrees=True)  # the soles are placed at the same yaw +- jitter
    assert np.abs(tilt[:, 0] - 0.5).max() < 0.05 and np.abs(tilt[:, 1]).max() < 0.05


def test_bad_effect_specs_name_the_fix(tmp_path):
    with pytest.raises(ConfigError, match="unknown effect 'shank'"):
        parse_effect("shank:mm=2")
    with pytest.raises(ConfigError, match="give mm"):
        parse_effect("link_length:link=left_shank")
    with pytest.raises(ConfigError, match="k is a stiffness"):
        parse_effect("compliance:joint=left_knee,k=-3")
    with pytest.raises(ConfigError, match="joint 'left_elbow' is not one of"):
        _reality(tmp_path, "a3", "encoder_scale:joint=left_elbow,scale=0.01")
    with pytest.raises(ConfigError, match="compliance, joints legcal_compliance_.*needs physics"):
        collect(CollectConfig(robot="a3", mode="kinematic", **SHORT, effects=("compliance:k=1e4",)), tmp_path / "x",
                progress=False)


def test_a_slope_tilts_both_soles_alike(tmp_path):
    cfg = CollectConfig(robot="a3", mode="kinematic", sensors="zero", offsets="none", **SHORT,
                        effects=("slope:pitch=0.4",))
    collect(cfg, tmp_path / "s", progress=False)
    tr = load_truth(tmp_path / "s" / "stance_I.npz")
    from scipy.spatial.transform import Rotation

    for side in (0, 1):
        q = tr.sole_poses_world[:, side, 3:]
        normal = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()[:, :, 2]  # each sole's normal in the world
        assert np.abs(normal - [np.sin(np.radians(0.4)), 0, np.cos(np.radians(0.4))]).max() < 1e-9


@pytest.mark.parametrize("robot", ["a3", "a2"])
def test_a_shank_bent_3mm_sideways_moves_the_true_sole_3mm_along_y_and_does_not_turn_it(tmp_path, robot):
    lm, r = _reality(tmp_path, robot, "link_offset:link=right_shank,axis=y,mm=3")
    nominal, real = LegKinematics(lm), LegKinematics(r.sim_legmap)
    q = np.zeros(12)
    (L0, R0), (L1, R1) = nominal.sole_poses_batch(q[None]), real.sole_poses_batch(q[None])
    assert R1[0, :3, 3] - R0[0, :3, 3] == pytest.approx([0.0, 0.003, 0.0], abs=1e-9)
    assert np.abs(R1[0, :3, :3] - R0[0, :3, :3]).max() < 1e-12 and np.abs(L1 - L0).max() < 1e-12


def test_a_shank_twisted_one_degree_turns_the_sole_one_degree_about_the_shank(tmp_path):
    lm, r = _reality(tmp_path, "a3", "link_twist:link=left_shank,deg=1")
    nominal, real = LegKinematics(lm), LegKinematics(r.sim_legmap)
    q = np.zeros(12)
    (L0, _), (L1, _) = nominal.sole_poses_batch(q[None]), real.sole_poses_batch(q[None])
    dR = L1[0, :3, :3] @ L0[0, :3, :3].T
    assert np.degrees(np.arccos((np.trace(dR) - 1) / 2)) == pytest.approx(1.0, abs=1e-6)
    assert r.truth[0]["kind"] == "link_twist" and r.truth[0]["link"] == "left_shank"


def test_a_knee_axis_tilted_is_a_joint_axis_effect_and_hip_axis_stays_on_the_hips(tmp_path):
    lm, r = _reality(tmp_path, "a3", "joint_axis:joint=left_knee,about=x,deg=0.5")
    nominal, real = LegKinematics(lm), LegKinematics(r.sim_legmap)
    k = [lm.joint_roles[int(c)] for c in nominal.poe["left"].cols].index("knee")
    a0, a1 = nominal.poe["left"].S[k][3:], real.poe["left"].S[k][3:]
    assert np.degrees(np.arccos(a0 @ a1 / np.linalg.norm(a0) / np.linalg.norm(a1))) == pytest.approx(0.5, abs=1e-9)
    with pytest.raises(ConfigError, match="joint 'left_knee' is not one of"):
        _reality(tmp_path, "a3", "hip_axis:joint=left_knee,deg=0.5")
