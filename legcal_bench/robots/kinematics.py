"""Leg kinematics on Pinocchio, loaded from the robot's MJCF (the single source of truth).

Every pose here is relative to the pelvis (base) frame B, so the floating base never
matters: T_BF(q) is the sole pose in the pelvis frame, and the inter-foot transform is
C(q) = T_BFL(q)^-1 T_BFR(q), the pose of the right sole in the left-sole frame.
`q` is always the vector of leg angles in leg-map order (left leg, then right): 12 for
legs of six joints, 10 for legs of five (no ankle roll).

A leg of six joints reaches any nearby sole pose, so in double support any pelvis pose
near the stance is a posture. A leg of five reaches only a five-dimensional family of
sole poses: each leg then constrains the pelvis by one equation, and of a commanded
pelvis pose only a nearby reachable pose can be held (`reachable_postures`).

Two paths compute the same kinematics:

* the per-posture methods of `LegKinematics` (`sole_poses`, `sole_jacobian`, `solve`,
  ...) call Pinocchio on one posture (single postures, the simulator's IK);
* the batched path (`frame_kinematics`, `LegKinematics.sole_poses_batch`,
  `LegKinematics.solve_batch`) evaluates all N frames of a recording at once with
  numpy, on each leg's product of exponentials (`LegPoE`) that `LegKinematics`
  extracts from the Pinocchio model when it is built (and checks against it).

The pitch sum of a leg, s = dq_hip_pitch + dq_knee + dq_ankle_pitch (each signed by its
axis direction against the pelvis y axis, one frame for both legs), is what orientation alone observes of the parallel pitch chain
(`pitch_sums`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares

from legcal_bench.errors import IKError, LegMapError
from legcal_bench.geometry.lie import Exp, Jr_inv, Log, adjoint, inverse
from legcal_bench.geometry.poses import pose_xyz_rpy, posture_pose, posture_poses
from legcal_bench.robots.holds import hold_angles
from legcal_bench.robots.design import PITCH_ROLES, ROLE_AXIS, ROLE_AXIS_NAME
from legcal_bench.robots.legmap import SIDES, FrameSpec, LegMap
from legcal_bench.robots.linkage import AnkleLinkage


@dataclass(frozen=True)
class RobotDims:
    """Sizes derived from the model, used to scale stances to any robot."""

    leg_length: float  # vertical pelvis-to-sole distance with all leg joints at zero
    foot_y: float  # lateral sole position at zero (left, positive)
    foot_x: float  # fore-aft sole position at zero
    sole_length: float
    sole_width: float


@dataclass(frozen=True)
class LegPoE:
    """One leg as a product of exponentials, read off the Pinocchio model at the neutral
    configuration (all leg joints at zero, held joints at their angles):

        T_B_sole(q) = M[0] exp(S[0] q_0) M[1] exp(S[1] q_1) ... M[5] exp(S[5] q_5) M_sole

    in chain order (pelvis to foot). M[0] is the first leg joint's frame in the pelvis
    frame, M[k] joint k's frame in joint k-1's (both including any fixed body or held
    joint in between), M_sole the sole frame in the last joint's frame, and S[k] the
    joint's motion subspace [v, w] in its own frame (Pinocchio's LOCAL joint Jacobian
    column). `cols[k]` is the column of q (0..11) that drives chain joint k.
    """

    M: np.ndarray  # (k, 4, 4), k the leg's joints
    S: np.ndarray  # (k, 6)
    M_sole: np.ndarray  # (4, 4)
    cols: np.ndarray  # (k,) int


def _hat(S: np.ndarray) -> np.ndarray:
    """4x4 se(3) matrix of a twist [v, w]."""
    X = np.zeros((4, 4))
    w = S[3:]
    X[:3, :3] = [[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]
    X[:3, 3] = S[:3]
    return X


def _screw_terms(S: np.ndarray) -> tuple[float, bool, np.ndarray]:
    """exp(S q) = I + f1 X1 + f2 X2 + f3 X3 with theta = scale q and constant X:
    a screw (w != 0) has f = (sin theta, 1 - cos theta, theta - sin theta) with X1 = S^,
    X2 = S^2, X3 = S^ + S^3 (the pitch part, zero for a revolute joint), S normalised to
    |w| = 1; a prismatic joint (w = 0) has f = (theta, 0, 0) with |v| = 1.
    Returns (scale, is_screw, X (4, 4, 4): I, X1, X2, X3)."""
    w, v = S[3:], S[:3]
    scale = float(np.linalg.norm(w))
    screw = scale > 1e-12
    if not screw:
        scale = float(np.linalg.norm(v))
    Sn = S / scale
    X1 = _hat(Sn)
    X = np.zeros((4, 4, 4))
    X[0] = np.eye(4)
    X[1] = X1
    if screw:
        X[2] = X1 @ X1
        wn = Sn[3:]
        X[3, :3, 3] = wn * (wn @ Sn[:3])  # S^ + S^3 = [[0, w w^T v], [0, 0]] for |w| = 1
    return scale, screw, X


def _mjcf_model(path) -> pin.Model:
    """Pinocchio's model of an MJCF. Pinocchio follows neither `<include>` (a scene file
    that includes the robot and its sensors) nor `<frame>`: includes are read as MuJoCo's
    dm_control reads them, full precision, frames folded by MuJoCo's compilation
    (`legcal_bench.robots.frames`), and that text is given to Pinocchio."""
    from pathlib import Path

    from legcal_bench.files.scratch import scratch_dir

    from legcal_bench.robots.frames import has_frames, mjcf_element

    path = Path(path)
    text = path.read_text()
    if "<include" not in text and not has_frames(text):
        return pin.buildModelFromMJCF(str(path))
    with scratch_dir("kinematics") as folder:
        flat = Path(folder) / path.name
        flat.write_text(mjcf_element(path).to_xml_string())
        return pin.buildModelFromMJCF(str(flat))


class LegKinematics:
    """Forward kinematics, sole Jacobians and closed-chain IK for one robot."""

    IK_TOL = 1e-13

    def __init__(self, legmap: LegMap):
        self.legmap = legmap
        try:
            if legmap.urdf is not None:  # the URDF's root link as the floating base
                from legcal_bench.robots.urdf import urdf_text

                self.model = pin.buildModelFromXML(urdf_text(legmap.urdf, str(legmap.source or legmap.urdf)),
                                                   pin.JointModelFreeFlyer())
            else:
                self.model = _mjcf_model(legmap.mjcf)
        except Exception as e:  # noqa: BLE001 - Pinocchio raises bare RuntimeErrors
            raise LegMapError(f"Pinocchio could not load {legmap.model_file}: {e}") from None
        m = self.model
        self.q_neutral = pin.neutral(m)
        n = self.n_joints = legmap.n_joints
        self.leg_joints = legmap.leg_joints
        self.leg_q_idx = np.empty(n, dtype=int)
        self.leg_v_idx = np.empty(n, dtype=int)
        self.leg_joint_ids = np.empty(n, dtype=int)
        for i, name in enumerate(legmap.joint_names):
            if not m.existJointName(name):
                raise LegMapError(f"{legmap.source}: leg joint '{name}' is not in {legmap.model_file}")
            j = m.joints[m.getJointId(name)]
            if j.nq != 1 or j.nv != 1:
                raise LegMapError(f"{legmap.source}: leg joint '{name}' is not a 1-DoF joint")
            self.leg_q_idx[i], self.leg_v_idx[i] = j.idx_q, j.idx_v
            self.leg_joint_ids[i] = m.getJointId(name)
        for side in SIDES:  # listed from pelvis to foot: each joint moves the next
            ids = [int(x) for x in self.leg_joint_ids[legmap.leg_slice(side)]]
            order = sorted(ids, key=lambda j: len(m.supports[j]))
            chain = [m.names[j] for j in order]
            is_chain = all(a in m.supports[b] for a, b in zip(order, order[1:]))  # else: the check below names it
            if is_chain and order != ids:
                raise LegMapError(
                    f"{legmap.source}: legs.{side}.joints are listed {[m.names[j] for j in ids]}, but the model's "
                    f"chain from pelvis to foot is {chain}: list the leg's joints in chain order, each with its own "
                    "role (the hip's three in any order, the ankle's two in either)")
        for name, angle in hold_angles(legmap).items():  # every other joint where the simulator holds it
            if not m.existJointName(name):
                raise LegMapError(f"{legmap.source}: held joint '{name}' is not in {legmap.model_file}")
            j = m.joints[m.getJointId(name)]
            if j.nq == 1:
                self.q_neutral[j.idx_q] = angle
        self.pelvis_frame = self._frame_id(legmap.pelvis, "body", "pelvis")
        self.sole_frame = {s: self._add_frame(f"legcal_{s}_sole", legmap.legs[s].sole, f"legs.{s}.sole")
                           for s in SIDES}
        self.imu_frame = self._add_frame("legcal_imu", legmap.imu, "imu")
        # The joints between the pelvis and the IMU (a torso IMU's waist): held in static
        # collection, the IMU's pose in the pelvis frame is the one at their held angles.
        base = set(int(j) for j in m.supports[m.frames[self.pelvis_frame].parentJoint])
        self.imu_joints = tuple(m.names[j] for j in m.supports[m.frames[self.imu_frame].parentJoint]
                                if int(j) not in base)
        stray = [j for j in legmap.imu_through if j not in self.imu_joints]
        if stray:
            raise LegMapError(f"{legmap.source or legmap.name}: imu.through lists {stray}, not between the pelvis and "
                              f"the IMU's body (the joints there: {list(self.imu_joints) or 'none'}); list those")
        self.ft_frame = ({s: self._add_frame(f"legcal_{s}_ft", legmap.legs[s].ft, f"legs.{s}.ft") for s in SIDES}
                         if all(legmap.legs[s].ft is not None for s in SIDES) else {})
        self.data = m.createData()
        self.corners = {s: np.array([legmap.legs[s].corners[c] for c in legmap.legs[s].corners]) for s in SIDES}
        self.leg_cols = {s: np.arange(n)[legmap.leg_slice(s)] for s in SIDES}
        lower = m.lowerPositionLimit[self.leg_q_idx]
        upper = m.upperPositionLimit[self.leg_q_idx]
        finite = np.isfinite(lower) & np.isfinite(upper) & (upper > lower)
        self.limited = finite  # (n,) False: the model gives the joint no range (searched within +-pi)
        self.q_lower = np.where(finite, lower, -np.pi)
        self.q_upper = np.where(finite, upper, np.pi)
        knees = [i for i, r in enumerate(legmap.joint_roles) if r == "knee"]
        ks = legmap.knee_straight_rad
        if not all(self.q_lower[i] - 0.1 <= ks <= self.q_upper[i] + 0.1 for i in knees):
            raise LegMapError(f"{legmap.source or legmap.name}: knee_straight_rad {ks!r} is outside the knees' "
                              f"range [{self.q_lower[knees[0]]:+.3f}, {self.q_upper[knees[0]]:+.3f}] rad: give the "
                              "knee angle (radians) at which the leg is mechanically straight (often 0)")
        self.poe = self._extract_poe()
        self._prepare_batched()
        self.linkages = self._linkages()  # parallel-linkage ankles (their columns: motor angles)

    # MJCF element kind -> Pinocchio frame type (its MJCF parser makes sites operational frames).
    FRAME_TYPES = {"site": pin.FrameType.OP_FRAME, "body": pin.FrameType.BODY}

    def _frame_id(self, name: str, kind: str, field: str) -> int:
        """The Pinocchio frame of MJCF element `name` of `kind` (site or body), looked up by
        type: a body, a joint and a site may share a name in an MJCF."""
        m, ftype = self.model, self.FRAME_TYPES[kind]
        matches = [i for i, f in enumerate(m.frames) if f.name == name and f.type == ftype]
        if not matches:
            others = sorted({str(f.type).split(".")[-1] for f in m.frames if f.name == name})
            also = f" (only a frame of type {', '.join(others)} has that name)" if others else ""
            raise LegMapError(f"{self.legmap.source}: {field} names {kind} '{name}', which is not a {kind} in "
                              f"{self.legmap.model_file}{also}; give the name of a {kind} (or write {field}: "
                              f"{{{'body' if kind == 'site' else 'site'}: ...}})")
        if len(matches) > 1:
            raise LegMapError(f"{self.legmap.source}: {field} names {kind} '{name}', which matches {len(matches)} "
                              f"{kind}s in {self.legmap.model_file}; rename one of them in the model file")
        return matches[0]

    def _add_frame(self, name: str, spec: FrameSpec, where: str) -> int:
        m = self.model
        if spec.site is not None:
            return self._frame_id(spec.site, "site", f"{where}.site")
        body = m.frames[self._frame_id(spec.body, "body", f"{where}.body")]
        placement = body.placement * pose_xyz_rpy(spec.pos, spec.rpy)
        return m.addFrame(pin.Frame(name, body.parentJoint, placement, pin.FrameType.OP_FRAME))

    # ------------------------------------------------- product of exponentials
    def _extract_poe(self) -> dict[str, LegPoE]:
        """Each leg's product of exponentials, from Pinocchio at the neutral configuration
        (leg joints at zero, held joints applied), checked against Pinocchio's forward
        kinematics at a bent configuration."""
        m, d, src = self.model, self.data, self.legmap.source
        names = self.legmap.joint_names
        leg_ids = set(int(j) for j in self.leg_joint_ids)
        moves = {f: set(int(j) for j in m.supports[m.frames[f].parentJoint]) & leg_ids
                 for f in (self.pelvis_frame, self.imu_frame)}
        if moves[self.pelvis_frame]:
            raise LegMapError(f"{src}: the pelvis '{self.legmap.pelvis}' is moved by leg joints "
                              f"{sorted(m.names[j] for j in moves[self.pelvis_frame])}; it must be the base the legs hang from")
        if moves[self.imu_frame]:
            raise LegMapError(f"{src}: the IMU is moved by leg joints {sorted(m.names[j] for j in moves[self.imu_frame])}; "
                              "it must be on the pelvis or the upper body")
        q0 = self.q_full(np.zeros(self.n_joints))
        pin.computeJointJacobians(m, d, q0)
        pin.updateFramePlacements(m, d)
        oMB = d.oMf[self.pelvis_frame]
        poe = {}
        for s in SIDES:
            cols = self.leg_cols[s]
            ids = self.leg_joint_ids[cols]
            support = [int(j) for j in m.supports[m.frames[self.sole_frame[s]].parentJoint]]
            on_chain = set(support) & leg_ids
            missing = [names[c] for c, j in zip(cols, ids) if j not in on_chain]
            foreign = sorted(m.names[j] for j in on_chain - set(int(j) for j in ids))
            if missing or foreign:
                raise LegMapError(f"{src}: legs.{s}: the joints between the pelvis and the {s} sole must be that "
                                  f"leg's {len(cols)} joints (not on the chain: {missing}; from another leg: {foreign})")
            order = np.argsort([support.index(int(j)) for j in ids])  # chain order, pelvis to foot
            chain_ids, chain_cols = [int(j) for j in ids[order]], cols[order]
            M, S = np.empty((len(cols), 4, 4)), np.empty((len(cols), 6))
            prev = oMB
            for k, (jid, c) in enumerate(zip(chain_ids, chain_cols)):
                M[k] = prev.actInv(d.oMi[jid]).homogeneous
                S[k] = pin.getJointJacobian(m, d, jid, pin.LOCAL)[:, self.leg_v_idx[c]]
                if not np.any(S[k]):
                    raise LegMapError(f"{src}: leg joint '{names[c]}' has no motion")
                prev = d.oMi[jid]
            M_sole = prev.actInv(d.oMf[self.sole_frame[s]]).homogeneous
            poe[s] = LegPoE(M, S, M_sole, chain_cols)
        # Pinocchio stays the reference: the chains must reproduce it (e.g. a joint whose
        # motion is not the exponential of a constant twist would not).
        q_test = 0.3 * np.sin(np.arange(1, self.n_joints + 1) * 1.7) + 0.2
        T_poe = self._poe_poses(poe, q_test)
        pin.framesForwardKinematics(m, d, self.q_full(q_test))
        for i, s in enumerate(SIDES):
            T_pin = self._rel(self.sole_frame[s]).homogeneous
            if np.abs(T_poe[i] - T_pin).max() > 1e-9:
                raise LegMapError(f"{src}: legs.{s}: the leg joints are not all screw (revolute or prismatic) "
                                  "joints; the batched kinematics cannot represent this leg")
        return poe

    def _linkages(self) -> tuple[AnkleLinkage, ...]:
        """Each leg map linkage ankle in its shank frame (`legcal_bench.robots.linkage`): the
        ankle joints' axes and the foot's pose at the ankle's zero, from Pinocchio."""
        m, d, out = self.model, self.data, []
        if not any(self.legmap.legs[s].linkage is not None for s in SIDES):
            return ()
        pin.framesForwardKinematics(m, d, self.q_full(np.zeros(self.n_joints)))

        def body_frame(joint: int) -> int:
            return next(i for i, f in enumerate(m.frames) if f.parentJoint == joint and f.type == pin.FrameType.BODY)

        for s in SIDES:
            motors = self.legmap.legs[s].linkage
            if motors is None:
                continue
            where = f"{self.legmap.source or self.legmap.name}: legs.{s}.linkage"
            cols = tuple(int(c) for c in self.poe[s].cols[-2:])
            ids = [int(self.leg_joint_ids[c]) for c in cols]
            ankle = m.frames[body_frame(ids[0])]
            shank = m.frames[ankle.parentFrame].parentFrame if m.frames[ankle.parentFrame].type == pin.FrameType.JOINT \
                else body_frame(int(m.parents[ids[0]]))
            foot = body_frame(ids[1])
            oMs = d.oMf[shank]
            axes, points = [], []
            for k, jid in zip((-2, -1), ids):
                v, w = self.poe[s].S[k][:3], self.poe[s].S[k][3:]
                if abs(np.linalg.norm(w) - 1.0) > 1e-9 or abs(w @ v) > 1e-9:
                    raise LegMapError(f"{where}: ankle joint '{m.names[jid]}' is not a hinge: a linkage turns two "
                                      "hinges")
                T = oMs.actInv(d.oMi[jid])
                axes.append(T.rotation @ w)
                points.append(T.act(np.cross(w, v)))
            out.append(AnkleLinkage.build(s, cols, motors, axes, points, oMs.actInv(d.oMf[foot]).homogeneous,
                                          m.frames[shank].name, m.frames[foot].name, where))
        return tuple(out)

    def joint_angles(self, Q: np.ndarray) -> np.ndarray:
        """Recorded angles (N, n) -> the joints' (N, n): a linkage ankle's two columns hold
        its motors' angles (NaN where the linkage cannot reach them); others are the joints'."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        if not self.linkages:
            return Q
        q = Q.copy()
        for lk in self.linkages:
            q[:, list(lk.cols)] = lk.joints(Q[:, list(lk.cols)])[0]
        return q

    def recorded_angles(self, q: np.ndarray) -> np.ndarray:
        """The joints' angles (N, n) -> what the encoders read at zero offsets (a linkage
        ankle's motors' angles in its columns): `joint_angles`' inverse."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if not self.linkages:
            return q
        Q = q.copy()
        for lk in self.linkages:
            Q[:, list(lk.cols)] = lk.motors(q[:, list(lk.cols)])
        return Q

    @staticmethod
    def _poe_poses(poe: dict[str, LegPoE], q: np.ndarray) -> list[np.ndarray]:
        """Plain (unbatched) evaluation of the products of exponentials, for the check."""
        out = []
        for s in SIDES:
            c = poe[s]
            T = np.eye(4)
            for k in range(len(c.cols)):
                scale, screw, X = _screw_terms(c.S[k])
                t = scale * q[c.cols[k]]
                f = (1.0, np.sin(t), 1 - np.cos(t), t - np.sin(t)) if screw else (1.0, t, 0.0, 0.0)
                T = T @ c.M[k] @ np.tensordot(f, X, axes=1)
            out.append(T @ c.M_sole)
        return out

    def _prepare_batched(self) -> None:
        """Constants of the batched path, which runs on the inverse chain. With
        exp(S q) = sum_i f_i(theta) X_i (`_screw_terms`), A_k^-1 = exp(-S_k q_k) M_k^-1
        = sum_i f_i(-theta) X_i M_k^-1 (the last joint's with M_sole^-1 in front), so all
        A_k^-1 of N frames are one product of (2, k, 16, 4) constants with the (2, k, 4, N)
        coefficients (k the joints per leg)."""
        nk = self.leg_joints
        A_inv = np.empty((2, nk, 4, 4, 4))  # side, chain joint, term, 4x4
        scale, screw = np.empty((2, nk)), np.empty((2, nk), dtype=bool)
        K = np.zeros((2, nk, 6, 4, 4))
        for i, s in enumerate(SIDES):
            c = self.poe[s]
            for k in range(nk):
                scale[i, k], screw[i, k], X = _screw_terms(c.S[k])
                A_inv[i, k] = X @ np.linalg.inv(c.M[k])
                for r in range(3):  # [R v, R w] = K @ H.ravel() for a 4x4 H with rotation R
                    K[i, k, r, r, :3] = c.S[k, :3]
                    K[i, k, 3 + r, r, :3] = c.S[k, 3:]
            A_inv[i, -1] = np.linalg.inv(c.M_sole) @ A_inv[i, -1]
        self._A_inv = A_inv.reshape(2, nk, 4, 16).transpose(0, 1, 3, 2).copy()  # (2, k, 16 entries, 4 terms)
        self._K = K.reshape(2, nk, 6, 16)
        self._M_sole_inv = np.array([np.linalg.inv(self.poe[s].M_sole) for s in SIDES])
        self._scale, self._screw = scale, screw
        self._chain_cols = np.array([self.poe[s].cols for s in SIDES])  # (2, k) columns of q
        # Column k of a leg's LOCAL sole Jacobian sits at position _jac_pos[k] (leg-map order).
        self._jac_pos = np.array([self.poe[s].cols - self.leg_cols[s][0] for s in SIDES])
        self._prismatic = [np.flatnonzero(~screw[i]) for i in range(2)]
        self._workspace: dict[str, np.ndarray] = {}

    _CHUNK = 512  # frames per block of the batched path (its scratch arrays stay small)

    def _work(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """A reusable scratch array (fresh large arrays would cost page faults on every
        call). The batched path is not re-entrant, like Pinocchio's shared `data`."""
        size = math.prod(shape)
        buf = self._workspace.get(name)
        if buf is None or buf.size < size:
            buf = self._workspace[name] = np.empty(size)
        return buf[:size].reshape(shape)

    def _chain_block(self, Q: np.ndarray, sides: list[int], jacobian: bool):
        """Both (or one) legs' kinematics for the rows of Q (n <= _CHUNK, n_joints), with the
        frame index last (4x4 matrices as (4, 4, n)) so each step is a few long vector
        operations. Returns scratch views, valid until the next call: T^-1
        (n_sides, 4, 4, n), the inverse sole poses in the pelvis frame, and (with
        `jacobian`) Y (n_sides, k, 6, n), Y[s, j] the LOCAL sole Jacobian column of chain
        joint j (leg-map column `_jac_pos[s, j]`), k the joints per leg."""
        ns, n, nk = len(sides), len(Q), self.leg_joints
        w = self._work
        theta = w("theta", (ns, nk, n))
        np.negative(Q[:, self._chain_cols[sides]].transpose(1, 2, 0), out=theta)  # the inverse chain: -q
        theta *= self._scale[sides][..., None]
        F = w("F", (ns, nk, 4, n))  # exp(S theta) = sum_i F_i X_i
        F[:, :, 0] = 1.0
        np.sin(theta, out=F[:, :, 1])
        np.cos(theta, out=F[:, :, 2])
        np.subtract(1.0, F[:, :, 2], out=F[:, :, 2])
        np.subtract(theta, F[:, :, 1], out=F[:, :, 3])
        for i, s in enumerate(sides):
            for k in self._prismatic[s]:
                F[i, k, 1], F[i, k, 2:] = theta[i, k], 0.0
        A_inv = w("A_inv", (ns, nk, 16, n))
        np.matmul(self._A_inv[sides], F, out=A_inv)  # A_k^-1 = exp(-S_k q_k) M_k^-1
        A_inv = A_inv.reshape(ns, nk, 4, 4, n)
        # D_k = B_k^-1, where B_k = A_{k+1} ... A_last is joint k's frame -> sole:
        # D_last = M_sole^-1, D_{k-1} = D_k A_k^-1, and T^-1 = D_0 A_0^-1.
        D = w("D", (ns, nk, 4, 4, n))
        D[:, nk - 1] = self._M_sole_inv[sides][..., None]
        D[:, nk - 2] = A_inv[:, nk - 1]
        for k in range(nk - 2, 0, -1):
            _mul_soa(D[:, k], A_inv[:, k], D[:, k - 1])
        T_inv = _mul_soa(D[:, 0], A_inv[:, 0], w("T_inv", (ns, 4, 4, n)))
        if not jacobian:
            return T_inv, None
        # Column k of the LOCAL Jacobian: Ad(D_k) S_k = [R v + p x (R w), R w], (R, p) of D_k.
        Y = w("Y", (ns, nk, 6, n))
        np.matmul(self._K[sides], D.reshape(ns, nk, 16, n), out=Y)  # [R v, R w]
        _add_cross(D[:, :, :3, 3], Y[:, :, 3:], Y[:, :, :3])
        return T_inv, Y

    def _legs_batch(self, Q: np.ndarray, sides: tuple[int, ...] = (0, 1), jacobian: bool = True):
        """Sole poses (n_sides, N, 4, 4) in the pelvis frame and, with `jacobian`, LOCAL
        sole Jacobians (n_sides, N, 6, k) w.r.t. the leg's k joints in leg-map order, for
        the rows of Q (N, n_joints)."""
        Q = np.asarray(Q, dtype=float)
        sides = list(sides)
        n = len(Q)
        T = np.empty((len(sides), n, 4, 4))
        J = np.empty((len(sides), n, 6, self.leg_joints)) if jacobian else None
        for a in range(0, n, self._CHUNK):
            b = min(a + self._CHUNK, n)
            T_inv, Y = self._chain_block(Q[a:b], sides, jacobian)
            T[:, a:b] = _inv_soa(T_inv, self._work("T", T_inv.shape)).transpose(0, 3, 1, 2)
            for i, s in enumerate(sides):
                if jacobian:
                    J[i, a:b][..., self._jac_pos[s]] = Y[i].transpose(2, 1, 0)
        return T, J

    def sole_poses_batch(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(T_BFL, T_BFR), each (N, 4, 4): the sole poses in the pelvis frame for each row
        of Q (N, n_joints), batched (`sole_poses` for one posture)."""
        T, _ = self._legs_batch(np.atleast_2d(Q), jacobian=False)
        return T[0], T[1]

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
    def T_BI(self) -> np.ndarray:
        """(4, 4) pose of the (nominal) IMU frame in the pelvis frame. The IMU is on no leg
        (checked when the model is loaded), so it does not depend on the leg angles."""
        return self.imu_pose(np.zeros(self.n_joints)).homogeneous

    @cached_property
    def T_sole_ft(self) -> dict[str, np.ndarray]:
        """Per side, the (4, 4) pose of the ankle force/torque frame in the sole frame
        (constant: both must ride on the foot, after the last leg joint). Raises
        LegMapError if the leg map has no F/T frames or one sits elsewhere."""
        if not self.ft_frame:
            raise LegMapError(f"{self.legmap.source or self.legmap.name}: no ankle force/torque frames (legs.<side>.ft)")
        m, d = self.model, self.data
        pin.framesForwardKinematics(m, d, self.q_full(np.zeros(self.n_joints)))
        out = {}
        for s in SIDES:
            if m.frames[self.ft_frame[s]].parentJoint != m.frames[self.sole_frame[s]].parentJoint:
                raise LegMapError(f"{self.legmap.source or self.legmap.name}: legs.{s}.ft must be on the foot (moved "
                                  "by the same joints as the sole) for loads at the joints to come from it")
            out[s] = d.oMf[self.sole_frame[s]].actInv(d.oMf[self.ft_frame[s]]).homogeneous
        return out

    @cached_property
    def R_BI(self) -> np.ndarray:
        """Rotation of the (nominal) IMU frame in the pelvis frame (the IMU frame's one
        definition; see `T_BI`)."""
        return self.T_BI[:3, :3].copy()

    def com(self, q: np.ndarray) -> np.ndarray:
        """Centre of mass of the whole robot in the pelvis frame."""
        c = pin.centerOfMass(self.model, self.data, self.q_full(q))  # also runs forward kinematics
        pin.updateFramePlacements(self.model, self.data)
        return self.data.oMf[self.pelvis_frame].actInv(c)

    def joint_axes(self, q: np.ndarray | None = None) -> np.ndarray:
        """(n_joints, 3) leg joint axes in the pelvis frame (at q, default all zeros)."""
        qf = self.q_full(np.zeros(self.n_joints) if q is None else q)
        pin.computeJointJacobians(self.model, self.data, qf)
        pin.updateFramePlacements(self.model, self.data)
        R_B = self.data.oMf[self.pelvis_frame].rotation
        axes = np.empty((self.n_joints, 3))
        for i, name in enumerate(self.legmap.joint_names):
            J = pin.getJointJacobian(self.model, self.data, self.model.getJointId(name), pin.WORLD)
            axes[i] = R_B.T @ J[3:, self.leg_v_idx[i]]
        return axes

    def role_axes(self) -> tuple[np.ndarray, np.ndarray]:
        """(signs (n_joints,), angles (n_joints,) rad) of each leg joint's axis at zero angles against
        its role's pelvis axis (`ROLE_AXIS`: pitch y, roll x, yaw z): +1 where they point
        the same way, -1 where the axis points the other way (a joint mirrored by design:
        a positive angle turns the leg the other way about the pelvis axis); the angle
        between the axis and that axis's line (0 to pi/2; a canted axis has a few
        degrees or tens of degrees)."""
        signs, angles = self._role_axes
        return signs.copy(), angles.copy()

    @cached_property
    def _role_axes(self) -> tuple[np.ndarray, np.ndarray]:
        axes = self.joint_axes()
        ref = np.array([ROLE_AXIS[r] for r in self.legmap.joint_roles])
        cos = np.einsum("ij,ij->i", axes, ref) / np.linalg.norm(axes, axis=1)
        return np.where(cos < 0, -1.0, 1.0), np.arccos(np.clip(np.abs(cos), 0.0, 1.0))

    def physical_signs(self) -> np.ndarray:
        """(n_joints,) +-1: each joint's angle sign against its role's pelvis axis
        (`role_axes`). A role's offset times its sign is the same physical rotation on
        every robot and on both legs, mirrored axes or not (the paper's presets)."""
        return self.role_axes()[0]

    def pitch_signs(self) -> np.ndarray:
        """(n_joints,) +-1 for hip pitch, knee and ankle pitch: each axis's direction relative to
        the pelvis y axis, one frame for both legs (a common pitch of the pelvis, such as
        an IMU tilt, moves both legs' pitch sums alike, mirrored axes or not); 0 for the
        other joints."""
        pitch = np.array([r in PITCH_ROLES for r in self.legmap.joint_roles])
        return np.where(pitch, self.physical_signs(), 0.0)

    def sole_jacobian(self, side: str, q: np.ndarray) -> np.ndarray:
        """(6, k) Jacobian of the sole pose in its own (local) frame w.r.t. that leg's k joints."""
        qf = self.q_full(q)
        J = pin.computeFrameJacobian(self.model, self.data, qf, self.sole_frame[side], pin.LOCAL)
        return J[:, self.leg_v_idx[self.leg_cols[side]]]

    # ---------------------------------------------------------------- inverse
    def solve_leg(self, side: str, T_B_sole: pin.SE3, q_init: np.ndarray, max_iter: int = 50) -> np.ndarray:
        """Newton IK for one leg: the joint vector `q_init` with that leg's joints solved."""
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

    def solve_batch(self, T_B_left: np.ndarray, T_B_right: np.ndarray, q_init: np.ndarray | None = None,
                    check_limits: bool = True, max_iter: int = 50) -> np.ndarray:
        """`solve` for N targets at once: T_B_left, T_B_right (N, 4, 4) sole poses in the
        pelvis frame (or sequences of pin.SE3), q_init (N, n_joints) or (n_joints,)
        (default `q_init()`); returns (N, n_joints).

        Each frame runs `solve_leg`'s Newton iteration (error log6(T^-1 T_target) in the
        sole frame, least-squares step on the LOCAL sole Jacobian, at most 0.5 rad a
        step, until the error is below IK_TOL), all frames in parallel. Raises IKError
        naming the frames (indices also in the error's `frames`) that do not converge or,
        with `check_limits`, that need joints beyond their limits."""
        targets = [_homogeneous(T) for T in (T_B_left, T_B_right)]
        n = len(targets[0])
        if len(targets[1]) != n:
            raise ValueError(f"solve_batch: {n} left but {len(targets[1])} right sole poses")
        q0 = self.q_init() if q_init is None else np.asarray(q_init, dtype=float)
        q = np.array(np.broadcast_to(q0, (n, self.n_joints)), dtype=float)
        for i, side in enumerate(SIDES):
            residual = self._newton_batch(i, targets[i], q, max_iter)
            failed = np.flatnonzero(residual > 1e-9)
            if failed.size:
                raise _ik_error(f"{side} sole pose not reachable in {failed.size} of {n} frames "
                                f"(largest residual {residual[failed].max():.2e})", failed)
        if check_limits:
            bad = (q < self.q_lower - 1e-9) | (q > self.q_upper + 1e-9)
            frames = np.flatnonzero(bad.any(axis=1))
            if frames.size:
                detail = "; ".join(f"frame {k}: {[self.legmap.joint_names[j] for j in np.flatnonzero(bad[k])]}"
                                   for k in frames[:5])
                more = f"; ... ({frames.size} frames)" if frames.size > 5 else ""
                raise _ik_error(f"postures need joints beyond their limits: {detail}{more}", frames)
        return q

    def _newton_batch(self, side: int, target: np.ndarray, q: np.ndarray, max_iter: int) -> np.ndarray:
        """Solves leg `side` of every row of q in place; returns each frame's last error norm."""
        n = len(q)
        cols = self.leg_cols[SIDES[side]]
        err_norm = np.full(n, np.inf)
        active = np.arange(n)
        for _ in range(max_iter):
            if active.size == 0:
                break
            qa = q[active]
            T, J = self._legs_batch(qa, (side,))
            err = Log(inverse(T[0]) @ target[active])
            norm = np.linalg.norm(err, axis=1)
            err_norm[active] = norm
            go = norm >= self.IK_TOL
            active, J, err, qa = active[go], J[0][go], err[go], qa[go]
            if active.size == 0:
                break
            step = _lstsq_batch(J, err)
            scale = np.minimum(1.0, 0.5 / np.maximum(np.abs(step).max(axis=1), 1e-300))  # at most 0.5 rad a step
            q[np.ix_(active, cols)] = qa[:, cols] + scale[:, None] * step
        return err_norm

    def q_init(self) -> np.ndarray:
        """A mildly bent-knee seed in the middle of the joint ranges (IK starting point):
        the knee bent forward physically, a mirrored axis's angle signed accordingly."""
        q = np.clip(np.zeros(self.n_joints), self.q_lower, self.q_upper)
        roles, signs = self.legmap.joint_roles, self._role_axes[0]
        for i, r in enumerate(roles):
            bend = signs[i] * {"hip_pitch": -0.3, "knee": 0.6, "ankle_pitch": -0.3}.get(r, 0.0)
            q[i] = np.clip(q[i] + bend, self.q_lower[i], self.q_upper[i])
        return q

    @property
    def reaches_any_sole_pose(self) -> bool:
        """A leg of six joints reaches any sole pose near its own, so in double support any
        pelvis pose near a stance is a posture; shorter legs hold only some
        (`holdable_postures`)."""
        return self.leg_joints == 6

    @cached_property
    def dims(self) -> RobotDims:
        left, right = self.sole_poses(np.zeros(self.n_joints))
        c = self.corners["left"]
        return RobotDims(
            leg_length=float(-(left.translation[2] + right.translation[2]) / 2),
            foot_y=float((left.translation[1] - right.translation[1]) / 2),
            foot_x=float((left.translation[0] + right.translation[0]) / 2),
            sole_length=float(c[:, 0].max() - c[:, 0].min()),
            sole_width=float(c[:, 1].max() - c[:, 1].min()),
        )


def joint_limits(legmap: LegMap) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) of the leg joints (rad), as `LegKinematics` reads them."""
    kin = LegKinematics(legmap)
    return kin.q_lower, kin.q_upper


def _homogeneous(T) -> np.ndarray:
    """(N, 4, 4) from an (N, 4, 4) or (4, 4) array, a pin.SE3 or a sequence of them."""
    if isinstance(T, pin.SE3):
        return T.homogeneous[None]
    if len(T) and isinstance(T[0], pin.SE3):
        return np.array([t.homogeneous for t in T])
    return np.asarray(T, dtype=float).reshape(-1, 4, 4)


def _ik_error(message: str, frames: np.ndarray) -> IKError:
    shown = ", ".join(str(k) for k in frames[:20]) + (", ..." if len(frames) > 20 else "")
    err = IKError(f"{message}; frames [{shown}]")
    err.frames = frames
    return err


def _unstandable(message: str, frames: np.ndarray) -> IKError:
    err = _ik_error(message, frames)
    err.unstandable = True  # the soles, not the joint limits: `holdable_postures`
    return err


def _lstsq_batch(J: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise np.linalg.lstsq(J[k], b[k], rcond=None)[0]: for square J a plain solve
    where J[k] is well conditioned; where the solve fails or amplifies b by more than
    1e6 (relative to |J|), and for a non-square J (a leg of five joints), the
    minimum-norm least-squares solution through the SVD with singular values below
    eps * max(m, n) * s_max dropped (lstsq's rule)."""
    square = J.shape[-1] == J.shape[-2]
    x, bad = np.empty(J.shape[:-2] + J.shape[-1:]), np.ones(len(b), dtype=bool)
    if square:
        try:
            x = np.linalg.solve(J, b[..., None])[..., 0]
            amplified = np.linalg.norm(x, axis=1) * np.linalg.norm(J, axis=(1, 2)) > 1e6 * np.linalg.norm(b, axis=1)
            bad = ~np.isfinite(x).all(axis=1) | amplified
        except np.linalg.LinAlgError:  # an exactly singular J somewhere
            pass
    if bad.any():
        U, s, Vt = np.linalg.svd(J[bad], full_matrices=square)
        cutoff = np.finfo(float).eps * max(J.shape[-2:]) * s[:, :1]
        inv_s = np.where(s > cutoff, 1.0 / np.where(s > cutoff, s, 1.0), 0.0)
        x[bad] = np.einsum("nji,nj->ni", Vt, inv_s * np.einsum("nji,nj->ni", U, b[bad]))
    return x


def _mul_soa(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> np.ndarray:
    """Products of stacks of matrices stored frame-last: (..., i, j, n) @ (..., j, k, n)."""
    return np.einsum("...ijn,...jkn->...ikn", A, B, out=out)


def _inv_soa(H: np.ndarray, out: np.ndarray) -> np.ndarray:
    """Inverses of homogeneous transforms stored frame-last, (..., 4, 4, n)."""
    R, p = H[..., :3, :3, :], H[..., :3, 3, :]
    out[..., :3, :3, :] = np.swapaxes(R, -3, -2)
    np.einsum("...rcn,...rn->...cn", R, p, out=out[..., :3, 3, :])
    np.negative(out[..., :3, 3, :], out=out[..., :3, 3, :])
    out[..., 3, :3, :] = 0.0
    out[..., 3, 3, :] = 1.0
    return out


def _add_cross(p: np.ndarray, a: np.ndarray, out: np.ndarray) -> None:
    """out += p x a for 3-vectors along axis -2 (frame-last arrays)."""
    px, py, pz = p[..., 0, :], p[..., 1, :], p[..., 2, :]
    ax, ay, az = a[..., 0, :], a[..., 1, :], a[..., 2, :]
    out[..., 0, :] += py * az - pz * ay
    out[..., 1, :] += pz * ax - px * az
    out[..., 2, :] += px * ay - py * ax


def solve_standing(kin: LegKinematics, T_W_left: pin.SE3, T_W_right: pin.SE3, posture0: np.ndarray,
                   knee_angles: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Closed-chain posture with both knees held at given angles (straight-leg standing).

    With a knee fixed a leg of six joints keeps five, so the pelvis height and roll are
    freed: twelve unknowns for the twelve sole-pose equations. A leg of five joints
    keeps four: the rest of the pelvis pose is freed too, pulled weakly (1e-6 of
    `_pose_metric`) toward `posture0`, which decides only what the equations leave open.
    Returns (posture, q).
    """
    roles = kin.legmap.joint_roles
    n = kin.n_joints
    knees = [i for i, r in enumerate(roles) if r == "knee"]
    others = [i for i in range(n) if i not in knees]
    equations = 2 * 6  # both soles' poses
    free = [2, 3] if 2 + len(others) >= equations else list(range(6))  # posture entries solved for
    pull = 1e-6 * _pose_metric(kin)

    def unpack(u):
        posture = np.array(posture0, dtype=float)
        posture[free] = u[:len(free)]
        q = np.empty(n)
        q[knees] = knee_angles
        q[others] = u[len(free):]
        return posture, q

    def residual(u):
        posture, q = unpack(u)
        T_WB = posture_pose(posture)
        left, right = kin.sole_poses(q)
        r = [pin.log6((T_WB * left).actInv(T_W_left)).vector, pin.log6((T_WB * right).actInv(T_W_right)).vector]
        if len(free) == 6:
            r.append(pull * (posture - posture0))
        return np.concatenate(r)

    # Seed: the bent-knee IK solution at the starting posture, knees then snapped.
    seed = np.array(posture0, dtype=float)
    seed[2] -= 0.03 * kin.dims.leg_length  # straight legs are singular; start bent
    if len(free) == 6:
        (seed,), q0 = reachable_postures(kin, T_W_left, T_W_right, seed[None])
        q0 = q0[0]
    else:
        T_WB = posture_pose(seed)
        q0 = kin.solve(T_WB.actInv(T_W_left), T_WB.actInv(T_W_right), check_limits=False)
    u0 = np.concatenate([seed[free], q0[others]])
    sol = least_squares(residual, u0, xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200)
    feet = np.linalg.norm(sol.fun[:equations])
    if feet > 1e-10:
        raise IKError(f"no straight-leg standing posture for these sole placements (residual {feet:.1e})")
    return unpack(sol.x)


# How a commanded pelvis pose is weighed against a reachable one (`reachable_postures`):
# a translation counts per leg length, a rotation per radian.
def _pose_metric(kin: LegKinematics) -> np.ndarray:
    return np.r_[np.full(3, 1.0 / kin.dims.leg_length), np.ones(3)]


# `reachable_postures`: the closure's weight against the pose metric in its least squares
# (per rad or m of inter-foot error), and the least-squares iterations at most.
CLOSURE_WEIGHT = 1e3
REACH_MAX_STEPS = 100
REACH_BLOCK = 10  # frames of a trajectory solved together, from the previous block's last solution


def reachable_postures(kin: LegKinematics, T_W_left: pin.SE3 | np.ndarray, T_W_right: pin.SE3 | np.ndarray,
                       postures: np.ndarray, q_init: np.ndarray | None = None, tol: float = 1e-12,
                       slide: bool = False) -> tuple[np.ndarray, ...]:
    """(postures (N, 6), q (N, n)): for each commanded pelvis posture (stance frame), a
    nearby one (not farther than the nearest by more than the solver's tolerance) from
    which both legs reach their soles at T_W_left/T_W_right (stance
    frame), and its joint angles. Legs of six joints reach every posture near a stance:
    the postures come back as commanded. A leg of k < 6 joints reaches a k-dimensional
    family of sole poses, so the postures of both legs form a (2k - 6)-dimensional family
    (four for k = 5), and at flat parallel soles a singular one: the pelvis roll of a
    five-joint robot is free to first order (hip rolls and knees take it) and bound only
    at second order (the hips' spacing shrinks with its cosine), where the closure's
    Jacobian loses a rank.

    Each posture starts from its seed (`q_init` (N, n)); from one seed (`q_init` (n,)
    or None), a trajectory's frames are solved in blocks of REACH_BLOCK, each from the
    previous block's last angles, which keeps a motion on one branch of solutions.

    Solved in joint space: the pelvis follows the left leg, T_WB = T_W_left T_BL(q)^-1,
    and the right sole must close the chain, C(q) = C_target (`frame_kinematics`'s
    inter-foot transform and Jacobian G). Levenberg-Marquardt on the pelvis pose's
    departure from the commanded one (translation per leg length, rotation per rad:
    `_pose_metric`) and the closure error weighted by CLOSURE_WEIGHT (a penalty, which
    the singular roll does not break as an equality constraint's multipliers would),
    stopped once a step gains less than 1e-6 of the cost (so "nearby": within 0.1 % of
    the nearest in tests/robots/test_five_joint.py), then Gauss-Newton on the closure
    alone until it is below `tol`. Raises IKError naming
    the frames that do not close. Joint limits are not checked here (`solve_batch` on
    the result does).

    With `slide`, the right sole may also slide on the floor (in its plane: x, y, yaw,
    weighed like the pelvis), as a foot placed where its leg cannot stand flat settles
    where it can: returns (postures, q, the right soles (N, 4, 4) in the stance frame)."""
    P = np.atleast_2d(np.asarray(postures, dtype=float))
    n = len(P)
    S_L, S_R = (_homogeneous(X)[0] for X in (T_W_left, T_W_right))
    if q_init is None:  # seed: each leg's least-squares IK for the first commanded pose
        q_init = kin.q_init()[None].copy()
        for i, S in enumerate((S_L, S_R)):
            kin._newton_batch(i, inverse(posture_poses(P[:1])) @ S, q_init, 20)
    seeds = np.asarray(q_init, dtype=float)
    if n > 1 and seeds.ndim == 1 or len(seeds) == 1 and n > 1:
        # A trajectory from one seed: each block of frames from the previous block's last
        # solution, so the postures stay on one branch (near flat parallel soles the
        # pelvis roll has two) at a fraction of the cost of a frame-by-frame solve.
        out, q_prev = [], seeds.reshape(-1)
        for k in range(0, n, REACH_BLOCK):
            block = P[k:k + REACH_BLOCK]
            out.append(_reach(kin, S_L, S_R, block, np.broadcast_to(q_prev, (len(block), len(q_prev))), tol, slide))
            q_prev = out[-1][1][-1]
        return tuple(np.concatenate(parts) for parts in zip(*out))
    return _reach(kin, S_L, S_R, P, np.broadcast_to(seeds, (n, kin.n_joints)), tol, slide)


def _reach(kin: LegKinematics, S_L: np.ndarray, S_R: np.ndarray, P: np.ndarray, q_init: np.ndarray, tol: float,
           slide: bool) -> tuple[np.ndarray, ...]:
    """`reachable_postures` of postures P (N, 6), each frame from its seed q_init (N, n)."""
    n = len(P)
    C_target = np.linalg.solve(S_L, S_R)
    W = _pose_metric(kin)
    q = np.array(q_init, dtype=float)
    T_cmd = posture_poses(P)
    left = kin.leg_cols["left"]
    nq, ns = kin.n_joints, (3 if slide else 0)
    P_slide = np.zeros((6, 3))
    P_slide[[0, 1, 5], [0, 1, 2]] = 1.0  # the right sole's in-plane twist (x, y, yaw in its frame)
    W_slide = W[[0, 1, 5]]

    def targets(x):
        return C_target @ Exp(x[:, nq:] @ P_slide.T) if slide else C_target

    def residuals(x, rows=slice(None)):
        fk = joint_frame_kinematics(kin, x[:, :nq])
        T_BL = np.zeros((len(x), 4, 4))
        T_BL[:, :3, :3], T_BL[:, :3, 3], T_BL[:, 3, 3] = fk.R_L, fk.p_L, 1.0
        r = Log(inverse(fk.C) @ targets(x))  # closure error; G dq - P ds = r closes it to first order
        d0 = Log(inverse(T_cmd[rows]) @ S_L @ inverse(T_BL))  # the pelvis pose against the commanded one
        jac = np.zeros((len(x), 12 + ns, nq + ns))
        # dq_L moves the pelvis by xi = -Ad(T_BL) J_L dq_L, the departure by Jr^-1(d0) xi.
        jac[:, :6, left] = -(W[:, None] * Jr_inv(d0)) @ adjoint(T_BL) @ fk.J_L
        jac[:, 6:12, :nq] = -CLOSURE_WEIGHT * fk.G
        rows = [W * d0, CLOSURE_WEIGHT * r]
        if slide:
            jac[:, 6:12, nq:] = CLOSURE_WEIGHT * P_slide
            jac[:, 12:, nq:] = np.diag(W_slide)
            rows.append(W_slide * x[:, nq:])
        return np.concatenate(rows, axis=1), jac, fk.G, r

    x = np.concatenate([q, np.zeros((n, ns))], axis=1)
    res, jac, _, _ = residuals(x)
    cost = np.einsum("ni,ni->n", res, res)
    lam = np.full(n, 1e-6)
    eye = np.eye(nq + ns)
    active = np.arange(n)  # frames still moving
    for _ in range(REACH_MAX_STEPS):
        jac_a, res_a = jac[active], res[active]
        JtJ = np.swapaxes(jac_a, 1, 2) @ jac_a
        g = np.einsum("nji,nj->ni", jac_a, res_a)
        damped = JtJ + (lam[active, None, None] * eye) * np.einsum("nii->ni", JtJ)[:, None, :]
        step = -np.linalg.solve(damped + 1e-300 * eye, g[..., None])[..., 0]
        step *= np.minimum(1.0, 0.5 / np.maximum(np.abs(step).max(axis=1), 1e-300))[:, None]  # <= 0.5 rad
        res_t, jac_t, _, _ = residuals(x[active] + step, active)
        cost_t = np.einsum("ni,ni->n", res_t, res_t)
        better = cost_t < cost[active]
        small = np.abs(step).max(axis=1) < 1e-8  # rad
        done = small | (better & (cost[active] - cost_t <= 1e-6 * cost[active]))  # near enough: the closure is polished next
        idx = active[better]
        x[idx] += step[better]
        res[idx], jac[idx], cost[idx] = res_t[better], jac_t[better], cost_t[better]
        lam[active] = np.where(better, np.maximum(lam[active] / 3, 1e-12), lam[active] * 4)
        active = active[~done & (lam[active] < 1e12)]
        if active.size == 0:
            break
    closure = np.full(n, np.inf)
    for _polish in range(60):  # the closure alone (the joints); the singular roll converges by halving
        _, _, G, r = residuals(x)
        closure = np.linalg.norm(r, axis=1)
        if closure.max() < tol:
            break
        x[:, :nq] += _lstsq_batch(G, r)
    failed = np.flatnonzero(closure >= max(tol, 1e-9))
    if failed.size:
        raise _ik_error(f"no reachable posture near {failed.size} of {n} commanded ones (largest closure error "
                        f"{closure[failed].max():.2e})", failed)
    q = x[:, :nq]
    postures = _postures_of(S_L @ inverse(_left_poses(kin, q)))
    return (postures, q, S_L @ targets(x)) if slide else (postures, q)


def reached_as_commanded(kin: LegKinematics, T_W_left, T_W_right, postures: np.ndarray,
                         q_init: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(reached (N,) bool, q (N, n)): which postures (N, 6) both legs reach exactly as
    commanded with their soles at T_W_left/T_W_right (each leg's least-squares Newton
    from `q_init` closes to 1e-10), and the angles found. Joint limits not checked."""
    P = np.asarray(postures, dtype=float).reshape(-1, 6)
    T_BW = inverse(posture_poses(P))
    q = np.array(np.broadcast_to(kin.q_init() if q_init is None else q_init, (len(P), kin.n_joints)), dtype=float)
    err = np.maximum(*(kin._newton_batch(i, T_BW @ _homogeneous(S)[0], q, 50)
                       for i, S in enumerate((T_W_left, T_W_right))))
    return err <= 1e-10, q


# `holdable_postures`: a held posture farther than these from the commanded one (rad; leg
# lengths) is refused. Near flat parallel soles a five-joint robot's held posture moves
# with the square root of the soles' misfit (the fold of `reachable_postures`): a 0.05 deg
# roll shim under one sole of the A3-like robot without ankle roll turns its pelvis 2.7 deg
# in yaw, where a real robot rocks its sole onto an edge; no clean stance departs at all.
HOLD_MAX_DEPARTURE = math.radians(1.0)
HOLD_MAX_SHIFT = 0.01


def holdable_postures(kin: LegKinematics, T_W_left, T_W_right, postures: np.ndarray,
                      q_init: np.ndarray | None = None) -> np.ndarray:
    """(N, 6) the postures the robot can hold with its soles at T_W_left/T_W_right: the
    commanded ones for legs of six joints (returned as given); for shorter legs the
    commanded ones both legs reach, the others replaced by nearby reachable ones
    (`reachable_postures`; IKError naming the frames that have none within
    HOLD_MAX_DEPARTURE and HOLD_MAX_SHIFT)."""
    postures = np.asarray(postures, dtype=float)
    if kin.reaches_any_sole_pose:
        return postures
    P = postures.reshape(-1, 6)
    reached, q = reached_as_commanded(kin, T_W_left, T_W_right, P, q_init)  # kept; only the others move
    moved = np.flatnonzero(~reached)
    out = P.copy()
    if moved.size:
        out[moved] = reachable_postures(kin, T_W_left, T_W_right, P[moved], q[moved[0]])[0]
        d = out[moved] - P[moved]
        away = np.maximum(np.abs(d[:, :3]).max(axis=1) / (HOLD_MAX_SHIFT * kin.dims.leg_length),
                          np.abs(d[:, 3:]).max(axis=1) / HOLD_MAX_DEPARTURE)
        if away.max() > 1.0:
            far = moved[away > 1.0]
            w = int(np.argmax(away))
            raise _unstandable(
                f"no posture within {math.degrees(HOLD_MAX_DEPARTURE):g} deg and {HOLD_MAX_SHIFT:.0%} of the "
                f"leg's length of the commanded one keeps both soles flat where they are (the nearest found is "
                f"{math.degrees(np.abs(d[w, 3:]).max()):.1f} deg and {np.abs(d[w, :3]).max() * 1e3:.0f} mm away): legs "
                f"without {', '.join(kin.legmap.absent_roles)} cannot stand flat on soles placed like these (a sole "
                "tilted by a shim or an uneven floor, or placed off its hip's line)", far)
    return out.reshape(postures.shape)


def _left_poses(kin: LegKinematics, q: np.ndarray) -> np.ndarray:
    """(N, 4, 4) the left sole's poses in the pelvis frame."""
    return kin._legs_batch(q, (0,), jacobian=False)[0][0]


def _postures_of(T: np.ndarray) -> np.ndarray:
    """(N, 6) posture vectors [x, y, z, roll, pitch, yaw] of pelvis poses (N, 4, 4): the
    inverse of `posture_poses` (fixed axes x, y, z)."""
    from scipy.spatial.transform import Rotation

    return np.concatenate([T[:, :3, 3], Rotation.from_matrix(T[:, :3, :3]).as_euler("xyz")], axis=1)


# A joint's axis this far from its role's pelvis axis is reported (`axis_warnings`): the
# role then names a motion the joint makes only in part (the G1's hip roll and yaw are
# canted 10 degrees, well inside; at 45 degrees a hip axis is as much roll as yaw).
ROLE_AXIS_WARN_RAD = math.radians(30.0)


def axis_warnings(kin: LegKinematics) -> list[str]:
    """A warning per leg joint whose axis is more than `ROLE_AXIS_WARN_RAD` from the
    pelvis axis its role names (`LegKinematics.role_axes`)."""
    _, angles = kin.role_axes()
    out = []
    for name, role, a in zip(kin.legmap.joint_names, kin.legmap.joint_roles, angles):
        if a > ROLE_AXIS_WARN_RAD:
            out.append(f"joint {name}: its axis is {math.degrees(a):.0f} deg from the pelvis "
                       f"{ROLE_AXIS_NAME[role]} axis its role {role} names; the presets, pitch sums and "
                       "observability read it by that role: check the leg map's role for it")
    return out


def pitch_sums(dq: np.ndarray, signs: np.ndarray) -> dict[str, float]:
    """Per-leg pitch sums s_L, s_R and s_R - s_L of an offset vector (`signs` from
    `LegKinematics.pitch_signs`)."""
    h = len(dq) // 2  # the left leg's joints, then the right's
    left, right = float(signs[:h] @ dq[:h]), float(signs[h:] @ dq[h:])
    return {"left": left, "right": right, "right_minus_left": right - left}


@dataclass
class FrameKinematics:
    """Per-frame kinematics (batched arrays) of N leg configurations."""

    C: np.ndarray  # (N, 4, 4) inter-foot transforms, homogeneous
    G: np.ndarray  # (N, 6, n) right-perturbation Jacobian of C w.r.t. the n leg angles
    p_L: np.ndarray  # (N, 3) sole positions in the pelvis frame
    p_R: np.ndarray
    R_L: np.ndarray  # (N, 3, 3) sole rotations in the pelvis frame
    R_R: np.ndarray
    J_L: np.ndarray  # (N, 6, k) local sole Jacobians w.r.t. the leg's own k joints
    J_R: np.ndarray


def frame_kinematics(kin: LegKinematics, Q: np.ndarray) -> FrameKinematics:
    """`joint_frame_kinematics` of recorded angles Q (N, n), the calibration's coordinates:
    the joints' angles, but a linkage ankle's columns hold its motors' angles
    (`legcal_bench.robots.linkage`), so G and the sole Jacobians are by the motors' angles
    there (dq/dm applied): offsets added to Q are the encoders' own."""
    if not kin.linkages:
        return joint_frame_kinematics(kin, Q)
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    q = Q.copy()
    D = []
    for lk in kin.linkages:
        q[:, list(lk.cols)], d = lk.joints(Q[:, list(lk.cols)])
        D.append(d)
    fk = joint_frame_kinematics(kin, q)
    for lk, d in zip(kin.linkages, D):
        cols = list(lk.cols)
        fk.G[:, :, cols] = fk.G[:, :, cols] @ d
        J = fk.J_L if lk.side == "left" else fk.J_R
        local = [c - kin.leg_cols[lk.side][0] for c in cols]
        J[:, :, local] = J[:, :, local] @ d
    return fk


def joint_frame_kinematics(kin: LegKinematics, q: np.ndarray) -> FrameKinematics:
    """Forward kinematics and sole Jacobians for each row of the joints' angles q (N, n),
    all frames at once on the legs' products of exponentials (`LegPoE`).

    A right perturbation of the sole poses, T_BF(q + d) = T_BF Exp(J_F d), perturbs C
    on the right by G d with G = [-Ad(C^-1) J_L | J_R]."""
    Q = np.atleast_2d(np.asarray(q, dtype=float))
    n = len(Q)
    nk = kin.leg_joints
    T, C, G = np.empty((2, n, 4, 4)), np.empty((n, 4, 4)), np.empty((n, 6, 2 * nk))
    J = np.empty((2, n, 6, nk))
    pos_L, pos_R = kin._jac_pos
    w = kin._work
    for a in range(0, n, kin._CHUNK):
        b = min(a + kin._CHUNK, n)
        T_inv, Y = kin._chain_block(Q[a:b], [0, 1], True)
        Tb = _inv_soa(T_inv, w("T", T_inv.shape))
        T[:, a:b] = Tb.transpose(0, 3, 1, 2)
        J[0, a:b][..., pos_L] = Y[0].transpose(2, 1, 0)
        J[1, a:b][..., pos_R] = Y[1].transpose(2, 1, 0)
        C[a:b] = _mul_soa(T_inv[0], Tb[1], w("C", Tb.shape[1:])).transpose(2, 0, 1)
        # -Ad(C^-1) J_L, column by column: -[R a + p x (R b), R b] with (R, p) of C^-1.
        C_inv = _mul_soa(T_inv[1], Tb[0], w("C_inv", Tb.shape[1:]))
        AdJ = w("AdJ", Y.shape[1:])  # (k joints, 6, n)
        np.einsum("ijn,kjn->kin", C_inv[:3, :3], Y[0, :, :3], out=AdJ[:, :3])
        np.einsum("ijn,kjn->kin", C_inv[:3, :3], Y[0, :, 3:], out=AdJ[:, 3:])
        _add_cross(C_inv[None, :3, 3], AdJ[:, 3:], AdJ[:, :3])
        G[a:b, :, pos_L] = -AdJ.transpose(2, 1, 0)
        G[a:b, :, nk + pos_R] = Y[1].transpose(2, 1, 0)
    TL, TR = T
    return FrameKinematics(C, G, TL[:, :3, 3], TR[:, :3, 3], TL[:, :3, :3], TR[:, :3, :3], J[0], J[1])
