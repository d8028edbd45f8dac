"""Robot logs from Python (`import_log` is on the API's top level): `simulate_log`, a
simulated long log written as a robot's logger would, with its mapping file."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from legcal_bench.errors import ConfigError
from legcal_bench.files.atomic import atomic_write_dir, atomic_write_json
from legcal_bench.logs.write import LogStreams, mapping_document, write_log, write_mapping
from legcal_bench.robots import load_robot, resolve_robot

__all__ = ["simulate_log", "long_log_streams"]

LOG_NAMES = {"mcap": "log", "sqlite3": "log", "ros1": "log.bag", "csv": "log.csv", "parquet": "log.parquet"}


def long_log_streams(log, ft: bool = True) -> LogStreams:
    """A simulated `LongLog` as its logger writes it: joints named as in the leg map."""
    return LogStreams(joint_names=list(log.joint_names), joint_time=log.time, joint_pos=log.q_enc,
                      imu_time=log.time, imu_acc=log.imu_acc, imu_gyro=log.imu_gyro,
                      ft_time=log.time if ft else None, ft=log.ft if ft else None)


def simulate_log(robot: str, out: str | Path, fmt: str = "mcap", seed: int = 0, ft: bool = True,
                 sensors: str = "realistic", declare_sensors: bool = True, progress: bool = False) -> dict:
    """Simulate a long log (`legcal_bench.evaluation.long_log`) and write, into the new
    folder `out`: the log in `fmt`, `mapping.yaml` for `import`, and `truth.json` (the
    injected offsets, which a real log never has)."""
    from legcal_bench.evaluation.long_log import simulate_long_log
    from legcal_bench.sim.sensors import SENSOR_PRESETS

    out = Path(out)
    if out.exists():
        raise ConfigError(f"--out {out} exists: give a new folder")
    if sensors not in SENSOR_PRESETS:
        raise ConfigError(f"--sensors {sensors!r}: use one of {sorted(SENSOR_PRESETS)}")
    legmap = load_robot(robot)
    log = simulate_long_log(resolve_robot(robot), seed=seed, sensors=sensors, progress=progress)
    name = LOG_NAMES[fmt]

    def write(folder: Path) -> None:
        write_log(folder / name, long_log_streams(log, ft), fmt)
        write_mapping(folder / "mapping.yaml", mapping_document(
            legmap.name, legmap.joint_names, legmap.joint_names, [1] * legmap.n_joints, fmt,
            SENSOR_PRESETS[sensors].model if declare_sensors else None, ft))
        atomic_write_json(folder / "truth.json", {
            "robot": legmap.name, "seed": seed, "sensors": sensors, "convention": "q = q_enc + offset",
            "offsets_rad": dict(zip(legmap.joint_names, map(float, log.offsets))),
            "offsets_deg": dict(zip(legmap.joint_names, map(float, np.rad2deg(log.offsets)))),
            "labels": [{"label": label, "t0": float(log.time[a]), "t1": float(log.time[b - 1])}
                       for label, a, b in log.segments()]})

    atomic_write_dir(out, write)
    return {"log": str(out / name), "mapping": str(out / "mapping.yaml"), "truth": str(out / "truth.json")}

