"""One geometry description for the built-in humanoid legs.

A `LegDesign` says everything about a robot's lower body: link offsets, masses,
joint limits, servos and feet. `build.py` turns it into MJCF; the MJCF is then the
single source of truth that both MuJoCo and Pinocchio load. The built-in robots are
small edits of one base design (`dataclasses.replace`), so the matched pair differs
in exactly one field: the proximal hip ordering.

Conventions (left leg; the right leg mirrors every y coordinate and the roll/yaw
limits): x forward, y left, z up; hip pitch, knee and ankle pitch rotate about +y,
so a squat has hip pitch < 0, knee > 0, ankle pitch < 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from itertools import permutations

HIP_ROLES = ("hip_pitch", "hip_roll", "hip_yaw")
LEG_ROLES = HIP_ROLES + ("knee", "ankle_pitch", "ankle_roll")
# The parallel pitch chain of a leg: what orientation alone sees only as a sum.
PITCH_ROLES = ("hip_pitch", "knee", "ankle_pitch")
ROLE_AXIS = {
    "hip_pitch": (0.0, 1.0, 0.0),
    "hip_roll": (1.0, 0.0, 0.0),
    "hip_yaw": (0.0, 0.0, 1.0),
    "knee": (0.0, 1.0, 0.0),
    "ankle_pitch": (0.0, 1.0, 0.0),
    "ankle_roll": (1.0, 0.0, 0.0),
}
ROLE_AXIS_NAME = {role: "xyz"[axis.index(1.0)] for role, axis in ROLE_AXIS.items()}  # "y" for hip_pitch, ...

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class Servo:
    """A position servo: stiffness (N m/rad), damping (N m s/rad), torque limit (N m)."""

    kp: float
    kv: float
    torque_limit: float


@dataclass(frozen=True)
class LegDesign:
    name: str
    # The three proximal hip joints, from pelvis outwards: A3-like is
    # (hip_pitch, hip_roll, hip_yaw), A2-like is (hip_roll, hip_yaw, hip_pitch).
    hip_order: tuple[str, str, str]
    # Pelvis (with the lumped trunk; these robots have no upper-body joints).
    pelvis_mass: float = 28.0
    pelvis_com: Vec3 = (0.0, 0.0, 0.16)
    pelvis_box: Vec3 = (0.11, 0.14, 0.22)  # half sizes of the trunk block
    # Where each chain element sits in its parent, left leg. The hip offsets are
    # listed per chain slot, not per role: swapping hip_order keeps the geometry.
    hip_origin: Vec3 = (0.0, 0.095, -0.06)
    hip_slot_offsets: tuple[Vec3, Vec3] = ((0.0, 0.045, -0.025), (0.0, 0.0, -0.075))
    # Thigh: last hip joint to knee; shin: knee to ankle pitch. The millimetre-scale
    # lateral components are the wiring/structure offsets real legs have.
    thigh: Vec3 = (0.002, 0.004, -0.36)
    shin: Vec3 = (-0.001, -0.003, -0.36)
    ankle_gap: Vec3 = (0.0, 0.0, -0.012)  # ankle pitch to ankle roll axis
    sole_offset: Vec3 = (0.035, 0.001, -0.058)  # ankle roll axis to sole centre
    sole_half: tuple[float, float] = (0.115, 0.05)  # sole half length, half width
    sole_thickness: float = 0.02
    # Masses (kg) per chain slot: hip slot 1, hip slot 2, thigh, shin, ankle link, foot.
    masses: tuple[float, ...] = (1.6, 1.6, 4.6, 3.0, 0.35, 1.1)
    # Joint limits (rad) per role, left leg.
    limits: dict[str, tuple[float, float]] = field(
        default_factory=lambda: {
            "hip_pitch": (-2.4, 1.6),
            "hip_roll": (-0.45, 0.7),
            "hip_yaw": (-1.0, 1.0),
            "knee": (-0.08, 2.6),
            "ankle_pitch": (-0.9, 0.55),
            "ankle_roll": (-0.35, 0.35),
        }
    )
    # Joint-level position servos as stiff as a full-size humanoid's drives in position
    # mode, with torque limits of its actuators.
    servos: dict[str, Servo] = field(
        default_factory=lambda: {
            "hip_pitch": Servo(1500.0, 60.0, 150.0),
            "hip_roll": Servo(1500.0, 60.0, 150.0),
            "hip_yaw": Servo(800.0, 32.0, 90.0),
            "knee": Servo(2000.0, 80.0, 250.0),
            "ankle_pitch": Servo(800.0, 32.0, 100.0),
            "ankle_roll": Servo(500.0, 20.0, 60.0),
        }
    )
    armature: float = 0.03
    joint_damping: float = 0.2
    knee_straight_rad: float = 0.0
    imu_pos: Vec3 = (-0.02, 0.0, 0.08)  # pelvis IMU, in the pelvis frame
    ft_pos: Vec3 = (0.0, 0.0, -0.03)  # ankle F/T sensor site, in the foot body
    # Roles whose right-leg joint axis points the other way (-ROLE_AXIS; its limits
    # negated with it): mirrored servos, as many small robots mount them. The same
    # physical posture then has the opposite angle on that joint.
    flipped_axes: tuple[str, ...] = ()
    # Hip roll and yaw axes canted by this angle (rad) about the pelvis y axis, both
    # legs: x -> (cos, 0, -sin), z -> (sin, 0, cos).
    hip_cant: float = 0.0
    # Roles the leg does not have ("ankle_roll": a leg of five joints whose foot hangs
    # from the ankle pitch, at the same place, with the ankle link's mass).
    absent_roles: tuple[str, ...] = ()
    # The two ankle joints from shin to foot: pitch then roll (the built-ins), or roll
    # then pitch (an ankle whose roll axis is the proximal one).
    ankle_order: tuple[str, str] = ("ankle_pitch", "ankle_roll")
    # The sole's collision shape: "box" (one box the sole's size), or "capsule" (a toe box
    # over the sole's front half and, behind it, the heel as one capsule on the foot's
    # centre line, lying along it: the heel touches the floor along a line, not a face).
    heel: str = "box"

    @property
    def roles(self) -> tuple[str, ...]:
        """The leg's roles from pelvis to foot."""
        return tuple(r for r in self.hip_order + ("knee", *self.ankle_order) if r not in self.absent_roles)

    @property
    def foot_sole_offset(self) -> Vec3:
        """The sole centre in the foot body (the last joint's body)."""
        if "ankle_roll" not in self.absent_roles:
            return self.sole_offset
        return tuple(a + b for a, b in zip(self.ankle_gap, self.sole_offset))  # type: ignore[return-value]

    @property
    def foot_mass(self) -> float:
        return self.masses[5] + (self.masses[4] if "ankle_roll" in self.absent_roles else 0.0)

    def axis(self, role: str, side: str) -> Vec3:
        """The joint axis of `role` on `side`, in its body's frame (= the pelvis frame
        at zero angles)."""
        import math

        x, y, z = ROLE_AXIS[role]
        if self.hip_cant and role in ("hip_roll", "hip_yaw"):
            c, s = math.cos(self.hip_cant), math.sin(self.hip_cant)
            x, z = c * x + s * z, -s * x + c * z
        sign = -1.0 if side == "right" and role in self.flipped_axes else 1.0
        return (round(sign * x, 12) + 0.0, round(sign * y, 12) + 0.0, round(sign * z, 12) + 0.0)

    def scaled(self, name: str, length: float, mass: float) -> "LegDesign":
        """The same design with every length times `length` and mass times `mass`."""

        def s(v: Vec3) -> Vec3:
            return tuple(length * x for x in v)  # type: ignore[return-value]

        return replace(
            self,
            name=name,
            pelvis_mass=self.pelvis_mass * mass,
            pelvis_com=s(self.pelvis_com),
            pelvis_box=s(self.pelvis_box),
            hip_origin=s(self.hip_origin),
            hip_slot_offsets=(s(self.hip_slot_offsets[0]), s(self.hip_slot_offsets[1])),
            thigh=s(self.thigh),
            shin=s(self.shin),
            ankle_gap=s(self.ankle_gap),
            sole_offset=s(self.sole_offset),
            sole_half=(self.sole_half[0] * length, self.sole_half[1] * length),
            masses=tuple(m * mass for m in self.masses),
            servos={
                r: Servo(v.kp * mass * length, v.kv * mass * length, v.torque_limit * mass * length)
                for r, v in self.servos.items()
            },
            imu_pos=s(self.imu_pos),
            ft_pos=s(self.ft_pos),
        )


P_R_Y = ("hip_pitch", "hip_roll", "hip_yaw")
R_Y_P = ("hip_roll", "hip_yaw", "hip_pitch")

BASE = LegDesign(name="base", hip_order=P_R_Y)

# A3-like: pitch->roll->yaw, a 1.6 m class humanoid (~55 kg) with a shorter thigh
# than shin and a heavier trunk.
A3 = replace(BASE, name="a3", hip_order=P_R_Y, thigh=(0.002, 0.004, -0.34), shin=(-0.001, -0.003, -0.37),
             pelvis_mass=30.0, hip_origin=(0.0, 0.09, -0.055))
# A2-like: roll->yaw->pitch, a larger 1.7 m class humanoid (~66 kg) with its own
# proportions (longer thigh, wider hips).
A2 = replace(
    BASE.scaled("a2", length=1.08, mass=1.25),
    hip_order=R_Y_P,
    thigh=(0.001, 0.005, -0.40),
    hip_origin=(0.0, 0.105, -0.065),
)
# The controlled comparison: the base design, identical in every field but the hip ordering.
PAIR_RYP = replace(BASE, name="pair_ryp", hip_order=R_Y_P)
PAIR_PRY = replace(BASE, name="pair_pry", hip_order=P_R_Y)

DESIGNS: dict[str, LegDesign] = {d.name: d for d in (A2, A3, PAIR_RYP, PAIR_PRY)}


# Generated test robots: the A3-like body with any of the six proximal hip orders, soft
# uniform servos (kp N m/rad, kd = 0.04 s kp) and a narrow symmetric ankle-pitch range:
# the robots published models are, which the built-ins are not.
HIP_ORDERS: tuple[tuple[str, str, str], ...] = tuple(permutations(HIP_ROLES))  # type: ignore[assignment]
GENERATED_KP = (10.0, 30.0, 100.0)
GENERATED_ANKLE_DEG = (25.0, 35.0)


def generated_design(hip_order: tuple[str, str, str], kp: float, ankle_pitch_deg: float,
                     base: LegDesign = A3) -> LegDesign:
    """`base` with `hip_order`, every servo at `kp` (kd 0.04 s kp, torque limits kept) and
    ankle pitch limited to +-`ankle_pitch_deg`, named e.g. gen_ryp_kp30_ankle25."""
    import math

    order = "".join(r[len("hip_")] for r in hip_order)
    lim = math.radians(ankle_pitch_deg)
    return replace(base, name=f"gen_{order}_kp{kp:g}_ankle{ankle_pitch_deg:g}", hip_order=tuple(hip_order),
                   servos={r: Servo(kp, 0.04 * kp, s.torque_limit) for r, s in base.servos.items()},
                   limits={**base.limits, "ankle_pitch": (-lim, lim)})


def stiff_twin(design: LegDesign, base: LegDesign = A3) -> LegDesign:
    """`design` with `base`'s stiff servos: the same robot, servos that hold."""
    return replace(design, name=design.name + "_stiff", servos=dict(base.servos))


# Six robots covering every hip order once and every (kp, ankle range) pair once.
GENERATED: tuple[LegDesign, ...] = tuple(
    generated_design(order, GENERATED_KP[i % 3], GENERATED_ANKLE_DEG[i % 2]) for i, order in enumerate(HIP_ORDERS))


# Robots as third parties build them (issue #37), each one change from A3-like: right-leg
# pitch servos mounted mirrored; hip roll and yaw axes canted 45 degrees; a kid-size
# robot (0.3 m legs, ~3 kg, servos scaled with it) with mirrored pitch servos; legs of
# five joints (no ankle roll: the foot hangs from the ankle pitch).
VARIATIONS: tuple[LegDesign, ...] = (
    replace(A3, name="a3_mirrored_pitch", flipped_axes=PITCH_ROLES),
    replace(A3, name="a3_canted_hips", hip_cant=0.7853981633974483),
    replace(A3.scaled("kid_size", length=0.321, mass=0.055), flipped_axes=PITCH_ROLES),
    replace(A3, name="five_joint", absent_roles=("ankle_roll",)),
)
# Issue #59's generated test robot: the A3-like robot with its ankle roll before its
# ankle pitch (the same chain slots: the roll axis where the pitch axis was).
ROLL_FIRST_ANKLE = replace(A3, name="a3_roll_first_ankle", ankle_order=("ankle_roll", "ankle_pitch"))


# Issue #60's stand-ins for robots unlike ours on a contact floor: a leg of five joints
# whose heel is one capsule on the foot's centre line (no ankle roll to level the sole, a
# heel that rolls); a heavy full-size robot (~90 kg, legs 1.2x the A3-like's) with servos
# soft for its weight; a
# roll-yaw-pitch hip with its roll and yaw axes canted 45 degrees.
# (The heavy robot's servo stiffness is scaled with its mass, not with mass x length as
# its gravity load is: 0.83x the A3-like's stiffness against its weight.)
STAND_INS: tuple[LegDesign, ...] = (
    replace(A3, name="five_joint_capsule_heel", absent_roles=("ankle_roll",), heel="capsule"),
    replace(A3.scaled("heavy_full_size", length=1.2, mass=1.65),
            servos={r: Servo(s.kp * 1.65, s.kv * 1.65, s.torque_limit * 1.65 * 1.2) for r, s in A3.servos.items()}),
    replace(A3, name="ryp_canted_hips", hip_order=R_Y_P, hip_cant=0.7853981633974483),
)

# Every generated robot by name (what `legcal_bench.robots.build.write_designs` writes).
GENERATED_DESIGNS: dict[str, LegDesign] = {d.name: d for d in (*VARIATIONS, *GENERATED, *STAND_INS, ROLL_FIRST_ANKLE)}
