import gymnasium as gym
import numpy as np
import pinocchio as pin
import pytest
from gymnasium.utils.env_checker import check_env

from legcal_bench.envs import STATIC_ROBOTS, env_id
from legcal_bench.envs.static_double_support import StaticDoubleSupportEnv
from legcal_bench.geometry.poses import pos_quat_to_se3
from legcal_bench.protocol.stances import feasible_trajectory

from pathlib import Path

G1_LEGMAP = Path(__file__).resolve().parents[2] / "examples" / "unitree_g1.legmap.yaml"


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
    env = StaticDoubleSupportEnv(robot="a3", mode=mode, settle_s=0.2)
    check_env(env, skip_render_check=True)
    assert "ft" in env.observation_space.spaces


def test_observation_has_no_ground_truth():
    env = StaticDoubleSupportEnv(robot="a3", mode="kinematic")
    obs, _ = env.reset(seed=0)
    assert set(obs) == {"q_enc", "imu_acc", "imu_gyro"}


def test_reset_is_reproducible():
    a = StaticDoubleSupportEnv(robot="a2", mode="weld", settle_s=0.2)
    b = StaticDoubleSupportEnv(robot="a2", mode="weld", settle_s=0.2)
    for env in (a, b):
        _, info = env.reset(seed=11, options={"stance": "II"})
    for _ in range(5):
        oa = a.step(info["posture"] + 0.001)[0]
        ob = b.step(info["posture"] + 0.001)[0]
        for k in oa:
            np.testing.assert_array_equal(oa[k], ob[k])


def _run_stance(env, stance, seconds, seed=0):
    _, info = env.reset(seed=seed, options={"stance": stance})
    traj = feasible_trajectory(env.sim.nominal, env.placement, seconds, env.metadata["render_fps"],
                               np.random.default_rng(seed))
    infos = [env.step(p)[4] for p in traj]
    return info, infos


def test_kinematic_postures_close_the_chain_and_encoders_are_offset():
    env = StaticDoubleSupportEnv(robot="a3", mode="kinematic", sensors="zero")
    first, infos = _run_stance(env, "III", 3.0)
    C_ref = pos_quat_to_se3(first["sole_poses_world"][0]).actInv(pos_quat_to_se3(first["sole_poses_world"][1]))
    for info in infos:
        assert info["posture_reachable"]
        left, right = env.sim.true_kin.sole_poses(info["q_true"])
        assert np.linalg.norm(pin.log6(C_ref.actInv(left.actInv(right))).vector) < 1e-12
        assert info["sole_drift_m"].max() < 1e-12
    # Zero-noise encoders are exactly q_true - offsets.
    obs, _, _, _, info = env.step(infos[-1]["posture"])
    np.testing.assert_allclose(obs["q_enc"], info["q_true"] - info["offsets"], atol=1e-15)


def test_weld_holds_the_feet():
    env = StaticDoubleSupportEnv(robot="a3", mode="weld")
    for stance in ("I", "IV"):
        _, infos = _run_stance(env, stance, 6.0)
        drift_m = max(i["sole_drift_m"].max() for i in infos)
        drift_rad = max(i["sole_drift_rad"].max() for i in infos)
        assert drift_m < 1e-4 and np.rad2deg(drift_rad) < 0.01, (stance, drift_m, drift_rad)


def test_contact_feet_slip_less_than_a_millimetre():
    env = StaticDoubleSupportEnv(robot="a3", mode="contact")
    for stance in ("I", "II"):
        _, infos = _run_stance(env, stance, 12.0)
        slip = max(np.linalg.norm((i["sole_poses_world"][:, :2] - infos[0]["sole_poses_world"][:, :2]), axis=1).max()
                   for i in infos)
        assert slip < 1e-3, (stance, slip)


def test_standing_knee_sits_at_straight_angle_plus_error():
    err = np.deg2rad(0.3)
    env = StaticDoubleSupportEnv(robot="a3", mode="kinematic", knee_straight_error_rad=err, sensors="zero")
    _, info = env.reset(seed=0, options={"stance": "standing"})
    knees = [i for i, r in enumerate(env.legmap.joint_roles) if r == "knee"]
    np.testing.assert_allclose(info["q_true"][knees], env.legmap.knee_straight_rad + err, atol=1e-12)
    # The action is ignored while standing.
    _, _, _, _, info2 = env.step(env.action_space.sample())
    np.testing.assert_array_equal(info2["q_true"], info["q_true"])


def test_paper_offsets_map_by_role():
    a2 = StaticDoubleSupportEnv(robot="a2", mode="kinematic")
    roles = a2.legmap.joint_roles
    assert a2.offsets[roles.index("hip_pitch")] == pytest.approx(0.03)
    assert a2.offsets[roles.index("hip_roll")] == pytest.approx(0.04)
    assert roles.index("hip_pitch") == 2  # A2 order: roll, yaw, pitch


def test_sim_model_must_match_joint_names(testbot_legmap):
    from legcal_bench.errors import LegMapError

    with pytest.raises(LegMapError, match="same 12 leg joint names"):
        StaticDoubleSupportEnv(robot="a3", sim_robot=str(testbot_legmap))


def test_reward_is_the_information_gain_of_each_frame():
    env = StaticDoubleSupportEnv(robot="a3", mode="kinematic", sensors="zero")
    _, info = env.reset(seed=0, options={"stance": "I"})
    traj = feasible_trajectory(env.sim.nominal, env.placement, 4.0, 50, np.random.default_rng(0))
    steps = [env.step(p) for p in traj]
    rewards = [s[1] for s in steps]
    assert np.isfinite(rewards).all() and sum(rewards) > 20  # varied postures add information
    assert np.isclose(sum(rewards), steps[-1][4]["log_det_information"] - info["log_det_information"])
    # The running value is the log-determinant of the information gathered (ε = 1).
    assert np.isclose(steps[-1][4]["log_det_information"], np.linalg.slogdet(env.information_matrix + np.eye(12))[1])
    # Repeating the same posture adds almost nothing.
    still = [env.step(traj[-1])[1] for _ in range(20)]
    assert max(still[5:]) < 0.05 * max(rewards)


def test_gym_make_imports_the_package_itself_in_a_fresh_interpreter():
    import subprocess
    import sys

    code = ("import gymnasium as gym\n"
            "env = gym.make('legcal_bench.envs:legcal/StaticDoubleSupport-A3-v0', mode='kinematic')\n"
            "obs, info = env.reset(seed=0)\n"
            "print(env.unwrapped.legmap.name, obs['q_enc'].shape, env.metadata['render_fps'])\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.split() == ["a3", "(12,)", "50"]


def test_register_envs_route_and_the_path_id_needs_a_robot():
    import legcal_bench.envs
    from legcal_bench.errors import LegMapError

    gym.register_envs(legcal_bench.envs)
    with pytest.raises(LegMapError, match="robot: give a built-in name or the path of a leg map"):
        gym.make(env_id("Path"))


def test_render_fps_follows_the_logging_rate():
    env = StaticDoubleSupportEnv(robot="a3", mode="kinematic", rate_hz=100.0)
    assert env.metadata["render_fps"] == 100 and env.dt == pytest.approx(0.01)
    assert StaticDoubleSupportEnv.metadata["render_fps"] == 50  # the class default is untouched


def test_a_recorded_segment_is_an_env_episode(tmp_path):
    """The collector and the env share one simulator: same seed, same postures, same data
    (to 1e-9: the collector solves the posture motion's IK in one batch, the env frame by
    frame, and the two solutions differ at the 1e-13 level)."""
    from legcal_bench.data.recording import load_recording, load_truth
    from legcal_bench.protocol.collect import CollectConfig, collect

    collect(CollectConfig(robot="a3", mode="weld", stances=("II",), heldout=0, standing_s=0.0, stance_s=1.0,
                          seed=4), tmp_path, progress=False)
    rec, truth = load_recording(tmp_path / "stance_II.npz"), load_truth(tmp_path / "stance_II.npz")
    env = StaticDoubleSupportEnv(robot="a3", mode="weld", offset_seed=4, information_reward=False)
    env.reset(seed=truth.meta["seed"], options={"stance": "II"})
    for k, posture in enumerate(truth.posture):
        obs = env.step(posture)[0]
        np.testing.assert_allclose(obs["q_enc"], rec.q_enc[k], rtol=0, atol=1e-9)
        np.testing.assert_allclose(obs["imu_acc"], rec.imu_acc[k], rtol=0, atol=1e-9)
