"""Legs of five joints (issue #37: no ankle roll): every joint vector the simulator, the
envs, the offset presets and the recordings make has the leg map's own length."""

from __future__ import annotations

import numpy as np
import pytest

from legcal_bench.errors import OffsetSpecError, RecordingError
from legcal_bench.paper import A3_BASE_DEG, A3_PLATFORM_ORDER, INJECTION_RAD
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import VARIATIONS
from legcal_bench.sim.offsets import paper_note, resolve_offsets

FIVE = [d for d in VARIATIONS if d.absent_roles]
pytestmark = pytest.mark.skipif(not FIVE, reason="no five-joint design among the variations")


@pytest.fixture(scope="module")
def five(tmp_path_factory):
    return load_robot(str(write_robot(FIVE[0], tmp_path_factory.mktemp("five"))))


def test_the_paper_presets_go_by_role_and_say_what_they_leave_out(five):
    assert (five.leg_joints, five.n_joints, five.absent_roles) == (5, 10, ("ankle_roll",))
    paper = resolve_offsets("paper", five)
    assert paper.shape == (five.n_joints,)
    assert np.allclose(np.abs(paper), [abs(INJECTION_RAD[r]) for r in five.joint_roles])
    assert "ankle_roll" in paper_note("paper", five) and "not injected" in paper_note("paper", five)
    assert "ankle_roll" in paper_note("paper@3", five) and "ankle_roll" in paper_note("paper-base", five)
    assert paper_note("none", five) is None and paper_note("paper", load_robot("a3")) is None
    base = np.rad2deg(np.abs(resolve_offsets("paper-base", five)))  # an A3-like leg: the A3's table, by role
    per_leg = len(A3_PLATFORM_ORDER)
    want = [abs(A3_BASE_DEG[(five.side_of(i) == "right") * per_leg + A3_PLATFORM_ORDER.index(r)])
            for i, r in enumerate(five.joint_roles)]
    assert np.allclose(base, want)
    assert resolve_offsets("random:1", five, np.random.default_rng(0)).shape == (five.n_joints,)
    assert resolve_offsets(",".join(["0.01"] * five.n_joints), five).shape == (five.n_joints,)
    with pytest.raises(OffsetSpecError, match=f"expected {five.n_joints} finite values"):
        resolve_offsets(np.zeros(12), five)


@pytest.mark.parametrize("mode", ["kinematic", "weld"])
def test_the_simulator_logs_one_column_per_leg_joint(five, mode):
    from legcal_bench.protocol.servos import servo_gains
    from legcal_bench.protocol.stances import STANDING, fit_stance, place
    from legcal_bench.sim.double_support import DoubleSupportSim
    from legcal_bench.sim.sensors import sim_sensors

    sim = DoubleSupportSim(five, mode, resolve_offsets("paper", five), sim_sensors("realistic"),
                           servo_gains=servo_gains(five) if mode != "kinematic" else None, settle_s=0.2)
    pl = place(fit_stance(STANDING, sim.nominal).stance, sim.true_kin.dims)
    sim.reset(pl.left, pl.right, pl.nominal, standing=True)
    obs, truth = sim.run(np.repeat(sim.posture[None], 5, axis=0), np.random.default_rng(0))
    assert obs["q_enc"].shape == truth["q_true"].shape == (5, five.n_joints)
    assert sim.observe(np.random.default_rng(0))["q_enc"].shape == (five.n_joints,)
    if mode != "kinematic":
        assert len(sim.scene.qpos_adr) == len(sim.scene.servo_kp) == five.n_joints


def test_the_envs_spaces_have_the_leg_maps_count(five):
    from legcal_bench.envs.static_double_support import StaticDoubleSupportEnv
    from legcal_bench.envs.walking import WalkingEnv

    env = StaticDoubleSupportEnv(robot=five, mode="kinematic", sensors="zero")
    assert env.observation_space["q_enc"].shape == (five.n_joints,)
    obs, _ = env.reset(seed=0, options={"stance": "standing"})
    assert env.observation_space.contains(obs) and env.information_matrix.shape == (five.n_joints,) * 2
    walking = WalkingEnv(robot=five, sensors="zero")
    assert walking.action_space.shape == (five.n_joints,)
    assert walking.observation_space["q_enc"].shape == walking.observation_space["dq_enc"].shape == (five.n_joints,)
    obs, _ = walking.reset(seed=0)
    obs, *_ = walking.step(walking.sim.config.default_q)
    assert obs["q_enc"].shape == obs["dq_enc"].shape == (five.n_joints,)


def test_a_recording_is_checked_against_the_leg_maps_count(five, tmp_path):
    from legcal_bench.data.recording import Recording, load_recording
    from legcal_bench.sim.sensors import SENSOR_PRESETS

    n = 20
    rec = Recording(name="s", kind="stance", stance="I", robot=five.name, joint_names=five.joint_names,
                    time=np.arange(n) * 0.02, q_enc=np.full((n, five.n_joints), 0.1),
                    imu_acc=np.tile([0, 0, 9.81], (n, 1)), imu_gyro=np.zeros((n, 3)),
                    sensor_model=SENSOR_PRESETS["realistic"].model)
    path = rec.save(tmp_path / "s.npz")
    assert load_recording(path, five.joint_names).q_enc.shape == (n, five.n_joints)
    with pytest.raises(RecordingError, match=f"must list the robot's 12 leg joints, got {five.n_joints}"):
        load_recording(path, load_robot("a3").joint_names)


def test_collects_summary_prints_what_the_preset_leaves_out(five):
    from legcal_bench.protocol.collect import CollectSummary, format_summary

    note = paper_note("paper", five)
    s = CollectSummary("out", {}, resolve_offsets("paper", five).tolist(), five.joint_names, notes=[note],
                       servo_gains={"kp": [100.0] * five.n_joints, "kd": [1.0] * five.n_joints,
                                    "source": ["MJCF"] * five.n_joints, "note": ""})
    text = format_summary(s)
    assert note in text and f"over {five.n_joints})" in text
    gains = next(line for line in text.splitlines() if line.startswith("servo gains"))
    assert gains.count("(MJCF)") == five.leg_joints  # the left leg's


def test_the_pelvis_hold_error_takes_a_chain_that_cannot_move_every_way(tmp_path):
    """Issue #60: straight legs of five joints with the sole under the ankle cannot move
    one sole vertically relative to the other; the strained pose's 6x6 system is then
    singular (it raised `numpy.linalg.LinAlgError`) and the compromise is the least-norm one."""
    from dataclasses import replace

    from legcal_bench.protocol.servos import servo_gains
    from legcal_bench.robots.design import A3
    from legcal_bench.sim.double_support import DoubleSupportSim
    from legcal_bench.sim.sensors import sim_sensors

    straight = replace(A3, name="straight_five", absent_roles=("ankle_roll",), thigh=(0.0, 0.0, -0.34),
                       shin=(0.0, 0.0, -0.37), sole_offset=(0.0, 0.0, -0.058))
    lm = load_robot(str(write_robot(straight, tmp_path)))
    sim = DoubleSupportSim(lm, "weld", np.zeros(lm.n_joints), sim_sensors("zero"), servo_gains=servo_gains(lm),
                           settle_s=0.2)
    q = np.zeros((2, lm.n_joints))
    soles = np.stack(sim.true_kin.sole_poses_batch(q), axis=1)
    soles[1, 1, 0, 3] += 1e-3  # the right sole 1 mm forward in the second frame: a strain the chain can take
    hold, strain, beyond = sim._pelvis_hold_error({"time": np.zeros(2), "q_target": q}, soles,
                                                  np.repeat(np.eye(4)[None], 2, axis=0))
    assert np.all(np.isfinite(hold)) and np.all(np.isfinite(strain)) and np.all(np.isfinite(beyond))
    assert strain[0] == 0.0 and 0.0 < strain[1] < 1e-3
