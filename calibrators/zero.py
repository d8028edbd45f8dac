"""The floor every method must beat: no correction at all."""

from __future__ import annotations

from legcal_bench.calibrators.base import CalibrationResult, Calibrator
from legcal_bench.data.recording import Recording
from legcal_bench.robots.legmap import LegMap


class ZeroCalibrator(Calibrator):
    name = "zero"

    def calibrate(self, robot: LegMap, recordings: list[Recording]) -> CalibrationResult:
        return CalibrationResult(calibrator=self.name, robot=robot.name,
                                 offsets_rad={n: 0.0 for n in robot.joint_names},
                                 pitch_sums_rad={"left": 0.0, "right": 0.0, "right_minus_left": 0.0},
                                 timing_s={"total": 0.0})
