"""The batched SE(3) tools against Pinocchio, against their own definitions (central
differences, exact identities) and, where mpmath is available, against high-precision
references."""

import numpy as np
import pinocchio as pin
import pytest

from legcal_bench.geometry import lie
from legcal_bench.geometry.lie import (Ad, Exp, Jl, Jl_inv, Jr, Jr_inv, Log, adjoint, frechet_mean, inverse)

# Rotation angles (rad) the tools must handle: tiny deviations from a mean (the
# residuals' typical size), around the series/closed-form switch, and up to near pi.
ANGLES = [0.0, 1e-12, 1e-9, 1e-6, 1e-4, 3e-4, 1e-3, 1e-2, 0.1, 0.5, 0.999, 1.0, 1.001, 2.0, 3.0]


def random_tau(rng, n, angle, rho_scale=0.3):
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    return np.hstack([rng.normal(0, rho_scale, (n, 3)), angle * axis])


def mixed_tau(rng, per_angle=20):
    return np.vstack([random_tau(rng, per_angle, a) for a in ANGLES])


# --------------------------------------------------------------------- Pinocchio


@pytest.mark.parametrize("angle", ANGLES)
def test_exp_and_log_match_pinocchio(angle):
    """To 1e-13, except where Pinocchio's own exp6/log6 are off by more (its series
    switches): up to ~3e-13 (exp6, ~1e-4 rad) and ~1e-12 (log6, ~2e-3 rad) against the
    high-precision reference below, which ours match to rounding."""
    rng = np.random.default_rng(int(angle * 1e6) % 2**32)
    tau = random_tau(rng, 200, angle)
    H = np.array([pin.exp6(t).homogeneous for t in tau])
    tol = 2e-12 if 1e-4 <= angle <= 3e-3 else 1e-13
    np.testing.assert_allclose(Exp(tau), H, rtol=0, atol=tol)
    np.testing.assert_allclose(Log(H), [pin.log6(pin.SE3(h)).vector for h in H], rtol=0, atol=tol)


def test_exp_and_log_match_pinocchio_over_a_sweep_of_angles():
    rng = np.random.default_rng(12)
    tau = np.vstack([random_tau(rng, 10, a) for a in np.geomspace(1e-9, 3.0, 200)])
    H = np.array([pin.exp6(t).homogeneous for t in tau])
    np.testing.assert_allclose(Exp(tau), H, rtol=0, atol=2e-12)
    np.testing.assert_allclose(Log(H), [pin.log6(pin.SE3(h)).vector for h in H], rtol=0, atol=2e-12)


@pytest.mark.parametrize("angle", ANGLES)
def test_jacobians_match_pinocchio(angle):
    """Pinocchio's Jlog6/Jexp6 switch from a short series to closed forms that cancel
    near the switch: errors up to ~3e-7 (Jlog6) and ~4e-6 (Jexp6) absolute around
    3e-4 rad, ~1e-8 at 1e-3 rad, ~3e-11 at 1e-2 rad. That is Pinocchio's error, not
    ours (see the high-precision tests below); outside 1e-5..0.1 rad they agree to
    rounding."""
    rng = np.random.default_rng(int(angle * 1e6) % 2**32 + 1)
    tau = random_tau(rng, 100, angle)
    H = np.array([pin.exp6(t).homogeneous for t in tau])
    pin_jlog = np.array([pin.Jlog6(pin.SE3(h)) for h in H])
    pin_jlog_inv = np.array([pin.Jlog6(pin.SE3(h).inverse()) for h in H])
    pin_jexp = np.array([pin.Jexp6(t) for t in tau])
    tol = 1e-5 if 1e-5 < angle < 0.1 else 1e-12
    L = Log(H)
    np.testing.assert_allclose(Jr_inv(L), pin_jlog, rtol=0, atol=tol)
    np.testing.assert_allclose(Jl_inv(L), pin_jlog_inv, rtol=0, atol=tol)
    np.testing.assert_allclose(Jr(tau), pin_jexp, rtol=0, atol=tol)


def test_adjoint_and_inverse_match_pinocchio():
    rng = np.random.default_rng(1)
    H = Exp(rng.normal(size=(20, 6)))
    np.testing.assert_allclose(adjoint(H), [pin.SE3(h).action for h in H], rtol=0, atol=1e-14)
    np.testing.assert_allclose(inverse(H), [pin.SE3(h).inverse().homogeneous for h in H], rtol=0, atol=1e-15)
    np.testing.assert_allclose(inverse(H) @ H, np.broadcast_to(np.eye(4), H.shape), rtol=0, atol=1e-14)
    assert Ad is adjoint


# -------------------------------------------------------------- own definitions


def test_log_inverts_exp_to_relative_precision_even_for_tiny_rotations():
    rng = np.random.default_rng(3)
    for angle in ANGLES[1:] + [3.1, np.pi - 1e-6]:
        tau = random_tau(rng, 50, angle)
        back = Log(Exp(tau))
        np.testing.assert_allclose(back[:, 3:], tau[:, 3:], rtol=0, atol=2e-15 * angle)
        np.testing.assert_allclose(back[:, :3], tau[:, :3], rtol=0, atol=1e-15 * (1 + angle) ** 2)


def test_log_near_and_at_pi():
    """Angles at pi come back as angle pi about +-axis; Exp(Log T) = T throughout."""
    rng = np.random.default_rng(4)
    for angle in [2.2, 3.1, np.pi - 1e-4, np.pi - 1e-9, np.pi]:
        H = Exp(random_tau(rng, 50, angle))
        L = Log(H)
        np.testing.assert_allclose(np.linalg.norm(L[:, 3:], axis=1), angle, rtol=0, atol=1e-14)
        np.testing.assert_allclose(Exp(L), H, rtol=0, atol=1e-14)


def test_jacobian_identities():
    rng = np.random.default_rng(5)
    tau = mixed_tau(rng)
    I6 = np.broadcast_to(np.eye(6), (len(tau), 6, 6))
    np.testing.assert_allclose(Jr_inv(tau) @ Jr(tau), I6, rtol=0, atol=1e-14)
    np.testing.assert_allclose(Jl_inv(tau) @ Jl(tau), I6, rtol=0, atol=1e-14)
    np.testing.assert_allclose(Jl(tau), Jr(-tau), rtol=0, atol=0)
    np.testing.assert_allclose(Jl_inv(tau), Jr_inv(-tau), rtol=0, atol=0)
    # Jl = Ad(Exp tau) Jr: ties the Jacobians to Exp through an independent route.
    np.testing.assert_allclose(Jl(tau), adjoint(Exp(tau)) @ Jr(tau), rtol=0, atol=1e-14)


def test_jacobians_by_central_differences():
    """Log(T Exp(d)) = Log T + Jr_inv(Log T) d, Log(Exp(d) T) = Log T + Jl_inv(Log T) d,
    Exp(tau + d) = Exp(tau) Exp(Jr(tau) d) = Exp(Jl(tau) d) Exp(tau), to first order."""
    rng = np.random.default_rng(6)
    tau = mixed_tau(rng, per_angle=5)
    T = Exp(tau)
    L = Log(T)
    h = 1e-6
    Tinv = inverse(T)
    for k in range(6):
        d = np.zeros(6)
        d[k] = h
        fd_r = (Log(T @ Exp(d)) - Log(T @ Exp(-d))) / (2 * h)
        fd_l = (Log(Exp(d) @ T) - Log(Exp(-d) @ T)) / (2 * h)
        fd_jr = (Log(Tinv @ Exp(tau + d)) - Log(Tinv @ Exp(tau - d))) / (2 * h)
        fd_jl = (Log(Exp(tau + d) @ Tinv) - Log(Exp(tau - d) @ Tinv)) / (2 * h)
        np.testing.assert_allclose(Jr_inv(L)[:, :, k], fd_r, rtol=0, atol=1e-8)
        np.testing.assert_allclose(Jl_inv(L)[:, :, k], fd_l, rtol=0, atol=1e-8)
        np.testing.assert_allclose(Jr(tau)[:, :, k], fd_jr, rtol=0, atol=1e-8)
        np.testing.assert_allclose(Jl(tau)[:, :, k], fd_jl, rtol=0, atol=1e-8)


def test_adjoint_moves_a_perturbation_across():
    rng = np.random.default_rng(7)
    T = Exp(rng.normal(size=(10, 6)))
    d = rng.normal(0, 0.1, (10, 6))
    np.testing.assert_allclose(T @ Exp(d), Exp(np.einsum("nij,nj->ni", Ad(T), d)) @ T, rtol=0, atol=1e-14)


# ------------------------------------------------------------------ shapes


def test_shapes_and_batches_agree_with_single_elements():
    rng = np.random.default_rng(8)
    tau = mixed_tau(rng, per_angle=2)
    T = Exp(tau)
    assert T.shape == (len(tau), 4, 4) and Log(T).shape == (len(tau), 6)
    for f in (Jr, Jl, Jr_inv, Jl_inv):
        assert f(tau).shape == (len(tau), 6, 6)
    for k in (0, 5, len(tau) - 1):
        assert Exp(tau[k]).shape == (4, 4) and Log(T[k]).shape == (6,)
        np.testing.assert_array_equal(Exp(tau[k]), T[k])
        np.testing.assert_array_equal(Log(T[k]), Log(T)[k])
        for f in (Jr, Jl, Jr_inv, Jl_inv):
            assert f(tau[k]).shape == (6, 6)
            np.testing.assert_array_equal(f(tau[k]), f(tau)[k])
        assert adjoint(T[k]).shape == (6, 6) and inverse(T[k]).shape == (4, 4)
    grid = tau[:12].reshape(3, 4, 6)
    np.testing.assert_array_equal(Exp(grid), T[:12].reshape(3, 4, 4, 4))
    np.testing.assert_array_equal(Jr_inv(grid), Jr_inv(tau[:12]).reshape(3, 4, 6, 6))
    # A pin.SE3 is a pose wherever a pose is taken; a Jacobian wants Log(T), not T.
    P = pin.SE3(T[3])
    np.testing.assert_array_equal(Log(P), Log(T[3]))
    with pytest.raises(ValueError, match="Log"):
        Jr_inv(P)
    with pytest.raises(ValueError):
        Log(tau)


# ----------------------------------------------------------------- Frechet mean


def _mean_log(M, C):
    return Log(inverse(M) @ C).mean(axis=0)


def test_frechet_mean_is_the_log_exp_fixed_point():
    rng = np.random.default_rng(2)
    M_true = Exp(rng.normal(size=6))
    C = M_true @ Exp(rng.normal(0, 0.05, (50, 6)))
    M = frechet_mean(C)
    assert np.linalg.norm(_mean_log(M, C)) < 1e-14
    # Same fixed point from a given start, and with a tiny spread (the residuals' size).
    M2 = frechet_mean(C, M0=M_true)
    np.testing.assert_allclose(M2, M, rtol=0, atol=1e-14)
    C_tight = M_true @ Exp(rng.normal(0, 1e-6, (450, 6)))
    M3 = frechet_mean(C_tight)
    assert np.linalg.norm(_mean_log(M3, C_tight)) < 1e-15


def test_frechet_mean_matches_the_per_frame_pinocchio_iteration():
    rng = np.random.default_rng(9)
    C = Exp(rng.normal(size=6)) @ Exp(rng.normal(0, 0.02, (100, 6)))
    M = pin.exp6(np.mean([pin.log6(pin.SE3(c)).vector for c in C], axis=0))
    for _ in range(50):
        step = np.mean([pin.log6(M.actInv(pin.SE3(c))).vector for c in C], axis=0)
        M = M * pin.exp6(step)
        if np.linalg.norm(step) < 1e-15:
            break
    np.testing.assert_allclose(frechet_mean(C), M.homogeneous, rtol=0, atol=1e-14)


def test_frechet_mean_stops_after_max_iter_and_at_tol():
    rng = np.random.default_rng(10)
    C = Exp(rng.normal(0, 0.3, (30, 6)))
    M0 = Exp(rng.normal(size=6))
    one = frechet_mean(C, M0=M0, max_iter=1)
    np.testing.assert_allclose(one, M0 @ Exp(_mean_log(M0, C)), rtol=0, atol=0)
    loose = frechet_mean(C, M0=M0, tol=1e10)  # one step, then stop
    np.testing.assert_array_equal(loose, one)


# ------------------------------------------------------- high-precision references


def test_coefficients_against_high_precision():
    """Series below SERIES_BELOW, closed forms above: every coefficient to ~1e-15
    relative (e, which only enters multiplied by theta^4, to 2e-14), tiny angles included."""
    mp = pytest.importorskip("mpmath")
    exact = [lambda t: mp.sin(t) / t, lambda t: (1 - mp.cos(t)) / t**2, lambda t: (t - mp.sin(t)) / t**3,
             lambda t: (t**2 + 2 * mp.cos(t) - 2) / (2 * t**4),
             lambda t: (2 * t - 3 * mp.sin(t) + t * mp.cos(t)) / (2 * t**5),
             lambda t: (1 - (t / 2) * mp.cot(t / 2)) / t**2]
    theta = np.concatenate([np.geomspace(1e-12, 3.1, 300), [lie.SERIES_BELOW * (1 - 1e-12), lie.SERIES_BELOW]])
    got = lie._coefficients(theta)
    with mp.workdps(120):  # e's numerator cancels ~5 x 12 digits at 1e-12 rad
        ref = np.array([[float(f(mp.mpf(float(t)))) for f in exact] for t in theta])
    rel = np.abs(got / ref - 1)
    assert rel[:, [0, 1, 2, 3, 5]].max() < 3e-15
    assert rel[:, 4].max() < 2e-14
    zero = lie._coefficients(0.0)
    np.testing.assert_allclose(zero, [1, 1 / 2, 1 / 6, 1 / 24, 1 / 120, 1 / 12], rtol=1e-16)


def _mp_exp6(mp, tau):
    rho, w = mp.matrix(tau[:3]), mp.matrix(tau[3:])
    t = mp.sqrt(sum(x**2 for x in w))
    W = mp.matrix([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    a, b, c = mp.sin(t) / t, (1 - mp.cos(t)) / t**2, (t - mp.sin(t)) / t**3
    return mp.eye(3) + a * W + b * W * W, (mp.eye(3) + b * W + c * W * W) * rho


def test_exp_and_log_against_high_precision():
    """Exp(tau) against a 60-digit evaluation; Log of that pose (rounded to doubles)
    gives tau back to the rounding's effect."""
    mp = pytest.importorskip("mpmath")
    rng = np.random.default_rng(13)
    for angle in [1e-12, 1e-9, 1e-6, 1.5e-4, 3e-4, 1e-3, 2.35e-3, 0.3, 1.0, 2.0, 3.0, 3.1]:
        for tau in random_tau(rng, 5, angle):
            with mp.workdps(60):
                R, p = _mp_exp6(mp, [mp.mpf(float(x)) for x in tau])
                H = np.eye(4)
                H[:3, :3] = np.array(R.tolist(), dtype=float)
                H[:3, 3] = np.array(p.tolist(), dtype=float).ravel()
            np.testing.assert_allclose(Exp(tau), H, rtol=0, atol=1e-15)
            np.testing.assert_allclose(Log(H), tau, rtol=0, atol=2e-15)


def test_jacobians_against_high_precision_differences():
    """Jr by 60-digit central differences of Exp/Log (independent of the closed forms);
    Pinocchio's own error at 3e-4 rad is ~1e-6, ours is rounding."""
    mp = pytest.importorskip("mpmath")

    def hat(w):
        return mp.matrix([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])

    def log6(R, p):
        v = mp.matrix([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2
        s = mp.sqrt(sum(x**2 for x in v))
        t = mp.atan2(s, (R[0, 0] + R[1, 1] + R[2, 2] - 1) / 2)
        w, f = (v, mp.mpf(1) / 12) if s == 0 else (v * (t / s), (1 - (t / 2) * mp.cot(t / 2)) / t**2)
        W = hat(w)
        return [*((mp.eye(3) - W / 2 + f * W * W) * p), *w]

    rng = np.random.default_rng(11)
    for angle in [1e-9, 1e-6, 3e-4, 1e-3, 0.3, 1.0, 2.5]:
        tau = random_tau(rng, 1, angle)[0]
        ref = np.empty((6, 6))
        with mp.workdps(60):
            h = mp.mpf("1e-25")
            tm = [mp.mpf(float(x)) for x in tau]
            R0, p0 = _mp_exp6(mp, tm)
            for k in range(6):
                cols = []
                for sgn in (1, -1):
                    tk = list(tm)
                    tk[k] += sgn * h
                    R1, p1 = _mp_exp6(mp, tk)
                    cols.append(log6(R0.T * R1, R0.T * (p1 - p0)))
                ref[:, k] = [float((a - b) / (2 * h)) for a, b in zip(*cols)]
        np.testing.assert_allclose(Jr(tau), ref, rtol=0, atol=5e-16)
        np.testing.assert_allclose(Jr_inv(tau), np.linalg.inv(ref), rtol=0, atol=1e-15)


@pytest.mark.parametrize("scale", [0.0, 1e-9, 1e-4, 1e-2, 0.5, 2.0, 3.1])
def test_the_inverse_jacobians_together_are_the_two_apart_bit_for_bit(scale):
    from legcal_bench.geometry.lie import Jr_Jl_inv

    tau = np.random.default_rng(7).normal(size=(200, 6)) * scale
    right, left = Jr_Jl_inv(tau)
    assert np.array_equal(right, Jr_inv(tau)) and np.array_equal(left, Jl_inv(tau))
