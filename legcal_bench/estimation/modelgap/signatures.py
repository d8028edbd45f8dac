"""Candidate signatures for tracing a residual (issue #17): columns that a physical
cause would add to the residual, scored against the whitened residual by
`legcal_bench.estimation.modelgap.lineartests.score` (no fit, no library needed).

  leg geometry   a generic error of one leg's chain: a 6-dof twist at its mounting and
                 after each of its joints (`LegGeometry`, an effect with factors, not a
                 library effect: parameters that say which leg, not what);
  joint angle    a joint's apparent offset growing with its angle (any scale-like cause);
  joint load     ... with its gravity/contact load from the ankle wrenches (compliance-like);
  motion         ... with the sign of its velocity (backlash, friction-like);
  time           a segment's residual drifting linearly in time (creep, slip, warm-up).

Each per-joint signature is the joint's column of the residual's Jacobian w.r.t. the
joint angles, frame by frame, times the signature's value in that frame.
"""

from __future__ import annotations

import numpy as np

from legcal_bench.estimation.modelgap.effect_library import AXIS_TOLERANCE, LENGTH_TOLERANCE, ImuTilt
from legcal_bench.estimation.modelgap.effects import Effect
from legcal_bench.estimation.problem.residuals import project_mean
from legcal_bench.robots.kinematics import LegKinematics

FAMILIES = ("angle", "load", "motion")


TWIST = ("tx", "ty", "tz", "rx", "ry", "rz")  # a twist's components: translations (m), rotations (rad)


class LegGeometry(Effect):
    """A generic geometric error of one leg (not registered): a 6-dof twist at the hip's
    mounting (after M_0: the first joint's anchor and axis moved) and after each of its
    joints (link translations, bends and twists, the next axis's direction, the sole's
    placement). Tracing scores it as a location; the generic alternative
    (`generic_effects`) fits both legs' together with the IMU's mount."""

    summary = "a 6-dof twist at the hip's mounting and after each joint of one leg"

    def __init__(self, side: str):
        self.side = side
        self.name = f"leg_geometry_{side}"

    def _places(self, kin: LegKinematics) -> list[tuple[str, int]]:
        """(label, chain element the twist follows) of each twist: the mounting, then
        after each joint (`legcal_bench.robots.chain.Factor`'s element numbering)."""
        roles = [kin.legmap.joint_roles[int(c)] for c in kin.poe[self.side].cols]
        return [("mount", 0)] + [(f"after_{r}", 2 * k + 1) for k, r in enumerate(roles)]

    def parameters(self, kin: LegKinematics):
        return [(f"{place}_{c}", "m" if c[0] == "t" else "rad") for place, _ in self._places(kin) for c in TWIST]

    def bounds(self, kin: LegKinematics):
        """A link frame off by at most the library's tolerances: a length's in translation,
        an axis's in rotation."""
        return [(-LENGTH_TOLERANCE, LENGTH_TOLERANCE) if c[0] == "t" else (-AXIS_TOLERANCE, AXIS_TOLERANCE)
                for _ in self._places(kin) for c in TWIST]

    def factors(self, kin: LegKinematics):
        places = self._places(kin)
        out = []
        for i, (_, after) in enumerate(places):
            gens = np.zeros((6 * len(places), 6))
            gens[6 * i:6 * i + 6] = np.eye(6)
            out.append((self.side, after, gens))
        return out


class ImuMount(ImuTilt):
    """The IMU's mounting tilt as part of the generic alternative: the library's
    `imu_tilt` under its own name, so that a fit may hold some of its parameters while
    the IMU's noise keeps both of its directions (`legcal_bench.estimation.problem.fit.NOISE_TILT`)."""

    name = "imu_mount"


def generic_effects() -> list[Effect]:
    """The generic kinematic alternative: both legs' full geometry (`LegGeometry`) and
    the IMU's mount (its tilt), one model. The legs are one block: moving one hip by +d
    is, in inter-foot data, moving the other by -d, so they are reduced together
    (`legcal_bench.estimation.modelgap.lineartests.identifiable`)."""
    return [LegGeometry("left"), LegGeometry("right"), ImuMount()]


# Families of geometry changes the generic fit is tested against (`family_columns`):
# which of them alone explain the data as well as the whole.
GEOMETRY_FAMILIES = {
    "link translations (mounting points, lengths, axis offsets)": lambda name: _part(name) == "t",
    "axis directions and link twists": lambda name: _part(name) == "r",
    "the IMU's mount": lambda name: name.startswith("imu_mount."),
    "the left leg's geometry": lambda name: name.startswith("leg_geometry_left."),
    "the right leg's geometry": lambda name: name.startswith("leg_geometry_right."),
}


def _part(name: str) -> str:
    return name.rsplit("_", 1)[-1][0] if name.startswith("leg_geometry_") else ""


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
