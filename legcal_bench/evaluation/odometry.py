"""Leg kinematic-inertial odometry: the robot's own estimate of where it walked,
from its IMU and its encoders through forward kinematics (the paper's LiDAR check,
with the simulator's truth in place of LiDAR).

Orientation comes from the IMU: the gyro propagates it, and its roll and pitch are
taken from the orientation filter's gravity direction (the walking env's `gravity`
observation), so only the heading drifts. Position comes from the stance foot's contact
point, fixed in the world while the foot carries the robot (the paper's eq. legodom,
with the contact point rather than the foot's whole pose: a foot rolling from heel to
toe keeps its contact point, not its orientation):

    p_WB(t) = p_WA - R_WB(t) p_BA(q(t)),

A the stance sole's centre of pressure from the ankle force/torque sensor, followed as
it moves (rolling without slipping), or, for a robot without them, the sole's origin.
When the other foot takes the larger load, its contact point is placed where the
current estimate puts it: p_WA' = p_WB(t) + R_WB(t) p_BA'(q(t)). The stance foot is the more loaded
one, by the ankle force sensors where the robot has them (else by the simulator's
contact loads). Started from the true initial pose. Offsets in the encoders (added to a
logged walk afterwards, as the paper did, so no fall changes the walk) bend each
foot's position and make the estimate drift; a symmetric hip-pitch offset drifts it
vertically, linearly in the offset (paper: 1.04 m per degree, over its walks).
"""

from __future__ import annotations

import numpy as np

from legcal_bench.evaluation.metrics import rms
from legcal_bench.geometry.poses import pos_quat_to_homogeneous
from legcal_bench.robots.kinematics import LegKinematics, joint_frame_kinematics


def imu_orientation(gravity: np.ndarray, ang_vel: np.ndarray, dt: float, R0: np.ndarray) -> np.ndarray:
    """Base orientations (n, 3, 3): the gyro's rates (base frame) integrated from R0 for
    the heading, roll and pitch from the gravity direction (base frame, unit "down")."""
    import pinocchio as pin

    out = np.empty((len(gravity), 3, 3))
    R = np.asarray(R0, dtype=float)
    for k in range(len(gravity)):
        R = R @ pin.exp3(ang_vel[k] * dt)
        g = gravity[k] / np.linalg.norm(gravity[k])
        pitch, roll, yaw = np.arcsin(np.clip(g[0], -1, 1)), np.arctan2(-g[1], -g[2]), np.arctan2(R[1, 0], R[0, 0])
        R = pin.rpy.rpyToMatrix(roll, pitch, yaw)
        out[k] = R
    return out


def sole_from_ft(legmap) -> tuple[np.ndarray, np.ndarray] | None:
    """(R, p): the ankle F/T frame in each sole frame (the same for both legs is not
    assumed: (2, 3, 3), (2, 3)), when the leg map places both on the same body by pose;
    else None."""
    from scipy.spatial.transform import Rotation

    Rs, ps = [], []
    for side in ("left", "right"):
        leg = legmap.legs[side]
        ft, sole = leg.ft, leg.sole
        if ft is None or ft.site or sole.site or ft.body != sole.body:
            return None
        R_bs, R_bf = Rotation.from_euler("xyz", sole.rpy).as_matrix(), Rotation.from_euler("xyz", ft.rpy).as_matrix()
        Rs.append(R_bs.T @ R_bf)
        ps.append(R_bs.T @ (np.asarray(ft.pos) - np.asarray(sole.pos)))
    return np.array(Rs), np.array(ps)


def centre_of_pressure(ft: np.ndarray, sole_ft) -> np.ndarray:
    """Centre of pressure on each sole (n, 2, 3), in the sole frame (z = 0), from the
    ankle wrenches (n, 2, 6) [force, torque] in the F/T frames."""
    R, p = sole_ft
    f = np.einsum("sij,nsj->nsi", R, ft[..., :3])
    tau = np.einsum("sij,nsj->nsi", R, ft[..., 3:]) + np.cross(p[None], f)  # about the sole origin
    fz = np.where(np.abs(f[..., 2]) > 1e-6, f[..., 2], 1e-6)
    return np.stack([-tau[..., 1] / fz, tau[..., 0] / fz, np.zeros_like(fz)], axis=-1)


def leg_odometry(kin: LegKinematics, q: np.ndarray, loads: np.ndarray, R_WB: np.ndarray, p0: np.ndarray,
                 cop: np.ndarray | None = None) -> np.ndarray:
    """Base positions (n, 3) from joint angles q (n, n_joints), per-foot loads (n, 2: left,
    right), base orientations R_WB (n, 3, 3), the initial base position p0 and, if the
    robot measures it, each sole's centre of pressure (n, 2, 3; sole frame), the
    contact point (else the sole's origin, anchored at each change of stance foot)."""
    fk = joint_frame_kinematics(kin, q)
    R_BS, p_BS = np.stack([fk.R_L, fk.R_R]), np.stack([fk.p_L, fk.p_R])  # (2, n, ...)
    n = len(q)
    c = np.zeros((n, 2, 3)) if cop is None else cop
    # The stance foot at each step (before, after its switch): the more loaded one, a tie keeping it.
    before, after = np.empty(n, dtype=int), np.empty(n, dtype=int)
    stance = int(np.argmax(loads[0]))
    for k, (left, right) in enumerate(loads.tolist()):
        before[k] = stance
        if (left if stance else right) > (right if stance else left):
            stance = 1 - stance
        after[k] = stance
    moved = (after != before) if cop is None else np.ones(n, dtype=bool)  # steps whose anchor p_WA moves
    # The contact point each step measures from (the one its foot was anchored at) and
    # the one anchored after it: a point of the sole (sole frame) in the base frame, then
    # turned into the world (one matrix-vector product per step, as one step at a time).
    steps = np.arange(n)
    point = c[np.maximum(steps - 1, 0), before] if cop is not None else c[0, before]
    a = _turn(R_WB, p_BS[before, steps] + _turn(R_BS[before, steps], point))
    b = _turn(R_WB, p_BS[after, steps] + _turn(R_BS[after, steps], c[steps, after]))
    # p = p_WA - R_WB p_BA each step; p_WA = p + R_WB p_BA' where the anchor moves.
    out = np.empty((n, 3))
    p_WA, start = p0 + a[0], 0
    for k in np.flatnonzero(moved).tolist():
        out[start:k + 1] = p_WA - a[start:k + 1]
        p_WA, start = out[k] + b[k], k + 1
    out[start:] = p_WA - a[start:]
    return out


def _turn(R: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R[k] @ v[k] for each k: (n, 3, 3), (n, 3) -> (n, 3)."""
    return np.matmul(R, v[:, :, None])[:, :, 0]


def pose_matrices(poses: np.ndarray) -> np.ndarray:
    """(n, 4, 4) from [x y z qw qx qy qz] rows (the walk's pelvis poses)."""
    return pos_quat_to_homogeneous(poses)


def odometry_errors(est: np.ndarray, truth: np.ndarray) -> dict:
    """RMS error (mm) of the estimated base positions (n, 3) against the true poses
    (n, 4, 4), vertical, forward and lateral (in the initial heading) and 3-D, and the
    final vertical drift."""
    d = est - truth[:, :3, 3]
    yaw = np.arctan2(truth[0, 1, 0], truth[0, 0, 0])
    c, s = np.cos(yaw), np.sin(yaw)
    fwd, lat = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    return {"vertical_mm": 1e3 * rms(d[:, 2]), "forward_mm": 1e3 * rms(fwd), "lateral_mm": 1e3 * rms(lat),
            "total_mm": 1e3 * rms(np.linalg.norm(d, axis=1)), "final_vertical_drift_mm": 1e3 * float(d[-1, 2])}


def pitch_sensitivity(kin: LegKinematics, q: np.ndarray, loads: np.ndarray, R_WB: np.ndarray, truth: np.ndarray,
                      cop: np.ndarray | None = None, degrees=(-3.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0)) -> dict:
    """Final vertical drift (m) with a symmetric hip-pitch offset of each size added to
    the logged encoders (q_enc = q - dq), and its slope (m per degree, least squares)."""
    roles = kin.legmap.joint_roles
    pitch = np.array([r == "hip_pitch" for r in roles], dtype=float)
    drift = []
    for deg in degrees:
        est = leg_odometry(kin, q - np.deg2rad(deg) * pitch, loads, R_WB, truth[0, :3, 3], cop)
        drift.append(float(est[-1, 2] - truth[-1, 2, 3]))
    slope = float(np.polyfit(np.asarray(degrees), np.asarray(drift), 1)[0])
    distance = float(np.linalg.norm(truth[-1, :2, 3] - truth[0, :2, 3]))
    return {"degrees": list(degrees), "final_vertical_drift_m": drift, "m_per_deg": slope, "distance_m": distance}
