"""The observation vocabulary of policy specs: each term, what it reads, its size.

A term reads what the robot's software sees (the walking env's observation, in the
base frame through the nominal IMU mount, encoders corrected), the policy's own state
(its last action, its clock) or, if `privileged`, the simulator's truth: a result
from a policy using a privileged term says so (`PolicySpec.privileged`).

  ang_vel       3   base angular rate from the gyro (rad/s)
  gravity       3   unit gravity direction in the base frame, from the IMU's orientation filter
  base_lin_vel  3   base linear velocity in the base frame (m/s): PRIVILEGED, from the simulator
  command       3   the spec's command [vx, vy, yaw rate]
  joint_pos     n   corrected encoder angles minus default_q (policy order; mask: a subset)
  joint_vel     n   joint velocities (rad/s)
  last_action   n   the policy's previous output (zeros after reset)
  phase         2   sin, cos of 2 pi t / period (t: time since reset)
  foot_phase    2k  per foot i: sin, cos of 2 pi (t / period + offsets[i])
  time          1   t, the time since reset (s): with `clip`, a start-up clock
  gait_phase    2k  per foot i an angle initial[i] + 2 pi frequency t (frozen at initial while
                    the command is zero, if asked), as [cos..., sin...] (grouped) or
                    [cos, sin] per foot (interleaved)
  gravity_true  3   unit gravity direction in the IMU frame from its true orientation: PRIVILEGED
  sensor        k   an MJCF sensor of the robot, by name (e.g. a velocimeter): PRIVILEGED

Joint terms read every joint the policy drives, in its order: the leg joints' corrected
encoders, and a whole-body policy's other joints (waist, arms: no offsets).

Each term's values are multiplied by its scale (one number or one per value) and then
clipped to +-clip if given. With `history: k`, a term gives its last k control steps'
values, oldest first (after a reset, the first step's values k times: Isaac Lab's
observation history), k times its size.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np


@dataclass
class ObsContext:
    """Everything a term may read at one control step."""

    obs: dict  # the walking env's observation (leg-map order)
    truth: dict  # the env's info (privileged terms only)
    time: float  # s since reset
    last_action: np.ndarray  # policy order
    command: np.ndarray
    joint_index: np.ndarray  # policy joint k -> column of the body vector (leg joints, then the others)
    default_q: np.ndarray  # policy order
    q_body: np.ndarray | None = None  # corrected encoders of the leg joints, then a whole-body policy's others
    dq_body: np.ndarray | None = None

    def __post_init__(self):
        if self.q_body is None:  # from the env's observation: the leg joints, then any others
            o = self.obs
            self.q_body = np.concatenate([o["q_enc"], o["q_extra"]]) if "q_extra" in o else o["q_enc"]
            self.dq_body = np.concatenate([o["dq_enc"], o["dq_extra"]]) if "dq_extra" in o else o["dq_enc"]


@dataclass(frozen=True)
class Term:
    read: Callable  # (ObsContext, ObsTerm) -> values
    size: Callable  # (n joints, ObsTerm) -> int
    privileged: bool = False
    per_joint: bool = False
    needs_period: bool = False


def _joints(values: np.ndarray, ctx: ObsContext, t) -> np.ndarray:
    v = values[ctx.joint_index]
    return v if t.mask is None else v[t.mask_index]


def _gait_phase(ctx: ObsContext, t) -> np.ndarray:
    a = t.initial
    if not (t.stop_at_zero_command and not np.any(ctx.command)):
        a = a + 2 * np.pi * t.frequency * ctx.time
    c, s = np.cos(a), np.sin(a)
    return np.concatenate([c, s]) if t.layout == "grouped" else np.column_stack([c, s]).ravel()


def _sensor(ctx: ObsContext, t) -> np.ndarray:
    v = np.asarray(ctx.truth["sensors"][t.name], dtype=float)
    if v.shape != (t.size,):
        from legcal_bench.errors import ConfigError

        raise ConfigError(f"observation term sensor {t.name!r}: the spec gives size {t.size}, the sensor has "
                          f"{v.size} values")
    return v


_NO_OFFSET = np.zeros(1)


def _phase(ctx: ObsContext, t, offsets) -> np.ndarray:
    a = 2 * np.pi * (ctx.time / t.period + np.asarray(offsets))
    out = np.empty((len(a), 2))  # [sin, cos] per offset
    np.sin(a, out=out[:, 0])
    np.cos(a, out=out[:, 1])
    return out.ravel()


TERMS: dict[str, Term] = {
    "ang_vel": Term(lambda c, t: c.obs["ang_vel"], lambda n, t: 3),
    "gravity": Term(lambda c, t: c.obs["gravity"], lambda n, t: 3),
    "base_lin_vel": Term(lambda c, t: c.truth["base_lin_vel"], lambda n, t: 3, privileged=True),
    "command": Term(lambda c, t: c.command, lambda n, t: 3),
    "joint_pos": Term(lambda c, t: _joints(c.q_body, c, t) - (
        c.default_q if t.mask is None else c.default_q[t.mask_index]), lambda n, t: n if t.mask is None else len(
        t.mask), per_joint=True),
    "joint_vel": Term(lambda c, t: _joints(c.dq_body, c, t), lambda n, t: n if t.mask is None else len(t.mask),
                      per_joint=True),
    "last_action": Term(lambda c, t: c.last_action if t.mask is None else c.last_action[t.mask_index],
                        lambda n, t: n if t.mask is None else len(t.mask), per_joint=True),
    "phase": Term(lambda c, t: _phase(c, t, _NO_OFFSET), lambda n, t: 2, needs_period=True),
    "time": Term(lambda c, t: np.array([c.time]), lambda n, t: 1),
    "foot_phase": Term(lambda c, t: _phase(c, t, t.offsets), lambda n, t: 2 * len(t.offsets), needs_period=True),
    "gait_phase": Term(_gait_phase, lambda n, t: 2 * len(t.initial)),
    "gravity_true": Term(lambda c, t: c.truth["gravity_true"], lambda n, t: 3, privileged=True),
    "sensor": Term(_sensor, lambda n, t: t.size, privileged=True),
}


@dataclass(frozen=True)
class BoundTerm:
    """A spec term bound to the policy's joints (mask as indices)."""

    term: str
    scale: np.ndarray
    clip: float | None
    mask: tuple | None
    mask_index: np.ndarray | None
    period: float | None
    offsets: tuple | None
    frequency: float | None = None
    initial: np.ndarray | None = None  # gait_phase: per-foot initial angles (rad)
    layout: str | None = None
    stop_at_zero_command: bool = False
    name: str | None = None
    size: int | None = None
    history: int = 1


def bind(spec) -> list[BoundTerm]:
    out = []
    for t in spec.observation:
        mi = None if t.mask is None else np.array([spec.joints.index(j) for j in t.mask])
        out.append(BoundTerm(t.term, np.asarray(t.scale, dtype=float), t.clip, t.mask, mi, t.period, t.offsets,
                             t.frequency, None if t.initial is None else np.asarray(t.initial, dtype=float),
                             t.layout, t.stop_at_zero_command, t.name, t.size, t.history))
    return out


def observation_size(spec, terms=None) -> int:
    n = len(spec.joints)
    return int(sum(TERMS[t.term].size(n, t) * t.history for t in (spec.observation if terms is None else terms)))


def build_observation(terms: list[BoundTerm], ctx: ObsContext, history: list | None = None) -> np.ndarray:
    """The policy's observation vector (float32): each term scaled, then clipped; a
    term with `history` > 1 gives its last values from `history` (one list per term,
    the caller's memory: empty after a reset), oldest first."""
    parts = []
    for k, t in enumerate(terms):
        v = np.multiply(TERMS[t.term].read(ctx, t), t.scale, dtype=float)
        if t.clip is not None:  # np.clip's arithmetic (max, then min), without its wrapper
            v = np.minimum(np.maximum(v, -t.clip), t.clip)
        if t.history > 1:
            past = history[k]
            past[:] = (past or [v] * (t.history - 1))[-(t.history - 1):] + [v]
            v = np.concatenate(past)
        parts.append(v)
    return np.concatenate(parts).astype(np.float32)
