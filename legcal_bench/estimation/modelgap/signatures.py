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
from legcal_bench.geometry.lie import Ad, Exp, Log
from legcal_bench.robots.kinematics import LegKinematics

FAMILIES = ("angle", "load", "motion")


TWIST = ("tx", "ty", "tz", "rx", "ry", "rz")  # a twist's components: translations (m), rotations (rad)


class LegGeometry(Effect):
    """A generic geometric error of one leg (not registered): a 6-dof twist at the hip's
    mounting (after M_0: the first joint's anchor and axis moved) and after each of its
    joints (link translations, bends and twists, the next axis's direction, the sole's
    placement), and each joint's axis tilted about its anchor (`AXIS_TILTS`). Tracing
    scores it as a location; the generic alternative (`generic_effects`) fits both legs'
    together with the IMU's mount.

    The tilts add no direction the twists lack (a tilt is a rotation before the joint
    and its inverse after it), only a sparser name for one: a joint's axis tilted in its
    own frame is one tilt column, but three twist columns once the rotation before it is
    carried back through the link to the previous joint's twist, and there its component
    along the previous joint's axis is that joint's offset, which the twists cannot hold
    apart from it. The sparse description (`forward_selection`) then gave the G1's knee
    axis tilted by 0.5 deg a hip-yaw offset 0.09 deg off (22 sigma). So the tilts serve
    the sparse description only; the whole and its families are reduced and fitted over
    the twists (`legcal_bench.evaluation.modelgap.generic_fit`), as before them."""

    summary = "a 6-dof twist at the hip's mounting and after each joint of one leg, and each joint's axis tilted"

    def __init__(self, side: str):
        self.side = side
        self.name = f"leg_geometry_{side}"

    def _places(self, kin: LegKinematics) -> list[tuple[str, int]]:
        """(label, chain element the twist follows) of each twist: the mounting, then
        after each joint (`legcal_bench.robots.chain.Factor`'s element numbering)."""
        return [("mount", 0)] + [(f"after_{r}", 2 * k + 1) for k, r in enumerate(self._roles(kin))]

    def _roles(self, kin: LegKinematics) -> list[str]:
        return [kin.legmap.joint_roles[int(c)] for c in kin.poe[self.side].cols]

    def _tilts(self, kin: LegKinematics) -> list[tuple[str, int, np.ndarray]]:
        """(label, joint k of the chain, twist (6,)) of each axis tilt: a unit rotation
        about an axis u normal to joint k's axis w, through its anchor, in the joint's
        frame; u the frame's axes least along w, made normal to it (the label names the
        frame axis u is closest to; a, b when both are closest to one)."""
        poe, out = kin.poe[self.side], []
        for k, role in enumerate(self._roles(kin)):
            v, w = poe.S[k][:3], poe.S[k][3:]
            w = w / np.linalg.norm(w)
            anchor = np.cross(w, v)  # the point of the axis nearest the frame's origin
            first = np.eye(3)[int(np.argmin(np.abs(w)))]
            u1 = first - (first @ w) * w
            u1 /= np.linalg.norm(u1)
            u2 = np.cross(w, u1)
            u2 *= np.sign(u2[int(np.argmax(np.abs(u2)))])
            us = sorted((u1, u2), key=lambda u: int(np.argmax(np.abs(u))))
            labels = ["xyz"[int(np.argmax(np.abs(u)))] for u in us]
            for label, u in zip(labels if labels[0] != labels[1] else ["a", "b"], us):
                out.append((f"{role}_axis_r{label}", k, np.concatenate([np.cross(anchor, u), u])))
        return out

    def parameters(self, kin: LegKinematics):
        return ([(f"{place}_{c}", "m" if c[0] == "t" else "rad") for place, _ in self._places(kin) for c in TWIST]
                + [(label, "rad") for label, _, _ in self._tilts(kin)])

    def bounds(self, kin: LegKinematics):
        """A link frame off by at most the library's tolerances: a length's in translation,
        an axis's in rotation."""
        return ([(-LENGTH_TOLERANCE, LENGTH_TOLERANCE) if c[0] == "t" else (-AXIS_TOLERANCE, AXIS_TOLERANCE)
                 for _ in self._places(kin) for c in TWIST]
                + [(-AXIS_TOLERANCE, AXIS_TOLERANCE)] * len(self._tilts(kin)))

    def values(self, kin: LegKinematics, edited: LegKinematics) -> np.ndarray:
        """The parameters (`parameters` order) that take `kin`'s chain of this leg to
        `edited`'s (the same robot with its geometry changed, e.g. a simulator's edited
        model): each place's twist the log of its constant transform's change (the
        mount's after M_0, a joint's before the next constant, as `factors` inserts
        them); each joint's axis tilts the rotation, about its anchor, that turns its
        axis into the edited one (exact for one tilt a joint; two compose to first order
        in the chain). Raises ValueError for a joint whose motion changed otherwise
        (e.g. its anchor moved): no tilt describes that."""
        a, b = kin.poe[self.side], edited.poe[self.side]
        places = [Log(np.linalg.inv(a.M[0]) @ b.M[0])] + [Log(B @ np.linalg.inv(A))
                                                           for A, B in zip(_after_joints(a), _after_joints(b))]
        tilts = self._tilts(kin)
        tilt_values = np.zeros(len(tilts))
        for k, (S, S_new) in enumerate(zip(a.S, b.S)):
            w, w_new = S[3:] / np.linalg.norm(S[3:]), S_new[3:] / np.linalg.norm(S_new[3:])
            c = np.cross(w, w_new)
            r = c / np.linalg.norm(c) * np.arctan2(np.linalg.norm(c), w @ w_new) if np.any(c) else np.zeros(3)
            anchor = np.cross(w, S[:3] / np.linalg.norm(S[3:]))
            if np.abs(Ad(Exp(np.concatenate([np.cross(anchor, r), r]))) @ S - S_new).max() > 1e-9:
                role = kin.legmap.joint_roles[int(a.cols[k])]
                raise ValueError(f"{self.side} {role}: its motion changed in a way no axis tilt about its anchor "
                                 f"describes (S {np.round(S, 6).tolist()} -> {np.round(S_new, 6).tolist()})")
            for i, (_, kk, t) in enumerate(tilts):
                if kk == k:
                    tilt_values[i] = r @ t[3:]
        return np.concatenate([*places, tilt_values])

    def factors(self, kin: LegKinematics):
        places, tilts = self._places(kin), self._tilts(kin)
        n = 6 * len(places) + len(tilts)
        out = []
        for i, (_, after) in enumerate(places):
            gens = np.zeros((n, 6))
            gens[6 * i:6 * i + 6] = np.eye(6)
            out.append((self.side, after, gens))
        for i, (_, k, twist) in enumerate(tilts):  # R after M_k, R^-1 after E_k (the library's hip_axis)
            gens = np.zeros((n, 6))
            gens[6 * len(places) + i] = twist
            out += [(self.side, 2 * k, gens), (self.side, 2 * k + 1, -gens)]
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


def is_tilt(name: str) -> bool:
    """Whether a generic column (`EffectModel.names`) is a joint's axis tilt (`LegGeometry`)."""
    return name.startswith("leg_geometry_") and name.rsplit("_", 1)[0].endswith("_axis")


def _after_joints(poe) -> list[np.ndarray]:
    """The constant transform after each joint of a leg's chain (`LegPoE`): the next
    joint's frame, the sole's after the last."""
    return [*poe.M[1:], poe.M_sole]


def twist_place(name: str) -> str | None:
    """The place (`leg_geometry_<side>.<place>`) whose twist a generic column
    (`EffectModel.names`) is a component of; None for a tilt or another effect's column."""
    return name.rsplit("_", 1)[0] if name.startswith("leg_geometry_") and not is_tilt(name) else None


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
