"""A leg's product of exponentials with extra factors: the kinematics of model-gap
effects that change the robot's geometry (issue #16).

A leg (`LegPoE`) is the product M_0 E_0 M_1 E_1 ... M_{k-1} E_{k-1} M_sole, E_j =
exp(S_j q_j), k the leg's joints (6, or 5 without ankle roll).
An effect inserts factors Exp(zeta) after any element, zeta = sum_i p_i g_i linear in
its parameters p (generators g_i, (6,) twists [v, w] in the frame at that point):

  a link lengthened by d along u (the line from joint k-1's anchor to joint k's, in
      joint k-1's frame): Exp(d [u, 0]) after E_{k-1}; exact, translations commute;
  joint k's axis rotated by Exp(phi) about its anchor: Exp([0, phi]) after M_k and
      Exp(-[0, phi]) after E_k (exp(S' q) = R exp(S q) R^-1); exact.

Poses are exact for any parameter values; Jacobians (right perturbations of the sole
pose, Pinocchio's LOCAL frame) are exact too: a factor F_i = Exp(zeta_i) followed by
the rest of the chain B_i moves the sole by Ad(B_i^-1) Jr(zeta_i) d(zeta_i).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from legcal_bench.geometry.lie import Exp, Jr, adjoint, inverse
from legcal_bench.robots.legmap import SIDES


@dataclass(frozen=True)
class Factor:
    """Exp(sum_i p[cols[i]] g[i]) inserted after element `after` of one leg's chain
    (elements: 0 = M_0, 1 = E_0, 2 = M_1, ..., 2k - 1 = E_{k-1}; 2k = M_sole is last,
    k the leg's joints)."""

    side: str
    after: int
    generators: np.ndarray  # (P, 6)
    cols: np.ndarray  # (P,) columns of the parameter vector p


def link_direction(poe, k: int) -> np.ndarray:
    """Unit vector from chain joint k-1's anchor to joint k's, in joint k-1's frame."""
    t = poe.M[k][:3, 3]
    return t / np.linalg.norm(t)


class FactorChain:
    """Sole poses and Jacobians of both legs with inserted factors, batched over frames."""

    def __init__(self, kin, factors: list[Factor], n_params: int):
        self.kin, self.factors, self.n_params = kin, list(factors), int(n_params)
        self.poe = {s: kin.poe[s] for s in SIDES}

    def legs(self, Q: np.ndarray, p: np.ndarray):
        """For the rows of Q (N, n) and parameters p (n_params,): per side (T (N, 4, 4)
        sole pose in the pelvis frame, Jq (N, 6, k) LOCAL sole Jacobian w.r.t. the leg's
        k joints in leg-map order, Jp (N, 6, n_params) w.r.t. the parameters)."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        n = len(Q)
        out = {}
        for s_i, s in enumerate(SIDES):
            poe = self.poe[s]
            elements: list[tuple] = []  # ("const", 4x4) | ("exp", (N,4,4), kind, payload)
            inserted = {}
            for f in self.factors:
                if f.side == s:
                    inserted.setdefault(f.after, []).append(f)
            nk = len(poe.cols)
            for e in range(2 * nk + 1):
                if e == 2 * nk:
                    elements.append(("const", poe.M_sole, None, None))
                elif e % 2 == 0:
                    elements.append(("const", poe.M[e // 2], None, None))
                else:
                    k = e // 2
                    twist = poe.S[k][None] * Q[:, poe.cols[k], None]
                    elements.append(("exp", Exp(twist), "joint", k))
                for f in inserted.get(e, []):
                    zeta = np.asarray(p, dtype=float)[f.cols] @ f.generators  # (6,)
                    elements.append(("exp", Exp(zeta)[None].repeat(n, axis=0), "factor", (f, zeta)))
            # Suffix products B_i = elements[i+1] ... elements[-1].
            B = [None] * len(elements)
            acc = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
            for i in range(len(elements) - 1, -1, -1):
                B[i] = acc
                acc = elements[i][1] @ acc
            T = acc
            Jq = np.zeros((n, 6, nk))
            Jp = np.zeros((n, 6, self.n_params))
            for i, (kind, _, what, payload) in enumerate(elements):
                if kind != "exp":
                    continue
                AdB = adjoint(inverse(B[i]))
                if what == "joint":
                    k = payload
                    Jq[:, :, poe.cols[k] - nk * s_i] = AdB @ poe.S[k]
                else:
                    f, zeta = payload
                    G = Jr(zeta) @ f.generators.T  # (6, P)
                    Jp[:, :, f.cols] += AdB @ G
            out[s] = (T, Jq, Jp)
        return out
