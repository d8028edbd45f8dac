"""Injected encoder offsets, in the paper's convention.

The corrected angle is q = q_enc + dq, so a robot with offsets dq reports
q_enc = q_true - dq. Presets map by joint role, never by position.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from legcal_bench.errors import OffsetSpecError
from legcal_bench.paper import A2_BASE_DEG, A2_PLATFORM_ORDER, A3_BASE_DEG, A3_PLATFORM_ORDER, INJECTION_RAD
from legcal_bench.robots.legmap import LegMap
from legcal_bench.sim.names import PRESETS_HELP


def _physical_signs(legmap: LegMap) -> np.ndarray:
    from legcal_bench.robots.kinematics import LegKinematics  # Pinocchio: not at import (command start-up)

    return LegKinematics(legmap).physical_signs()


def paper_injection(legmap: LegMap) -> np.ndarray:
    """The paper's injection (rad) on this robot's 12 leg joints, by role, each signed by
    its axis against the role's pelvis axis (`LegKinematics.physical_signs`): the same
    physical pattern on every robot, a mirrored axis's joint included."""
    return np.array([INJECTION_RAD[r] for r in legmap.joint_roles]) * _physical_signs(legmap)


def paper_base(legmap: LegMap) -> np.ndarray:
    """The paper's real robots' base offsets (Table II, rad) on this robot, by role: the
    A3's for a hip-pitch-first ordering, the A2's otherwise; signed as `paper_injection`."""
    if legmap.hip_order[0] == "hip_pitch":
        order, table = A3_PLATFORM_ORDER, A3_BASE_DEG
    else:
        order, table = A2_PLATFORM_ORDER, A2_BASE_DEG
    sides = list(legmap.legs)
    out = np.empty(12)
    for i, (name, role) in enumerate(zip(legmap.joint_names, legmap.joint_roles)):
        side = next(k for k, s in enumerate(sides) if name in [j.name for j in legmap.legs[s].joints])
        out[i] = np.deg2rad(table[6 * side + order.index(role)])
    return out * _physical_signs(legmap)


def _degrees(spec: str, prefix: str, example: str) -> float:
    """The <deg> of `prefix<deg>`, within [0, 10]."""
    try:
        deg = float(spec.strip()[len(prefix):])
    except ValueError:
        raise OffsetSpecError(f"offsets {spec!r}: write {prefix}<deg>, e.g. {prefix}{example}") from None
    if not 0 <= deg <= 10:
        raise OffsetSpecError(f"offsets {spec!r}: <deg> must be in [0, 10] degrees")
    return deg


def resolve_offsets(spec: str | np.ndarray | Sequence[float], legmap: LegMap,
                    rng: np.random.Generator | None = None) -> np.ndarray:
    """The 12-vector of offsets (rad) for `spec`; `random:<deg>` draws from `rng`
    uniformly in [-deg, +deg] per joint."""
    if not isinstance(spec, str):
        try:
            v = np.asarray(spec, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise OffsetSpecError(f"offsets: expected 12 numbers in radians, got {spec!r}") from None
        if v.size != 12 or not np.all(np.isfinite(v)):
            raise OffsetSpecError(f"offsets: expected 12 finite values in radians, got {v.size}")
        return v
    s = spec.strip()
    if s == "none":
        return np.zeros(12)
    if s == "paper":
        return paper_injection(legmap)
    if s == "paper-base":
        return paper_base(legmap)
    if s.startswith("paper@"):
        # The signs of the paper's injection by role, <deg> on every joint (issue #13's "paper@3").
        return np.sign(paper_injection(legmap)) * np.deg2rad(_degrees(spec, "paper@", "3"))
    if s.startswith("random:"):
        deg = _degrees(spec, "random:", "1.5")
        if rng is None:
            raise OffsetSpecError("offsets random:<deg> needs a seeded generator")
        return rng.uniform(-1, 1, 12) * np.deg2rad(deg)
    parts = s.split(",")
    if len(parts) == 12:
        try:
            return resolve_offsets([float(p) for p in parts], legmap)
        except ValueError:
            pass
    raise OffsetSpecError(f"offsets {spec!r} not understood: use {PRESETS_HELP}")
