"""Injected encoder offsets, in the paper's convention.

The corrected angle is q = q_enc + dq, so a robot with offsets dq reports
q_enc = q_true - dq. Presets map by joint role, never by position.

Random patterns: `random:<deg>` draws every joint's offset uniformly in [-deg, +deg]
from the generator its caller seeds (a session set's seed, a trial's: see
`legcal_bench.evaluation.walk.trial_offsets`); `random:<deg>@<seed>` fixes the
pattern's seed: it draws from `numpy.random.default_rng(<seed>)` whatever the caller's
generator (a trial-by-trial evaluation draws trial s's pattern from seed <seed> + s).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from legcal_bench.errors import OffsetSpecError
from legcal_bench.paper import A2_BASE_DEG, A2_PLATFORM_ORDER, A3_BASE_DEG, A3_PLATFORM_ORDER, INJECTION_RAD
from legcal_bench.robots.legmap import SIDES, LegMap
from legcal_bench.sim.names import PRESETS_HELP


def _physical_signs(legmap: LegMap) -> np.ndarray:
    from legcal_bench.robots.kinematics import LegKinematics  # Pinocchio: not at import (command start-up)

    return LegKinematics(legmap).physical_signs()


def paper_injection(legmap: LegMap) -> np.ndarray:
    """The paper's injection (rad) on this robot's leg joints (`legmap.n_joints`), by role,
    each signed by its axis against the role's pelvis axis (`LegKinematics.physical_signs`):
    the same physical pattern on every robot, a mirrored axis's joint included. A role the
    robot lacks (`legmap.absent_roles`, e.g. no ankle roll) has no joint and gets nothing
    (`paper_note` says so)."""
    return np.array([INJECTION_RAD[r] for r in legmap.joint_roles]) * _physical_signs(legmap)


def _paper_table(legmap: LegMap) -> tuple[tuple[str, ...], tuple[float, ...]]:
    """The paper's base-offset table (Table II) this robot takes: the A3's for a
    hip-pitch-first ordering, the A2's otherwise; (platform role order per leg, degrees
    left leg then right)."""
    if legmap.hip_order[0] == "hip_pitch":
        return A3_PLATFORM_ORDER, A3_BASE_DEG
    return A2_PLATFORM_ORDER, A2_BASE_DEG


def paper_base(legmap: LegMap) -> np.ndarray:
    """The paper's real robots' base offsets (Table II, rad) on this robot, by role: the
    A3's for a hip-pitch-first ordering, the A2's otherwise; signed as `paper_injection`.
    A role the robot lacks has no joint, and its table entry is left out."""
    order, table = _paper_table(legmap)
    per_leg = len(order)  # the paper's platforms: one table entry per role and leg
    by_role = {(side, role): table[k * per_leg + j] for k, side in enumerate(SIDES) for j, role in enumerate(order)}
    out = np.array([by_role[legmap.side_of(i), role] for i, role in enumerate(legmap.joint_roles)])
    return np.deg2rad(out) * _physical_signs(legmap)


def paper_note(spec: str | np.ndarray | Sequence[float], legmap: LegMap) -> str | None:
    """What a paper preset (`paper`, `paper@<deg>`, `paper-base`) leaves out on this robot:
    the paper's roles the robot lacks (`legmap.absent_roles`), whose offsets have no joint
    to go to; None for other specs or a robot with every role."""
    if not isinstance(spec, str) or not legmap.absent_roles:
        return None
    s = spec.strip()
    if s not in ("paper", "paper-base") and not s.startswith("paper@"):
        return None
    if s == "paper-base":
        order, table = _paper_table(legmap)
        per_leg = len(order)
        left_out = ", ".join(f"{role} ({table[order.index(role)]:+.3f}° left, {table[per_leg + order.index(role)]:+.3f}° "
                             "right)" for role in legmap.absent_roles)
    elif s == "paper":
        left_out = ", ".join(f"{role} ({np.rad2deg(INJECTION_RAD[role]):+.2f}°)" for role in legmap.absent_roles)
    else:
        left_out = ", ".join(legmap.absent_roles)
    return (f"offsets {s}: robot {legmap.name} has no {', '.join(legmap.absent_roles)} joint; the paper's offsets "
            f"for {left_out} are not injected ({legmap.n_joints} leg joints)")


def _degrees(spec: str, prefix: str, example: str) -> float:
    """The <deg> of `prefix<deg>`, within [0, 10]."""
    try:
        deg = float(spec.strip()[len(prefix):])
    except ValueError:
        raise OffsetSpecError(f"offsets {spec!r}: write {prefix}<deg>, e.g. {prefix}{example}") from None
    if not 0 <= deg <= 10:
        raise OffsetSpecError(f"offsets {spec!r}: <deg> must be in [0, 10] degrees")
    return deg


def parse_random(spec: str) -> tuple[float, int | None]:
    """(<deg>, <seed>) of `random:<deg>` (seed None) or `random:<deg>@<seed>`; <deg> in
    [0, 10], <seed> a whole number >= 0."""
    s = spec.strip()
    deg_text, at, seed_text = s[len("random:"):].partition("@")
    try:
        deg = float(deg_text)
    except ValueError:
        raise OffsetSpecError(f"offsets {spec!r}: write random:<deg> or random:<deg>@<seed>, e.g. random:1.5 or "
                              "random:1.5@7") from None
    if not 0 <= deg <= 10:
        raise OffsetSpecError(f"offsets {spec!r}: <deg> must be in [0, 10] degrees")
    if not at:
        return deg, None
    if not (seed_text.strip().isascii() and seed_text.strip().isdigit()):
        raise OffsetSpecError(f"offsets {spec!r}: write random:<deg>@<seed> with <seed> a whole number >= 0, "
                              "e.g. random:1.5@7")
    return deg, int(seed_text)


def random_pattern(deg: float, legmap: LegMap, rng: np.random.Generator) -> np.ndarray:
    """One `random:<deg>` pattern (rad): every leg joint uniform in [-deg, +deg] from `rng`."""
    return rng.uniform(-1, 1, legmap.n_joints) * np.deg2rad(deg)


def with_magnitude(spec: str, deg: float) -> str:
    """`spec` with its magnitude replaced by `deg` (a sweep): `paper@<deg>`, or
    `random:<deg>` keeping its `@<seed>`; other specs have no magnitude to sweep."""
    s = spec.strip() if isinstance(spec, str) else ""
    if s.startswith("paper@"):
        return f"paper@{deg:g}"
    if s.startswith("random:"):
        _, seed = parse_random(s)
        return f"random:{deg:g}" + (f"@{seed}" if seed is not None else "")
    raise OffsetSpecError(f"offsets {spec!r}: a sweep needs paper@<deg> or random:<deg> (with or without @<seed>), "
                          "whose <deg> it replaces")


def resolve_offsets(spec: str | np.ndarray | Sequence[float], legmap: LegMap,
                    rng: np.random.Generator | None = None) -> np.ndarray:
    """The vector of offsets (rad, one per leg joint: `legmap.n_joints`) for `spec`;
    `random:<deg>` draws from `rng` uniformly in [-deg, +deg] per joint,
    `random:<deg>@<seed>` from `default_rng(<seed>)` instead (`rng` unused). A paper preset
    on a robot lacking one of the paper's roles: `paper_note` says what is left out."""
    n = legmap.n_joints
    if not isinstance(spec, str):
        try:
            v = np.asarray(spec, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise OffsetSpecError(f"offsets: expected {n} numbers in radians (one per leg joint of {legmap.name}), "
                                  f"got {spec!r}") from None
        if v.size != n or not np.all(np.isfinite(v)):
            raise OffsetSpecError(f"offsets: expected {n} finite values in radians (one per leg joint of "
                                  f"{legmap.name}), got {v.size}")
        return v
    s = spec.strip()
    if s == "none":
        return np.zeros(n)
    if s == "paper":
        return paper_injection(legmap)
    if s == "paper-base":
        return paper_base(legmap)
    if s.startswith("paper@"):
        # The signs of the paper's injection by role, <deg> on every joint (issue #13's "paper@3").
        return np.sign(paper_injection(legmap)) * np.deg2rad(_degrees(spec, "paper@", "3"))
    if s.startswith("random:"):
        deg, seed = parse_random(spec)
        if seed is not None:
            rng = np.random.default_rng(seed)
        if rng is None:
            raise OffsetSpecError("offsets random:<deg> needs a seeded generator (or write random:<deg>@<seed>)")
        return random_pattern(deg, legmap, rng)
    parts = s.split(",")
    if len(parts) == n:
        try:
            return resolve_offsets([float(p) for p in parts], legmap)
        except ValueError:
            pass
    raise OffsetSpecError(f"offsets {spec!r} not understood: use {PRESETS_HELP}")
