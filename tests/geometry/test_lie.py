import numpy as np
import pinocchio as pin

from legcal_bench.geometry.lie import Ad, Exp, Jl_inv, Jr_inv, Log, adjoint, frechet_mean, inverse


def test_right_and_left_jacobians_of_log():
    rng = np.random.default_rng(0)
    for _ in range(5):
        T = Exp(rng.normal(0, 0.5, 6))
        for k in range(6):
            d = np.zeros(6)
            d[k] = 1e-7
            fd_r = (Log(T * Exp(d)) - Log(T * Exp(-d))) / 2e-7
            fd_l = (Log(Exp(d) * T) - Log(Exp(-d) * T)) / 2e-7
            np.testing.assert_allclose(Jr_inv(T)[:, k], fd_r, atol=1e-7)
            np.testing.assert_allclose(Jl_inv(T)[:, k], fd_l, atol=1e-7)


def test_adjoint_and_batched_helpers():
    rng = np.random.default_rng(1)
    T = Exp(rng.normal(size=6))
    d = rng.normal(0, 0.1, 6)
    assert np.allclose((T * Exp(d)).homogeneous, (Exp(Ad(T) @ d) * T).homogeneous)
    H = np.array([Exp(rng.normal(size=6)).homogeneous for _ in range(4)])
    np.testing.assert_allclose(inverse(H) @ H, np.tile(np.eye(4), (4, 1, 1)), atol=1e-13)
    np.testing.assert_allclose(adjoint(H)[2], pin.SE3(H[2]).action, atol=1e-14)


def test_frechet_mean_is_the_log_exp_fixed_point():
    rng = np.random.default_rng(2)
    M_true = Exp(rng.normal(size=6))
    C = np.array([(M_true * Exp(rng.normal(0, 0.05, 6))).homogeneous for _ in range(50)])
    M = frechet_mean(C)
    residual = np.mean([Log(pin.SE3(np.linalg.inv(M) @ c)) for c in C], axis=0)
    assert np.linalg.norm(residual) < 1e-14
