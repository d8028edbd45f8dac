import gymnasium as gym
import numpy as np
import pinocchio as pin
import pytest
from gymnasium.utils.env_checker import check_env

import legcal_bench.envs as envs
from legcal_bench.envs import STATIC_ROBOTS, env_id
from legcal_bench.kinematics import pos_quat_to_se3
from legcal_bench.stances import feasible_trajectory

from pathlib import Path

G1_LEGMAP = Path(__file__).resolve().parents[1] / "examples" / "unitree_g1.legmap.yaml"


def _make(suffix: str, **kw):
    if STATIC_ROBOTS[suffix] is None:
        kw.setdefault("robot", str(G1_LEGMAP))
    return gym.make(env_id(suffix), **kw)


@pytest.mark.parametrize("suffix", list(STATIC_ROBOTS))
def test_registered_env_passes_check_env(suffix):
    env = _make(suffix, mode="kinematic")
    check_env(env.unwrapped, skip_render_check=True)
    obs, info = env.reset(seed=3)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs)
    assert set(info) >= {"q_true", "offsets", "sole_poses_world", "pelvis_pose_world"}


@pytest.mark.parametrize("mode", ["weld", "contact"])
def test_dynamic_modes_pass_check_env(mode):
    env = envs.StaticDoubleSupportEnv(robot="a3", mode=mode, settle_s=0.2)
    check_env(env, skip_render_check=True)
    assert "ft" in env.observation_space.spaces


def test_observation_has_no_ground_truth():
    env = envs.StaticDoubleSupportEnv(robot="a3", mode="kinematic")
    obs, _ = env.reset(seed=0)
    assert set(obs) == {"q_enc", "imu_acc", "imu_gyro"}


def test_reset_is_reproducible():
    a = envs.StaticDoubleSupportEnv(robot="a2", mode="weld", settle_s=0.2)
    b = envs.StaticDoubleSupportEnv(robot="a2", mode="weld", settle_s=0.2)
    for env in (a, b):
        env.reset(seed=11, options={"stance": "II"})
    for _ in range(5):
        oa = a.step(a._posture + 0.001)[0]
        ob = b.step(b._posture + 0.001)[0]
        for k in oa:
            np.testing.assert_array_equal(oa[k], ob[k])


def _run_stance(env, stance, seconds, seed=0):
    _, info = env.reset(seed=seed, options={"stance": stance})
    traj = feasible_trajectory(env.nominal, env._placement, seconds, env.rate_hz, np.random.default_rng(seed))
    infos = [env.step(p)[4] for p in traj]
    return info, infos


def test_kinematic_postures_close_the_chain_and_encoders_are_offset():
    env = envs.StaticDoubleSupportEnv(robot="a3", mode="kinematic", sensors="zero")
    first, infos = _run_stance(env, "III", 3.0)
    C_ref = pos_quat_to_se3(first["sole_poses_world"][0]).actInv(pos_quat_to_se3(first["sole_poses_world"][1]))
    for info in infos:
        assert info["posture_reachable"]
        left, right = env.true_kin.sole_poses(info["q_true"])
        assert np.linalg.norm(pin.log6(C_ref.actInv(left.actInv(right))).vector) < 1e-12
        assert info["sole_drift_m"].max() < 1e-12
    # Zero-noise encoders are exactly q_true - offsets.
    obs = env.step(infos[-1]["posture"])[0]
    np.testing.assert_allclose(obs["q_enc"], env._q_true - env.offsets, atol=1e-15)


def test_weld_holds_the_feet():
    env = envs.StaticDoubleSupportEnv(robot="a3", mode="weld")
    for stance in ("I", "IV"):
        _, infos = _run_stance(env, stance, 6.0)
        drift_m = max(i["sole_drift_m"].max() for i in infos)
        drift_rad = max(i["sole_drift_rad"].max() for i in infos)
        assert drift_m < 1e-4 and np.rad2deg(drift_rad) < 0.01, (stance, drift_m, drift_rad)


def test_contact_feet_slip_less_than_a_millimetre():
    env = envs.StaticDoubleSupportEnv(robot="a3", mode="contact")
    for stance in ("I", "II"):
        _, infos = _run_stance(env, stance, 12.0)
        slip = max(np.linalg.norm((i["sole_poses_world"][:, :2] - infos[0]["sole_poses_world"][:, :2]), axis=1).max()
                   for i in infos)
        assert slip < 1e-3, (stance, slip)


def test_standing_knee_sits_at_straight_angle_plus_error():
    err = np.deg2rad(0.3)
    env = envs.StaticDoubleSupportEnv(robot="a3", mode="kinematic", knee_straight_error_rad=err, sensors="zero")
    _, info = env.reset(seed=0, options={"stance": "standing"})
    knees = [i for i, r in enumerate(env.legmap.joint_roles) if r == "knee"]
    np.testing.assert_allclose(info["q_true"][knees], env.legmap.knee_straight_rad + err, atol=1e-12)
    # The action is ignored while standing.
    _, _, _, _, info2 = env.step(env.action_space.sample())
    np.testing.assert_array_equal(info2["q_true"], info["q_true"])


def test_paper_offsets_map_by_role():
    a2 = envs.StaticDoubleSupportEnv(robot="a2", mode="kinematic")
    roles = a2.legmap.joint_roles
    assert a2.offsets[roles.index("hip_pitch")] == pytest.approx(0.03)
    assert a2.offsets[roles.index("hip_roll")] == pytest.approx(0.04)
    assert roles.index("hip_pitch") == 2  # A2 order: roll, yaw, pitch


def test_sim_model_must_match_joint_names(testbot_legmap):
    from legcal_bench.robots.legmap import LegMapError

    with pytest.raises(LegMapError, match="same 12 leg joint names"):
        envs.StaticDoubleSupportEnv(robot="a3", sim_robot=str(testbot_legmap))


def test_reward_is_the_information_gain_of_each_frame():
    env = envs.StaticDoubleSupportEnv(robot="a3", mode="kinematic", sensors="zero")
    _, info = env.reset(seed=0, options={"stance": "I"})
    traj = feasible_trajectory(env.nominal, env._placement, 4.0, 50, np.random.default_rng(0))
    rewards = [env.step(p)[1] for p in traj]
    total = env.unwrapped._information.logdet if hasattr(env, "unwrapped") else None
    assert np.isfinite(rewards).all() and sum(rewards) > 20  # varied postures add information
    assert np.isclose(sum(rewards), total - info["log_det_information"])
    # Repeating the same posture adds almost nothing.
    still = [env.step(traj[-1])[1] for _ in range(20)]
    assert max(still[5:]) < 0.05 * max(rewards)
