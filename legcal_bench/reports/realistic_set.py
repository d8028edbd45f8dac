"""One session set collected, calibrated by interfoot and scored: the case the
verdicts, imu-mount and vendor-cases pages are made of; and their cases kept as they
finish. Light at import."""

from __future__ import annotations

import json
from pathlib import Path


def calibrated_set(spec: str, mode: str, seed: int, scratch: str, sensors: str = "realistic"):
    """(leg map, collect summary, calibration result, score) of a set of robot `spec` on
    floor `mode` with `seed` and `sensors` (default realistic), collected in a scratch
    folder named after `scratch`; HoldError if the robot cannot hold the set."""
    from legcal_bench.calibrators.base import calibrate_training
    from legcal_bench.calibrators.registry import get_calibrator
    from legcal_bench.data.recording import load_session
    from legcal_bench.evaluation.scoring import score
    from legcal_bench.files.parallel import single_thread
    from legcal_bench.files.scratch import scratch_dir
    from legcal_bench.protocol.collect import CollectConfig, collect
    from legcal_bench.robots import load_robot

    single_thread()
    legmap = load_robot(spec)
    with scratch_dir(scratch) as tmp:
        summary = collect(CollectConfig(robot=spec, mode=mode, sensors=sensors, seed=seed), tmp, progress=False)
        result = calibrate_training(get_calibrator("interfoot"), legmap, load_session(tmp, robot=legmap))
        return legmap, summary, result, score(str(tmp), result, legmap)


def kept_cases(run, jobs: list, paths: list, workers: int, desc: str, progress: bool) -> list[dict]:
    """`run(job)` of every job whose file in `paths` is missing, in worker processes, each
    result written to its file as it finishes (a stopped run resumes there); then every
    job's result, read back in the jobs' order."""
    from legcal_bench.files.parallel import map_with_progress

    todo = [(run, job, str(p)) for job, p in zip(jobs, paths) if not Path(p).is_file()]
    for p in paths:
        Path(p).parent.mkdir(parents=True, exist_ok=True)
    map_with_progress(_run_and_keep, todo, workers=workers, desc=desc, progress=progress)
    return [json.loads(Path(p).read_text()) for p in paths]


def _run_and_keep(arg) -> str:
    from legcal_bench.files.atomic import atomic_write_json

    run, job, path = arg
    atomic_write_json(path, run(job))
    return path
