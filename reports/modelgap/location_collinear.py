"""The poor-fit rule's location test on clean data, with and without the `leg_length`
block in the model: tracing's left-leg score (`trace`: a 6-dof error after each left-leg
joint, `LegGeometry`) on the residual of a clean set, its nuisance the fit's own columns; then
the same columns on synthetic white noise drawn from the declared covariance, which is
what the test's chi2(dof) reference assumes.

    python reports/modelgap/location_collinear.py a3 kinematic 3

(`calibrated-imu`, the paper's injection, `interfoot` `sensor`; no effect in the reality.)
A score far above its dof on clean data, where white noise through the same columns stays
near it, means the test reaches directions made of the noise itself. At commit 6d75831
it did: 1185.4 on 26 dof with `leg_length` in the model (white noise 17-28), through
combinations of the leg's geometry with the fitted lengths and offsets that are exactly
collinear on noise-free data and that the noise moves apart by ~1e-4 of their size
(those singular values scale with the noise: ~6e-6 at 1 % of it), and through mean
columns averaged plainly where the fit projects them. The model-gap suite's one A3-like
leg-length "poor fit" (seed 7) failed this test while its fit was right. Since commit
a2bab88 tracing projects its columns as the fit does and does not test directions below
the sensors' resolution (`lineartests.score`): 19.7 on 14 dof.
"""

import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from legcal_bench.benchmark.modelgap import _collect
from legcal_bench.estimation.problem.fit import fit_model
from legcal_bench.evaluation.modelgap import context, evaluate, trace


def main(robot: str, mode: str, seed: int) -> None:
    with tempfile.TemporaryDirectory() as work:
        legmap, recs, _ = _collect(robot, (), seed, Path(work), mode)
        ctx = context(legmap, recs)
        rng = np.random.default_rng(0)
        print(f"{robot} {mode} seed {seed}, clean: left-leg location score (delta chi2 / dof)")
        for effects in ((), ("leg_length",)):
            fit = fit_model(ctx.prep, effects)
            ev = evaluate(ctx, fit, ctx.prep.segments, keep_frames=True)
            n = len(ev.frames.r)
            loc = trace(ctx, ev)["locations"]["left leg"]
            lam, U = np.linalg.eigh(ev.cov)
            white = []
            for _ in range(5):  # the same test on noise drawn from the declared covariance
                r = np.einsum("nij,nj->ni", U * np.sqrt(np.clip(lam, 0, None))[:, None, :],
                              rng.standard_normal((n, 11)))
                z = np.einsum("nij,nj->ni", ev.W, r).ravel()
                noise = replace(ev, z=z, step=np.linalg.lstsq(ev.Jw, z, rcond=None)[0])
                white.append(trace(ctx, noise)["locations"]["left leg"]["delta_chi2"])
            d, dof = loc["delta_chi2"], loc["dof"]
            model = "offsets + " + "+".join(effects) if effects else "offsets only"
            print(f"  {model:24s} data {d:8.1f} / {dof}; white noise (5 draws) "
                  f"{' '.join(f'{w:.1f}' for w in white)}; chi2/dof of the fit {ev.chi2 / ev.dof:.4f}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
