"""ZMP preview control (issue #14's teacher core): the pendulum's ZMP follows a stepping
reference, and the CoM moves before the reference does."""

import numpy as np
import pytest

from legcal_bench.policies.zmp_preview import preview_gains, track


def test_the_zmp_follows_a_stepping_reference_and_the_com_anticipates():
    dt, z_c = 0.01, 0.8
    g = preview_gains(z_c, dt)
    # Lateral ZMP: 1 s centred, then alternate feet +-0.1 m every 0.5 s, then centred.
    t = np.arange(0, 6, dt)
    ref = np.where(t < 1, 0.0, np.where((t - 1) // 0.5 % 2 == 0, 0.1, -0.1))
    ref[t >= 5] = 0.0
    X, P = track(g, ref)
    settled = (t > 1.6) & (t < 5)
    # Away from the switches the model's ZMP sits on the reference foot ...
    switch = np.abs(np.diff(ref, prepend=ref[0])) > 0
    near = np.convolve(switch, np.ones(15), mode="same") > 0
    assert np.abs(P - ref)[settled & ~near].max() < 0.01
    # ... the CoM sways less than the feet are apart, and starts before the first step.
    assert np.abs(X[settled, 0]).max() < 0.1
    assert abs(X[int(0.9 / dt), 0]) > 1e-3
    # And it comes back to rest in the middle.
    assert abs(X[-1, 0]) < 0.005 and abs(X[-1, 1]) < 0.01


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError):
        preview_gains(-0.8, 0.01)
    with pytest.raises(ValueError):
        preview_gains(0.8, 0.01, preview_s=0.001)


def test_the_gait_plan_puts_the_zmp_on_the_stance_foot_and_ik_closes_the_chain():
    from legcal_bench.policies.zmp_walker import GaitParams, joint_targets, plan_gait
    from legcal_bench.robots import load_robot
    from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics

    kin = LegKinematics(load_robot("a3"))
    p = GaitParams()
    gait = plan_gait(kin, 4, p)
    y0 = kin.dims.foot_y
    # Right, left, right steps of 0.12 m, then the left closes the feet: 0.36 m.
    assert gait.distance == pytest.approx(0.36)
    assert gait.left[-1, 0] == pytest.approx(0.36) and gait.right[-1, 0] == pytest.approx(0.36)
    assert np.allclose(gait.zmp[0], 0) and np.allclose(gait.zmp[-1], [0.36, 0])
    # Never both feet in the air; never above the lift.
    up = np.stack([gait.left[:, 2], gait.right[:, 2]]) > 1e-9
    assert not (up[0] & up[1]).any() and gait.left[:, 2].max() <= p.lift + 1e-12
    # In single support the ZMP is on the stance foot.
    single = up[0] | up[1]
    stance_y = np.where(up[1], y0, -y0)
    assert np.allclose(gait.zmp[single, 1], stance_y[single])
    # The joint targets put both soles where the plan does, relative to each other.
    Q = joint_targets(kin, gait, p)
    fk = frame_kinematics(kin, Q)
    planned = gait.right - gait.left
    got = np.einsum("nji,nj->ni", fk.R_L, fk.p_R - fk.p_L)  # right sole in the left sole's (level) frame
    assert np.abs(got - planned).max() < 1e-3
