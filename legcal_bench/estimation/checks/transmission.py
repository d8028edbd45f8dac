"""Leg joints the model couples to another joint (a drive joint, a gear, a URDF mimic).

A joint equality `joint = c0 + c1 drive` in the model says the leg joint is turned through
another joint. Its encoder may then sit on the drive (the motor's side), reading the
drive's angle, not the joint's; legcal-bench reads every encoder column as its leg
joint's angle and does not convert through transmissions yet. A result on such a robot
says so (`DOUBTS`: look before applying it): right if the encoders read the joints'
outputs, off by the transmission if they read the motors.
"""

from __future__ import annotations

from legcal_bench.estimation.verdict import DOUBTS, Finding
from legcal_bench.robots.holds import joint_couplings
from legcal_bench.robots.kinematics import LegKinematics


def coupled_leg_joints(kin: LegKinematics) -> list[Finding]:
    legs = set(kin.legmap.joint_names)
    out = []
    for c in joint_couplings(kin.legmap.mjcf):
        if c.joint in legs or c.drive in legs:
            leg, other = (c.joint, c.drive) if c.joint in legs else (c.drive, c.joint)
            out.append(Finding(
                f"leg joint {leg} is coupled to joint {other} in the model ({c.joint} = {c.polycoef[0]:g} + "
                f"{c.polycoef[1]:g} {c.drive}{' + higher terms' if any(c.polycoef[2:]) else ''}): its encoder column "
                f"was read as {leg}'s own angle; if the robot's encoder sits on {other} (the motor's side), convert "
                f"the column to {leg}'s angle through the coupling before calibrating (legcal-bench does not read "
                "transmissions yet)", DOUBTS))
    return out
