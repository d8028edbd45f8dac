"""Where the IMU sits: on the pelvis, or above non-leg joints (a torso IMU above a waist).

The flat-ground constraint levels the legs against the IMU's vertical in the pelvis
frame. An IMU above joints the legs do not list reaches the pelvis through those joints:
held still in static collection, they put it at one fixed pose, the one at their held
angles, and an offset of their encoders turns it like an IMU mounting tilt would.

- Joints the leg map does not declare (`imu.through`): the calibration was told of no
  joint between the IMU and the pelvis, so the vertical it levels against is one it
  cannot place: `INVALIDATES` (do not apply the offsets), with the fix.
- Declared joints: the IMU is carried through them (`LegKinematics`, at their held
  angles), and the finding states what static data cannot tell apart, per joint: a joint
  whose axis stands near the vertical does not move the vertical (its offset is not
  determined); any other tilts it about its axis, the same direction as an IMU mounting
  tilt (a waist pitch offset and the IMU's pitch tilt are one direction), which the
  legs' pitch and roll sums take up (`estimation.imu.tilt`): `LIMITS`.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from legcal_bench.estimation.verdict import INVALIDATES, LIMITS, Finding
from legcal_bench.robots.kinematics import LegKinematics

VERTICAL_AXIS_RAD = np.deg2rad(10.0)  # a joint axis this close to the pelvis's z does not tilt the vertical


def imu_mount(kin: LegKinematics) -> list[Finding]:
    """The finding of the IMU's mount (none for an IMU on the pelvis)."""
    joints = kin.imu_joints
    if not joints:
        return []
    through = kin.legmap.imu_through
    undeclared = [j for j in joints if j not in through]
    if undeclared:
        return [Finding(
            f"the IMU sits above joint(s) {', '.join(undeclared)} that the leg map does not declare (imu.through): its "
            "vertical in the pelvis frame turns with their angles and their encoders' offsets, which this calibration "
            "was not told of, and the flat-ground constraint levels the legs against it. Fix: declare them "
            f"(imu: {{..., through: [{', '.join(joints)}]}}), or give the pelvis's IMU as the leg map's imu "
            "(a walking policy's IMU elsewhere goes in policy_imu)", INVALIDATES)]
    tilting, vertical = [], []
    for name, axis in zip(joints, joint_axes_in_pelvis(kin, joints)):
        (vertical if np.arccos(min(1.0, abs(axis[2]))) < VERTICAL_AXIS_RAD else tilting).append(name)
    parts = []
    if tilting:
        parts.append(f"an offset of {', '.join(tilting)} tilts the IMU's vertical about its axis, one direction with "
                     "an IMU mounting tilt, which static data do not tell from the legs' pitch and roll sums")
    if vertical:
        parts.append(f"{', '.join(vertical)} turn(s) about the vertical: an offset there does not move the IMU's "
                     "vertical and is not determined")
    return [Finding(f"the IMU is carried to the pelvis through {', '.join(joints)} at their held angles (imu.through): "
                    + "; ".join(parts), LIMITS)]


def joint_axes_in_pelvis(kin: LegKinematics, names) -> np.ndarray:
    """(k, 3) each named joint's axis in the pelvis frame at the held configuration."""
    m, d = kin.model, kin.data
    pin.computeJointJacobians(m, d, kin.q_full(np.zeros(kin.n_joints)))
    pin.updateFramePlacements(m, d)
    R_WB = d.oMf[kin.pelvis_frame].rotation
    out = []
    for name in names:
        j = m.getJointId(name)
        axis = pin.getJointJacobian(m, d, j, pin.ReferenceFrame.LOCAL)[3:, m.joints[j].idx_v]
        out.append(R_WB.T @ d.oMi[j].rotation @ axis)
    return np.array(out)
