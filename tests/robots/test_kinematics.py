"""MuJoCo and Pinocchio load the same MJCF and must agree; IK closes the chain; the
batched path (products of exponentials) reproduces Pinocchio frame by frame."""

import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pinocchio as pin
import pytest
import yaml

from legcal_bench.errors import IKError, LegMapError
from legcal_bench.geometry.poses import posture_pose, se3
from legcal_bench.protocol.stances import STANCES, place, posture_trajectory
from legcal_bench.robots import load_robot
from legcal_bench.geometry.lie import Log
from legcal_bench.robots.kinematics import LegKinematics, _lstsq_batch, frame_kinematics
from legcal_bench.robots.legmap import SIDES, load_legmap
from legcal_bench.sim.scene import build_scene


def _mj_pose(d, kind, i):
    if kind == "site":
        return se3(d.site_xmat[i].reshape(3, 3), d.site_xpos[i])
    return se3(d.xmat[i].reshape(3, 3), d.xpos[i])


def test_mujoco_and_pinocchio_sole_poses_agree(all_robots):
    rng = np.random.default_rng(0)
    for robot in all_robots:
        legmap = load_robot(robot)
        kin = LegKinematics(legmap)
        scene = build_scene(legmap, "kinematic")
        d = mujoco.MjData(scene.model)
        for _ in range(20):
            q = rng.uniform(kin.q_lower, kin.q_upper)
            d.qpos[:] = scene.model.qpos0
            a = scene.free_qpos_adr
            d.qpos[a:a + 3] = rng.normal(size=3)
            d.qpos[a + 3:a + 7] = pin.Quaternion(pin.SE3.Random().rotation).coeffs()[[3, 0, 1, 2]]
            d.qpos[scene.qpos_adr] = q
            for name, angle in legmap.held_joints_rad.items():
                d.qpos[scene.model.jnt_qposadr[scene.model.joint(name).id]] = angle
            mujoco.mj_kinematics(scene.model, d)
            T_WB = _mj_pose(d, "body", scene.pelvis_body)
            soles = kin.sole_poses(q)
            for side, T_pin in zip(SIDES, soles):
                T_mj = T_WB.actInv(_mj_pose(d, "site", scene.sole_site[side]))
                assert np.abs(T_mj.translation - T_pin.translation).max() < 1e-9, robot
                assert np.abs(T_mj.rotation - T_pin.rotation).max() < 1e-9, robot
                # The four corners are the leg map's points in the sole frame.
                for k, c in enumerate(kin.corners[side]):
                    p_mj = T_WB.actInv(d.site_xpos[scene.corner_sites[side][k]])
                    assert np.abs(p_mj - T_pin.act(c)).max() < 1e-9, robot
            T_imu = T_WB.actInv(_mj_pose(d, "site", scene.imu_site))
            assert np.abs(T_imu.homogeneous - kin.imu_pose(q).homogeneous).max() < 1e-9, robot


def test_ik_closes_the_chain(all_robots):
    rng = np.random.default_rng(1)
    for robot in all_robots:
        kin = LegKinematics(load_robot(robot))
        for stance in STANCES.values():
            pl = place(stance, kin.dims, rng, 0.015, 0.05)
            T_WB = posture_pose(pl.nominal)
            q = kin.solve(T_WB.actInv(pl.left), T_WB.actInv(pl.right))
            left, right = kin.sole_poses(q)
            C = left.actInv(right)
            C_true = pl.left.actInv(pl.right)
            assert np.linalg.norm(pin.log6(C_true.actInv(C)).vector) < 1e-12, (robot, stance.name)


def test_sole_jacobian_matches_finite_differences():
    kin = LegKinematics(load_robot("a3"))
    q = kin.q_init() + 0.1
    for side in SIDES:
        J = kin.sole_jacobian(side, q)
        T0 = kin.sole_poses(q)[SIDES.index(side)]
        cols = kin.leg_cols[side]
        for k in range(6):
            dq = np.zeros(12)
            dq[cols[k]] = 1e-7
            T1 = kin.sole_poses(q + dq)[SIDES.index(side)]
            fd = pin.log6(T0.actInv(T1)).vector / 1e-7
            assert np.abs(fd - J[:, k]).max() < 1e-5


# ------------------------------------------------------------------ batched path
def _random_postures(kin, rng, n):
    """n configurations within the joint limits, including the limits' corners and zero."""
    Q = rng.uniform(kin.q_lower, kin.q_upper, size=(n, 12))
    Q[0], Q[1], Q[2] = kin.q_lower, kin.q_upper, np.clip(0.0, kin.q_lower, kin.q_upper)
    return Q


def _assert_batched_matches_pinocchio(kin, Q, label):
    fk = frame_kinematics(kin, Q)
    T_L, T_R = kin.sole_poses_batch(Q)
    for k, q in enumerate(Q):
        left, right = kin.sole_poses(q)
        C = left.actInv(right)
        J_L, J_R = kin.sole_jacobian("left", q), kin.sole_jacobian("right", q)
        G = np.hstack([-C.inverse().action @ J_L, J_R])
        assert np.abs(T_L[k] - left.homogeneous).max() < 1e-12, (label, k)
        assert np.abs(T_R[k] - right.homogeneous).max() < 1e-12, (label, k)
        assert np.abs(fk.C[k] - C.homogeneous).max() < 1e-12, (label, k)
        assert np.abs(fk.p_L[k] - left.translation).max() < 1e-12, (label, k)
        assert np.abs(fk.p_R[k] - right.translation).max() < 1e-12, (label, k)
        assert np.abs(fk.R_L[k] - left.rotation).max() < 1e-12, (label, k)
        assert np.abs(fk.R_R[k] - right.rotation).max() < 1e-12, (label, k)
        assert np.abs(fk.J_L[k] - J_L).max() < 1e-11, (label, k)
        assert np.abs(fk.J_R[k] - J_R).max() < 1e-11, (label, k)
        assert np.abs(fk.G[k] - G).max() < 1e-11, (label, k)


def test_batched_kinematics_match_pinocchio_frame_by_frame(all_robots):
    rng = np.random.default_rng(2)
    for robot in all_robots:
        kin = LegKinematics(load_robot(robot))
        # More frames than one block of the batched path, so blocks join correctly.
        Q = _random_postures(kin, rng, kin._CHUNK + 41)
        _assert_batched_matches_pinocchio(kin, Q, robot)
        one = frame_kinematics(kin, Q[5])  # a single configuration works too
        assert one.C.shape == (1, 4, 4) and np.abs(one.C[0] - kin.inter_foot(Q[5]).homogeneous).max() < 1e-12


def test_product_of_exponentials_is_the_documented_formula(all_robots):
    rng = np.random.default_rng(3)
    for robot in all_robots:
        kin = LegKinematics(load_robot(robot))
        for q in _random_postures(kin, rng, 5):
            for side, T_pin in zip(SIDES, kin.sole_poses(q)):
                c = kin.poe[side]
                T = np.eye(4)
                for k in range(6):
                    T = T @ c.M[k] @ pin.exp6(c.S[k] * q[c.cols[k]]).homogeneous
                assert np.abs(T @ c.M_sole - T_pin.homogeneous).max() < 1e-12, robot


def test_imu_pose_is_fixed(all_robots):
    for robot in all_robots:
        kin = LegKinematics(load_robot(robot))
        q = kin.q_init() + 0.2
        assert np.abs(kin.T_BI - kin.imu_pose(q).homogeneous).max() < 1e-15, robot
        assert np.array_equal(kin.R_BI, kin.T_BI[:3, :3])


def _central_difference(f, Q, h=1e-6):
    """(N, 6, 12) right-perturbation derivative of the (N, 4, 4) poses f(Q)."""
    T0_inv = np.linalg.inv(f(Q))
    out = np.empty((len(Q), 6, 12))
    for j in range(12):
        d = np.zeros(12)
        d[j] = h
        plus, minus = Log(T0_inv @ f(Q + d)), Log(T0_inv @ f(Q - d))
        out[:, :, j] = (plus - minus) / (2 * h)
    return out


def test_batched_jacobians_match_central_differences(all_robots):
    rng = np.random.default_rng(4)
    for robot in all_robots:
        kin = LegKinematics(load_robot(robot))
        Q = _random_postures(kin, rng, 8)
        fk = frame_kinematics(kin, Q)
        fd_L = _central_difference(lambda X: kin.sole_poses_batch(X)[0], Q)
        fd_R = _central_difference(lambda X: kin.sole_poses_batch(X)[1], Q)
        fd_C = _central_difference(lambda X: frame_kinematics(kin, X).C, Q)
        assert np.abs(fd_L[:, :, :6] - fk.J_L).max() < 1e-8, robot
        assert np.abs(fd_R[:, :, 6:] - fk.J_R).max() < 1e-8, robot
        assert np.abs(fd_L[:, :, 6:]).max() < 1e-8 and np.abs(fd_R[:, :, :6]).max() < 1e-8, robot
        assert np.abs(fd_C - fk.G).max() < 1e-8, robot


# --------------------------------------------------------- unusual leg chains
def _variant(testbot_legmap, tmp_path, edit_xml=None, edit_legmap=None):
    """A copy of the test robot with its MJCF and leg map edited."""
    lm = yaml.safe_load(testbot_legmap.read_text())
    tree = ET.parse(testbot_legmap.parent / lm["mjcf"])
    if edit_xml:
        edit_xml(tree.getroot())
    tree.write(tmp_path / "variant.xml")
    lm["mjcf"] = "variant.xml"
    if edit_legmap:
        edit_legmap(lm)
    path = tmp_path / "variant.legmap.yaml"
    path.write_text(yaml.safe_dump(lm, sort_keys=False))
    return load_legmap(path)


def _body(root, name):
    return next(b for b in root.iter("body") if b.get("name") == name)


def _insert_parent(root, child_name, new_name, pos, quat, joint_axis=None):
    """Puts a new body (with a hinge when `joint_axis` is given) between a body and its parent."""
    parent = next(p for p in root.iter("body") if any(c.get("name") == child_name for c in p))
    child = _body(root, child_name)
    new = ET.Element("body", name=new_name, pos=pos, quat=quat)
    ET.SubElement(new, "inertial", pos="0 0 0", mass="0.1", diaginertia="1e-4 1e-4 1e-4")
    if joint_axis is not None:
        ET.SubElement(new, "joint", name=f"{new_name}_joint", axis=joint_axis, range="-1 1")
    parent.insert(list(parent).index(child), new)
    parent.remove(child)
    new.append(child)


def test_batched_path_handles_held_joints_fixed_bodies_and_unaligned_axes(testbot_legmap, tmp_path):
    def edit_xml(root):
        # A held hinge with an oblique axis between the pelvis and the left hip, a fixed
        # rotated body between the pelvis and the right hip.
        _insert_parent(root, "left_hip_roll_link", "left_mount", "0.01 0.02 -0.01", "0.98 0.1 0.1 0.1", "0.3 0.2 0.9")
        _insert_parent(root, "right_hip_roll_link", "right_mount", "0.01 -0.02 -0.01", "0.97 -0.1 0.2 0.05")
        for name, axis in (("left_knee_joint", "0.05 1 0.1"), ("right_hip_yaw_joint", "0.1 -0.2 1")):
            next(j for j in root.iter("joint") if j.get("name") == name).set("axis", axis)

    def edit_legmap(lm):
        lm["held_joints_rad"]["left_mount_joint"] = 0.3
        # The IMU on the torso, behind the held waist joint.
        lm["imu"] = {"body": "torso", "pos": [0.02, 0.0, 0.05], "rpy": [0.1, 0.0, 0.2]}
        # (The hip joints listed out of chain order were accepted here before issue #59;
        # they are refused now, naming the chain: tests/robots/test_ankle_order.py.)

    legmap = _variant(testbot_legmap, tmp_path, edit_xml, edit_legmap)
    kin = LegKinematics(legmap)
    names = legmap.joint_names
    assert [names[c] for c in kin.poe["left"].cols] == names[:6]  # the chain is the listing
    Q = _random_postures(kin, np.random.default_rng(5), 60)
    _assert_batched_matches_pinocchio(kin, Q, "variant")
    # The held mount joint moved the left leg away from where the right one mirrors it.
    assert np.abs(kin.poe["left"].M[0][:3, :3] - np.eye(3)).max() > 0.1
    for q in Q[:3]:
        assert np.abs(kin.T_BI - kin.imu_pose(q).homogeneous).max() < 1e-15
    # IK on the variant closes the chain.
    q_true = np.clip(kin.q_init() + 0.1, kin.q_lower, kin.q_upper)
    T_L, T_R = kin.sole_poses_batch(q_true)
    q = kin.solve_batch(T_L, T_R, kin.q_init())
    assert np.abs(q[0] - q_true).max() < 1e-9


def test_a_leg_joint_that_is_not_1dof_is_refused(testbot_legmap, tmp_path):
    def edit_xml(root):
        knee = next(j for j in root.iter("joint") if j.get("name") == "left_knee_joint")
        knee.set("type", "ball")
        del knee.attrib["axis"]
        del knee.attrib["range"]

    with pytest.raises(LegMapError, match="left_knee_joint' is not a 1-DoF joint"):
        LegKinematics(_variant(testbot_legmap, tmp_path, edit_xml))


def test_legs_must_be_chains_from_the_pelvis(testbot_legmap, tmp_path):
    def swap_knees(lm):
        left, right = lm["legs"]["left"]["joints"], lm["legs"]["right"]["joints"]
        left[3]["name"], right[3]["name"] = right[3]["name"], left[3]["name"]

    with pytest.raises(LegMapError, match="must be that leg's 6 joints"):
        LegKinematics(_variant(testbot_legmap, tmp_path, edit_legmap=swap_knees))

    def imu_on_shin(lm):
        lm["imu"] = {"body": "left_knee_link", "pos": [0.0, 0.0, 0.0]}

    with pytest.raises(LegMapError, match="IMU is moved by leg joints"):
        LegKinematics(_variant(testbot_legmap, tmp_path, edit_legmap=imu_on_shin))


# ------------------------------------------------------------------ batched IK
def _stance_targets(kin, rng, per_stance):
    """Sole targets in the pelvis frame along each stance's posture motion."""
    T_L, T_R = [], []
    for stance in STANCES.values():
        pl = place(stance, kin.dims, rng, 0.015, 0.05)
        for posture in posture_trajectory(pl, kin.dims, per_stance, 1.0, rng, ramp_s=0):
            T_WB = posture_pose(posture)
            T_L.append(T_WB.actInv(pl.left))
            T_R.append(T_WB.actInv(pl.right))
    return T_L, T_R


def test_solve_batch_reproduces_solve(all_robots):
    rng = np.random.default_rng(6)
    for robot in all_robots:
        kin = LegKinematics(load_robot(robot))
        T_L, T_R = _stance_targets(kin, rng, 8)
        q_loop = np.array([kin.solve(a, b, check_limits=False) for a, b in zip(T_L, T_R)])
        H_L, H_R = np.array([T.homogeneous for T in T_L]), np.array([T.homogeneous for T in T_R])
        q_batch = kin.solve_batch(H_L, H_R, check_limits=False)
        assert np.abs(q_batch - q_loop).max() < 1e-9, robot
        for k, q in enumerate(q_batch):  # each frame closes the chain (Pinocchio's kinematics)
            left, right = kin.sole_poses(q)
            assert np.linalg.norm(pin.log6(left.actInv(T_L[k])).vector) < 1e-12, (robot, k)
            assert np.linalg.norm(pin.log6(right.actInv(T_R[k])).vector) < 1e-12, (robot, k)
        # Per-frame seeds, and pin.SE3 targets, are accepted too; so is the straight-leg
        # seed, where the first Jacobians are singular (minimum-norm steps).
        for seeds in (q_loop + 0.01, np.zeros(12)):
            q_seeded = kin.solve_batch(T_L, T_R, seeds, check_limits=False)
            q_each = np.array([kin.solve(a, b, s, check_limits=False)
                               for a, b, s in zip(T_L, T_R, np.broadcast_to(seeds, q_loop.shape))])
            assert np.abs(q_seeded - q_each).max() < 1e-9, robot


def test_solve_batch_names_the_frames_it_cannot_solve():
    kin = LegKinematics(load_robot("a3"))
    rng = np.random.default_rng(7)
    Q = np.clip(kin.q_init() + rng.uniform(-0.1, 0.1, (5, 12)), kin.q_lower, kin.q_upper)
    T_L, T_R = kin.sole_poses_batch(Q)
    far = T_R.copy()
    far[3, :3, 3] += [0.0, 0.0, -10.0]  # ten metres below the pelvis
    with pytest.raises(IKError, match=r"right sole pose not reachable in 1 of 5 frames.*frames \[3\]") as e:
        kin.solve_batch(T_L, far, Q)
    assert list(e.value.frames) == [3]
    # A reachable posture past a joint limit: the frame and the joint are named.
    Q_bad = Q.copy()
    knee = kin.legmap.joint_names.index("left_knee_joint")
    Q_bad[1, knee] = kin.q_upper[knee] + 0.2
    T_L, T_R = kin.sole_poses_batch(Q_bad)
    with pytest.raises(IKError, match=r"frame 1: \['left_knee_joint'\]") as e:
        kin.solve_batch(T_L, T_R, Q_bad)
    assert list(e.value.frames) == [1]
    assert np.abs(kin.solve_batch(T_L, T_R, Q_bad, check_limits=False) - Q_bad).max() < 1e-12


# ------------------------------------------------------------------ helpers
def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def test_lstsq_batch_matches_numpy():
    rng = np.random.default_rng(9)
    J = rng.normal(size=(20, 6, 6))
    b = rng.normal(size=(20, 6))
    J[3, :, 2] = J[3, :, 1]  # numerically singular: the minimum-norm solution
    J[4] *= 1e-3  # badly scaled but regular
    for batch in (slice(None), slice(3, None), slice(5, None)):
        x = _lstsq_batch(J[batch], b[batch])
        for Jk, bk, xk in zip(J[batch], b[batch], x):
            assert np.abs(xk - np.linalg.lstsq(Jk, bk, rcond=None)[0]).max() < 1e-10
    J[7] = 0.0  # exactly singular: the solve refuses, the whole batch takes the SVD
    x = _lstsq_batch(J, b)
    for Jk, bk, xk in zip(J, b, x):
        assert np.abs(xk - np.linalg.lstsq(Jk, bk, rcond=None)[0]).max() < 1e-10
