"""MuJoCo and Pinocchio load the same MJCF and must agree; IK closes the chain."""

import mujoco
import numpy as np
import pinocchio as pin

from legcal_bench.geometry.poses import se3
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots import load_robot
from legcal_bench.robots.legmap import SIDES
from legcal_bench.sim.scene import build_scene
from legcal_bench.geometry.poses import posture_pose
from legcal_bench.protocol.stances import STANCES, place


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
