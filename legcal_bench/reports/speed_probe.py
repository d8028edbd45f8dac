"""Time legcal-bench's hot paths with whatever `legcal_bench` is importable.

Run as a script (`python speed_probe.py --data DIR --repeats 5`), it prints one JSON
object: for each case the list of timings. `legcal-bench bench-speed` runs it twice,
once on the code at hand and once on an older commit installed beside it, so both are
timed in the same run on the same recordings. It uses only interfaces both versions
have (calibrator registry, collection, loader, robot registry).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile  # not files.scratch: a probe runs on the baseline's package too
import time

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_k, "1")
os.environ.setdefault("MUJOCO_GL", "egl")

# name -> (calibrator, options, timing key): 4 stances x 450 frames (clustered straight to
# 450, no trimming) for the solves; the default pipeline end to end.
CALIBRATION_CASES = {
    # The solves on the sensor setting, named (the default was operating before #35).
    "interfoot_solve": ("interfoot", dict(setting="sensor", n_max=450, trim_fraction=0.0), "solve"),
    "interfoot_end_to_end": ("interfoot", {}, "total"),  # the default: operating before #35, sensor since
    "interfoot_end_to_end_operating": ("interfoot", dict(setting="operating"), "total"),
    "interfoot_end_to_end_sensor": ("interfoot", dict(setting="sensor"), "total"),
    "yamane_end_to_end": ("yamane", {}, "total"),
    "yamane_end_to_end_sensor": ("yamane", dict(weights="sensor"), "total"),
    "interfoot_solve_2point": ("interfoot", dict(setting="sensor", n_max=450, trim_fraction=0.0, jacobian="2-point"),
                               "solve"),
    "interfoot_solve_alternating": ("interfoot", dict(setting="sensor", n_max=450, trim_fraction=0.0,
                                                      solver="alternating"), "solve"),
    "yamane_solve_default": ("yamane", dict(n_max=450), "solve"),
    "yamane_solve_sensor": ("yamane", dict(n_max=450, weights="sensor"), "solve"),
}


def probe(data: str, robot: str, repeats: int, collect_repeats: int, only: str | None = None) -> dict:
    import legcal_bench

    try:  # the registry's home since #35; a baseline commit may be older (this file runs on both)
        from legcal_bench.calibrators.registry import get_calibrator
    except ImportError:
        from legcal_bench.calibrators.base import get_calibrator
    from legcal_bench.data.recording import load_session
    from legcal_bench.protocol.collect import CollectConfig, collect
    from legcal_bench.robots import load_robot

    lm = load_robot(robot)
    # The training recordings, as the framework hands them over (`calibrate_training`; here by hand,
    # since a baseline commit may predate it).
    recs = ([r for r in load_session(data, lm.joint_names) if r.kind in ("stance", "standing")]
            if only != "collection" else [])  # the collection group alone collects no data set
    out: dict = {"module": os.path.dirname(legcal_bench.__file__), "cases": {}}
    for name, (cal, options, key) in CALIBRATION_CASES.items() if only != "collection" else ():
        runs = [get_calibrator(cal, **options).calibrate(lm, recs) for _ in range(repeats)]
        out["cases"][name] = {"unit": "s", "values": [r.timing_s[key] for r in runs],
                              "offsets": [runs[0].offsets_rad[n] for n in lm.joint_names]}
        if key == "total":  # each stage of the calibrator's own timing (`timing_s`)
            out["cases"][name]["stages"] = {k: [r.timing_s[k] for r in runs] for k in runs[0].timing_s}
    # The framework's one door (`calibrate_training`: the default inter-foot calibrator, wall
    # time): what it adds around the calibrator (from #39, the motion measured and resolved).
    if only != "collection":
        try:
            from legcal_bench.calibrators.base import calibrate_training
        except ImportError:  # a baseline before the door existed
            calibrate_training = None
        if calibrate_training is not None:
            walls = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                r = calibrate_training(get_calibrator("interfoot"), lm, recs)
                walls.append(time.perf_counter() - t0)
            out["cases"]["interfoot_door"] = {"unit": "s", "values": walls,
                                              "offsets": [r.offsets_rad[n] for n in lm.joint_names]}
    # Contact: the default collection there, with the standing controller where the robot
    # has ankle force/torque sensors (from issue #38 on; before, the servos alone).
    for mode in ("kinematic", "weld", "contact") if only != "calibration" else ():
        rates = []
        for _ in range(collect_repeats):
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                s = collect(CollectConfig(robot=robot, mode=mode, sensors="realistic"), tmp, progress=False)
                wall = time.perf_counter() - t0
            frames = sum(g.frames for g in s.segments)
            rates.append({"frames_per_s": frames / wall, "x_real_time": s.sim_s / wall})
        out["cases"][f"collect_{mode}_frames_per_s"] = {"unit": "frames/s", "values": [r["frames_per_s"] for r in rates]}
        out["cases"][f"collect_{mode}_x_real_time"] = {"unit": "x", "values": [r["x_real_time"] for r in rates]}
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--data", required=True, help="a weld session set (legcal-bench collect --out)")
    p.add_argument("--robot", default="a3")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--collect-repeats", type=int, default=1)
    p.add_argument("--only", choices=("calibration", "collection"), help="one group of cases (default: both)")
    a = p.parse_args(argv)
    print(json.dumps(probe(a.data, a.robot, a.repeats, a.collect_repeats, a.only)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
