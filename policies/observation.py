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

Each term's values are multiplied by its scale (one number or one per value) and then
clipped to +-clip if given.
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
    joint_index: np.ndarray  # policy joint k -> leg-map column
    default_q: np.ndarray  # policy order


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
    "joint_pos": Term(lambda c, t: _joints(c.obs["q_enc"], c, t) - (
        c.default_q if t.mask is None else c.default_q[t.mask_index]), lambda n, t: n if t.mask is None else len(
        t.mask), per_joint=True),
    "joint_vel": Term(lambda c, t: _joints(c.obs["dq_enc"], c, t), lambda n, t: n if t.mask is None else len(t.mask),
                      per_joint=True),
    "last_action": Term(lambda c, t: c.last_action if t.mask is None else c.last_action[t.mask_index],
                        lambda n, t: n if t.mask is None else len(t.mask), per_joint=True),
    "phase": Term(lambda c, t: _phase(c, t, _NO_OFFSET), lambda n, t: 2, needs_period=True),
    "time": Term(lambda c, t: np.array([c.time]), lambda n, t: 1),
    "foot_phase": Term(lambda c, t: _phase(c, t, t.offsets), lambda n, t: 2 * len(t.offsets), needs_period=True),
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


def bind(spec) -> list[BoundTerm]:
    out = []
    for t in spec.observation:
        mi = None if t.mask is None else np.array([spec.joints.index(j) for j in t.mask])
        out.append(BoundTerm(t.term, np.asarray(t.scale, dtype=float), t.clip, t.mask, mi, t.period, t.offsets))
    return out


def observation_size(spec, terms=None) -> int:
    n = len(spec.joints)
    return int(sum(TERMS[t.term].size(n, t) for t in (spec.observation if terms is None else terms)))


def build_observation(terms: list[BoundTerm], ctx: ObsContext) -> np.ndarray:
    """The policy's observation vector (float32): each term scaled, then clipped."""
    parts = []
    for t in terms:
        v = np.multiply(TERMS[t.term].read(ctx, t), t.scale, dtype=float)
        if t.clip is not None:  # np.clip's arithmetic (max, then min), without its wrapper
            v = np.minimum(np.maximum(v, -t.clip), t.clip)
        parts.append(v)
    return np.concatenate(parts).astype(np.float32)
