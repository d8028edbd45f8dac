"""Leg kinematics on Pinocchio, loaded from the robot's MJCF (the single source of truth).

Every pose here is relative to the pelvis (base) frame B, so the floating base never
matters: T_BF(q) is the sole pose in the pelvis frame, and the inter-foot transform is
C(q) = T_BFL(q)^-1 T_BFR(q), the pose of the right sole in the left-sole frame.
`q` is always the 12-vector of leg angles in leg-map order (left then right).

`frame_kinematics` is the batched path (all frames of a recording at once) that the
estimators, the scores and the env's reward use; the per-posture methods of
`LegKinematics` serve IK and single postures. The pitch sum of a leg,
s = dq_hip_pitch + dq_knee + dq_ankle_pitch (each signed by its axis direction), is
what orientation alone observes of the parallel pitch chain (`pitch_sums`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares

from legcal_bench.errors import IKError, LegMapError
from legcal_bench.geometry.lie import adjoint, inverse
from legcal_bench.geometry.poses import pose_xyz_rpy, posture_pose
from legcal_bench.robots.design import PITCH_ROLES
from legcal_bench.robots.legmap import SIDES, FrameSpec, LegMap


@dataclass(frozen=True)
class RobotDims:
    """Sizes derived from the model, used to scale stances to any robot."""

    leg_length: float  # vertical pelvis-to-sole distance with all leg joints at zero
    foot_y: float  # lateral sole position at zero (left, positive)
    foot_x: float  # fore-aft sole position at zero
    sole_length: float
    sole_width: float


class LegKinematics:
    """Forward kinematics, sole Jacobians and closed-chain IK for one robot."""

    IK_TOL = 1e-13

    def __init__(self, legmap: LegMap):
        self.legmap = legmap
        try:
            self.model = pin.buildModelFromMJCF(str(legmap.mjcf))
        except Exception as e:  # noqa: BLE001 - Pinocchio raises bare RuntimeErrors
            raise LegMapError(f"Pinocchio could not load {legmap.mjcf}: {e}") from None
        m = self.model
        self.q_neutral = pin.neutral(m)
        self.leg_q_idx = np.empty(12, dtype=int)
        self.leg_v_idx = np.empty(12, dtype=int)
        for i, name in enumerate(legmap.joint_names):
            if not m.existJointName(name):
                raise LegMapError(f"{legmap.source}: leg joint '{name}' is not in {legmap.mjcf}")
            j = m.joints[m.getJointId(name)]
            if j.nq != 1 or j.nv != 1:
                raise LegMapError(f"{legmap.source}: leg joint '{name}' is not a 1-DoF joint")
            self.leg_q_idx[i], self.leg_v_idx[i] = j.idx_q, j.idx_v
        for name, angle in legmap.held_joints_rad.items():
            if not m.existJointName(name):
                raise LegMapError(f"{legmap.source}: held joint '{name}' is not in {legmap.mjcf}")
            self.q_neutral[m.joints[m.getJointId(name)].idx_q] = angle
        if not m.existFrame(legmap.pelvis):
            raise LegMapError(f"{legmap.source}: pelvis body '{legmap.pelvis}' is not in {legmap.mjcf}")
        self.pelvis_frame = m.getFrameId(legmap.pelvis)
        self.sole_frame = {s: self._add_frame(f"legcal_{s}_sole", legmap.legs[s].sole, f"legs.{s}.sole")
                           for s in SIDES}
        self.imu_frame = self._add_frame("legcal_imu", legmap.imu, "imu")
        self.data = m.createData()
        self.corners = {s: np.array([legmap.legs[s].corners[c] for c in legmap.legs[s].corners]) for s in SIDES}
        self.leg_cols = {"left": np.arange(6), "right": np.arange(6, 12)}
        lower = m.lowerPositionLimit[self.leg_q_idx]
        upper = m.upperPositionLimit[self.leg_q_idx]
        finite = np.isfinite(lower) & np.isfinite(upper) & (upper > lower)
        self.q_lower = np.where(finite, lower, -np.pi)
        self.q_upper = np.where(finite, upper, np.pi)

    def _add_frame(self, name: str, spec: FrameSpec, where: str) -> int:
        m = self.model
        if spec.site is not None:
            if not m.existFrame(spec.site):
                raise LegMapError(f"{self.legmap.source}: {where}.site '{spec.site}' is not a site in {self.legmap.mjcf}")
            return m.getFrameId(spec.site)
        if not m.existFrame(spec.body):
            raise LegMapError(f"{self.legmap.source}: {where}.body '{spec.body}' is not a body in {self.legmap.mjcf}")
        body = m.frames[m.getFrameId(spec.body)]
        placement = body.placement * pose_xyz_rpy(spec.pos, spec.rpy)
        return m.addFrame(pin.Frame(name, body.parentJoint, placement, pin.FrameType.OP_FRAME))

    # ---------------------------------------------------------------- forward
    def q_full(self, q: np.ndarray) -> np.ndarray:
        qf = self.q_neutral.copy()
        qf[self.leg_q_idx] = q
        return qf

    def _fk(self, q: np.ndarray) -> None:
        pin.framesForwardKinematics(self.model, self.data, self.q_full(q))

    def _rel(self, frame: int) -> pin.SE3:
        return self.data.oMf[self.pelvis_frame].actInv(self.data.oMf[frame])

    def sole_poses(self, q: np.ndarray) -> tuple[pin.SE3, pin.SE3]:
        """(T_BFL, T_BFR): left and right sole poses in the pelvis frame."""
        self._fk(q)
        return self._rel(self.sole_frame["left"]), self._rel(self.sole_frame["right"])

    def inter_foot(self, q: np.ndarray) -> pin.SE3:
        left, right = self.sole_poses(q)
        return left.actInv(right)

    def imu_pose(self, q: np.ndarray) -> pin.SE3:
        self._fk(q)
        return self._rel(self.imu_frame)

    @cached_property
    def R_BI(self) -> np.ndarray:
        """Rotation of the (nominal) IMU frame in the pelvis frame (the IMU frame's one
        definition). The IMU is on no leg, so it does not depend on the leg angles."""
        return self.imu_pose(np.zeros(12)).rotation.copy()

    def com(self, q: np.ndarray) -> np.ndarray:
        """Centre of mass of the whole robot in the pelvis frame."""
        c = pin.centerOfMass(self.model, self.data, self.q_full(q))  # also runs forward kinematics
        pin.updateFramePlacements(self.model, self.data)
        return self.data.oMf[self.pelvis_frame].actInv(c)

    def joint_axes(self, q: np.ndarray | None = None) -> np.ndarray:
        """(12, 3) leg joint axes in the pelvis frame (at q, default all zeros)."""
        qf = self.q_full(np.zeros(12) if q is None else q)
        pin.computeJointJacobians(self.model, self.data, qf)
        pin.updateFramePlacements(self.model, self.data)
        R_B = self.data.oMf[self.pelvis_frame].rotation
        axes = np.empty((12, 3))
        for i, name in enumerate(self.legmap.joint_names):
            J = pin.getJointJacobian(self.model, self.data, self.model.getJointId(name), pin.WORLD)
            axes[i] = R_B.T @ J[3:, self.leg_v_idx[i]]
        return axes

    def pitch_signs(self) -> np.ndarray:
        """(12,) +-1 for hip pitch, knee and ankle pitch: each axis's direction relative to
        its leg's common pitch axis (the knee's); 0 for the other joints."""
        axes, roles = self.joint_axes(), self.legmap.joint_roles
        signs = np.zeros(12)
        for leg in (range(6), range(6, 12)):
            knee = next(i for i in leg if roles[i] == "knee")
            for i in leg:
                if roles[i] in PITCH_ROLES:
                    signs[i] = np.sign(axes[i] @ axes[knee])
        return signs

    def sole_jacobian(self, side: str, q: np.ndarray) -> np.ndarray:
        """6x6 Jacobian of the sole pose in its own (local) frame w.r.t. that leg's joints."""
        qf = self.q_full(q)
        J = pin.computeFrameJacobian(self.model, self.data, qf, self.sole_frame[side], pin.LOCAL)
        return J[:, self.leg_v_idx[self.leg_cols[side]]]

    # ---------------------------------------------------------------- inverse
    def solve_leg(self, side: str, T_B_sole: pin.SE3, q_init: np.ndarray, max_iter: int = 50) -> np.ndarray:
        """Newton IK for one leg: the 12-vector `q_init` with that leg's joints solved."""
        q = np.array(q_init, dtype=float)
        cols = self.leg_cols[side]
        frame = self.sole_frame[side]
        err_norm = np.inf
        for _ in range(max_iter):
            self._fk(q)
            err = pin.log6(self._rel(frame).actInv(T_B_sole)).vector
            err_norm = float(np.linalg.norm(err))
            if err_norm < self.IK_TOL:
                break
            J = self.sole_jacobian(side, q)
            step = np.linalg.lstsq(J, err, rcond=None)[0]
            scale = min(1.0, 0.5 / max(np.abs(step).max(), 1e-300))  # at most 0.5 rad a step
            q[cols] += scale * step
        if err_norm > 1e-9:
            raise IKError(f"{side} sole pose not reachable (residual {err_norm:.2e})")
        return q

    def solve(self, T_B_left: pin.SE3, T_B_right: pin.SE3, q_init: np.ndarray | None = None,
              check_limits: bool = True) -> np.ndarray:
        """Both legs' angles that put the soles at the given pelvis-frame poses."""
        q = self.q_init() if q_init is None else np.asarray(q_init, dtype=float)
        q = self.solve_leg("left", T_B_left, q)
        q = self.solve_leg("right", T_B_right, q)
        if check_limits:
            bad = (q < self.q_lower - 1e-9) | (q > self.q_upper + 1e-9)
            if bad.any():
                names = [self.legmap.joint_names[i] for i in np.flatnonzero(bad)]
                raise IKError(f"posture needs joints beyond their limits: {names}")
        return q

    def q_init(self) -> np.ndarray:
        """A mildly bent-knee seed in the middle of the joint ranges (IK starting point)."""
        q = np.clip(np.zeros(12), self.q_lower, self.q_upper)
        roles = self.legmap.joint_roles
        for i, r in enumerate(roles):
            bend = {"hip_pitch": -0.3, "knee": 0.6, "ankle_pitch": -0.3}.get(r, 0.0)
            q[i] = np.clip(q[i] + bend, self.q_lower[i], self.q_upper[i])
        return q

    @cached_property
    def dims(self) -> RobotDims:
        left, right = self.sole_poses(np.zeros(12))
        c = self.corners["left"]
        return RobotDims(
            leg_length=float(-(left.translation[2] + right.translation[2]) / 2),
            foot_y=float((left.translation[1] - right.translation[1]) / 2),
            foot_x=float((left.translation[0] + right.translation[0]) / 2),
            sole_length=float(c[:, 0].max() - c[:, 0].min()),
            sole_width=float(c[:, 1].max() - c[:, 1].min()),
        )


def solve_standing(kin: LegKinematics, T_W_left: pin.SE3, T_W_right: pin.SE3, posture0: np.ndarray,
                   knee_angles: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Closed-chain posture with both knees held at given angles (straight-leg standing).

    With a knee fixed each leg keeps five joints, so the pelvis height and roll are
    freed: twelve unknowns for the twelve sole-pose equations. Returns (posture, q).
    """
    roles = kin.legmap.joint_roles
    knees = [i for i, r in enumerate(roles) if r == "knee"]
    others = [i for i in range(12) if i not in knees]

    def unpack(u):
        posture = np.array(posture0, dtype=float)
        posture[2], posture[3] = u[0], u[1]
        q = np.empty(12)
        q[knees] = knee_angles
        q[others] = u[2:]
        return posture, q

    def residual(u):
        posture, q = unpack(u)
        T_WB = posture_pose(posture)
        left, right = kin.sole_poses(q)
        return np.concatenate([pin.log6((T_WB * left).actInv(T_W_left)).vector,
                               pin.log6((T_WB * right).actInv(T_W_right)).vector])

    # Seed: the bent-knee IK solution at the starting posture, knees then snapped.
    seed = np.array(posture0, dtype=float)
    seed[2] -= 0.03 * kin.dims.leg_length  # straight legs are singular; start bent
    T_WB = posture_pose(seed)
    q0 = kin.solve(T_WB.actInv(T_W_left), T_WB.actInv(T_W_right), check_limits=False)
    u0 = np.concatenate([[seed[2], seed[3]], q0[others]])
    sol = least_squares(residual, u0, xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200)
    if np.linalg.norm(sol.fun) > 1e-10:
        raise IKError(f"no straight-leg standing posture for these sole placements (residual {np.linalg.norm(sol.fun):.1e})")
    return unpack(sol.x)


def pitch_sums(dq: np.ndarray, signs: np.ndarray) -> dict[str, float]:
    """Per-leg pitch sums s_L, s_R and s_R - s_L of an offset vector (`signs` from
    `LegKinematics.pitch_signs`)."""
    left, right = float(signs[:6] @ dq[:6]), float(signs[6:] @ dq[6:])
    return {"left": left, "right": right, "right_minus_left": right - left}


@dataclass
class FrameKinematics:
    """Per-frame kinematics (batched arrays) of N leg configurations."""

    C: np.ndarray  # (N, 4, 4) inter-foot transforms, homogeneous
    G: np.ndarray  # (N, 6, 12) right-perturbation Jacobian of C w.r.t. the 12 leg angles
    p_L: np.ndarray  # (N, 3) sole positions in the pelvis frame
    p_R: np.ndarray
    R_L: np.ndarray  # (N, 3, 3) sole rotations in the pelvis frame
    R_R: np.ndarray
    J_L: np.ndarray  # (N, 6, 6) local sole Jacobians w.r.t. the leg's own joints
    J_R: np.ndarray


def frame_kinematics(kin: LegKinematics, Q: np.ndarray) -> FrameKinematics:
    """Pinocchio forward kinematics and sole Jacobians for each row of Q (N, 12); the
    per-frame loop only calls Pinocchio, the algebra on its outputs is batched.

    A right perturbation of the sole poses, T_BF(q + d) = T_BF Exp(J_F d), perturbs C
    on the right by G d with G = [-Ad(C^-1) J_L | J_R]."""
    m, d = kin.model, kin.data
    fL, fR, fB = kin.sole_frame["left"], kin.sole_frame["right"], kin.pelvis_frame
    n = len(Q)
    HB, HL, HR = np.empty((n, 4, 4)), np.empty((n, 4, 4)), np.empty((n, 4, 4))
    JLf, JRf = np.empty((n, 6, m.nv)), np.empty((n, 6, m.nv))
    qf = kin.q_neutral.copy()
    for k in range(n):
        qf[kin.leg_q_idx] = Q[k]
        pin.computeJointJacobians(m, d, qf)
        pin.updateFramePlacements(m, d)
        HB[k], HL[k], HR[k] = d.oMf[fB].homogeneous, d.oMf[fL].homogeneous, d.oMf[fR].homogeneous
        JLf[k] = pin.getFrameJacobian(m, d, fL, pin.LOCAL)
        JRf[k] = pin.getFrameJacobian(m, d, fR, pin.LOCAL)
    Binv = inverse(HB)
    TL, TR = Binv @ HL, Binv @ HR
    C = inverse(TL) @ TR
    J_L, J_R = JLf[:, :, kin.leg_v_idx[:6]], JRf[:, :, kin.leg_v_idx[6:]]
    G = np.empty((n, 6, 12))
    G[:, :, :6] = -adjoint(inverse(C)) @ J_L
    G[:, :, 6:] = J_R
    return FrameKinematics(C, G, TL[:, :3, 3], TR[:, :3, 3], TL[:, :3, :3], TR[:, :3, :3], J_L, J_R)
