"""Two-motor parallel-linkage ankles: the motors' encoders stand in the ankle's columns,
the leg map gives the linkage, the kinematics maps motors to joints; the map is checked
against MuJoCo's own closed chain (equality constraints), and the offsets are recovered
where the encoders are."""

import mujoco
import numpy as np
import pytest
import yaml

from legcal_bench import api
from legcal_bench.data.recording import list_segments, load_recording, load_truth
from legcal_bench.errors import ConfigError, LegMapError, RecordingError
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics, joint_frame_kinematics
from legcal_bench.robots.samples import closed_chain, linkage_ankle

# Ankle angles (pitch, roll) inside the A3-like ankle's range (pitch -0.9..0.55, roll +-0.35).
ANKLES = np.array([[0.0, 0.0], [0.3, -0.2], [-0.85, 0.3], [0.5, -0.33], [-0.4, 0.1]])


@pytest.fixture(scope="module")
def robot(tmp_path_factory):
    path = linkage_ankle(tmp_path_factory.mktemp("linkage"))
    return path, LegKinematics(load_robot(str(path)))


def test_the_maps_invert_and_their_jacobians_are_the_derivatives(robot):
    _, kin = robot
    assert [(lk.side, lk.cols, lk.shank_body, lk.foot_body) for lk in kin.linkages] == [
        ("left", (4, 5), "left_knee_link", "left_foot_link"), ("right", (10, 11), "right_knee_link", "right_foot_link")]
    for lk in kin.linkages:
        m, J = lk.motor_jacobian(ANKLES)
        assert np.abs(lk.motors(np.zeros((1, 2)))).max() < 1e-15  # the sample's encoders read zero at the ankle's zero
        q, D = lk.joints(m)
        assert np.abs(q - ANKLES).max() < 1e-14
        assert np.abs(D @ J - np.eye(2)).max() < 1e-12
        h = 1e-6
        for j in range(2):
            step = np.zeros(2)
            step[j] = h
            assert np.abs((lk.motors(ANKLES + step) - lk.motors(ANKLES - step)) / (2 * h) - J[:, :, j]).max() < 1e-8


def test_the_maps_agree_with_mujocos_closed_chain(robot):
    """The robot's model with cranks, rods, ball joints and `connect` equalities built from
    the leg map's numbers in the shank and foot bodies' own frames (not from our geometry),
    the cranks locked at g(q): MuJoCo settles the ankle at q."""
    path, kin = robot
    left, right = kin.linkages
    for q_left, q_right in zip(ANKLES[1:], ANKLES[::-1]):
        motors = {"left": tuple(left.motors(q_left[None])[0]), "right": tuple(right.motors(q_right[None])[0])}
        model, ankles = closed_chain(path, motors)
        data = mujoco.MjData(model)
        for _ in range(4000):
            mujoco.mj_step(model, data)
        for side, q in (("left", q_left), ("right", q_right)):
            got = [data.qpos[model.jnt_qposadr[model.joint(n).id]] for n in ankles[side]]
            assert np.abs(np.array(got) - q).max() < 1e-9, (side, got, q)


def test_frame_kinematics_is_by_the_motors_angles(robot):
    """G and the sole Jacobians are by the recorded (motor) angles: finite differences of
    the inter-foot transform and the sole positions through the linkage."""
    _, kin = robot
    rng = np.random.default_rng(3)
    q = rng.uniform(-0.2, 0.2, (4, 12))
    Q = kin.recorded_angles(q)
    assert np.abs(kin.joint_angles(Q) - q).max() < 1e-14
    fk, ref = frame_kinematics(kin, Q), joint_frame_kinematics(kin, q)
    assert np.abs(fk.C - ref.C).max() < 1e-14
    h = 1e-6
    for c in (4, 5, 10, 11):
        step = np.zeros(12)
        step[c] = h
        plus, minus = frame_kinematics(kin, Q + step), frame_kinematics(kin, Q - step)
        side, local = ("left", c) if c < 6 else ("right", c - 6)
        p = {"left": (plus.p_L, minus.p_L, fk.R_L, fk.J_L), "right": (plus.p_R, minus.p_R, fk.R_R, fk.J_R)}[side]
        v_world = (p[0] - p[1]) / (2 * h)  # the sole's velocity in the pelvis frame = R J_v
        assert np.abs(v_world - np.einsum("nij,nj->ni", p[2], p[3][:, :3, local])).max() < 1e-8


def test_zero_noise_recovery_is_in_motor_space(robot, tmp_path):
    path, kin = robot
    out = tmp_path / "k"
    collect(CollectConfig(robot=str(path), mode="kinematic", sensors="zero", offsets="paper", seed=0), out,
            progress=False)
    result = api.calibrate(out, str(path))
    rec = api.score(out, result, str(path))["recovery"]
    assert rec["max_error_deg"] <= 1e-9
    assert result.decision == "apply"
    left = result.diagnostics["linkages"]["left"]
    assert left["motors"] == {"left_ankle_pitch_joint": "motor 0", "left_ankle_roll_joint": "motor 1"}
    # the recordings hold the motors' readings: g(q_true) - offsets
    lm = load_robot(str(path))
    r, t = load_recording(list_segments(out)[1], lm.joint_names), load_truth(list_segments(out)[1])
    assert np.abs(r.q_enc - (kin.recorded_angles(t.q_true) - t.offsets)).max() < 1e-12
    assert np.abs(r.q_enc[:, 4:6] - t.q_true[:, 4:6]).max() > 1e-3  # motors, not the joints


def test_in_weld_the_motors_hold_the_command_off_by_their_offsets(robot):
    """The servos hold g(q_cmd) + offsets at the motors: the true ankle is f(g(q_cmd) + dm)
    (not q_cmd + dm), and the encoders read g(q_true) - dm."""
    from legcal_bench.sim.double_support import DoubleSupportSim
    from legcal_bench.sim.sensors import sim_sensors

    path, kin = robot
    lm = load_robot(str(path))
    offsets = np.deg2rad(np.array([0, 0, 0, 0, 2.0, -1.5, 0, 0, 0, 0, -1.0, 2.5]))
    sim = DoubleSupportSim(lm, "weld", offsets, sim_sensors("zero"), settle_s=0.5)
    left, right = kin.sole_poses(np.zeros(12))
    sim.reset(left, right, np.array([0.0, 0.0, -0.05, 0.0, 0.0, 0.0]))
    q_cmd, target = sim._q_cmd, sim._servo_target()
    for lk in kin.linkages:
        c = list(lk.cols)
        assert np.abs(lk.motors(target[c][None]) - lk.motors(q_cmd[c][None]) - offsets[c]).max() < 1e-13
        assert np.abs(target[c] - q_cmd[c] - offsets[c]).max() > 1e-5  # a motor offset is no joint offset
    assert np.abs(sim._command_of(target) - q_cmd).max() < 1e-13
    enc = sim.encoder_input(sim.q_true)
    assert np.abs(enc - (kin.recorded_angles(sim.q_true)[0] - offsets)).max() < 1e-13


def _legmap_with(path, edit) -> str:
    d = yaml.safe_load(path.read_text())
    edit(d["legs"]["left"])
    out = path.parent / "edited.legmap.yaml"
    out.write_text(yaml.safe_dump(d, sort_keys=False))
    return str(out)


@pytest.mark.parametrize("edit, message", [
    (lambda leg: leg["linkage"]["motors"][0].update(crank=[-0.06, 0.01, 0.0]), r"motors\[0\]\.crank is not "
     "perpendicular"),
    (lambda leg: leg["linkage"]["motors"][1].update(rod=0.1), r"motors\[1\]: the rod \(0\.1000 m\) cannot close"),
    (lambda leg: leg["linkage"]["motors"][1].update(foot=leg["linkage"]["motors"][0]["foot"],
                                                    pivot=leg["linkage"]["motors"][0]["pivot"]),
     "do not turn the ankle's two joints independently"),
    (lambda leg: leg["joints"][4].update(ratio=2.0), "the linkage is their transmission"),
    (lambda leg: leg["linkage"]["motors"][0].pop("rod"), r"motors\[0\]: missing \['rod'\]"),
    (lambda leg: leg["linkage"].update(motors=leg["linkage"]["motors"][:1]), r"expected \{motors: \[two motors\]\}"),
])
def test_a_bad_linkage_is_refused_by_name(robot, edit, message):
    path, _ = robot
    with pytest.raises(LegMapError, match=message):
        LegKinematics(load_robot(_legmap_with(path, edit)))


def test_walking_and_unreachable_motor_angles_are_refused(robot, tmp_path):
    from legcal_bench.data.recording import check_against_robot
    from legcal_bench.sim.walking import WalkingConfig, build_walking_scene

    path, _ = robot
    lm = load_robot(str(path))
    with pytest.raises(ConfigError, match="walking does not simulate linkage ankles yet"):
        build_walking_scene(lm, WalkingConfig(kp=(100.0,) * 12, kd=(2.0,) * 12, default_q=(0.0,) * 12))
    out = tmp_path / "k"
    collect(CollectConfig(robot=str(path), mode="kinematic", sensors="zero", offsets="none", seed=0, stances=("I",)),
            out, progress=False)
    r = load_recording(list_segments(out)[0], lm.joint_names)
    r.q_enc[3, 5] = 2.5  # motor 1 of the left ankle past the crank's reach
    with pytest.raises(RecordingError, match=r"the left linkage ankle's motors \(columns left_ankle_pitch_joint, "
                       r"left_ankle_roll_joint\): 1 frame\(s\) \(first 3\) at \[-?0\.\d+, 2\.5\] rad"):
        check_against_robot([r], lm)
