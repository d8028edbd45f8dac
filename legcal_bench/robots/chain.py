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

from legcal_bench.geometry.lie import Exp, Jr
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
        k joints in leg-map order, Jp (N, 6, n_params) w.r.t. the parameters).

        Batched per side: the joints' exponentials in one call, the factors' (the same
        for every frame) and their right Jacobians in one, the constant elements applied
        by broadcasting, and Ad(B_i^-1) applied to each element's twists without forming
        the 6x6 adjoints (`_moved`)."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        p = np.asarray(p, dtype=float)
        n = len(Q)
        out = {}
        for s_i, s in enumerate(SIDES):
            poe = self.poe[s]
            nk = len(poe.cols)
            mine = [f for f in self.factors if f.side == s]
            zetas = np.array([p[f.cols] @ f.generators for f in mine]).reshape(len(mine), 6)
            F_exp, F_jr = Exp(zetas), Jr(zetas)  # (F, 4, 4), (F, 6, 6)
            twists = np.stack([poe.S[k][None] * Q[:, poe.cols[k], None] for k in range(nk)])  # (k, N, 6)
            E_exp = Exp(twists)  # (k, N, 4, 4)
            # The chain's elements in order: ("const", 4x4) | ("joint", k) | ("factor", index in `mine`).
            elements: list[tuple] = []
            by_after: dict[int, list[int]] = {}
            for i, f in enumerate(mine):
                by_after.setdefault(f.after, []).append(i)
            for e in range(2 * nk + 1):
                if e == 2 * nk:
                    elements.append(("const", poe.M_sole))
                elif e % 2 == 0:
                    elements.append(("const", poe.M[e // 2]))
                else:
                    elements.append(("joint", e // 2))
                elements += [("factor", i) for i in by_after.get(e, [])]
            # Suffix products B_i = elements[i+1] ... elements[-1] of the exponential elements.
            moving = [i for i, (kind, _) in enumerate(elements) if kind != "const"]
            B = np.empty((len(moving), n, 4, 4))
            acc = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
            slot = len(moving) - 1
            for i in range(len(elements) - 1, -1, -1):
                kind, what = elements[i]
                if kind != "const":
                    B[slot] = acc
                    slot -= 1
                acc = (what if kind == "const" else E_exp[what] if kind == "joint" else F_exp[what]) @ acc
            T = acc
            Rt = np.swapaxes(B[..., :3, :3], -1, -2)  # (moving, N, 3, 3)
            pos = B[..., :3, 3]
            Jq = np.zeros((n, 6, nk))
            Jp = np.zeros((n, 6, self.n_params))
            for slot, i in enumerate(moving):
                kind, what = elements[i]
                if kind == "joint":
                    Jq[:, :, poe.cols[what] - nk * s_i] = _moved(Rt[slot], pos[slot], poe.S[what][:, None])[..., 0]
                else:
                    f = mine[what]
                    Jp[:, :, f.cols] += _moved(Rt[slot], pos[slot], F_jr[what] @ f.generators.T)
            out[s] = (T, Jq, Jp)
        return out


def _moved(Rt: np.ndarray, p: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(N, 6, P) Ad(B^-1) X for the poses B = [R p] (given as R^T (N, 3, 3) and p (N, 3))
    and twists X (6, P) [v, w]: [R^T (v - p x w), R^T w], without forming the 6x6
    adjoints."""
    v, w = X[:3], X[3:]
    pxw = np.cross(p[:, :, None], w[None], axis=1)  # (N, 3, P)
    return np.concatenate([Rt @ (v[None] - pxw), Rt @ np.broadcast_to(w, (len(p), *w.shape))], axis=1)
