"""One realistic session set collected, calibrated by interfoot and scored: the case the
verdicts and imu-mount pages are made of. Light at import."""

from __future__ import annotations


def calibrated_set(spec: str, mode: str, seed: int, scratch: str):
    """(leg map, collect summary, calibration result, score) of a realistic-sensor set of
    robot `spec` on floor `mode` with `seed`, collected in a scratch folder named after
    `scratch`; HoldError if the robot cannot hold the set."""
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
        summary = collect(CollectConfig(robot=spec, mode=mode, sensors="realistic", seed=seed), tmp, progress=False)
        result = calibrate_training(get_calibrator("interfoot"), legmap, load_session(tmp, robot=legmap))
        return legmap, summary, result, score(str(tmp), result, legmap)
