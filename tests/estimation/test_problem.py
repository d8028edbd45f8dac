"""Residual terms and the assembled problem: Jacobians against central differences,
row and column layout, and the information matrix with per-frame blocks eliminated; on
legs of six joints (A3-like) and of five (no ankle roll: the joint count is the leg
map's)."""

import numpy as np
import pytest

from legcal_bench.estimation.imu.levelling import levelling_rotations, up_in_base
from legcal_bench.estimation.problem.problem import Block, Problem, Term
from legcal_bench.estimation.problem.terms import (OFFSETS, TILT, FlatGroundTerm, ImuTiltTerm, InterFootTerm, KneePriorTerm,
                                           SegmentKinematics, SoleHeightTerm, TikhonovTerm)
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import VARIATIONS
from legcal_bench.robots.kinematics import LegKinematics


@pytest.fixture(scope="module", params=["a3", "five_joint"])
def data(request, tmp_path_factory):
    if request.param == "a3":
        robot = "a3"
    else:
        design = next(d for d in VARIATIONS if d.name == request.param)
        robot = str(write_robot(design, tmp_path_factory.mktemp(request.param)))
    kin = LegKinematics(load_robot(robot))
    rng = np.random.default_rng(3)
    q = kin.q_init() + rng.normal(0, 0.08, (20, kin.legmap.n_joints))
    acc = np.array([0.2, -0.3, 9.8]) + rng.normal(0, 0.2, (20, 3))
    up = up_in_base(acc, kin.R_BI)
    return kin, q, up


def _knees(kin):
    return [i for i, r in enumerate(kin.legmap.joint_roles) if r == "knee"]


def _interfoot_problem(kin, q, up, mode):
    n = kin.legmap.n_joints
    seg = SegmentKinematics(kin, q)
    terms = [InterFootTerm("feet", seg, np.arange(1, 7.0), mode), FlatGroundTerm("flat", seg, up, levelling_rotations(up),
                                                                                 np.arange(1, 6.0)),
             TikhonovTerm(np.linspace(0.5, 2, n)), KneePriorTerm(_knees(kin), np.array([0.01, -0.02]), 3.0)]
    return Problem([Block(OFFSETS, n, bound=0.08)], terms)


def _yamane_problem(kin, q, up):
    return Problem([Block(OFFSETS, kin.legmap.n_joints, bound=0.08), Block(TILT, 2, per_frame=True)],
                   [SoleHeightTerm(kin, q, 1000.0), ImuTiltTerm(up, 500.0)])


def test_compute_error_and_jacobian_are_the_two_halves_of_compute(data):
    kin, q, up = data
    n = kin.legmap.n_joints
    term = FlatGroundTerm("flat", SegmentKinematics(kin, q), up, levelling_rotations(up), np.ones(5))
    x = {OFFSETS: 0.01 * np.ones(n)}
    r, J = term.compute(x)
    np.testing.assert_array_equal(term.compute_error(x), r)
    np.testing.assert_array_equal(term.compute_jacobian(x)[OFFSETS], J[OFFSETS])
    assert r.shape == (5 * len(q),) and J[OFFSETS].shape == (5 * len(q), n)


def _central_differences(problem, x, h=1e-6):
    fd = np.empty((len(problem.evaluate(x)[0]), len(x)))
    for i in range(len(x)):
        e = np.zeros(len(x))
        e[i] = h
        fd[:, i] = (problem.evaluate(x + e)[0] - problem.evaluate(x - e)[0]) / (2 * h)
    return fd


@pytest.mark.parametrize("mode", ["projected", "fixed"])
def test_interfoot_terms_jacobian_matches_central_differences(data, mode):
    kin, q, up = data
    n = kin.legmap.n_joints
    problem = _interfoot_problem(kin, q, up, mode)
    x = problem.pack({OFFSETS: 0.02 * np.sin(np.arange(n))})
    if mode == "fixed":
        problem.terms[0].update_mean(x)
    r, J = problem.evaluate(x)
    assert isinstance(J, np.ndarray) and J.shape == (20 * 11 + n + 2, n)
    fd = _central_differences(problem, x)
    assert np.abs(J - fd).max() < 1e-6 * np.abs(fd).max()


def test_yamane_terms_jacobian_matches_central_differences_and_rows_interleave(data):
    kin, q, up = data
    n = kin.legmap.n_joints
    problem = _yamane_problem(kin, q, up)
    assert problem.n_params == n + 2 * 20 and problem.sparse
    x = problem.pack({OFFSETS: 0.01 * np.cos(np.arange(n)), TILT: np.column_stack([0.02 * np.ones(20), -0.01 * np.ones(20)])})
    r, J = problem.evaluate(x)
    assert J.shape == (20 * 11, n + 40)
    fd = _central_differences(problem, x)
    assert np.abs(J.toarray() - fd).max() < 1e-6 * np.abs(fd).max()
    # Frame k's rows are 11k..11k+10 (8 heights, then 3 IMU rows) and touch only frame k's tilt columns.
    dense = J.toarray()
    k = 7
    rows = slice(11 * k, 11 * k + 11)
    tilt_cols = [c for c in range(n, n + 40) if np.any(dense[rows, c])]
    assert tilt_cols == [n + 2 * k, n + 1 + 2 * k]
    assert not dense[11 * k + 8:11 * k + 11, :n].any()  # IMU rows do not depend on the offsets


def test_information_eliminates_per_frame_blocks_like_the_dense_schur_complement(data):
    kin, q, up = data
    problem = _yamane_problem(kin, q, up)
    x = problem.pack({TILT: np.column_stack([np.full(20, 0.01), np.full(20, 0.02)])})
    H_data, H_reg = problem.information(x)
    J = problem.evaluate(x)[1].toarray()
    H = J.T @ J
    n = kin.legmap.n_joints
    Hqq, Hqa, Haa = H[:n, :n], H[:n, n:], H[n:, n:]
    expected = Hqq - Hqa @ np.linalg.solve(Haa, Hqa.T)
    np.testing.assert_allclose(H_data, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    np.testing.assert_allclose(H_reg, H_data)  # no priors in this problem


def test_priors_add_curvature_not_information(data):
    kin, q, up = data
    n = kin.legmap.n_joints
    problem = _interfoot_problem(kin, q, up, "projected")
    H_data, H_reg = problem.information(np.zeros(n))
    prior = np.diag(np.linspace(0.5, 2, n) ** 2)
    prior[_knees(kin), _knees(kin)] += 9.0
    np.testing.assert_allclose(H_reg - H_data, prior, atol=1e-9)


def test_a_new_block_plugs_in_without_touching_the_existing_terms(data):
    """An extra parameter block with its own term (as a model-gap effect adds) is
    solved jointly with the offsets."""
    kin, q, up = data
    n = kin.legmap.n_joints

    class Shift(Term):
        name, blocks = "shift", ("shift", OFFSETS)

        def compute(self, x):
            r = np.array([x["shift"][0] - 0.5, x["shift"][0] + x[OFFSETS][0] - 0.5])
            J_off = np.zeros((2, n))
            J_off[1, 0] = 1.0
            return r, {"shift": np.array([[1.0], [1.0]]), OFFSETS: J_off}

    problem = Problem([Block(OFFSETS, n, bound=0.08), Block("shift", 1)], [TikhonovTerm(np.ones(n)), Shift()])
    sol = problem.solve(np.zeros(n + 1), method="lm")
    np.testing.assert_allclose(problem.unpack(sol.x)["shift"], [0.5], atol=1e-9)
    assert np.abs(problem.unpack(sol.x)[OFFSETS]).max() < 1e-9


def test_bad_problem_layouts_are_refused(data):
    from legcal_bench.errors import CalibrationError

    kin, q, up = data
    n = kin.legmap.n_joints
    with pytest.raises(CalibrationError, match="unknown blocks"):
        Problem([Block(OFFSETS, n)], [ImuTiltTerm(up, 1.0)])
    with pytest.raises(CalibrationError, match="per-frame block"):
        Problem([Block(OFFSETS, n), Block(TILT, 2, per_frame=True)],
                [ImuTiltTerm(up, 1.0), type("T", (TikhonovTerm,), {"blocks": (TILT,)})(np.ones(2))])

