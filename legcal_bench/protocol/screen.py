"""The hold screen: simulate a candidate stance before a protocol asks a robot for it.

Stance design (`legcal_bench.estimation.design`) predicts information from the
kinematics alone; whether the robot holds a stance is a question for the physics. The
screen records the stance as `collect` would (the same fitting, placement and posture
motion, `record_segment`) in each physics mode, for a few seeds, each with the bench's
injected condition on the encoders (factory offsets drawn as the bench draws them,
plus the paper's injection) and the held-out sessions' placement jitter (the largest
`collect` draws), and for two extreme cases (the factory offsets at their bound with
the injection's signs, and against them). It holds the worst excursion to the hold
check's limits (`legcal_bench.sim.hold`) scaled by `HOLD_MARGIN`, for the seeds it did
not draw. (Issue #12: designed stances chosen without a screen failed the hold check
in 5 of 50 injected session sets, the pelvis sagging 49-61 mm against limits of
47-52 mm; screened on four seeds within 0.8 of the limits, in 1 of 50, 48.3 mm against
46.8 mm: one stance's sag varies with the motion's phases from 19 to 46 mm over 24
seeds.)
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from legcal_bench.errors import ConfigError
from legcal_bench.protocol.collect import CollectConfig, record_segment
from legcal_bench.protocol.servos import servo_gains
from legcal_bench.protocol.stances import ALL_STANCES, Stance
from legcal_bench.robots.legmap import LegMap
from legcal_bench.sim.double_support import DoubleSupportSim
from legcal_bench.sim.hold import HOLD_LIMITS, HoldReport
from legcal_bench.sim.offsets import resolve_offsets
from legcal_bench.sim.sensors import sim_sensors

# The screen's limits, as a fraction of the hold check's: the pelvis excursion of one
# stance varies with the motion's random phases by more than 2x across seeds (A3-like,
# a designed stance, the same offsets: 19-46 mm over 24 seeds), so the worst of a few
# seeds is held well inside the limit.
HOLD_MARGIN = 0.75
SCREEN_MODES = ("contact", "weld")  # contact first: a stance that tips over fails fastest
SCREEN_SEEDS = tuple(range(8))


@dataclass(frozen=True)
class ScreenReport:
    """The worst hold excursion of one stance per mode, against the screen's limits."""

    stance: str
    reports: dict  # mode -> HoldReport (worst pelvis / sole excursion over the cases; up to the first failure)

    @property
    def held(self) -> bool:
        return all(r.held for r in self.reports.values())

    def failures(self) -> list[str]:
        return [f"{mode}: {f}" for mode, r in self.reports.items() for f in r.failures()]

    def to_dict(self) -> dict:
        return {"stance": self.stance, "held": self.held,
                **{mode: r.to_dict() for mode, r in self.reports.items()}}


class HoldScreen:
    """Simulates stances on one robot; one simulator per mode and case, built once.
    `native`: the factory offsets the bench draws (`legcal_bench.benchmark.plan.NATIVE`)."""

    def __init__(self, legmap: LegMap, native: str, modes: tuple[str, ...] = SCREEN_MODES,
                 seeds: tuple[int, ...] = SCREEN_SEEDS, duration_s: float = 12.0, margin: float = HOLD_MARGIN):
        if not 0 < margin <= 1:
            raise ConfigError(f"margin {margin!r}: use a fraction of the hold check's limits in (0, 1] (--margin)")
        self.legmap, self.seeds, self.duration_s, self.margin = legmap, tuple(seeds), duration_s, margin
        self.limits = replace(HOLD_LIMITS, pelvis_leg_fraction=HOLD_LIMITS.pelvis_leg_fraction * margin,
                              sole_move_m=HOLD_LIMITS.sole_move_m * margin,
                              sole_tilt_rad=HOLD_LIMITS.sole_tilt_rad * margin)
        gains = servo_gains(legmap)
        paper = resolve_offsets("paper", legmap, np.random.default_rng(0))
        cases = {seed: resolve_offsets(native, legmap, np.random.default_rng(seed)) for seed in self.seeds}
        if native.startswith("random:"):  # the bound, with the injection's signs and against them
            bound = np.deg2rad(float(native.split(":", 1)[1]))
            cases.update({-1: bound * np.sign(paper), -2: -bound * np.sign(paper)})
        self.cases = tuple(cases)
        self.sims = {(mode, case): DoubleSupportSim(legmap, mode, paper + dq, sim_sensors("zero"), servo_gains=gains)
                     for mode in modes for case, dq in cases.items()}
        self.modes = tuple(modes)
        jit = CollectConfig()
        self.jitter = (jit.heldout_jitter_m, jit.heldout_jitter_rad)

    def __call__(self, stance: Stance) -> ScreenReport:
        """The stance's worst excursions; a stance stops being simulated once it fails."""
        catalog = {**ALL_STANCES, stance.name: stance}
        reports = {}
        for mode in self.modes:
            worst = None
            for case in self.cases:
                sim = self.sims[mode, case]
                seg = record_segment(sim, stance.name, self.duration_s, abs(case), *self.jitter, catalog=catalog)
                r = HoldReport.from_truth(seg.truth, sim.true_kin.dims.leg_length, self.limits)
                worst = r if worst is None else HoldReport(
                    max(worst.pelvis_m, r.pelvis_m), r.pelvis_limit_m,
                    tuple(np.maximum(worst.sole_move_m, r.sole_move_m).tolist()),
                    tuple(np.maximum(worst.sole_tilt_rad, r.sole_tilt_rad).tolist()), self.limits)
                if not worst.held:
                    return ScreenReport(stance.name, {**reports, mode: worst})
            reports[mode] = worst
        return ScreenReport(stance.name, reports)
