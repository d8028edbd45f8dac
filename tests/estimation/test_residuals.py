"""Analytic Jacobians of the paper's residuals against central differences."""

import numpy as np
import pytest

from legcal_bench.calibrators.interfoot import SETTINGS
from legcal_bench.estimation.problem.stance import Segment, StanceProblem
from legcal_bench.estimation.imu.levelling import levelling_rotations, up_in_base
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots import load_robot


@pytest.fixture(scope="module")
def problem():
    lm = load_robot("a2")
    kin = LegKinematics(lm)
    rng = np.random.default_rng(0)
    segs = []
    for s in range(2):
        q = kin.q_init() + rng.normal(0, 0.08, (25, 12))
        acc = np.array([0.3, -0.2, 9.8]) + rng.normal(0, 0.3, (25, 3))
        up = up_in_base(acc, kin.R_BI)
        segs.append(Segment(f"s{s}", q, up, levelling_rotations(up), np.arange(25)))
    w = SETTINGS["a2_operating"]
    return StanceProblem(kin, segs, w, prior=np.array([0.01, -0.02]), knees=[3, 9], bound=0.08)


@pytest.mark.parametrize("mode", ["projected", "fixed"])
@pytest.mark.parametrize("at", [0.0, 0.03])
def test_jacobian_matches_central_differences(problem, mode, at):
    dq = np.full(12, at) * np.sign(np.arange(12) % 3 - 1 + 0.5)
    if mode == "fixed":
        problem.means_at(dq)
    _, J = problem.evaluate(dq, mode)
    h = 1e-6
    fd = np.empty_like(J)
    for i in range(12):
        e = np.zeros(12)
        e[i] = h
        fd[:, i] = (problem.evaluate(dq + e, mode)[0] - problem.evaluate(dq - e, mode)[0]) / (2 * h)
    scale = np.abs(fd).max()
    # Central differences are good to ~1e-9 relative here; a wrong term is O(1).
    assert np.abs(J - fd).max() < 1e-6 * scale


def test_projected_jacobian_differs_from_fixed_mean(problem):
    dq = np.zeros(12)
    _, Jp = problem.evaluate(dq, "projected")
    problem.means_at(dq)
    _, Jf = problem.evaluate(dq, "fixed")
    assert np.abs(Jp - Jf).max() > 1e-3 * np.abs(Jf).max()
