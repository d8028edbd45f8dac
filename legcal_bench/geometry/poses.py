"""Pose conversions and the posture vector.

MuJoCo stores quaternions as [w, x, y, z]; SciPy and Pinocchio as [x, y, z, w]. The
conversions below are the only place that reorders them. A posture is the pelvis
pose in the stance frame as [x, y, z, roll, pitch, yaw] (m, rad; fixed axes x, y, z).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation


def se3(rot: np.ndarray, pos) -> pin.SE3:
    return pin.SE3(np.asarray(rot, dtype=float), np.asarray(pos, dtype=float))


def pose_xyz_rpy(xyz, rpy) -> pin.SE3:
    return se3(Rotation.from_euler("xyz", rpy).as_matrix(), xyz)


def se3_to_pos_quat(T: pin.SE3) -> np.ndarray:
    """[x, y, z, qw, qx, qy, qz] (MuJoCo's quaternion order)."""
    q = Rotation.from_matrix(T.rotation).as_quat()  # xyzw
    return np.concatenate([T.translation, [q[3], q[0], q[1], q[2]]])


def pos_quat_to_se3(v) -> pin.SE3:
    v = np.asarray(v, dtype=float)
    return se3(Rotation.from_quat([v[4], v[5], v[6], v[3]]).as_matrix(), v[:3])


def posture_pose(posture: np.ndarray) -> pin.SE3:
    """The pelvis pose in the stance frame for a posture vector."""
    return pose_xyz_rpy(posture[:3], posture[3:])
