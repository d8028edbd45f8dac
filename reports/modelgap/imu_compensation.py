"""What the accelerometer's motion compensation leaves on clean weld sets: the tilt error
of the compensated specific force against the simulator's true gravity direction, per
stance, noise-free (true accelerometer, true joint angles: the method's own error) and
with the recorded encoders (their noise through the second derivative), beside the raw
motion tilt and the declared per-frame tilt noise.

    python reports/modelgap/imu_compensation.py a3 a2 examples/unitree_g1.legmap.yaml

(weld, `calibrated-imu`, seed 3, `legcal_bench.estimation.imu.imu_motion` at its default window;
mrad RMS per tilt axis, as the declared noise, accel_noise_std / g, is stated.)
"Above 1 Hz": the part left after a 0.5 s moving average is taken out, i.e. frame-to-frame
scatter that no smooth model of the posture predicts. An error the declared noise does
not include shows in the tilt rows' chi-square; the model-gap suite's `at_truth` chi2/dof
is the figure it is compared with.
"""

import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.ndimage import uniform_filter1d

from legcal_bench.data.recording import list_segments, load_session, load_truth
from legcal_bench.estimation.imu.imu_motion import compensate
from legcal_bench.estimation.information.noise import noise_sigmas
from legcal_bench.geometry.poses import pos_quat_to_homogeneous
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics

SEED = 3
LOWPASS_FRAMES = 25  # 0.5 s at the default 50 Hz


def _rms(e: np.ndarray) -> float:
    """RMS per tilt axis (x and y pooled), as the declared noise is stated."""
    return float(np.sqrt((e[:, :2] ** 2).mean()))


def tilt_errors(kin: LegKinematics, rec, truth) -> dict:
    """RMS tilt errors (mrad) of one recording."""
    R_WI = pos_quat_to_homogeneous(truth.pelvis_pose_world)[:, :3, :3] @ kin.R_BI
    up_I = R_WI[:, 2, :]  # the world's up in the IMU frame: what a still accelerometer reads, normalized

    def tilt(f):  # small-angle tilt vector of f against the true up, IMU frame (mrad)
        return np.cross(up_I, f / np.linalg.norm(f, axis=1, keepdims=True)) * 1e3

    raw = tilt(np.asarray(truth.imu_true_acc))
    model = tilt(compensate(kin, rec.time, truth.q_true, truth.imu_true_acc))
    enc = tilt(compensate(kin, rec.time, rec.q_enc + truth.offsets, truth.imu_true_acc))
    return {"raw": _rms(raw), "noise_free": _rms(model),
            "noise_free_above_1hz": _rms(model - uniform_filter1d(model, LOWPASS_FRAMES, axis=0)),
            "with_encoders": _rms(enc)}


def main(robots: list[str]) -> None:
    print("| robot | stance | raw motion tilt | compensated, noise-free | … of it above 1 Hz | compensated, "
          "recorded encoders | declared tilt noise |")
    print("|---|---|---|---|---|---|---|")
    for robot in robots:
        lm = load_robot(robot)
        kin = LegKinematics(lm)
        with tempfile.TemporaryDirectory() as work:
            out = Path(work) / "s"
            collect(CollectConfig(robot=robot, mode="weld", sensors="calibrated-imu", seed=SEED), out, progress=False)
            recs = load_session(out, robot=lm)
            sigma_t = noise_sigmas(recs[0].sensor_model, kin.dims.leg_length)["tilt"] * 1e3
            for path, rec in zip(list_segments(out), recs):
                if rec.kind == "standing":
                    continue
                e = tilt_errors(kin, rec, load_truth(path))
                print(f"| {lm.name} | {rec.name} | {e['raw']:.2f} | {e['noise_free']:.2f} | "
                      f"{e['noise_free_above_1hz']:.2f} | {e['with_encoders']:.2f} | {sigma_t:.2f} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or ["a3"])
