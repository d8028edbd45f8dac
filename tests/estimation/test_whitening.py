"""The declared noise carried to each frame's residual (issue #17): whitening on the
covariance's range gives chi-square(rank) for pure noise; the linear tests agree with
an explicit refit."""

import numpy as np

from legcal_bench.estimation.modelgap.lineartests import chi2_after, score
from legcal_bench.estimation.information.whitening import expected_rows, frame_covariances, whiten


def test_whitened_noise_drawn_from_a_rank_8_covariance_is_chi2_8():
    rng = np.random.default_rng(0)
    n = 4000
    G = rng.standard_normal((n, 11, 12))
    G[:, 6] = G[:, 0] + 0.5 * G[:, 3]  # three rows are functions of the others, as in the real residual
    G[:, 9:] = G[:, 7:9] - G[:, 4:6]
    H = np.zeros((n, 11, 2))
    H[:, 7:9] = np.eye(2)
    H[:, 9:] = np.eye(2)
    cov = frame_covariances(G, H, 1e-4, 1e-3)
    r = np.einsum("nij,nj->ni", G, 1e-4 * rng.standard_normal((n, 12))) \
        + np.einsum("nij,nj->ni", H, 1e-3 * rng.standard_normal((n, 2)))
    w = whiten(r, cov)
    assert (w.rank == 8).all()
    # chi2(8 n): mean 8 n, std 4 sqrt(n); a wrong sigma by 10 % would be 20 sigma away.
    assert abs(w.chi2.sum() - 8 * n) < 4 * 4 * np.sqrt(n)
    assert np.allclose(expected_rows(cov).sum(axis=1), 8.0)


def test_the_score_test_is_the_chi2_a_refit_over_the_extra_columns_removes():
    rng = np.random.default_rng(1)
    N, C = rng.standard_normal((500, 6)), rng.standard_normal((500, 2))
    z = N @ rng.standard_normal(6) + C @ [0.3, -0.2] + rng.standard_normal(500)
    d, dof = score(z, N, C)
    assert dof == 2
    assert np.isclose(d, chi2_after(z, N) - chi2_after(z, np.hstack([N, C])), rtol=1e-10)
    assert score(z, N, N[:, :2])[1] == 0  # columns already in the nuisance add nothing


def test_a_direction_below_the_columns_resolution_is_not_tested():
    # A column exactly collinear with the nuisance on noise-free data, which the noise
    # moves off it by ~1e-4 of its size in a direction the residual shares (as columns
    # evaluated at measured angles do): without a resolution the test takes that
    # direction at full weight; with the sensors' resolution it is not tested, while a
    # column 1 % off the nuisance still is.
    rng = np.random.default_rng(2)
    N = rng.standard_normal((2000, 4))
    z = rng.standard_normal(2000)
    zp = z - N @ np.linalg.lstsq(N, z, rcond=None)[0]
    noise_made = N @ [1.0, 0.5, 0.0, 0.0] + 1e-4 * np.linalg.norm(N[:, 0]) * zp / np.linalg.norm(zp)
    assert score(z, N, noise_made[:, None])[0] > 0.99 * zp @ zp  # takes all of the residual
    assert score(z, N, noise_made[:, None], resolution=1e-3) == (0.0, 0)
    real = N @ [1.0, 0.5, 0.0, 0.0] + 1e-2 * rng.standard_normal(2000) * np.linalg.norm(N[:, 0]) / np.sqrt(2000)
    assert score(z, N, real[:, None], resolution=1e-3)[1] == 1
