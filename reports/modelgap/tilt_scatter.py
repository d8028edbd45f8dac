"""Can the data alone see the tilt error the accelerometer's motion compensation leaves?
Per stance of clean sets: the compensated IMU vertical's scatter about its own smooth
course (`legcal_bench.estimation.imu.tilt_noise.vertical_scatter`, the estimate `diagnose`
uses), as a per-axis sigma, against the declared tilt noise (accel_noise_std / g). No
truth is read: a robot team could run this on its own logs.

    python reports/modelgap/tilt_scatter.py a3 examples/unitree_g1.legmap.yaml

(`calibrated-imu`, seeds 0-1, kinematic and weld; kinematic sets are static and
uncompensated, the check that the estimate reads the declared noise.)
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

from legcal_bench.data.recording import load_session
from legcal_bench.estimation.information.noise import noise_sigmas
from legcal_bench.estimation.imu.tilt_noise import vertical_scatter
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics

SEEDS = 2


def main(robots: list[str]) -> None:
    print("| robot | mode | seed | declared (mrad) | measured per stance and held-out session (mrad) | mean / declared |")
    print("|---|---|---|---|---|---|")
    for robot in robots:
        lm = load_robot(robot)
        kin = LegKinematics(lm)
        for mode in ("kinematic", "weld"):
            for seed in range(SEEDS):
                with tempfile.TemporaryDirectory() as work:
                    out = Path(work) / "s"
                    collect(CollectConfig(robot=robot, mode=mode, sensors="calibrated-imu", seed=seed), out,
                            progress=False)
                    recs = [r for r in load_session(out, robot=lm) if r.kind != "standing"]
                declared = noise_sigmas(recs[0].sensor_model, kin.dims.leg_length)["tilt"] * 1e3
                m = [vertical_scatter(kin, r)[0] * 1e3 for r in recs]
                print(f"| {lm.name} | {mode} | {seed} | {declared:.3f} | {' '.join(f'{x:.3f}' for x in m)} | "
                      f"{np.mean(m) / declared:.3f} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or ["a3"])
