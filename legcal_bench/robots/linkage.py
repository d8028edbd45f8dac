"""Two-motor parallel-linkage ankles: the encoders on two motors, the ankle's pitch and
roll turned through cranks and rods.

Neither Pinocchio nor MuJoCo's serial joints carry the linkage, so the leg map gives it
(`legs.<side>.linkage`, `legcal_bench.robots.legmap.LinkageMotor`): per motor, a crank
turning about `axis` through `pivot` in the shank frame (the body the ankle's first joint's
body hangs from), its arm `crank` at the encoder's zero, and a rod of length `rod` from the
crank's tip to `foot` in the foot frame (the body of the ankle's second joint).

With the ankle's joints at q = (q1, q2) in chain order, the rod's foot end is p(q) =
E1(q1) E2(q2) x0 in the shank frame (Ej the rotation of joint j about its axis at q = 0, x0
the attachment at q = 0), and the crank's tip t(m) = pivot + R(axis, m) crank. Each motor's
loop closes where |p(q) - t(m)| = rod, which for m is A cos m + B sin m = C: the motors'
angles from the joints' in closed form (`motors`; one branch, the one nearest the encoder's
zero at q = 0) and the joints' from the motors' by Newton on that (`joints`), with the
Jacobians by implicit differentiation: dm/dq_j = (d . dp/dq_j) / (d . (axis x arm)), d =
p - t, arm = t - pivot; dq/dm its inverse.

Calibration coordinates. A linkage ankle's two leg-map columns hold its motors' encoder
readings (the first ankle joint's column motor 0, the second's motor 1) in recordings, in
calibration and in the offsets: the offsets live where the encoders are. Only the
kinematics maps them to the joints (`legcal_bench.robots.kinematics.frame_kinematics`,
`LegKinematics.joint_angles`), so every calibrator and check works on the motors' angles
without knowing; the simulator moves the joints and its encoders read the motors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from legcal_bench.errors import LegMapError

NEWTON_TOL = 1e-12  # rad: a Newton step this small has converged (quadratically: the next is ~1e-16)
NEWTON_MAX_ITER = 40
POLISH_STEPS = 1  # Newton steps after every row converged (the next is at rounding)


def _rotations(axis: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations by angles t (N,) about the unit `axis` (Rodrigues)."""
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(t)[:, None, None] * K + (1.0 - np.cos(t))[:, None, None] * (K @ K)


@dataclass(frozen=True)
class AnkleLinkage:
    """One leg's linkage ankle, everything in its shank frame at the ankle's zero."""

    side: str
    cols: tuple[int, int]  # the ankle's two columns in the leg-map vector, chain order
    axes: np.ndarray  # (2, 3) the ankle joints' unit axes
    points: np.ndarray  # (2, 3) a point on each axis
    x0: np.ndarray  # (2, 3) each rod's foot end at q = 0
    pivot: np.ndarray  # (2, 3)
    motor_axis: np.ndarray  # (2, 3) unit
    crank: np.ndarray  # (2, 3) crank arms at the encoders' zero
    rod: np.ndarray  # (2,)
    branch: np.ndarray  # (2,) +-1: the assembly (the root nearest the encoder's zero at q = 0)
    shank_body: str = ""
    foot_body: str = ""

    @classmethod
    def build(cls, side: str, cols: tuple[int, int], motors, axes, points, T_shank_foot: np.ndarray,
              shank_body: str, foot_body: str, where: str) -> AnkleLinkage:
        foot = np.array([mo.foot for mo in motors])
        x0 = foot @ T_shank_foot[:3, :3].T + T_shank_foot[:3, 3]
        lk = cls(side, cols, np.asarray(axes, dtype=float), np.asarray(points, dtype=float), x0,
                 np.array([mo.pivot for mo in motors]), np.array([mo.axis for mo in motors]),
                 np.array([mo.crank for mo in motors]), np.array([mo.rod for mo in motors]), np.ones(2),
                 shank_body, foot_body)
        A, B, C = lk._loop(lk.x0[None])
        rho = np.hypot(A, B)[0]
        c = C[0] / rho
        for i in range(2):
            if not abs(c[i]) < 1.0 - 1e-12:
                reach = np.linalg.norm(lk.x0[i] - lk.pivot[i])
                raise LegMapError(
                    f"{where}.motors[{i}]: the rod ({lk.rod[i]:.4f} m) cannot close the loop at the ankle's zero: "
                    f"its foot end is {reach:.4f} m from the pivot and the crank {np.linalg.norm(lk.crank[i]):.4f} m "
                    f"long; check rod, pivot and foot (foot in the frame of body '{foot_body}', the rest in the "
                    f"shank body '{shank_body}'s)")
        phi = np.arctan2(B[0], A[0])
        roots = np.stack([phi + np.arccos(c), phi - np.arccos(c)])
        roots = np.angle(np.exp(1j * roots))
        branch = np.where(np.abs(roots[0]) <= np.abs(roots[1]), 1.0, -1.0)
        object.__setattr__(lk, "branch", branch)
        J = lk.motor_jacobian(np.zeros((1, 2)))[1][0]
        if not np.all(np.isfinite(J)) or abs(np.linalg.det(J)) < 1e-6 * np.abs(J).max() ** 2:
            raise LegMapError(f"{where}: the two motors do not turn the ankle's two joints independently at its zero "
                              f"(dm/dq = {np.round(J, 4).tolist()}): the rods must act on the foot at different "
                              "points, one pair turning pitch, the other roll")
        return lk

    # ------------------------------------------------------------ geometry
    def _feet(self, q: np.ndarray):
        """The rods' foot ends p (N, 2 motors, 3) and dp/dq (N, 2 motors, 3, 2 joints)."""
        R1, R2 = _rotations(self.axes[0], q[:, 0]), _rotations(self.axes[1], q[:, 1])
        r1, r2 = self.points
        x = np.einsum("nij,mj->nmi", R2, self.x0 - r2) + r2  # E2(q2) x0
        p = np.einsum("nij,nmj->nmi", R1, x - r1) + r1  # E1(q1) E2(q2) x0
        w2 = R1 @ self.axes[1]  # joint 2's axis after joint 1
        o2 = R1 @ (r2 - r1) + r1
        dp = np.stack([np.cross(self.axes[0], p - r1), np.cross(w2[:, None], p - o2[:, None])], axis=-1)
        return p, dp

    def _loop(self, p: np.ndarray):
        """A cos m + B sin m = C per motor, (N, 2) each, for rod foot ends p (N, 2, 3)."""
        w = p - self.pivot
        ku = np.cross(self.motor_axis, self.crank)
        A = 2.0 * np.einsum("nmi,mi->nm", w, self.crank)
        B = 2.0 * np.einsum("nmi,mi->nm", w, ku)
        C = np.einsum("nmi,nmi->nm", w, w) + np.einsum("mi,mi->m", self.crank, self.crank) - self.rod ** 2
        return A, B, C

    def motor_jacobian(self, q: np.ndarray):
        """Motors' angles (N, 2) at the joints' angles q (N, 2) and dm/dq (N, 2, 2); NaN
        where the loop cannot close (out of the linkage's reach)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        p, dp = self._feet(q)
        A, B, C = self._loop(p)
        with np.errstate(invalid="ignore"):
            m = np.arctan2(B, A) + self.branch * np.arccos(C / np.hypot(A, B))
        m = np.angle(np.exp(1j * m))
        cm, sm = np.cos(m)[..., None], np.sin(m)[..., None]
        ku = np.cross(self.motor_axis, self.crank)
        arm = cm * self.crank + sm * ku  # R(axis, m) crank
        d = p - (self.pivot + arm)
        with np.errstate(divide="ignore", invalid="ignore"):
            J = np.einsum("nmi,nmij->nmj", d, dp) / np.einsum("nmi,nmi->nm", d, np.cross(self.motor_axis, arm))[..., None]
        return m, J

    def motors(self, q: np.ndarray) -> np.ndarray:
        """The motors' angles (N, 2) at the ankle joints' (N, 2)."""
        return self.motor_jacobian(q)[0]

    def joints(self, m: np.ndarray):
        """The ankle joints' angles (N, 2) at the motors' (N, 2), and dq/dm (N, 2, 2); NaN
        rows where Newton finds no closure (the linkage cannot reach those motor angles)."""
        m = np.atleast_2d(np.asarray(m, dtype=float))
        m0, J0 = self.motor_jacobian(np.zeros((1, 2)))
        q = np.angle(np.exp(1j * (m - m0))) @ np.linalg.inv(J0[0]).T  # the linear guess
        converged = np.zeros(len(m), dtype=bool)
        polish = 0
        for _ in range(NEWTON_MAX_ITER):
            mq, Jq = self.motor_jacobian(q)
            ok = np.all(np.isfinite(mq), axis=1) & np.all(np.isfinite(Jq), axis=(1, 2))
            r = np.where(ok[:, None], np.angle(np.exp(1j * (mq - m))), 0.0)
            step = np.linalg.solve(np.where(ok[:, None, None], Jq, np.eye(2)), r[..., None])[..., 0]
            q = q - step
            converged = ok & (np.abs(step).max(axis=1) <= NEWTON_TOL)
            if converged.all():
                polish += 1
                if polish > POLISH_STEPS:
                    break
        mq, J = self.motor_jacobian(q)
        good = converged & np.all(np.isfinite(J), axis=(1, 2))
        q[~good] = np.nan
        D = np.linalg.inv(np.where(good[:, None, None], J, np.eye(2)))
        D[~good] = np.nan
        return q, D


def linked_joints(legmap) -> list[str]:
    """The ankle joints a leg map's linkages turn (their columns hold motor angles)."""
    return [j.name for leg in legmap.legs.values() if leg.linkage is not None for j in leg.joints[-2:]]


def linkage_offsets(offsets: dict[str, float], kin) -> dict[str, dict]:
    """What a result's offsets mean at a linkage ankle (`offsets` in the calibration's
    coordinates, name -> rad): per side, which motor each ankle column holds, and the
    joints' angle errors those motor offsets make at the ankle's zero, f(g(0) + dm) - 0."""
    out = {}
    for lk in kin.linkages:
        names = [kin.legmap.joint_names[c] for c in lk.cols]
        dm = np.array([offsets[n] for n in names])
        dq = lk.joints(lk.motors(np.zeros((1, 2))) + dm)[0][0]
        out[lk.side] = {"motors": {n: f"motor {i}" for i, n in enumerate(names)},
                        "joint_offsets_at_zero_rad": {n: float(v) for n, v in zip(names, dq)},
                        "shank_body": lk.shank_body, "foot_body": lk.foot_body}
    return out
