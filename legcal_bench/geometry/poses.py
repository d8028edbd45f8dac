"""Pose conversions and the posture vector.

MuJoCo stores quaternions as [w, x, y, z]; SciPy and Pinocchio as [x, y, z, w]. The
conversions below are the only place that reorders them. A posture is the pelvis
pose in the stance frame as [x, y, z, roll, pitch, yaw] (m, rad; fixed axes x, y, z).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation


def wxyz(rot: Rotation) -> np.ndarray:
    """A SciPy rotation's quaternion in MuJoCo's [w, x, y, z] order."""
    return np.roll(rot.as_quat(), 1)


def from_wxyz(q) -> Rotation:
    """A SciPy rotation from a MuJoCo [w, x, y, z] quaternion."""
    return Rotation.from_quat(np.roll(np.asarray(q, dtype=float), -1))


def se3(rot: np.ndarray, pos) -> pin.SE3:
    return pin.SE3(np.asarray(rot, dtype=float), np.asarray(pos, dtype=float))


def pose_xyz_rpy(xyz, rpy) -> pin.SE3:
    return se3(Rotation.from_euler("xyz", rpy).as_matrix(), xyz)


def se3_to_pos_quat(T: pin.SE3) -> np.ndarray:
    """[x, y, z, qw, qx, qy, qz] (MuJoCo's quaternion order)."""
    return homogeneous_to_pos_quat(T.homogeneous)


def homogeneous_to_pos_quat(H: np.ndarray) -> np.ndarray:
    """(..., 4, 4) homogeneous transforms -> (..., 7) [x, y, z, qw, qx, qy, qz], batched."""
    H = np.asarray(H, dtype=float)
    q = Rotation.from_matrix(H[..., :3, :3].reshape(-1, 3, 3)).as_quat().reshape(H.shape[:-2] + (4,))  # xyzw
    return np.concatenate([H[..., :3, 3], q[..., 3:], q[..., :3]], axis=-1)


def pos_quat_to_homogeneous(v: np.ndarray) -> np.ndarray:
    """(n, 4, 4) from rows [x, y, z, qw, qx, qy, qz] (MuJoCo's quaternion order)."""
    v = np.atleast_2d(np.asarray(v, dtype=float))
    H = np.zeros((len(v), 4, 4))
    H[:, :3, :3] = Rotation.from_quat(v[:, [4, 5, 6, 3]]).as_matrix()
    H[:, :3, 3], H[:, 3, 3] = v[:, :3], 1.0
    return H


def pos_quat_to_se3(v) -> pin.SE3:
    v = np.asarray(v, dtype=float)
    return se3(from_wxyz(v[3:7]).as_matrix(), v[:3])


def posture_pose(posture: np.ndarray) -> pin.SE3:
    """The pelvis pose in the stance frame for a posture vector."""
    return pose_xyz_rpy(posture[:3], posture[3:])


def posture_poses(postures: np.ndarray) -> np.ndarray:
    """(N, 4, 4) pelvis poses in the stance frame for postures (N, 6): `posture_pose`
    batched (the same SciPy fixed-axis x-y-z conversion, so the same numbers)."""
    P = np.asarray(postures, dtype=float).reshape(-1, 6)
    H = np.zeros((len(P), 4, 4))
    H[:, :3, :3] = Rotation.from_euler("xyz", P[:, 3:]).as_matrix()
    H[:, :3, 3] = P[:, :3]
    H[:, 3, 3] = 1.0
    return H
