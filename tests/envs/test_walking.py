"""The walking env (issue #13): Gymnasium's checker, offsets that bend the real
posture, corrections applied as a robot applies them, and the G1 walking through its
published policy's spec."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import G1_LEGMAP

G1_POLICY = G1_LEGMAP.parent / "unitree_g1.policy.yaml"
G1_HERE = (G1_LEGMAP.parents[2] / "shared" / "external" / "unitree_g1" / "motion.pt").is_file()
needs_g1 = pytest.mark.skipif(not G1_HERE, reason="../shared/external/unitree_g1 is not beside the checkout")
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


def test_check_env_and_the_registered_ids():
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    import legcal_bench.envs  # noqa: F401

    env = gym.make("legcal/Walking-A3-v0", sensors="zero")
    check_env(env.unwrapped, skip_render_check=True)
    obs, info = env.reset(seed=3)
    assert set(obs) >= {"q_enc", "dq_enc", "ang_vel", "gravity", "imu_acc", "imu_gyro"}
    # Standing still at the default pose, the servos hold the encoders at their targets.
    u = env.unwrapped
    for _ in range(25):
        obs, r, term, trunc, info = env.step(np.asarray(u.sim.config.default_q))
    assert not term and r == 0.0 and np.abs(obs["q_enc"] - u.sim.config.default_q).max() < 0.02
    assert obs["gravity"] @ [0, 0, -1] > np.cos(np.deg2rad(3)) and info["foot_loads"].sum() > 0.8 * u.sim.weight
    with pytest.raises(Exception, match="robot"):
        gym.make("legcal/Walking-Path-v0")


def test_offsets_bend_the_real_posture_and_the_true_correction_undoes_them():
    from legcal_bench.envs.walking import WalkingEnv

    env = WalkingEnv(robot="a3", sensors="zero")
    hold = np.asarray(env.sim.config.default_q)
    finals = {}
    for name, opts in (("none", {"offsets": "none"}), ("paper@2", {"offsets": "paper@2"}),
                       ("corrected", {"offsets": "paper@2", "correction": None})):
        if name == "corrected":
            opts["correction"] = env.offsets.copy()
        env.reset(seed=0, options=opts)
        for _ in range(25):
            obs, _, _, _, info = env.step(hold)
        finals[name] = (obs["q_enc"], info["q_true"])
    # The encoders read the target either way; the true joints move by the offsets...
    assert np.abs(finals["paper@2"][0] - finals["none"][0]).max() < 0.04  # servo sag under a changed load
    dq = np.deg2rad(2) * np.sign(env.offsets)
    moved = finals["paper@2"][1] - finals["none"][1]
    assert np.allclose(moved, dq, atol=0.03) and (np.sign(moved) == np.sign(dq)).all()  # a wrong sign misses by 2 dq
    # ... unless the correction puts them back.
    assert np.abs(finals["corrected"][1] - finals["none"][1]).max() < 0.005


def test_a_robot_without_support_falls_and_the_episode_ends():
    from legcal_bench.envs.walking import WalkingEnv

    env = WalkingEnv(robot="a2", sensors="zero")
    env.reset(seed=0)
    limp = np.asarray(env.sim.config.default_q) + np.array([0, 0, 0, 1.2, 0, 0] * 2)  # knees fold
    for k in range(200):
        _, _, term, _, info = env.step(limp)
        if term:
            break
    assert term and info["fallen"] and 0 < info["fallen_at"] < 4.0


@needs_g1
def test_the_g1_walks_through_its_spec_and_offsets_move_it():
    """A fast guard: 4 s of the published policy, nominal, at paper@3 and corrected."""
    from legcal_bench.envs.walking import WalkingEnv
    from legcal_bench.evaluation.walk import deviation, walk
    from legcal_bench.policies.runner import PolicyRunner

    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    check_env(gym.make("legcal/Walking-Path-v0", robot=str(G1_LEGMAP), policy=str(G1_POLICY)).unwrapped,
              skip_render_check=True)
    env = WalkingEnv(robot=str(G1_LEGMAP), policy=str(G1_POLICY))
    runner = PolicyRunner(env.policy_spec, env.legmap)
    nominal = walk(env, runner, 4.0, seed=1, options={"offsets": "none"})
    offset = walk(env, runner, 4.0, seed=1, options={"offsets": "paper@3"})
    fixed = walk(env, runner, 4.0, seed=1, options={"offsets": "paper@3", "correction": env.offsets.copy()})
    again = walk(env, runner, 4.0, seed=1, options={"offsets": "none", "correction": None})
    assert nominal.upright and offset.upright and fixed.upright
    # It walks forward at about the commanded 0.5 m/s, stepping with both feet.
    assert 1.2 < nominal.pelvis[-1, 0] - nominal.pelvis[0, 0] < 3.0
    assert min(len(nominal.strikes[s]["time"]) for s in ("left", "right")) >= 3
    # Same seed, same walk (the recurrent policy's memory is reset); offsets move it;
    # the true correction brings it back.
    assert np.allclose(again.pelvis, nominal.pelvis)
    assert deviation(offset, nominal)["pelvis_rms_mm"] > 50
    assert deviation(fixed, nominal)["pelvis_rms_mm"] < 5
    assert nominal.privileged == [] and nominal.wall_s < 4.0


@needs_g1
def test_the_imu_filter_integrates_period_means_not_aliased_samples():
    """Why the filter is fed the rate and specific force averaged over each control
    period: one instantaneous IMU sample per 20 ms aliases the footfalls."""
    from legcal_bench.envs.walking import WalkingEnv
    from legcal_bench.policies.runner import PolicyRunner
    from legcal_bench.sim.orientation import GravityFilter

    env = WalkingEnv(robot=str(G1_LEGMAP), policy=str(G1_POLICY), sensors="zero")
    runner = PolicyRunner(env.policy_spec, env.legmap)
    obs, info = env.reset(seed=0)
    runner.reset()
    sim = env.sim
    sampled = GravityFilter()
    sampled.down = sim.filter.down.copy()
    err_mean, err_sampled = [], []
    for _ in range(500):  # 10 s
        obs, _, _, _, info = env.step(runner.act(obs, info, sim.time))
        acc, gyro = sim._true_imu()
        sampled.update(acc, gyro, sim.config.control_dt)
        true_down = sim.data.site_xmat[sim.scene.imu_site].reshape(3, 3).T @ [0.0, 0.0, -1.0]
        err_mean.append(np.degrees(np.arccos(np.clip(sim.filter.down @ true_down, -1, 1))))
        err_sampled.append(np.degrees(np.arccos(np.clip(sampled.down @ true_down, -1, 1))))
    m, s = np.mean(err_mean[100:]), np.mean(err_sampled[100:])  # after the first 2 s
    print(f"gravity error, mean over 2-10 s of walking: period means {m:.2f} deg, instantaneous samples {s:.2f} deg")
    assert s > 2 * m


@needs_g1
def test_walk_refuses_a_spec_for_another_robot_and_bad_offsets(capsys, tmp_path):
    import yaml

    from legcal_bench.cli import main

    # Joints are matched by name: a spec naming a joint the robot lacks is refused.
    doc = yaml.safe_load(G1_POLICY.read_text())
    doc["joints"][0] = "left_hip_pitch_motor"
    doc["model"]["file"] = str((G1_POLICY.parent / doc["model"]["file"]).resolve())
    other = tmp_path / "other.policy.yaml"
    other.write_text(yaml.safe_dump(doc))
    assert main(["walk", "--robot", str(G1_LEGMAP), "--policy", str(other), "--seconds", "1"]) == 2
    err = capsys.readouterr().err
    assert "not in the leg map: ['left_hip_pitch_motor']" in err and "does not drive: ['left_hip_pitch_joint']" in err
    assert main(["walk", "--robot", str(G1_LEGMAP), "--policy", str(G1_POLICY), "--offsets", "paper@99"]) == 2
    assert "must be in [0, 10] degrees" in capsys.readouterr().err
    assert main(["walk", "--robot", str(G1_LEGMAP), "--policy", "nowhere.yaml"]) == 2
    assert "nowhere.yaml: no such file; give a spec YAML or one of our policies (a2, a3)" in capsys.readouterr().err
    assert main(["walk-eval", "--robot", str(G1_LEGMAP), "--policy", str(G1_POLICY), "--trials", "0"]) == 2
