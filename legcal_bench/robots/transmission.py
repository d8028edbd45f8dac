"""Leg joints whose encoders read a motor, not the joint: a gear, or a drive joint.

A transmission maps the encoder's (motor's) angle e to the joint's angle q:

    q = c0 + c1 e

- a fixed ratio, the leg map's `ratio` on the joint's entry (motor turns per joint turn,
  the encoder on the motor): c0 = 0, c1 = 1 / ratio; the model's actuator turns the joint;
- a coupled drive joint, read from the model: a joint equality `joint = c0 + c1 drive`
  (MJCF `<equality><joint>`, a URDF `<mimic>` as MuJoCo compiles it), the encoder on the
  drive and the actuator on the drive.

Offsets live where the encoders are: q = c0 + c1 (e + dq_motor), so a joint-space offset
dq = c1 dq_motor. Recordings hold the encoders' readings (motor space for these joints);
`legcal_bench.data.recording.load_session` hands them on in joint space
(`to_joint_space`, `encoder_map`), every calibrator and check works in joint space, and results report
the offsets in both (`motor_offsets`). Joints without a transmission: c0 = 0, c1 = 1.
A parallel-linkage ankle's map is not linear: its motors' angles stay in the recordings'
columns and the kinematics maps them (`legcal_bench.robots.linkage`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from legcal_bench.errors import LegMapError
from legcal_bench.robots.holds import joint_couplings
from legcal_bench.robots.legmap import LegMap


@dataclass(frozen=True)
class Transmission:
    joint: str
    c0: float
    c1: float
    drive: str | None = None  # the drive joint whose actuator turns the leg joint (None: a fixed ratio)

    @property
    def kind(self) -> str:
        return "fixed ratio" if self.drive is None else f"drive joint {self.drive}"


def transmissions(legmap: LegMap) -> dict[str, Transmission]:
    """Leg joint name -> its transmission, for the leg joints that have one."""
    where = str(legmap.source or legmap.name)
    out: dict[str, Transmission] = {}
    ratio = {j.name: j.ratio for s in legmap.legs.values() for j in s.joints if j.ratio != 1.0}
    for name, r in ratio.items():
        out[name] = Transmission(name, 0.0, 1.0 / r)
    legs = set(legmap.joint_names)
    linked = {j.name for s in legmap.legs.values() if s.linkage is not None for j in s.joints[-2:]}
    for c in joint_couplings(legmap.mjcf):
        if c.joint not in legs:  # no leg joint, or another joint following a leg joint (not held, not ours)
            continue
        if c.joint in linked:
            raise LegMapError(f"{where}: ankle joint {c.joint} is turned by the leg map's linkage and coupled to "
                              f"{c.drive} by a joint equality of the model: give one transmission; drop the equality "
                              "or the linkage")
        if c.drive in legs:
            raise LegMapError(f"{where}: the model's joint equality couples two leg joints ({c.joint} = "
                              f"f({c.drive})): a leg joint is driven by its own motor or by a drive joint off the "
                              "legs; remove the equality or list the leg's own joints")
        if c.linear is None:
            raise LegMapError(f"{where}: leg joint {c.joint} is coupled to {c.drive} by a polynomial of degree > 1 "
                              f"(polycoef {list(c.polycoef)}): only a linear transmission (c0 + c1 drive) is read")
        if c.joint in out:
            raise LegMapError(f"{where}: leg joint {c.joint} has a ratio in the leg map and a drive joint "
                              f"({c.drive}) in the model: the drive's coupling is the transmission; drop the ratio")
        out[c.joint] = Transmission(c.joint, *c.linear, c.drive)  # the joints' references folded in
    return out


class EncoderMap(NamedTuple):
    """q = c0 + c1 e per leg joint, (n,) each in leg-map order."""

    c0: np.ndarray
    c1: np.ndarray


def encoder_map(legmap: LegMap) -> EncoderMap | None:
    """The robot's encoder map; None when every encoder reads its joint (no arithmetic)."""
    t = transmissions(legmap)
    if not t:
        return None
    return EncoderMap(np.array([t[n].c0 if n in t else 0.0 for n in legmap.joint_names]),
                      np.array([t[n].c1 if n in t else 1.0 for n in legmap.joint_names]))


def to_joint_space(q_enc: np.ndarray, emap: EncoderMap | None) -> np.ndarray:
    """Encoder readings (..., n) -> the joints' angles."""
    return q_enc if emap is None else emap.c0 + emap.c1 * q_enc


def to_encoder_space(q: np.ndarray, emap: EncoderMap | None) -> np.ndarray:
    """The joints' angles (..., n) -> what their encoders read."""
    return q if emap is None else (q - emap.c0) / emap.c1


def motor_offsets(dq: dict[str, float], legmap: LegMap) -> dict[str, float]:
    """Joint-space offsets -> the encoders' (motor-space) offsets, dq / c1."""
    t = transmissions(legmap)
    return {n: v / t[n].c1 if n in t else v for n, v in dq.items()}
