"""The encoder-scale block fitted to clean data (no effect in the reality), per seed:
offsets RMS error (deg) of the offsets-only fit and of the fit with `encoder_scale`
added, and each scale parameter's z (estimate / posterior std; the truth is zero), then
the mean after/before ratio beside the one the posterior standard deviations predict. An unbiased fit centres the z on zero; the ratio is the
price of the block's six near-collinear parameters.

    python reports/effects/clean_scale_fit.py a3 kinematic 8
    python reports/effects/clean_scale_fit.py a3 weld 8

(weld/kinematic floor, `calibrated-imu`, the paper's injection, `interfoot` `sensor`.)
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

from legcal_bench.calibrators.base import calibrate_training

from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import list_segments, load_session, load_truth
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot


def main(robot: str, mode: str, seeds: int) -> None:
    lm = load_robot(robot)
    ratios, predicted = [], []
    for seed in range(seeds):
        with tempfile.TemporaryDirectory() as work:
            collect(CollectConfig(robot=robot, mode=mode, sensors="calibrated-imu", seed=seed), Path(work) / "s",
                    progress=False)
            recs = load_session(Path(work) / "s", robot=lm)
            injected = np.asarray(load_truth(list_segments(Path(work) / "s")[0]).offsets)
            r = calibrate_training(get_calibrator("interfoot", setting="sensor", effects="encoder_scale"), lm, recs)
            e = r.diagnostics["effects"]
            after = np.array([r.offsets_rad[n] for n in lm.joint_names])
            before = np.array([e["offsets_only_rad"][n] for n in lm.joint_names])
            b, a = (float(np.rad2deg(np.sqrt(np.mean((x - injected) ** 2)))) for x in (before, after))
            ratios.append(a / b)
            std_b = np.array(list(r.diagnostics["posterior"]["std_rad"].values()))
            std_a = np.array(list(e["offsets_std_rad"].values()))
            predicted.append(np.sqrt(np.mean(std_a**2) / np.mean(std_b**2)))
            zs = " ".join(f"{n.split('.')[-1]}={p['value'] / p['std']:+.1f}" for n, p in e["parameters"].items())
            print(f"seed {seed}: offsets-only {b:.4f} deg, with encoder_scale {a:.4f} deg; z {zs}", flush=True)
    print(f"{robot} {mode}: mean after/before {np.mean(ratios):.2f} over {seeds} seeds; the posteriors' RMS std "
          f"ratio {np.mean(predicted):.2f}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
