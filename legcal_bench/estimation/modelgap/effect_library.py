"""The effect library (issue #16): the model gaps a leg calibration most often meets,
each an `Effect` plug-in (entry-point group `legcal_bench.effects`).

  leg_length     thigh and shank length per leg (m): the link from the last hip joint's
                 anchor to the knee's, and from the knee's to the first ankle joint's,
                 lengthened along that line
  encoder_scale  scale error of hip pitch, knee and ankle pitch encoders per leg: the true
                 angle is (1 + s) q_enc + offset
  compliance     series compliance (rad per N m) of hip roll, knee and ankle pitch per leg:
                 the link sits c tau away from the motor the encoder reads, tau the joint's
                 load from that leg's ankle force/torque wrench plus the weight of the
                 links between the joint and the sensor (`joint_loads`)
  imu_tilt       the IMU's mounting tilt about its x (roll) and y (pitch) axes (rad)
  hip_axis       the hip-pitch axis of each leg rotated about the hip's x and z axes (rad)

Which of these parameters the data can separate from the offsets is not written here:
the confound report (`legcal_bench.estimation.modelgap.confounds`) computes it for the robot and
data at hand (the IMU pitch tilt, for one, is equal hip-pitch offsets on a pitch-first
hip, and separable on a roll-first one).
"""

from __future__ import annotations

import numpy as np

from legcal_bench.estimation.modelgap.effects import Effect, SegmentData, joint_loads
from legcal_bench.errors import CalibrationError
from legcal_bench.robots.chain import link_direction
from legcal_bench.robots.design import PITCH_ROLES
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots.legmap import SIDES

COMPLIANT = ("hip_roll", "knee", "ankle_pitch")
# Admissible values (`Effect.bounds`): what a build or a mounting can plausibly be off by.
# Beyond them a fitted value is not the effect but something it is absorbing.
LENGTH_TOLERANCE = 0.010  # m: a link's length off by at most 1 cm
SCALE_TOLERANCE = 0.05  # an encoder's scale off by at most 5 %
MAX_COMPLIANCE = 1e-3  # rad/(N m): a joint no softer than 1000 N m/rad; and never negative
TILT_TOLERANCE = np.deg2rad(5.0)  # rad: an IMU mounted at most 5 deg off
AXIS_TOLERANCE = np.deg2rad(3.0)  # rad: a joint axis at most 3 deg off


def _role_joints(kin: LegKinematics, roles) -> list[tuple[str, int]]:
    """(label, leg-map index) of each joint with one of `roles`, left leg then right."""
    out = []
    for i, role in enumerate(kin.legmap.joint_roles):
        if role in roles:
            out.append((f"{kin.legmap.side_of(i)}_{role}", i))
    return out


class LegLength(Effect):
    name = "leg_length"
    summary = "thigh and shank length per leg"
    remedy = "stances with a wider range of knee angles (or a measured leg length: a tape or a motion-capture pose)"

    def _links(self, kin: LegKinematics):
        out = []
        for s in SIDES:
            chain = [kin.legmap.joint_roles[int(c)] for c in kin.poe[s].cols]
            knee = chain.index("knee")
            if knee == 0 or knee == len(chain) - 1:
                raise CalibrationError(f"effect {self.name}: the knee must have joints on both sides in the chain")
            out += [(f"{s}_thigh", s, knee), (f"{s}_shank", s, knee + 1)]
        return out

    def parameters(self, kin):
        return [(name, "m") for name, _, _ in self._links(kin)]

    def bounds(self, kin):
        return [(-LENGTH_TOLERANCE, LENGTH_TOLERANCE)] * len(self._links(kin))

    def factors(self, kin):
        links = self._links(kin)
        out = []
        for i, (_, s, k) in enumerate(links):
            gens = np.zeros((len(links), 6))
            gens[i, :3] = link_direction(kin.poe[s], k)
            out.append((s, 2 * k - 1, gens))  # after E_{k-1}: joint k's anchor moves along the link
        return out


class EncoderScale(Effect):
    name = "encoder_scale"
    summary = "encoder scale of hip pitch, knee and ankle pitch per leg"
    remedy = ("stances spanning a wider range of each pitch joint's angle (the range stance: collect --stances I II "
              "III IV tall; the load-varied protocol, push press, parts it from compliance)")

    def parameters(self, kin):
        return [(label, "1") for label, _ in _role_joints(kin, PITCH_ROLES)]

    def bounds(self, kin):
        return [(-SCALE_TOLERANCE, SCALE_TOLERANCE)] * len(_role_joints(kin, PITCH_ROLES))

    def joint_map(self, kin, seg: SegmentData):
        joints = _role_joints(kin, PITCH_ROLES)
        A = np.zeros((len(seg.q_enc), kin.legmap.n_joints, len(joints)))
        for p, (_, j) in enumerate(joints):
            A[:, j, p] = seg.q_enc[:, j]
        return A


class Compliance(Effect):
    name = "compliance"
    summary = "series compliance of hip roll, knee and ankle pitch per leg (load from the ankle F/T)"
    remedy = ("a load-varied protocol: stances pushing the feet apart and together and pitching against the floor, "
              "measured by the ankle F/T sensors (collect --stances I II III IV push press)")
    needs_ft = True

    def parameters(self, kin):
        return [(label, "rad/(N m)") for label, _ in _role_joints(kin, COMPLIANT)]

    def bounds(self, kin):
        return [(0.0, MAX_COMPLIANCE)] * len(_role_joints(kin, COMPLIANT))

    def joint_map(self, kin, seg: SegmentData):
        if seg.ft is None or seg.up_B is None:
            raise CalibrationError(f"effect {self.name}: the recordings have no ankle force/torque wrenches (ft); "
                                   "a joint's load cannot be known without them")
        # Loads at the best angles known (the encoders corrected by the current offsets):
        # a lever arm computed at angles a few degrees off is off by ~10 %.
        tau = joint_loads(kin, seg.q_enc if seg.q_ref is None else seg.q_ref, seg.ft, seg.up_B)
        joints = _role_joints(kin, COMPLIANT)
        A = np.zeros((len(seg.q_enc), kin.legmap.n_joints, len(joints)))
        for p, (_, j) in enumerate(joints):
            A[:, j, p] = tau[:, j]
        return A


class ImuTilt(Effect):
    name = "imu_tilt"
    summary = "IMU mounting tilt about its x (roll) and y (pitch) axes"
    remedy = "an inclinometer on the pelvis (or standing on a surface whose level is known)"

    def parameters(self, kin):
        return [("roll", "rad"), ("pitch", "rad")]

    def bounds(self, kin):
        return [(-TILT_TOLERANCE, TILT_TOLERANCE)] * 2

    def imu_axes(self, kin):
        return np.eye(3)[:2]


class HipAxis(Effect):
    name = "hip_axis"
    summary = "hip-pitch axis of each leg rotated about the hip's x and z axes"
    remedy = "stances combining hip pitch with hip roll and yaw excursions"

    def _joints(self, kin):
        out = []
        for s in SIDES:
            chain = [kin.legmap.joint_roles[int(c)] for c in kin.poe[s].cols]
            out.append((s, chain.index("hip_pitch")))
        return out

    def parameters(self, kin):
        return [(f"{s}_about_{a}", "rad") for s, _ in self._joints(kin) for a in ("x", "z")]

    def bounds(self, kin):
        return [(-AXIS_TOLERANCE, AXIS_TOLERANCE)] * 4

    def factors(self, kin):
        out = []
        for i, (s, k) in enumerate(self._joints(kin)):
            gens = np.zeros((4, 6))
            gens[2 * i, 3], gens[2 * i + 1, 5] = 1.0, 1.0  # rotations about the joint frame's x and z
            out += [(s, 2 * k, gens), (s, 2 * k + 1, -gens)]  # R after M_k, R^-1 after E_k
        return out
