"""The fast collection path: the posture motion's IK solved in one batch, the ground
truth converted once per segment, and the same data as the frame-by-frame path (the
env's), which solves each frame's IK in `step`."""

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from legcal_bench.errors import IKError
from legcal_bench.geometry.poses import posture_pose
from legcal_bench.protocol.collect import record_segment
from legcal_bench.protocol.stances import (ALL_STANCES, STANCES, Stance, feasible_trajectory, place,
                                           posture_bounds, posture_trajectory, support_margin)
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.geometry.poses import posture_poses
from legcal_bench.sim.double_support import DoubleSupportSim, posture_ik
from legcal_bench.sim.offsets import resolve_offsets
from legcal_bench.sim.scene import apply_servos, build_scene
from legcal_bench.sim.sensors import sim_sensors

JITTER = (0.015, 0.05)


def _sim(mode: str, sim_legmap=None) -> DoubleSupportSim:
    legmap = load_robot("a3")
    return DoubleSupportSim(legmap, mode, resolve_offsets("paper", legmap, np.random.default_rng(0)),
                            sim_sensors("realistic"), sim_legmap=sim_legmap, settle_s=1.0)


def _reset(sim: DoubleSupportSim, stance: str, seed: int):
    """record_segment's reset: the placement and reset observation from the seed's stream."""
    rng = np.random.default_rng(seed)
    placement = place(ALL_STANCES[stance], sim.true_kin.dims, rng, *JITTER)
    sim.reset(placement.left, placement.right, placement.nominal, standing=stance == "standing")
    sim.observe(rng)
    return rng, placement


def _frame_by_frame(sim: DoubleSupportSim, stance: str, duration: float, seed: int, postures=None):
    """The collector's loop without batching: step (IK solved inside), observe, truth."""
    rng, placement = _reset(sim, stance, seed)
    if postures is None:
        n = int(round(duration * sim.rate_hz))
        postures = (np.repeat(sim.posture[None], n, axis=0) if stance == "standing" else
                    feasible_trajectory(sim.nominal, placement, duration, sim.rate_hz, np.random.default_rng(seed + 7919)))
    low, high = posture_bounds(sim.nominal.dims)
    obs, truth = [], []
    for p in postures:
        sim.step(np.clip(p, low, high))
        obs.append(sim.observe(rng))
        truth.append(sim.truth())
    return ({k: np.array([o[k] for o in obs]) for k in obs[0]},
            {k: np.array([t[k] for t in truth]) for k in truth[0]})


def _assert_same(a: tuple[dict, dict], b: tuple[dict, dict]):
    """Observations and truth equal to 1e-9 (the ankle wrenches, hundreds of newtons
    from a stiff closed chain, to 1e-11 relative): the two paths' IK solutions differ
    at the 1e-13 level."""
    for part_a, part_b in zip(a, b):
        assert part_a.keys() == part_b.keys()
        for k in part_a:
            assert part_a[k].shape == part_b[k].shape, k
            if part_a[k].dtype == bool:
                np.testing.assert_array_equal(part_a[k], part_b[k], err_msg=k)
            else:
                np.testing.assert_allclose(part_a[k], part_b[k], rtol=1e-11 if k == "ft" else 0, atol=1e-9,
                                           err_msg=k)


@pytest.mark.parametrize("mode", ["kinematic", "weld"])
@pytest.mark.parametrize("stance", ["standing", "IV"])
def test_batched_segment_reproduces_the_frame_by_frame_path(mode, stance):
    sim = _sim(mode)
    batched = record_segment(sim, stance, 1.5, 21, *JITTER)[:2]
    stepped = _frame_by_frame(sim, stance, 1.5, 21)
    _assert_same(batched, stepped)
    assert batched[1]["posture_reachable"].all()
    if mode == "weld":
        assert batched[0]["ft"].shape == (75, 2, 6)


def test_each_frames_ik_is_solved_once_in_a_batch(monkeypatch):
    """Only the reset solves IK one posture at a time; the motion's IK is one batch."""
    calls = {"solve": 0, "solve_batch": 0}
    for name in calls:
        original = getattr(LegKinematics, name)

        def counted(self, *args, _name=name, _original=original, **kw):
            calls[_name] += 1
            return _original(self, *args, **kw)

        monkeypatch.setattr(LegKinematics, name, counted)
    for mode in ("kinematic", "weld"):
        calls.update(solve=0, solve_batch=0)
        obs = record_segment(_sim(mode), "I", 2.0, 5, *JITTER).obs
        assert len(obs["q_enc"]) == 100
        # One more batch: fitting the stance to the robot (once per stance and robot).
        assert calls["solve"] <= 2 and calls["solve_batch"] <= 3, (mode, calls)


@pytest.fixture(scope="module")
def long_shin_legmap(tmp_path_factory):
    """A3 with a 1 cm longer shin: the same joints, different kinematics."""
    from legcal_bench.robots.build import write_robot
    from legcal_bench.robots.design import A3

    path = write_robot(replace(A3, name="a3_long_shin", shin=(-0.001, -0.003, -0.38)),
                       tmp_path_factory.mktemp("long_shin"))
    return load_robot(str(path))


def test_kinematic_mode_solves_the_simulated_robot_with_its_own_kinematics(long_shin_legmap):
    sim = _sim("kinematic", sim_legmap=long_shin_legmap)
    assert sim.true_kin is not sim.nominal
    batched = record_segment(sim, "II", 1.5, 8, *JITTER)[:2]
    stepped = _frame_by_frame(sim, "II", 1.5, 8)
    _assert_same(batched, stepped)
    # The simulated robot's chain stays closed on its own soles (its IK, not the nominal one's).
    assert batched[1]["sole_drift_m"].max() < 1e-12 and batched[1]["sole_drift_rad"].max() < 1e-12
    nominal_q = posture_ik(sim.nominal, sim.left, sim.right, batched[1]["posture"])
    assert np.abs(batched[1]["q_true"] - nominal_q).max() > 1e-3


@pytest.mark.parametrize("mode", ["kinematic", "weld"])
def test_an_unreachable_posture_is_held_as_in_step(mode):
    sim = _sim(mode)
    _, placement = _reset(sim, "I", 3)
    postures = feasible_trajectory(sim.nominal, placement, 1.0, sim.rate_hz, np.random.default_rng(4))
    postures[20] = postures[19] + [0, 0, 0.5, 0, 0, 0]  # far out of reach (clipped to the bounds, still out)
    postures = np.clip(postures, *posture_bounds(sim.nominal.dims))
    q_cmd = sim.solve_postures(postures)
    assert np.isnan(q_cmd[20]).all() and not np.isnan(np.delete(q_cmd, 20, axis=0)).any()
    rng, _ = _reset(sim, "I", 3)
    batched = sim.run(postures, rng, q_cmd=q_cmd)
    stepped = _frame_by_frame(sim, "I", 1.0, 3, postures)
    _assert_same(batched, stepped)
    reachable = batched[1]["posture_reachable"]
    assert not reachable[20] and reachable.sum() == len(postures) - 1
    np.testing.assert_array_equal(batched[1]["posture"][20], postures[19])  # the previous posture is held


def test_solve_postures_matches_the_sequential_ik():
    sim = _sim("kinematic")
    _, placement = _reset(sim, "III", 6)
    postures = feasible_trajectory(sim.nominal, placement, 1.0, sim.rate_hz, np.random.default_rng(1))
    q = sim.solve_postures(postures)
    kin, q_seq = sim.nominal, sim.nominal.q_init()
    for k, p in enumerate(postures):
        T = posture_pose(p)
        q_seq = kin.solve(T.actInv(placement.left), T.actInv(placement.right), q_seq)
        np.testing.assert_allclose(q[k], q_seq, rtol=0, atol=1e-11)


def _feasible_trajectory_frame_by_frame(kin, placement, duration, rate_hz, rng, shrink=0.8, tries=10):
    """The pre-batching algorithm: each frame's IK from the previous one, the margin every fifth frame."""
    margin = 0.25 * kin.dims.sole_width
    base = posture_trajectory(placement, kin.dims, duration, rate_hz, rng)
    for k in range(tries):
        traj = placement.nominal + (shrink ** k) * (base - placement.nominal)
        q = kin.q_init()
        try:
            for i, p in enumerate(traj):
                T = posture_pose(p)
                q = kin.solve(T.actInv(placement.left), T.actInv(placement.right), q)
                if i % 5 == 0 and support_margin(kin, placement, p, q) < margin:
                    raise IKError("CoM too close to the support polygon's edge")
            return traj, k
        except IKError:
            continue
    raise IKError("no motion")


@pytest.mark.parametrize("amplitude, why", [
    ((0.02, 0.03, 0.14, 0.05, 0.08, 0.10), "out of reach"),  # rises past straight legs
    ((0.02, 0.30, 0.03, 0.05, 0.08, 0.10), "off balance"),  # sways the CoM off the soles
])
def test_an_infeasible_motion_is_shrunk_as_before(amplitude, why):
    kin = LegKinematics(load_robot("a3"))
    placement = place(replace(STANCES["I"], amplitude=amplitude), kin.dims, np.random.default_rng(2), *JITTER)
    expected, k = _feasible_trajectory_frame_by_frame(kin, placement, 6.0, 50.0, np.random.default_rng(9))
    assert k > 0, why  # the test's motion does need shrinking
    traj, q, scale = feasible_trajectory(kin, placement, 6.0, 50.0, np.random.default_rng(9), return_q=True)
    assert scale == 0.8 ** k
    np.testing.assert_array_equal(traj, expected)
    np.testing.assert_array_equal(feasible_trajectory(kin, placement, 6.0, 50.0, np.random.default_rng(9)), expected)
    np.testing.assert_allclose(q, posture_ik(kin, placement.left, placement.right, traj), rtol=0, atol=0)
    assert q.shape == (300, 12)


def test_an_unreachable_nominal_posture_still_raises():
    kin = LegKinematics(load_robot("a3"))
    placement = place(STANCES["I"], kin.dims)
    placement = replace(placement, nominal=placement.nominal + [0, 0, 0.3 * kin.dims.leg_length, 0, 0, 0])
    with pytest.raises(IKError, match="no reachable, balanced posture motion"):
        feasible_trajectory(kin, placement, 1.0, 50.0, np.random.default_rng(0))


def test_batched_helpers_match_their_single_posture_forms():
    kin = LegKinematics(load_robot("a3"))
    placement = place(Stance("x", "x"), kin.dims, np.random.default_rng(3), *JITTER)
    P = posture_trajectory(placement, kin.dims, 2.0, 50.0, np.random.default_rng(4))
    H = posture_poses(P)
    for p, h in zip(P, H):
        np.testing.assert_array_equal(h, posture_pose(p).homogeneous)  # the same conversion, bit for bit
    Q = posture_ik(kin, placement.left, placement.right, P)
    margins = support_margin(kin, placement, P[::7], Q[::7])
    assert margins.shape == (len(P[::7]),)
    for m, p, q in zip(margins, P[::7], Q[::7]):
        assert isinstance(support_margin(kin, placement, p, q), float)
        assert support_margin(kin, placement, p, q) == pytest.approx(m, abs=1e-15)


def test_apply_servos_position_targets_and_motor_pd_law():
    scene = build_scene(load_robot("a3"), "weld")
    data = mujoco.MjData(scene.model)
    rng = np.random.default_rng(0)
    data.qpos[scene.qpos_adr], data.qvel[scene.dof_adr] = rng.normal(size=12), rng.normal(size=12)
    target = rng.normal(size=12)
    apply_servos(scene, data, target)
    np.testing.assert_array_equal(data.ctrl[scene.position_act], target)
    # The same model driven through torque motors on half the joints (the leg map's PD law).
    motors = np.arange(12) % 2 == 1
    kp, kd, gear = rng.uniform(100, 900, 12), rng.uniform(1, 20, 12), rng.uniform(0.5, 2, 12)
    mixed = replace(scene, position_act=np.where(motors, -1, scene.position_act),
                    motor_act=np.where(motors, scene.position_act, -1), servo_kp=np.where(motors, kp, 0),
                    servo_kd=np.where(motors, kd, 0), motor_gear=np.where(motors, gear, 1.0))
    data.ctrl[:] = 0.0
    apply_servos(mixed, data, target)
    q, qd = data.qpos[scene.qpos_adr], data.qvel[scene.dof_adr]
    expected = np.where(motors, (kp * (target - q) - kd * qd) / gear, target)
    np.testing.assert_array_equal(data.ctrl[scene.position_act], expected)


def test_heldout_sessions_come_from_the_recorded_stances(tmp_path):
    import json

    from legcal_bench.protocol.collect import CollectConfig, collect

    collect(CollectConfig(robot="a3", mode="kinematic", stances=("I", "IV"), heldout=6, stance_s=0.4,
                          heldout_s=0.2, standing_s=0.0), tmp_path, progress=False)
    from legcal_bench.data.recording import load_session

    held = [r.stance for r in load_session(tmp_path) if r.kind == "heldout"]
    assert len(held) == 6 and set(held) <= {"I", "IV"}
    assert json.loads((tmp_path / "session.json").read_text())["config"]["stances"] == ["I", "IV"]


def test_a_stance_out_of_reach_names_the_stance_and_the_fix(tmp_path):
    import yaml

    from legcal_bench.errors import IKError
    from legcal_bench.protocol.collect import CollectConfig, collect
    from legcal_bench.robots import ASSETS

    # A3-like with its ankle pitch limited to +-2 deg: no squat posture is reachable.
    xml = (ASSETS / "a3.xml").read_text()
    lm = yaml.safe_load((ASSETS / "a3.legmap.yaml").read_text())
    for side in ("left", "right"):
        name = f"{side}_ankle_pitch_joint"
        i = xml.index(f'name="{name}"')
        j = xml.index("range=", i)
        k = xml.index('"', xml.index('"', j) + 1)
        xml = xml[:j] + 'range="-0.035 0.035' + xml[k:]
    (tmp_path / "a3.xml").write_text(xml)
    lm["mjcf"] = "a3.xml"
    (tmp_path / "narrow.legmap.yaml").write_text(yaml.safe_dump(lm))
    with pytest.raises(IKError, match=r"stance I \(normal squat\) does not fit this robot even shrunk to 0.2 .*"
                                      r"ankle_pitch.*--stances"):
        collect(CollectConfig(robot=str(tmp_path / "narrow.legmap.yaml"), mode="kinematic", stances=("I",),
                              heldout=0, standing_s=0.0, stance_s=0.2), tmp_path / "out", progress=False)
    assert not (tmp_path / "out").exists()  # nothing half-written
