"""The hold check: did the robot hold the commanded posture, with both soles planted?

A recording is static double-support data only if the robot did what it was told.
Each simulated segment is checked against documented limits:

  pelvis  more than 5 % of the leg length from its commanded pose (47 mm on the
          A3-like robot). The commanded pose is where the servo targets put the
          pelvis on the simulated robot's kinematics, from each sole's actual pose
          (the midpoint of the two legs' predictions: with offsets the two legs
          disagree by the closed-chain strain, 3-16 mm on the built-ins).
          Position servos without gravity feed-forward settle below their targets
          under the robot's weight: the built-ins' servos (kp 500-2000 N m/rad) hold
          the stances within about 2 % of the leg length (up to 20 mm), servos 2.5x
          softer sag up to 320 mm and 5x softer fold by 210-1080 mm. (A 5 mm limit
          would reject the built-ins' own sag, which costs the calibration nothing:
          the encoders read the sagged angles.)
  sole    a sole moving more than 2 mm (lift or slip) or tilting more than 1 deg from
          its pose after settling (contact mode; welded soles cannot move).

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


@dataclass(frozen=True)
class HoldReport:
    """The largest excursions of one segment, and the limits they are held to."""

    pelvis_m: float
    pelvis_limit_m: float
    sole_move_m: tuple[float, float]  # left, right
    sole_tilt_rad: tuple[float, float]
    limits: HoldLimits = HOLD_LIMITS

    @classmethod
    def from_truth(cls, truth: dict, leg_length: float, limits: HoldLimits = HOLD_LIMITS) -> "HoldReport":
        """From a segment's ground truth (`DoubleSupportSim.run`)."""
        return cls(float(np.max(truth["pelvis_hold_error_m"], initial=0.0)), limits.pelvis_leg_fraction * leg_length,
                   tuple(float(v) for v in np.max(truth["sole_drift_m"], axis=0, initial=0.0)),
                   tuple(float(v) for v in np.max(truth["sole_drift_rad"], axis=0, initial=0.0)), limits)

    def failures(self) -> list[str]:
        """What moved beyond its limit, in words (empty: the robot held)."""
        out = []
        if self.pelvis_m > self.pelvis_limit_m:
            out.append(f"the pelvis was {self.pelvis_m * 1e3:.1f} mm from its commanded pose "
                       f"(limit {self.pelvis_limit_m * 1e3:.1f} mm, {100 * self.limits.pelvis_leg_fraction:g} % "
                       "of the leg length)")
        for side, move, tilt in zip(("left", "right"), self.sole_move_m, self.sole_tilt_rad):
            if move > self.limits.sole_move_m:
                out.append(f"the {side} sole moved {move * 1e3:.1f} mm (limit {self.limits.sole_move_m * 1e3:g} mm)")
            if tilt > self.limits.sole_tilt_rad:
                out.append(f"the {side} sole tilted {np.rad2deg(tilt):.2f} deg "
                           f"(limit {np.rad2deg(self.limits.sole_tilt_rad):g} deg)")
        return out

    @property
    def held(self) -> bool:
        return not self.failures()

    def to_dict(self) -> dict:
        return {"held": self.held, "pelvis_mm": self.pelvis_m * 1e3, "pelvis_limit_mm": self.pelvis_limit_m * 1e3,
                "sole_move_mm": [v * 1e3 for v in self.sole_move_m],
                "sole_tilt_deg": [float(np.rad2deg(v)) for v in self.sole_tilt_rad]}
