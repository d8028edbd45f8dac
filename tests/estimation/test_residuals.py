"""Analytic Jacobians of the paper's residuals against central differences, on legs of
six joints (A2-like) and of five (no ankle roll: the priors' weights read by role)."""

import numpy as np
import pytest

from legcal_bench.calibrators.interfoot import SETTINGS
from legcal_bench.estimation.problem.stance import Segment, StanceProblem
from legcal_bench.estimation.imu.levelling import levelling_rotations, up_in_base
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import VARIATIONS
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots import load_robot


@pytest.fixture(scope="module", params=["a2", "five_joint"])
def problem(request, tmp_path_factory):
    robot = request.param
    if robot != "a2":
        design = next(d for d in VARIATIONS if d.name == robot)
        robot = str(write_robot(design, tmp_path_factory.mktemp(robot)))
    lm = load_robot(robot)
    kin = LegKinematics(lm)
    rng = np.random.default_rng(0)
    segs = []
    for s in range(2):
        q = kin.q_init() + rng.normal(0, 0.08, (25, lm.n_joints))
        acc = np.array([0.3, -0.2, 9.8]) + rng.normal(0, 0.3, (25, 3))
        up = up_in_base(acc, kin.R_BI)
        segs.append(Segment(f"s{s}", q, up, levelling_rotations(up), np.arange(25)))
    w = SETTINGS["a2_operating"]
    knees = [i for i, r in enumerate(lm.joint_roles) if r == "knee"]
    return StanceProblem(kin, segs, w, prior=np.array([0.01, -0.02]), knees=knees, bound=0.08)


@pytest.mark.parametrize("mode", ["projected", "fixed"])
@pytest.mark.parametrize("at", [0.0, 0.03])
def test_jacobian_matches_central_differences(problem, mode, at):
    n = problem.n_offsets
    dq = np.full(n, at) * np.sign(np.arange(n) % 3 - 1 + 0.5)
    if mode == "fixed":
        problem.means_at(dq)
    _, J = problem.evaluate(dq, mode)
    h = 1e-6
    fd = np.empty_like(J)
    for i in range(n):
        e = np.zeros(n)
        e[i] = h
        fd[:, i] = (problem.evaluate(dq + e, mode)[0] - problem.evaluate(dq - e, mode)[0]) / (2 * h)
    scale = np.abs(fd).max()
    # Central differences are good to ~1e-9 relative here; a wrong term is O(1).
    assert np.abs(J - fd).max() < 1e-6 * scale


def test_projected_jacobian_differs_from_fixed_mean(problem):
    dq = np.zeros(problem.n_offsets)
    _, Jp = problem.evaluate(dq, "projected")
    problem.means_at(dq)
    _, Jf = problem.evaluate(dq, "fixed")
    assert np.abs(Jp - Jf).max() > 1e-3 * np.abs(Jf).max()


def test_prior_weights_are_read_by_role(problem):
    """W_q is per leg in the platform's order (three hips, knee, ankle pitch, ankle roll):
    each joint takes its role's weight, and a leg without an ankle roll has no joint
    for that weight."""
    lm, w = problem.kin.legmap, SETTINGS["a2_operating"]
    by_role = dict(zip(lm.hip_order + ("knee", "ankle_pitch", "ankle_roll"), w.w_q))
    expected = np.sqrt(w.lambda_q) * w.unit_scale * np.array([by_role[r] for r in lm.joint_roles])
    np.testing.assert_array_equal(problem.wq, expected)
    assert len(problem.wq) == lm.n_joints
