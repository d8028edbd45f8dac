"""The Python API: what the CLI does, in a few lines of a script, each call returning
the object the matching command writes. `import legcal_bench` stays light: these load
(with MuJoCo, Pinocchio, scipy) on first use, through the package's `__getattr__`.

    import legcal_bench as lb

    lb.collect("runs/api/set", robot="a3", sensors="realistic", seed=0)  # legcal-bench collect
    lb.import_log(["robot.mcap"], "mapping.yaml", "runs/api/log", robot="my_robot.legmap.yaml")  # import
    result = lb.calibrate("runs/api/set", robot="a3")                    # legcal-bench calibrate
    result.save("runs/api/result.json")
    scores = lb.score("runs/api/set", result)                            # legcal-bench score --json
    report = lb.diagnose("runs/api/set", robot="a3", result=result)      # legcal-bench diagnose
    w = lb.walk(robot="a3", policy="a3", offsets="paper@3", seconds=5)   # legcal-bench walk
    summary, trials = lb.walk_eval(robot="a3", policy="a3", trials=2)    # legcal-bench walk-eval

Robots are named as on the command line: a built-in name or a leg-map YAML path, or a
`LegMap`. Calibrator options are keyword arguments, as the constructor takes them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from legcal_bench.calibrators.base import CalibrationResult, calibrate_training
from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import Recording, load_session
from legcal_bench.robots import load_robot
from legcal_bench.robots.legmap import LegMap

__all__ = ["collect", "import_log", "load", "calibrate", "score", "diagnose", "walk", "walk_eval"]


def _robot(robot) -> LegMap:
    return robot if isinstance(robot, LegMap) else load_robot(robot)


def collect(out: str | Path, robot: str = "a3", **config):
    """Simulate a session set into folder `out` (`legcal-bench collect`); `config` takes
    the fields of `legcal_bench.protocol.collect.CollectConfig` (mode, sensors, seed,
    offsets, stances, heldout, stance_s, ...). Returns the `CollectSummary`."""
    from legcal_bench.protocol.collect import CollectConfig, collect as _collect

    return _collect(CollectConfig(robot=robot, **config), out, progress=False)


def import_log(logs: list[str | Path], mapping: str | Path, out: str | Path, robot: str | LegMap = "a3",
               heldout: list[str] | None = None, ranges: list[tuple[float, float]] | None = None, plot: bool = True):
    """A robot's log (bags or tables) through its mapping file into the session folder
    `out` (`legcal-bench import`): the static double-support segments found (or the given
    `ranges`, seconds from the log's start), `heldout` segment names kept out of training.
    Returns the `ImportSummary` (segments, timeline intervals, streams, gaps, warnings)."""
    from legcal_bench.logs.importer import import_log as _import_log

    return _import_log(logs, mapping, _robot(robot), out, heldout=heldout, ranges=ranges, plot=plot)


def load(bags: str | Path, robot: str | LegMap = "a3", allow_partial: bool = False) -> list[Recording]:
    """The session set's recordings, checked against the robot (held-out ones included:
    the framework hands calibrators only the training ones)."""
    return load_session(bags, allow_partial=allow_partial, robot=_robot(robot))


def calibrate(bags: str | Path | list[Recording], robot: str | LegMap = "a3", calibrator: str = "interfoot",
              **options) -> CalibrationResult:
    """Offsets from a session folder (or loaded recordings) by a registered calibrator with
    its constructor `options` (`legcal-bench calibrate`); the calibrator sees the training
    recordings only. `result.save(path)` writes the CLI's JSON."""
    cal = get_calibrator(calibrator, **options)  # a bad name or option fails before any data is read
    legmap = _robot(robot)
    recordings = bags if isinstance(bags, list) else load(bags, legmap)
    return calibrate_training(cal, legmap, recordings)


def score(bags: str | Path, result: CalibrationResult, robot: str | LegMap | None = None) -> dict:
    """The result against the ground truth kept with simulated recordings: recovery and
    held-out foot height (`legcal-bench score --json`)."""
    from legcal_bench.evaluation.scoring import score as _score

    legmap = _robot(robot if robot is not None else result.settings.get("robot_spec", result.robot))
    return _score(str(bags), result, legmap, allow_partial=True)


def diagnose(bags: str | Path, robot: str | LegMap = "a3", result: CalibrationResult | None = None,
             calibrator: str = "interfoot", effects=None, **options) -> dict:
    """The model-gap loop (`legcal-bench diagnose`; the report's JSON-ready form is what
    diagnosis.json holds): its fit starts from `result`'s offsets, else from
    `calibrator`'s (run now with `options`); held-out sessions are never read."""
    from legcal_bench.evaluation.modelgap import diagnose as _diagnose
    from legcal_bench.reports.diagnose import json_ready

    legmap = _robot(robot)
    recordings = load(bags, legmap, allow_partial=True)
    if result is None:
        result = calibrate(recordings, legmap, calibrator, **options)
    report = _diagnose(legmap, recordings, start=result.offsets_vector(legmap.joint_names), effects=effects)
    report["start"] = {"calibrator": result.calibrator, "settings": result.settings, "offsets_rad": result.offsets_rad}
    return json_ready(report)


def walk(robot: str = "a3", policy: str = "a3", offsets: str = "paper@3", correction=None, seconds: float = 20.0,
         seed: int = 0, sensors: str = "realistic"):
    """One walk of a policy (a built-in walker's name or a spec YAML) with encoder offsets
    (`paper@<deg>`, a preset) and an optional correction (a `CalibrationResult` or
    offsets in rad), as `legcal-bench walk`. Returns the `Walk` (`.summary()` is what the
    command prints)."""
    from legcal_bench.envs.walking import WalkingEnv
    from legcal_bench.evaluation.walk import trial_offsets, walk as _walk
    from legcal_bench.policies.runner import PolicyRunner

    env = WalkingEnv(robot=robot, policy=policy, sensors=sensors)
    runner = PolicyRunner(env.policy_spec, env.legmap)
    if isinstance(correction, CalibrationResult):
        correction = correction.offsets_vector(env.legmap.joint_names)
    dq = trial_offsets(offsets, env.legmap, seed)
    return _walk(env, runner, seconds, seed, {"offsets": dq, "correction": None if correction is None
                                              else np.asarray(correction, dtype=float)})


def walk_eval(robot: str = "a3", policy: str = "a3", offsets: str = "paper@3", trials: int = 35,
              seconds: float = 20.0, calibrator: str = "interfoot", workers: int = 1, progress: bool = False,
              **options) -> tuple[dict, list[dict]]:
    """The closed-loop evaluation (`legcal-bench walk-eval`): per trial a static session
    set, the calibrator's estimate, then nominal, uncorrected, corrected and oracle walks.
    Returns (summary, trials), what the report's JSON holds."""
    from legcal_bench.benchmark.runner import executing
    from legcal_bench.evaluation.closed_loop import ClosedLoopConfig, calibrator_options, evaluate

    options = {**calibrator_options(calibrator), **options}
    get_calibrator(calibrator, **options)
    cfg = ClosedLoopConfig(robot=robot, policy=policy, offsets=offsets, trials=trials, seconds=seconds,
                           calibrator=calibrator, options=options)
    with executing(None, workers) as executor:
        return evaluate(cfg, executor, progress=progress)
