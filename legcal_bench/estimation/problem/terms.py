"""The residual terms calibrators assemble into a `Problem`.

Inter-foot method (the paper's objective, one pair of terms per contact segment):
  InterFootTerm   sqrt(l_f) W (Log(M_s^-1 C_k)), M_s the segment's Fréchet mean
  FlatGroundTerm  sqrt(l_g) W [p_Lz - p_Rz, z_Lx, z_Ly, z_Rx, z_Ry] in the IMU-levelled frame
  TikhonovTerm    sqrt(l_q) W_q . dq                    (prior: curvature, not information)
  KneePriorTerm   sqrt(l_knee) (dq_knee - dq_knee_prior) (prior)
Yamane's method (per frame: a root roll and pitch, plus the shared offsets):
  SoleHeightTerm  w_h (z_kv - mean_v z_kv) over the eight sole corners
  ImuTiltTerm     w_imu (R_k^T e_z - u_k)

Terms of one segment share its batched kinematics through a `SegmentKinematics`, so
forward kinematics runs once per segment and offsets value.
"""

from __future__ import annotations

import numpy as np

from legcal_bench.estimation.problem.problem import Term
from legcal_bench.estimation.problem.residuals import feet_residuals, flat_residuals, flat_residuals_extended
from legcal_bench.geometry.lie import frechet_mean
from legcal_bench.robots.kinematics import FrameKinematics, LegKinematics, frame_kinematics

OFFSETS = "offsets"
TILT = "tilt"  # Yamane's per-frame root roll and pitch


class SegmentKinematics:
    """A segment's encoder frames and their kinematics at the offsets last asked for.
    The terms' segment interface: `blocks`, `state(x)` (kinematics at the block values)
    and `split(J)` (Jacobian columns by block); `legcal_bench.estimation.modelgap.effects.
    EffectSegment` is the same with model-gap effects."""

    blocks = (OFFSETS,)

    def __init__(self, kin: LegKinematics, q_enc: np.ndarray):
        self.kin, self.q_enc = kin, q_enc
        self._dq: np.ndarray | None = None
        self._fk: FrameKinematics | None = None

    def at(self, dq: np.ndarray) -> FrameKinematics:
        if self._dq is None or not np.array_equal(self._dq, dq):
            self._fk = frame_kinematics(self.kin, self.q_enc + dq)
            self._dq = np.array(dq, copy=True)
        return self._fk

    def state(self, x) -> FrameKinematics:
        return self.at(x[OFFSETS])

    def split(self, J: np.ndarray) -> dict[str, np.ndarray]:
        return {OFFSETS: J}


class InterFootTerm(Term):
    """Contact consistency of one segment: 6 rows per frame, (translation, rotation).

    mode "projected": the mean is re-estimated with the offsets (variable projection;
    the Jacobian includes dM/d dq); "fixed": the mean is held (`update_mean` sets it),
    as in the paper's alternation; "both": the fixed mode's rows and Jacobian, and the
    projected Jacobian at the same mean kept in `projected` (one kinematics pass for
    both)."""

    def __init__(self, name: str, seg: SegmentKinematics, weights: np.ndarray, mode: str = "projected"):
        self.name, self.seg, self.w, self.mode = name, seg, np.asarray(weights, dtype=float), mode
        self.blocks = seg.blocks
        self.mean: np.ndarray | None = None
        self.projected: dict[str, np.ndarray] | None = None

    def update_mean(self, x) -> np.ndarray:
        """The segment's Fréchet mean at `x` (block values, or the offsets alone)."""
        x = x if isinstance(x, dict) else {OFFSETS: x}
        self.mean = frechet_mean(self.seg.state(x).C, self.mean, tol=1e-15)
        return self.mean

    def compute(self, x):
        fk = self.seg.state(x)
        if self.mode == "projected":
            self.update_mean(x)
        r, J, *projected = feet_residuals(fk.C, fk.G, self.mean, self.mode)
        if self.mode == "both":
            self.projected = self._weighted(projected[0])
        return (self.w * r).ravel(), self._weighted(J)

    def _weighted(self, J: np.ndarray) -> dict[str, np.ndarray]:
        return self.seg.split((self.w[:, None] * J).reshape(-1, J.shape[-1]))


class FlatGroundTerm(Term):
    """Flat ground against the IMU vertical: 5 rows per frame."""

    def __init__(self, name: str, seg: SegmentKinematics, up_B: np.ndarray, R_WB: np.ndarray, weights: np.ndarray):
        self.name, self.seg, self.up_B, self.R_WB = name, seg, up_B, R_WB
        self.blocks = seg.blocks
        self.w = np.asarray(weights, dtype=float)

    def compute(self, x):
        fk = self.seg.state(x)
        if isinstance(fk, FrameKinematics):
            r, J = flat_residuals(fk, self.up_B, self.R_WB)
        else:
            r, J = flat_residuals_extended(fk, self.up_B, self.R_WB)
        return (self.w * r).ravel(), self.seg.split((self.w[:, None] * J).reshape(-1, J.shape[-1]))


class TikhonovTerm(Term):
    """W_q . dq, already scaled by sqrt(lambda_q): a ridge toward zero offsets."""

    name = "tikhonov"
    blocks = (OFFSETS,)
    data = False

    def __init__(self, weights: np.ndarray):
        self.w = np.asarray(weights, dtype=float)

    def compute(self, x):
        return self.w * x[OFFSETS], {OFFSETS: np.diag(self.w)}


class HeldParametersTerm(Term):
    """weight * p_i for the effect parameters the data cannot determine (`held`, indices
    into an `EffectModel`'s columns): they stay at zero (a prior, not information)."""

    name = "held_parameters"
    data = False

    def __init__(self, model, held, weight: float = 1e8):
        self.model, self.held, self.weight = model, list(held), float(weight)
        self.blocks = tuple(e.name for e in model.effects)

    def compute(self, x):
        v = self.model.vector({OFFSETS: np.zeros(self.model.n_offsets), **x})
        rows = self.weight * v[self.held]
        J = np.zeros((len(self.held), self.model.n))
        J[np.arange(len(self.held)), self.held] = self.weight
        split = self.model.split(J)
        split.pop(OFFSETS)
        return rows, split


class KneePriorTerm(Term):
    """weight (dq_knee - prior): the straight-leg standing prior on the knee offsets."""

    name = "knee_prior"
    blocks = (OFFSETS,)
    data = False

    def __init__(self, knees: list[int], prior: np.ndarray, weight: float):
        self.knees, self.prior, self.weight = list(knees), np.asarray(prior, dtype=float), float(weight)

    def compute(self, x):
        J = np.zeros((len(self.knees), len(x[OFFSETS])))
        J[np.arange(len(self.knees)), self.knees] = self.weight
        return self.weight * (x[OFFSETS][self.knees] - self.prior), {OFFSETS: J}


def _tilt_up(roll: np.ndarray, pitch: np.ndarray):
    """The third row of R = R_y(pitch) R_x(roll), R^T e_z (the model's up vector in the
    tilted frame), and its partial derivatives by roll and pitch, batched (N, 3) each:
    the only rows of R the sole and IMU terms use, in closed form."""
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    up = np.stack([-sp, cp * sr, cp * cr], axis=1)
    d_roll = np.stack([np.zeros_like(cr), cp * cr, -cp * sr], axis=1)
    d_pitch = np.stack([-cp, -sp * sr, -sp * cr], axis=1)
    return up, d_roll, d_pitch


class SoleHeightTerm(Term):
    """Yamane's sole term: the eight corner heights, centred per frame (8 rows per frame)."""

    name = "sole_heights"
    blocks = (OFFSETS, TILT)
    rows_per_frame = 8

    def __init__(self, kin: LegKinematics, q_enc: np.ndarray, weight: float):
        self.seg = SegmentKinematics(kin, q_enc)
        self.legmap = kin.legmap
        self.n_frames, self.weight = len(q_enc), float(weight)
        self.c = np.vstack([kin.corners["left"], kin.corners["right"]]).reshape(2, 4, 3)  # corners, sole frames

    def compute(self, x):
        n = self.n_frames
        ang = x[TILT]
        g, dg_roll, dg_pitch = _tilt_up(ang[:, 0], ang[:, 1])
        fk = self.seg.at(x[OFFSETS])
        # Corner positions in the pelvis frame, P = R c + p, per foot (n, 4, 3).
        P = np.concatenate([self.c[0] @ np.swapaxes(fk.R_L, 1, 2) + fk.p_L[:, None],
                            self.c[1] @ np.swapaxes(fk.R_R, 1, 2) + fk.p_R[:, None]], axis=1)
        # Corner velocity: R (J_v - [c]x J_w); only its vertical component in the tilted
        # frame matters: g = R_k^T e_z (the third row of R_k), so dz = (g^T R_foot) (J_v - [c]x J_w).
        z = (P @ g[:, :, None])[..., 0]
        r = self.weight * (z - z.mean(axis=1, keepdims=True))
        Jz = np.zeros((n, 8, self.legmap.n_joints))
        for side, (Rf, Jf) in enumerate(((fk.R_L, fk.J_L), (fk.R_R, fk.J_R))):
            a = (g[:, None, :] @ Rf)[:, 0]  # (n, 3): e_z of the tilted frame, in the sole frame
            # a . (J_v - c x J_w) = a . J_v - (a x c) . J_w ... as rows over the 4 corners.
            aJv = (a[:, None, :] @ Jf[:, :3])  # (n, 1, leg joints)
            axc = np.cross(a[:, None, :], self.c[side][None])  # (n, 4, 3)
            Jz[:, 4 * side:4 * side + 4, self.legmap.leg_slice(side)] = aJv - axc @ Jf[:, 3:]
        J_dq = self.weight * (Jz - Jz.mean(axis=1, keepdims=True))
        J_tilt = np.zeros((n, 8, 2))
        for j, dg in enumerate((dg_roll, dg_pitch)):
            dz = (P @ dg[:, :, None])[..., 0]
            J_tilt[:, :, j] = self.weight * (dz - dz.mean(axis=1, keepdims=True))
        return r.ravel(), {OFFSETS: J_dq, TILT: J_tilt}


class ImuTiltTerm(Term):
    """Yamane's IMU term: the model's up vector R_k^T e_z against the IMU's (3 rows per frame)."""

    name = "imu_tilt"
    blocks = (TILT,)
    rows_per_frame = 3

    def __init__(self, up_B: np.ndarray, weight: float):
        self.up_B, self.n_frames, self.weight = up_B, len(up_B), float(weight)

    def compute(self, x):
        ang = x[TILT]
        g, dg_roll, dg_pitch = _tilt_up(ang[:, 0], ang[:, 1])
        r = self.weight * (g - self.up_B)  # R^T e_z, as rows
        J = np.stack([self.weight * dg_roll, self.weight * dg_pitch], axis=2)  # (n, 3, 2)
        return r.ravel(), {TILT: J}
