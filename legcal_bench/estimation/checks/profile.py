"""The offsets the data checks judge a session at when no calibration is given
(`legcal-bench check` without `--result`).

Offsets of a few degrees move the soles' relative pose by tens of millimetres and
degrees, which the checks would read as soles off one plane, a slide or a wrong IMU
mount. They are profiled out: the framework's own inter-foot fit of the same recordings
(declared-noise row weights, solve, trim, solve; no generalized least squares), the
estimate the checks then judge at beside the raw encoders, as they judge a
calibrator's. A defect the checks look for shows in both (the checks keep the better
fit); when the fit cannot run, the raw encoders alone, and the note says so.
"""

from __future__ import annotations

import numpy as np

from legcal_bench.data.recording import Recording
from legcal_bench.errors import CalibrationError
from legcal_bench.estimation.problem.stance import StanceProblem, prepare_sensor
from legcal_bench.robots.legmap import LegMap


def profiled_offsets(legmap: LegMap, recordings: list[Recording]) -> tuple[np.ndarray | None, str]:
    """(offsets in rad or None, a note for the report) of `recordings` (the training
    kinds are used: stances, standing)."""
    training = [r for r in recordings if r.kind in ("stance", "standing")]
    try:
        prep = prepare_sensor(legmap, training)
        dq, _, _ = StanceProblem.of(prep).solve_trimmed(np.zeros(legmap.n_joints), prep.options)
    except CalibrationError as e:
        return None, (f"offsets not profiled out ({e}); the checks judge the raw encoders alone, which offsets of a "
                      "few degrees move by tens of millimetres: give --result for a calibration of these recordings")
    return dq, ("offsets profiled out: the checks judge the raw encoders and the framework's inter-foot fit of these "
                "recordings (no --result given), the better of the two")
