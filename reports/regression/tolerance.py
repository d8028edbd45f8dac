"""Would the regression fixture's tolerance (`legcal_bench.reports.regression.REL_TOL`)
hide a wrong constant? On the fixture's A3-like weld cell (seed 0, injected set), the
`operating` setting's offsets with each paper weight off by 1 %, the trim fraction at
0.11 and the knee prior shifted by 1e-4 rad, against the paper's: the largest relative
change of any offset (what the fixture compares) and of the offsets' norm.

    python reports/regression/tolerance.py > reports/regression/tolerance.md
"""

import tempfile

import numpy as np

from legcal_bench import paper
from legcal_bench.benchmark.plan import Dataset
from legcal_bench.calibrators.base import calibrate_training
from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import load_session
from legcal_bench.protocol.collect import collect
from legcal_bench.provenance import code_version, describe
from legcal_bench.reports.regression import REL_TOL
from legcal_bench.robots import load_robot


def main() -> None:
    with tempfile.TemporaryDirectory() as work:
        collect(Dataset("a3", "weld", 0, 1.0, "injected").config(), work, progress=False)
        lm = load_robot("a3")
        recs = load_session(work, robot=lm)

        def offsets(**options):
            cal = get_calibrator("interfoot", setting="operating", **options)
            return calibrate_training(cal, lm, recs).offsets_vector(lm.joint_names)

        base = offsets()
        changes = {f"{k} x 1.01": {k: paper.A3_OPERATING[k] * 1.01}
                   for k in ("lambda_f", "lambda_g", "lambda_q", "lambda_knee")}
        changes.update({"trim_fraction 0.11": {"trim_fraction": 0.11}, "knee prior + 1e-4 rad":
                        {"knee_prior_shift_rad": 1e-4}})
        print(f"# A wrong constant against the regression tolerance ({describe(code_version())})\n")
        print(f"REL_TOL = {REL_TOL:g}. Made by `python reports/regression/tolerance.py`.\n")
        print("| change | max relative change of an offset | relative change of the norm | caught |")
        print("|---|---:|---:|---|")
        for label, options in changes.items():
            d = offsets(**options) - base
            worst = float(np.max(np.abs(d) / np.abs(base)))
            print(f"| {label} | {worst:.2e} | {np.linalg.norm(d) / np.linalg.norm(base):.2e} | "
                  f"{'yes' if worst > REL_TOL else 'NO'} |")


if __name__ == "__main__":
    main()
