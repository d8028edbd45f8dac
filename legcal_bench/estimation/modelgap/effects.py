"""Model-gap effects: what a calibration model may lack beyond the joint offsets, each a
parameter block that plugs into the assembled problem (issue #16).

An `Effect` names its parameters and enters the kinematics in one or more of three ways:

  joint map     q = q_enc + dq + A_k p, A_k (n, P) per frame from the data (an encoder
                scale: the encoder angle; a compliance: the joint's load from the ankle
                force/torque wrenches);
  chain factors Exp(sum_i p_i g_i) inserted in a leg's chain (`legcal_bench.robots.chain`):
                link lengths, joint axis directions;
  IMU axes      the IMU's vertical rotated by Exp(sum_i p_i a_i), a_i axes of the IMU frame
                (a mounting tilt).

`EffectModel` compiles a list of effects into one parameter layout (offsets first, then
each effect's block) and `EffectSegment` evaluates a contact segment's kinematics with
them; the inter-foot and flat-ground terms take it in place of `SegmentKinematics`.

Effects are plug-ins, like calibrators: the entry-point group `legcal_bench.effects`
maps a name to an `Effect` subclass (the library: `legcal_bench.estimation.modelgap.effect_library`).
"""

from __future__ import annotations

import sys
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from legcal_bench.errors import CalibrationError, LegMapError
from legcal_bench.geometry.lie import Exp, Jr, adjoint, inverse
from legcal_bench.robots.chain import Factor, FactorChain
from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics
from legcal_bench.robots.legmap import SIDES

OFFSETS = "offsets"
ENTRY_POINT_GROUP = "legcal_bench.effects"


@dataclass
class SegmentData:
    """What an effect may read of one contact segment's frames, in time order. The frames
    are those the frame selection kept (static, in contact, not trimmed): samples of one
    recording, increasing in time but not always consecutive, so an effect of motion or
    time reads `time`, never the index."""

    q_enc: np.ndarray  # (N, n), n the leg joints
    ft: np.ndarray | None = None  # (N, 2, 6) ankle wrenches [force, torque] in each F/T frame
    up_B: np.ndarray | None = None  # (N, 3) the IMU's vertical in the pelvis frame
    q_ref: np.ndarray | None = None  # (N, n) the angles at which loads are evaluated (default q_enc)
    time: np.ndarray | None = None  # (N,) the frames' timestamps, s, increasing (None: not given)


class Effect(ABC):
    """One model-gap effect. Subclasses set `name` and `summary` (and `needs_ft` if they
    read the ankle wrenches: only such an effect reads loads, at `SegmentData.q_ref`,
    and a fit with one re-evaluates them at its own offsets), implement `parameters` and
    any of `joint_map`, `factors`, `imu_axes`."""

    name: str = ""
    summary: str = ""
    needs_ft: bool = False
    # The data that would separate it from what it is confounded with (reports say it).
    remedy: str = "stances whose postures or loads change its signature relative to the offsets'"

    @abstractmethod
    def parameters(self, kin: LegKinematics) -> list[tuple[str, str]]:
        """(name, unit) of each parameter, SI units."""

    def joint_map(self, kin: LegKinematics, seg: SegmentData) -> np.ndarray | None:
        """(N, n, P): how the parameters move the joint angles, per frame (or None)."""
        return None

    def factors(self, kin: LegKinematics) -> list[tuple[str, int, np.ndarray]]:
        """Chain factors (side, after, generators (P, 6)); rows of generators over this
        block's parameters (zero rows for parameters a factor does not use)."""
        return []

    def imu_axes(self, kin: LegKinematics) -> np.ndarray | None:
        """(P, 3) IMU-frame rotation axis per parameter (zero rows elsewhere), or None."""
        return None

    def bounds(self, kin: LegKinematics) -> list[tuple[float, float]]:
        """(low, high) of each parameter's physically admissible values, SI units (a
        stiffness is positive, a length within its declared tolerance); default: any
        value. A fit whose value lies outside by more than its noise is set aside."""
        return [(-np.inf, np.inf)] * len(self.parameters(kin))

    # Physics for simulation (optional): an effect that sets `sim_keys` ({key: (kind,
    # default)}, kind "number" or "text") and defines `simulate(self, values, edit) ->
    # dict` can be injected by `collect --effect <name>:key=value,...`; the simulator
    # (`legcal_bench.sim.effects`, which refuses a class with one and not the other) calls
    # it with the parsed values and a `legcal_bench.sim.effects.ModelEdit` (the simulated
    # robot's MJCF to change) and records the dict it returns as the truth.
    sim_keys: dict | None = None


class Restricted(Effect):
    """An effect with only some of its parameters (`keep`, indices into its
    `parameters`); the others are fixed at zero and cost nothing to evaluate. Same name,
    so its columns keep their names (`<effect>.<parameter>`)."""

    def __init__(self, effect: Effect, keep):
        self.effect, self.keep = effect, [int(i) for i in keep]
        self.name, self.summary, self.needs_ft = effect.name, effect.summary, effect.needs_ft

    def parameters(self, kin):
        every = self.effect.parameters(kin)
        return [every[i] for i in self.keep]

    def bounds(self, kin):
        every = self.effect.bounds(kin)
        return [every[i] for i in self.keep]

    def joint_map(self, kin, seg):
        A = self.effect.joint_map(kin, seg)
        return None if A is None else A[:, :, self.keep]

    def factors(self, kin):
        return [(side, after, np.asarray(g)[self.keep]) for side, after, g in self.effect.factors(kin)]

    def imu_axes(self, kin):
        ax = self.effect.imu_axes(kin)
        return None if ax is None else np.asarray(ax)[self.keep]


def restricted(model: "EffectModel", columns) -> list[Effect]:
    """The effects of `model` restricted to the parameter columns `columns` (indices of
    the model's columns, the offsets' first); effects left with none are dropped."""
    cols = set(int(c) for c in columns)
    out = []
    for e in model.effects:
        sl = model.slices[e.name]
        keep = [i - sl.start for i in range(sl.start, sl.stop) if i in cols]
        if keep:
            out.append(Restricted(e, keep))
    return out


def registry() -> dict[str, type[Effect]]:
    """Effect classes by name: the entry-point group `legcal_bench.effects`. Read once
    per import path (`sys.path`): scanning the installed distributions costs ~10 ms, and
    a fit asks for its effects many times."""
    return dict(_registry(tuple(sys.path)))


@lru_cache(maxsize=8)
def _registry(path: tuple[str, ...]) -> tuple[tuple[str, type[Effect]], ...]:
    from importlib.metadata import entry_points

    return tuple((ep.name, ep.load()) for ep in entry_points(group=ENTRY_POINT_GROUP))


def load_effects(names) -> list[Effect]:
    reg = registry()
    out = []
    for n in names:
        if n not in reg:
            raise CalibrationError(f"--with-effects {n!r}: unknown effect; installed: {', '.join(sorted(reg))} "
                                   f"(entry-point group {ENTRY_POINT_GROUP})")
        out.append(reg[n]())
    if len({e.name for e in out}) != len(out):
        raise CalibrationError(f"--with-effects {list(names)}: an effect is named twice")
    return out


@dataclass
class EffectModel:
    """Effects compiled into one parameter layout: the first `n_offsets` columns the
    offsets (one per leg joint), then each effect's block in order (`slices`)."""

    kin: LegKinematics
    effects: list[Effect]
    names: list[str] = field(default_factory=list)  # per column: joint names, then "<effect>.<parameter>"
    units: list[str] = field(default_factory=list)

    def __post_init__(self):
        self.names = list(self.kin.legmap.joint_names)  # one per column: the offsets, then the effects'
        self.n_offsets = self.kin.legmap.n_joints
        self.units = ["rad"] * self.n_offsets
        self.slices, col = {}, self.n_offsets
        factors, imu = [], []
        for e in self.effects:
            params = e.parameters(self.kin)
            if not params:
                raise CalibrationError(f"effect {e.name}: it has no parameters on this robot")
            sl = slice(col, col + len(params))
            self.slices[e.name] = sl
            self.names += [f"{e.name}.{p}" for p, _ in params]
            self.units += [u for _, u in params]
            for side, after, gens in e.factors(self.kin):
                gens = np.asarray(gens, dtype=float)
                used = np.flatnonzero(np.abs(gens).sum(axis=1) > 0)
                factors.append(Factor(side, after, gens[used], np.arange(sl.start, sl.stop)[used] - self.n_offsets))
            ax = e.imu_axes(self.kin)
            if ax is not None:
                imu.append((sl, np.asarray(ax, dtype=float)))
            col = sl.stop
        self.n = col
        if factors and self.kin.linkages:
            raise LegMapError(f"{self.kin.legmap.source or self.kin.legmap.name}: geometry effects "
                              f"({', '.join(e.name for e in self.effects if e.factors(self.kin))}) move the legs' "
                              "joints, and this robot's linkage ankles are read through their motors: the model gap "
                              "does not fit geometry on linkage ankles yet; try the effects of sensors and joints")
        self.chain = FactorChain(self.kin, factors, self.n - self.n_offsets) if factors else None
        self.imu = imu

    @property
    def blocks(self) -> list[tuple[str, int]]:
        return [(e.name, self.slices[e.name].stop - self.slices[e.name].start) for e in self.effects]

    def vector(self, x: dict) -> np.ndarray:
        """The packed (n,) vector of block values `x` (missing effect blocks: zero)."""
        v = np.zeros(self.n)
        v[:self.n_offsets] = x[OFFSETS]
        for e in self.effects:
            if e.name in x:
                v[self.slices[e.name]] = x[e.name]
        return v

    def values(self, v: np.ndarray) -> dict[str, np.ndarray]:
        """The packed (n,) vector `v` -> block name -> values (`vector`'s inverse)."""
        out = {OFFSETS: v[:self.n_offsets]}
        for e in self.effects:
            out[e.name] = v[self.slices[e.name]]
        return out

    def split(self, J: np.ndarray) -> dict[str, np.ndarray]:
        """Jacobian (rows, n) -> block name -> columns."""
        out = {OFFSETS: J[:, :self.n_offsets]}
        for e in self.effects:
            out[e.name] = J[:, self.slices[e.name]]
        return out

    def imu_rotation(self, v: np.ndarray):
        """(Q (3, 3), W (3, n)): the correction of the IMU's vertical in the pelvis frame,
        up = Q up_measured, and its right-perturbation axes per column (zero elsewhere)."""
        W = np.zeros((3, self.n))
        if not self.imu:
            return np.eye(3), W
        R_BI = self.kin.R_BI
        phi = np.zeros(3)
        for sl, ax in self.imu:
            phi += v[sl] @ ax

        Q = R_BI @ Exp(np.r_[0, 0, 0, phi])[:3, :3] @ R_BI.T
        Jso3 = Jr(np.r_[0, 0, 0, phi])[3:, 3:]
        for sl, ax in self.imu:
            W[:, sl] = R_BI @ Jso3 @ ax.T
        return Q, W


@dataclass(frozen=True)
class ExtendedKinematics:
    """A segment's kinematics at one parameter vector, Jacobians over all n columns."""

    C: np.ndarray  # (N, 4, 4)
    G: np.ndarray  # (N, 6, n)
    p_L: np.ndarray
    p_R: np.ndarray
    R_L: np.ndarray
    R_R: np.ndarray
    JL: np.ndarray  # (N, 6, n) LOCAL left sole Jacobian over all columns
    JR: np.ndarray
    imu_Q: np.ndarray  # (3, 3)
    imu_W: np.ndarray  # (3, n)


class EffectSegment:
    """A contact segment's kinematics with effects; the terms' segment interface
    (`state`, `split`, `blocks`) like `SegmentKinematics`."""

    def __init__(self, model: EffectModel, seg: SegmentData):
        self.model, self.data = model, seg
        self.kin, self.q_enc = model.kin, seg.q_enc
        self.blocks = (OFFSETS, *[e.name for e in model.effects])
        maps = []
        for e in model.effects:
            A = e.joint_map(model.kin, seg)
            if A is not None:
                maps.append((model.slices[e.name], np.asarray(A, dtype=float)))
        self.maps = maps
        self._v: np.ndarray | None = None
        self._ek: ExtendedKinematics | None = None

    def split(self, J: np.ndarray) -> dict[str, np.ndarray]:
        return self.model.split(J)

    def state(self, x: dict) -> ExtendedKinematics:
        v = self.model.vector(x)
        if self._v is None or not np.array_equal(self._v, v):
            self._ek = self._evaluate(v)
            self._v = v.copy()
        return self._ek

    def _evaluate(self, v: np.ndarray) -> ExtendedKinematics:
        m, n_cols, n_q = self.model, self.model.n, self.model.n_offsets
        Q = self.q_enc + v[:n_q]
        A_full = np.zeros((len(Q), n_q, n_cols))
        A_full[:, np.arange(n_q), np.arange(n_q)] = 1.0
        for sl, A in self.maps:
            Q = Q + np.einsum("njp,p->nj", A, v[sl])
            A_full[:, :, sl] += A
        if m.chain is None:
            fk = frame_kinematics(self.kin, Q)
            TL = _pose(fk.R_L, fk.p_L)
            TR = _pose(fk.R_R, fk.p_R)
            JqL, JqR, JpL, JpR = fk.J_L, fk.J_R, None, None
        else:
            legs = m.chain.legs(Q, v[n_q:])
            (TL, JqL, JpL), (TR, JqR, JpR) = legs["left"], legs["right"]
        JL = JqL @ A_full[:, self.kin.legmap.leg_slice("left"), :]
        JR = JqR @ A_full[:, self.kin.legmap.leg_slice("right"), :]
        if JpL is not None:
            JL[:, :, n_q:] += JpL
            JR[:, :, n_q:] += JpR
        C = inverse(TL) @ TR
        G = JR - adjoint(inverse(C)) @ JL
        imu_Q, imu_W = m.imu_rotation(v)
        return ExtendedKinematics(C, G, TL[:, :3, 3], TR[:, :3, 3], TL[:, :3, :3], TR[:, :3, :3], JL, JR, imu_Q,
                                  imu_W)


def _pose(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.zeros((len(R), 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, p, 1.0
    return T


def joint_loads(kin: LegKinematics, q_enc: np.ndarray, ft: np.ndarray, up_B: np.ndarray) -> np.ndarray:
    """(N, n) the load each leg joint carries from the links below it, in the sense that
    bends it positively (a series spring of compliance c deflects by c tau): the ankle
    force/torque wrench w (as the sensor reports it: the force the foot and what it
    touches exert on the leg above, in the sensor's frame) mapped through the LOCAL
    Jacobian of the F/T frame at the angles `q_enc`, tau = -J^T w, plus the weight of the
    links between the joint and the sensor (the sensor cannot see them), from the model's
    masses and the IMU's vertical `up_B` (N, 3, pelvis frame). Batched over frames on
    the legs' products of exponentials."""
    fk = frame_kinematics(kin, q_enc)
    T = kin.T_sole_ft
    out = np.empty((len(q_enc), kin.legmap.n_joints))
    m = kin.model
    weight = -9.81 * np.asarray(up_B, dtype=float)  # gravity per unit mass, pelvis frame (N, 3)
    for i, s in enumerate(SIDES):
        J_ft = adjoint(inverse(T[s])) @ (fk.J_L, fk.J_R)[i]  # (N, 6, leg joints)
        out[:, kin.legmap.leg_slice(s)] = -np.einsum("nrj,nr->nj", J_ft, ft[:, i])
        poe = kin.poe[s]
        chain = [int(kin.leg_joint_ids[c]) for c in poe.cols]
        support = [int(j) for j in m.supports[m.frames[kin.ft_frame[s]].parentJoint]]
        below = support[support.index(chain[0]):-1]  # leg links up to (not including) the sensor's
        if any(j not in chain for j in below):
            raise LegMapError(f"{kin.legmap.source or kin.legmap.name}: legs.{s}: a joint that is not a leg joint "
                              "sits between the hip and the F/T sensor; loads from the F/T cannot be computed")
        frames, P = [], np.broadcast_to(np.eye(4), (len(q_enc), 4, 4))
        for k in range(len(poe.cols)):  # chain joint k's frame in the pelvis frame, at the angles
            P = P @ poe.M[k] @ Exp(poe.S[k][None] * q_enc[:, poe.cols[k], None])
            frames.append(P)
        com = {}  # chain index -> (mass, (N, 3) centre of mass)
        for j in below:
            k, inertia = chain.index(j), m.inertias[j]
            com[k] = (inertia.mass, frames[k][:, :3, :3] @ inertia.lever + frames[k][:, :3, 3])
        for k, c in enumerate(poe.cols):
            axis = frames[k][:, :3, :3] @ poe.S[k][3:]
            anchor = frames[k][:, :3, 3]
            moment = sum((mass * np.cross(p - anchor, weight) for kk, (mass, p) in com.items() if kk >= k),
                         np.zeros((len(q_enc), 3)))
            out[:, c] += np.einsum("ni,ni->n", axis, moment)
    return out
