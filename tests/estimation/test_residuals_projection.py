"""Variable projection of the feet columns (`residuals.project_mean`): the one formula
for the fit's columns and tracing's, so what the segment mean absorbs is absorbed
exactly in both."""

import numpy as np

from legcal_bench.estimation.problem.residuals import project_mean
from legcal_bench.estimation.modelgap.signatures import project_means
from legcal_bench.geometry.lie import Jl_inv


def test_a_mean_change_projects_to_zero_exactly_and_a_plain_average_does_not():
    # dr_k = -Jl_inv(r_k) mu is what a change mu of the segment's mean does to each
    # frame's residual: the projection removes it to rounding; subtracting the plain
    # average (the earlier tracing columns) leaves O(|r|) ~ 1e-4 of it.
    rng = np.random.default_rng(0)
    r = 3e-4 * rng.standard_normal((400, 6))
    mu = rng.standard_normal(6)
    J = -(Jl_inv(r) @ mu)[:, :, None]
    assert np.abs(project_mean(J, r)).max() < 1e-12 * np.abs(J).max()
    plain = J - J.mean(axis=0)
    assert np.abs(plain).max() > 1e-5 * np.abs(J).max()
    C = np.zeros((400, 11, 1))
    C[:, :6] = J
    assert np.abs(project_means(C, np.zeros(400, dtype=int), r)).max() < 1e-12 * np.abs(J).max()

