"""Yamane's calibrator: both solvers reach the same optimum, and zero-noise data give
the injection back."""

import numpy as np
import pytest

from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import load_session
from legcal_bench.errors import CalibrationError
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.sim.offsets import paper_injection


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    out = tmp_path_factory.mktemp("yamane")
    collect(CollectConfig(robot="a3", mode="kinematic", sensors="zero", stance_s=4.0, heldout=0, standing_s=0.0),
            out, progress=False)
    lm = load_robot("a3")
    return lm, load_session(out, lm.joint_names)


def test_projected_and_sparse_solvers_recover_the_injection_from_zero_noise_data(session):
    lm, recs = session
    truth = paper_injection(lm)
    found = {}
    for solver in ("projected", "sparse"):
        res = get_calibrator("yamane", solver=solver, tol=1e-12).calibrate(lm, recs)
        found[solver] = res.offsets_vector(lm.joint_names)
        assert np.abs(found[solver] - truth).max() < 1e-8, solver
        assert res.settings["solver"] == solver
    assert np.abs(found["projected"] - found["sparse"]).max() < 1e-9


def test_unknown_solver_is_refused():
    with pytest.raises(CalibrationError, match="solver 'exact': use one of projected, sparse"):
        get_calibrator("yamane", solver="exact")
