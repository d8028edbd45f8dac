"""The hold check: did the robot hold the commanded posture, with both soles planted?

A recording is static double-support data only if the robot did what it was told.
Each simulated segment is checked against documented limits:

  pelvis  more than 5 % of the leg length from its commanded pose (47 mm on the
          A3-like robot) beyond what the offsets' strain explains. The commanded
          pose is where the servo targets put the pelvis on the simulated robot's
          kinematics, from each sole's actual pose (the midpoint of the two legs'
          predictions). With offsets the two legs' targets disagree (the closed
          chain's strain): the pelvis settles at their compromise, the joint angles
          nearest the targets (weighed by the servos' stiffness) that put both
          soles where they are, which stiffer servos do not move. Its distance from
          the midpoint is `pelvis_strain_m`; the pelvis is judged by its distance
          from the compromise (`pelvis_beyond_strain_m`: sag, folding, tipping).
          Position servos without gravity feed-forward settle below their targets
          under the robot's weight: the built-ins' servos (kp 500-2000 N m/rad) hold
          the stances within about 2 % of the leg length (up to 20 mm), servos 2.5x
          softer sag up to 320 mm and 5x softer fold by 210-1080 mm. (A 5 mm limit
          would reject the built-ins' own sag, which costs the calibration nothing:
          the encoders read the sagged angles.)
  sole    a sole moving more than 2 mm (lift or slip) or rotating more than 1 deg from
          its pose after settling (contact mode; welded soles cannot move): tipping onto
          an edge, or turning about its normal (a twist: the legs' strain about the
          vertical beats the floor's friction), which the message tells apart; a sole
          more than 50 mm away or turned more than 30 deg fell with the robot.

Measured by `DoubleSupportSim` (ground truth, never given to calibrators); checked by
the collector, which names the stance, what moved, the likely cause and the fix.
Kinematic mode has no physics and always holds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class HoldLimits:
    pelvis_leg_fraction: float = 0.05
    sole_move_m: float = 0.002
    sole_tilt_rad: float = float(np.deg2rad(1.0))


HOLD_LIMITS = HoldLimits()
STRAIN_SHOWN_M = 5e-4  # a smaller strain is left out of the pelvis's failure message
FALL_MOVE_M, FALL_TILT_RAD = 0.05, float(np.deg2rad(30.0))  # beyond either, a sole fell with the robot
# A rigidly held non-leg joint (`legcal_bench.robots.holds`) departs from its hold angle
# by less than this in a segment (the equality's stiffness against the joint's load); a
# servo hold's departure is its sag, reported, not limited.
RIGID_HOLD_LIMIT_RAD = float(np.deg2rad(0.1))


def held_joints_table(holds, max_error_rad: np.ndarray) -> list[dict]:
    """Each held non-leg joint (`JointHold`s, as simulated) with its largest departure
    from its hold angle over the recorded segments (`max_error_rad`, (h,)): the
    `sag_deg` of a servo hold, the `error_deg` of a rigid one (`within_limit` says
    whether it stayed inside RIGID_HOLD_LIMIT_RAD)."""
    out = []
    for h, e in zip(holds, np.asarray(max_error_rad, dtype=float)):
        d = h.to_dict()
        if h.how == "servo":
            d["sag_deg"] = float(np.rad2deg(e))
        else:
            d.update(error_deg=float(np.rad2deg(e)), within_limit=bool(e <= RIGID_HOLD_LIMIT_RAD))
        out.append(d)
    return out


@dataclass(frozen=True)
class HoldReport:
    """The largest excursions of one segment, and the limits they are held to."""

    pelvis_m: float  # the largest error from the commanded pose
    pelvis_limit_m: float
    sole_move_m: tuple[float, float]  # left, right
    sole_tilt_rad: tuple[float, float]
    limits: HoldLimits = HOLD_LIMITS
    pelvis_strain_m: float = 0.0  # how far the offsets' strain alone moves the commanded pose, largest
    pelvis_excess_m: float | None = None  # the largest distance from the strained pose (None: the error itself)
    sole_turn_rad: tuple[float, float] = (0.0, 0.0)  # of the tilt, the largest turn about the sole's normal

    @classmethod
    def from_truth(cls, truth: dict, leg_length: float, limits: HoldLimits = HOLD_LIMITS) -> "HoldReport":
        """From a segment's ground truth (`DoubleSupportSim.run`)."""
        err = np.asarray(truth["pelvis_hold_error_m"], dtype=float)
        strain = np.asarray(truth.get("pelvis_strain_m", np.zeros_like(err)), dtype=float)
        beyond = np.asarray(truth.get("pelvis_beyond_strain_m", err), dtype=float)
        return cls(float(np.max(err, initial=0.0)), limits.pelvis_leg_fraction * leg_length,
                   tuple(float(v) for v in np.max(truth["sole_drift_m"], axis=0, initial=0.0)),
                   tuple(float(v) for v in np.max(truth["sole_drift_rad"], axis=0, initial=0.0)), limits,
                   float(np.max(strain, initial=0.0)), float(np.max(beyond, initial=0.0)),
                   tuple(float(v) for v in np.max(truth.get("sole_turn_rad", np.zeros((1, 2))), axis=0, initial=0.0)))

    @property
    def pelvis_beyond_strain_m(self) -> float:
        return self.pelvis_m if self.pelvis_excess_m is None else self.pelvis_excess_m

    @property
    def fell(self) -> bool:
        """Whether the robot fell: a sole moved or turned far beyond anything standing does
        (FALL_MOVE_M, FALL_TILT_RAD), not a slip or an edge."""
        return max(self.sole_move_m) > FALL_MOVE_M or max(self.sole_tilt_rad) > FALL_TILT_RAD

    def failures(self) -> list[str]:
        """What moved beyond its limit, in words (empty: the robot held)."""
        if self.fell:
            side = int(np.argmax(self.sole_move_m))
            return [f"the robot fell: the {('left', 'right')[side]} sole moved {self.sole_move_m[side] * 1e3:.0f} mm "
                    f"and turned {np.rad2deg(self.sole_tilt_rad[side]):.0f} deg, the pelvis ended "
                    f"{self.pelvis_m * 1e3:.0f} mm from its commanded pose"]
        out = []
        if self.pelvis_beyond_strain_m > self.pelvis_limit_m:
            strain = (f", {self.pelvis_beyond_strain_m * 1e3:.1f} mm from where the offsets' strain of the closed "
                      f"chain puts it ({self.pelvis_strain_m * 1e3:.1f} mm from that pose)"
                      if self.pelvis_strain_m >= STRAIN_SHOWN_M else "")
            out.append(f"the pelvis was {self.pelvis_m * 1e3:.1f} mm from its commanded pose{strain} "
                       f"(limit {self.pelvis_limit_m * 1e3:.1f} mm, {100 * self.limits.pelvis_leg_fraction:g} % "
                       "of the leg length)")
        for side, move, tilt, turn in zip(("left", "right"), self.sole_move_m, self.sole_tilt_rad, self.sole_turn_rad):
            if move > self.limits.sole_move_m:
                out.append(f"the {side} sole moved {move * 1e3:.1f} mm (limit {self.limits.sole_move_m * 1e3:g} mm)")
            if tilt > self.limits.sole_tilt_rad:
                limit = f"(limit {np.rad2deg(self.limits.sole_tilt_rad):g} deg)"
                out.append(f"the {side} sole twisted on the floor: it turned {np.rad2deg(tilt):.2f} deg, "
                           f"{np.rad2deg(turn):.2f} of it about its normal {limit}" if self.twisted(tilt, turn) else
                           f"the {side} sole tilted {np.rad2deg(tilt):.2f} deg {limit}")
        return out

    @property
    def soles_failed(self) -> bool:
        """Whether a sole moved or rotated beyond its limit (a fall among them)."""
        return (max(self.sole_move_m) > self.limits.sole_move_m
                or max(self.sole_tilt_rad) > self.limits.sole_tilt_rad)

    @staticmethod
    def twisted(tilt: float, turn: float) -> bool:
        """Whether a sole's rotation is mostly a turn about its normal (a twist on the floor)."""
        return turn > 0.5 * tilt

    @property
    def soles_twisted(self) -> bool:
        """Whether every sole over its tilt limit turned about its normal rather than tipped."""
        over = [(t, u) for t, u in zip(self.sole_tilt_rad, self.sole_turn_rad) if t > self.limits.sole_tilt_rad]
        return bool(over) and all(self.twisted(t, u) for t, u in over)

    @property
    def held(self) -> bool:
        return not self.failures()

    def to_dict(self) -> dict:
        return {"held": self.held, "pelvis_mm": self.pelvis_m * 1e3, "pelvis_limit_mm": self.pelvis_limit_m * 1e3,
                "pelvis_strain_mm": self.pelvis_strain_m * 1e3, "pelvis_beyond_strain_mm": self.pelvis_beyond_strain_m * 1e3,
                "sole_move_mm": [v * 1e3 for v in self.sole_move_m],
                "sole_tilt_deg": [float(np.rad2deg(v)) for v in self.sole_tilt_rad],
                "sole_turn_deg": [float(np.rad2deg(v)) for v in self.sole_turn_rad]}
