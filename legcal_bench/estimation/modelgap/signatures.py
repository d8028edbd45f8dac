"""Candidate signatures for tracing a residual (issue #17): columns that a physical
cause would add to the residual, scored against the whitened residual by
`legcal_bench.estimation.modelgap.lineartests.score` (no fit, no library needed).

  leg geometry   a generic error of one leg's chain: a 6-dof twist after each of its
                 joints (`LegGeometry`, an effect with factors, not a library effect:
                 6 parameters per joint that say which leg, not what);
  joint angle    a joint's apparent offset growing with its angle (any scale-like cause);
  joint load     ... with its gravity/contact load from the ankle wrenches (compliance-like);
  motion         ... with the sign of its velocity (backlash, friction-like);
  time           a segment's residual drifting linearly in time (creep, slip, warm-up).

Each per-joint signature is the joint's column of the residual's Jacobian w.r.t. the
joint angles, frame by frame, times the signature's value in that frame.
"""

from __future__ import annotations

import numpy as np

from legcal_bench.estimation.modelgap.effects import Effect
from legcal_bench.estimation.problem.residuals import project_mean
from legcal_bench.robots.kinematics import LegKinematics

FAMILIES = ("angle", "load", "motion")


class LegGeometry(Effect):
    """A generic geometric error of one leg (tracing only: not registered)."""

    summary = "a 6-dof twist after each joint of one leg"

    def __init__(self, side: str):
        self.side = side
        self.name = f"leg_geometry_{side}"

    def parameters(self, kin: LegKinematics):
        return [(f"after_joint{k}_{c}", "m" if c < 3 else "rad") for k in range(kin.legmap.leg_joints)
                for c in range(6)]

    def factors(self, kin: LegKinematics):
        out = []
        n_chain = kin.legmap.leg_joints
        for k in range(n_chain):
            gens = np.zeros((6 * n_chain, 6))
            gens[6 * k:6 * k + 6] = np.eye(6)
            out.append((self.side, 2 * k + 1, gens))  # after E_k
        return out


def joint_columns(G: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(N, 11, n): each joint's Jacobian column G (N, 11, n) times its per-frame
    signature value (N, n), centred over the frames (n the leg joints)."""
    v = values - values.mean(axis=0)
    return G * v[:, None, :]


def time_columns(segment: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, 11, 11 S): per segment, every row drifting with centred time."""
    segs = np.unique(segment)
    C = np.zeros((len(t), 11, 11 * len(segs)))
    for i, s in enumerate(segs):
        m = segment == s
        tc = t[m] - t[m].mean()
        C[np.ix_(m, range(11), range(11 * i, 11 * i + 11))] = tc[:, None, None] * np.eye(11)[None]
    return C


def project_means(C: np.ndarray, segment: np.ndarray, r_feet: np.ndarray) -> np.ndarray:
    """Fixed-mean columns C (N, 11, P) with each segment's inter-foot mean re-estimated
    exactly as the fit's own columns are (`residuals.project_mean`, from the frames' feet
    residuals r_feet (N, 6)); the flat rows have no mean."""
    out = np.array(C, dtype=float, copy=True)
    for s in np.unique(segment):
        m = segment == s
        out[m, :6] = project_mean(out[m, :6], r_feet[m])
    return out
