"""ZMP preview control of the linear inverted pendulum (Kajita et al. 2003), the core of
the model-based walking teacher of issue #14 (started: the planner and its test; the
walker around it comes next).

The centre of mass at constant height z_c moves as a cart on a table: with the state
x = [c, c', c''] per horizontal axis and the jerk u as input, sampled at dt,

    x_{k+1} = A x_k + B u_k,    p_k = C x_k = c_k - (z_c / g) c''_k

(p the zero-moment point). The optimal preview servo (Katayama's form) adds the
integral of the ZMP error to the state and minimises sum Qe e^2 + R u^2; its gains come
from the discrete algebraic Riccati equation (scipy), and the jerk is

    u_k = -Gi sum_{i<=k} (p_i - p_ref_i) - Gx x_k - sum_{j=1..N} Gd_j p_ref_{k+j}.

So the CoM starts moving before the reference does: the preview window N dt (about
1.5 s) is what lets the robot shift its weight onto the next stance foot in time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_discrete_are

G = 9.81


@dataclass(frozen=True)
class PreviewGains:
    A: np.ndarray  # (3, 3)
    B: np.ndarray  # (3,)
    C: np.ndarray  # (3,)
    Gi: float
    Gx: np.ndarray  # (3,)
    Gd: np.ndarray  # (N,) preview gains on p_ref(k + 1 .. k + N)
    dt: float


def preview_gains(z_c: float, dt: float, preview_s: float = 1.6, Qe: float = 1.0, R: float = 1e-6) -> PreviewGains:
    """The preview servo's gains for CoM height z_c (m) at sampling time dt (s)."""
    if z_c <= 0 or dt <= 0 or preview_s < dt:
        raise ValueError("z_c and dt must be > 0 and the preview at least one sample")
    A = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    B = np.array([dt ** 3 / 6, dt * dt / 2, dt])
    C = np.array([1.0, 0.0, -z_c / G])
    # Augmented with the integrated ZMP error: state [e_sum, x].
    At = np.zeros((4, 4))
    At[0, 0], At[0, 1:], At[1:, 1:] = 1.0, C @ A, A
    Bt = np.concatenate([[C @ B], B])[:, None]
    Q = np.zeros((4, 4))
    Q[0, 0] = Qe
    P = solve_discrete_are(At, Bt, Q, np.array([[R]]))
    S = R + (Bt.T @ P @ Bt).item()
    K = (Bt.T @ P @ At / S).ravel()
    Ac = At - Bt @ K[None]
    I = np.zeros(4)
    I[0] = 1.0
    n = int(round(preview_s / dt))
    Gd = np.empty(n)
    X = P @ I  # (Ac^T)^(j-1) P I
    for j in range(n):
        Gd[j] = -(Bt.T @ X).item() / S
        X = Ac.T @ X
    return PreviewGains(A, B, C, float(K[0]), K[1:], Gd, dt)


def track(gains: PreviewGains, p_ref: np.ndarray, x0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Run the preview servo along a ZMP reference (n,) of one axis (held at its last
    value beyond the end): the CoM states (n, 3) and the model's ZMP (n,)."""
    g = gains
    n, N = len(p_ref), len(g.Gd)
    ref = np.concatenate([p_ref, np.full(N + 1, p_ref[-1])])
    x = np.zeros(3) if x0 is None else np.asarray(x0, dtype=float).copy()
    e_sum = 0.0
    X, P = np.empty((n, 3)), np.empty(n)
    for k in range(n):
        X[k], P[k] = x, g.C @ x
        e_sum += P[k] - ref[k]
        u = -g.Gi * e_sum - g.Gx @ x - g.Gd @ ref[k + 1:k + 1 + N]
        x = g.A @ x + g.B * u
    return X, P
