"""Can the data alone see the tilt error the accelerometer's motion compensation leaves?
Per stance of clean sets: the compensated IMU vertical's scatter about its own smooth
course (a quadratic Savitzky-Golay fit over WINDOW_S; the pelvis tilts on a ~10 s
scale, which the fit passes), as a per-axis sigma (the residual's variance over the
white noise's share that passes the fit, 1 - h0), against the declared tilt noise
(accel_noise_std / g). No truth is read: a robot team could run this on its own logs.

    python reports/modelgap/tilt_scatter.py a3 examples/unitree_g1.legmap.yaml

(`calibrated-imu`, seeds 0-1, kinematic and weld; kinematic sets are static and
uncompensated, the check that the estimate reads the declared noise.) With a 0.3 s
window the G1's weld excess hardly shows (ratio 1.01): most of it lies at 1-3 Hz, which
a short fit passes.
"""

import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.signal import savgol_coeffs, savgol_filter

from legcal_bench.data.recording import load_session
from legcal_bench.estimation.imu_motion import compensate
from legcal_bench.estimation.noise import noise_sigmas
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics

WINDOW_S = 1.0
SEEDS = 2


def scatter(kin, rec, window: int) -> float:
    """Per-axis sigma (mrad) of the compensated vertical about its smooth course."""
    f = np.asarray(rec.imu_acc) if rec.motion == "static" else compensate(kin, rec.time, rec.q_enc, rec.imu_acc)
    u = f / np.linalg.norm(f, axis=1, keepdims=True)
    s = savgol_filter(u, window, 2, axis=0)
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    e = np.cross(s, u)[window:-window, :2] * 1e3  # interior: the fit's ends differ
    return float(np.sqrt((e**2).mean() / (1 - savgol_coeffs(window, 2)[window // 2])))


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
                window = int(round(WINDOW_S / np.median(np.diff(recs[0].time)))) | 1
                m = [scatter(kin, r, window) for r in recs]
                print(f"| {lm.name} | {mode} | {seed} | {declared:.3f} | {' '.join(f'{x:.3f}' for x in m)} | "
                      f"{np.mean(m) / declared:.3f} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or ["a3"])
