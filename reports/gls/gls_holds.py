"""Where does the generalized least squares help, and where does it hurt? Per set of the
full suite's datasets (factory offsets + the paper's injection, realistic sensors):
the whitened chi-square per degree of freedom at the generalized least-squares solution
(`legcal_bench.estimation.problem.fit.refine`), and the offsets RMS error of that solution and of the
row-weighted fit it starts from. The `sensor` setting uses the first only where the
chi-square per dof is at most `GLS_MAX_CHI2_PER_DOF`.

    python reports/gls/gls_holds.py a3 a2 examples/unitree_g1.legmap.yaml

(weld and contact floors, seeds 0-5; a contact set the robot cannot hold is skipped.)
"""

import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from legcal_bench.benchmark.plan import Dataset
from legcal_bench.estimation.problem.stance import prepare_sensor
from legcal_bench.estimation.problem.fit import GLS_MAX_CHI2_PER_DOF, fit_model, refine
from legcal_bench.data.recording import list_segments, load_session, load_truth
from legcal_bench.errors import HoldError
from legcal_bench.protocol.collect import collect
from legcal_bench.robots import load_robot

SEEDS = 6


def main(robots: list[str]) -> None:
    print(f"| robot | floor | seed | chi2/dof at the GLS | offsets RMS error, GLS (deg) | row-weighted (deg) | "
          f"used (<= {GLS_MAX_CHI2_PER_DOF}) |")
    print("|---|---|---|---:|---:|---:|---|")
    for robot in robots:
        lm = load_robot(robot)
        for mode in ("weld", "contact"):
            for seed in range(SEEDS):
                with tempfile.TemporaryDirectory() as work:
                    out = Path(work) / "s"
                    try:
                        collect(Dataset(robot, mode, seed, 1.0, "injected").config(), out, progress=False)
                    except HoldError:
                        print(f"| {lm.name} | {mode} | {seed} | – | – | – | not held |", flush=True)
                        continue
                    recs = load_session(out, robot=lm)
                    truth = load_truth(list_segments(out)[0]).offsets
                prep = prepare_sensor(lm, recs)
                # The row-weighted fit as the setting starts it: `fit_model` refines only when
                # `prep.whitens` (the "sensor" setting), so any other name stops it there.
                rows = fit_model(replace(prep, setting_name="row-weighted"))
                gls = refine(prep, rows)
                err = [float(np.rad2deg(np.sqrt(np.mean((x[:12] - truth) ** 2)))) for x in (gls.fit.x, rows.x)]
                print(f"| {lm.name} | {mode} | {seed} | {gls.chi2_per_dof:.3f} | {err[0]:.4f} | {err[1]:.4f} | "
                      f"{'yes' if gls.holds else 'no'} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or ["a3"])
