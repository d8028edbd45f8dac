"""The one error family of legcal-bench.

Every error a user can cause (a bad leg map, recording, option, robot or request)
is a `LegcalError`; its message names the field and the fix. The CLI turns these,
and only these, into exit code 2 with the message. Anything else is a bug in
legcal-bench (or a library under it) and propagates with its traceback.
"""

from __future__ import annotations


class LegcalError(Exception):
    """Base class: bad input, with a message naming the field and the fix."""


class ConfigError(LegcalError):
    """A bad argument or option: unknown suite, stance, mode, preset, option value."""


class LegMapError(LegcalError):
    """A leg map (or robot reference) that cannot be used."""


class MissingModelError(LegMapError):
    """The robot's MJCF file is not where its leg map says (e.g. an example robot
    outside a checkout); suites skip such robots with this message."""


class OffsetSpecError(LegcalError):
    """An offsets specification that is not understood."""


class SensorModelError(LegcalError):
    """A sensor model (preset name or declared fields) that cannot be used."""


class RecordingError(LegcalError):
    """A recording that cannot be used; the message names the file, the field and the fix."""


class IKError(LegcalError):
    """The requested posture is out of reach (or beyond the joint limits)."""


class CalibrationError(LegcalError):
    """The data cannot determine a calibration; the message says why and what to record."""


class HoldError(LegcalError):
    """The simulated robot did not hold a posture (it folded, tipped or slid): its
    recording would not be static double-support data. The message names the stance,
    what moved, the likely cause and the leg-map field that fixes it; `report` is the
    hold check's `HoldReport` where the check raised it (None otherwise, and after
    crossing a process boundary)."""

    def __init__(self, message: str, report=None):
        super().__init__(message)
        self.report = report


class SimulationError(HoldError):
    """The simulation itself failed (it diverged or shook: its state is not a robot
    standing still), which no recording check should be left to find: the message names
    the segment, what diverged and the body moving fastest, as a simulation fault."""


class LogImportError(LegcalError):
    """A robot log or its mapping file that cannot be imported; the message names the
    mapping field (or the log, topic, column) and the fix."""


class NestedFitError(RuntimeError):
    """A model fitted with more parameters ended above the model it extends
    (`legcal_bench.evaluation.modelgap.nested`): a bug in the fit, not in the data or the
    user's input (the extended fit starts at the smaller one's optimum and only ever
    steps downhill), hence not a `LegcalError`."""
