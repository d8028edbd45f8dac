"""The IMU-tilt direction in offset space: what a fixed error of the IMU's vertical
looks like to a calibration.

On level ground the flat-ground constraint aligns the soles' normals with the IMU's
vertical. If that vertical is off by a small rotation w (about the pelvis x and y
axes: mounting tilt, or a horizontal accelerometer bias over g), the offsets that fit
rotate both soles by w in the pelvis frame while keeping every inter-foot transform:
on a pitch-first hip, equal hip-pitch offsets do exactly that (no static data separate
them). `tilt_directions` returns that linear map, V (n, 2) with dq = V w (n the leg
joints), as the least-squares solution over the session's postures of

    G_k dq = 0                          (inter-foot transforms unchanged, weighted)
    P_xy J_side,k dq_side = P_xy R_side,k^T w   (each sole rotated by w, its yaw free)

so a recovery error e splits into a part along V (explained by an IMU tilt t = the
least-squares fit of e on V) and the rest, which the data determine.
"""

from __future__ import annotations

import numpy as np

from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics

INTERFOOT_WEIGHT = 100.0  # per m (translation rows, times the leg length) and per rad


def tilt_directions(kin: LegKinematics, Q: np.ndarray) -> np.ndarray:
    """(n, 2) offsets per rad of IMU tilt about the pelvis x and y axes, for the
    postures Q (N, n), n the leg joints."""
    fk = frame_kinematics(kin, Q)
    n = len(Q)
    L = kin.dims.leg_length
    names = kin.legmap.joint_names
    cols = {s: [names.index(j.name) for j in kin.legmap.legs[s].joints] for s in kin.legmap.legs}
    rows, rhs = [], []
    scale = np.array([1.0 / L] * 3 + [1.0] * 3) * INTERFOOT_WEIGHT  # translation in leg lengths
    for k in range(n):
        rows.append(fk.G[k] * scale[:, None] * L)
        rhs.append(np.zeros((6, 2)))
        for side, J, R in (("left", fk.J_L[k], fk.R_L[k]), ("right", fk.J_R[k], fk.R_R[k])):
            A = np.zeros((2, kin.legmap.n_joints))
            A[:, cols[side]] = J[3:5]
            rows.append(A)
            rhs.append(R.T[:2, :2])  # sole-frame x, y rotation for unit pelvis-frame x, y rotations
    A, b = np.vstack(rows), np.vstack(rhs)
    return np.linalg.lstsq(A, b, rcond=None)[0]


def split_by_tilt(e: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t, rest): the IMU tilt (rad, about pelvis x and y) whose offsets V t fit e best,
    and e - V t, the part an IMU tilt cannot explain."""
    t = np.linalg.lstsq(V, e, rcond=None)[0]
    return t, e - V @ t
