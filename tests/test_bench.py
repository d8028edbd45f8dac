"""The runner, the registry's entry-point group and the Dask executor."""

import json
import sys
import textwrap
from concurrent.futures import ThreadPoolExecutor
from importlib import invalidate_caches

import pytest

from legcal_bench import bench
from legcal_bench.calibration import available_calibrators
from legcal_bench.leaderboard import generate

TINY = dict(stance_s=3.0, heldout_s=2.0, standing_s=1.0, heldout=1)


@pytest.fixture
def toy_calibrator(tmp_path, monkeypatch):
    """A third-party package, installed the way pip would: a module and a dist-info
    whose entry_points.txt registers it in the group."""
    (tmp_path / "toy_cal.py").write_text(textwrap.dedent('''
        from legcal_bench.calibration import CalibrationResult, Calibrator

        class Toy(Calibrator):
            name = "toy"
            def calibrate(self, robot, recordings):
                return CalibrationResult(calibrator="toy", robot=robot.name,
                                         offsets_rad={n: 0.001 for n in robot.joint_names})
    '''))
    info = tmp_path / "toy_cal-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-cal\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[legcal_bench.calibrators]\ntoy = toy_cal:Toy\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    invalidate_caches()
    yield "toy"
    sys.modules.pop("toy_cal", None)


def test_a_third_party_calibrator_runs_through_the_runner(tmp_path, toy_calibrator):
    assert "toy" in available_calibrators()
    cells = bench.plan("smoke", robots=["a3"], modes=["kinematic"], seeds=1, calibrators=["toy", "zero"],
                       collect_overrides=TINY)
    assert {(c.calibrator, c.variant) for c in cells} == {("toy", "default"), ("zero", "default")}
    with ThreadPoolExecutor(2) as ex:
        counts = bench.run(cells, tmp_path / "data", tmp_path / "lb" / "results", executor=ex, progress=False)
    assert counts == {"cells": 2, "computed": 2, "skipped": 0}
    toy = json.loads(cells[0].path(tmp_path / "lb" / "results").read_text())
    assert toy["cell"]["calibrator"] == "toy"
    assert toy["injected"]["offsets_rad"]["left_knee_joint"] == 0.001
    assert abs(toy["paired_delta_rms_deg"] - 1.7188733853924696) < 0.2  # 0 - injection
    # Resumable: nothing is recomputed.
    with ThreadPoolExecutor(2) as ex:
        assert bench.run(cells, tmp_path / "data", tmp_path / "lb" / "results", executor=ex,
                         progress=False)["computed"] == 0
    # The leaderboard regenerates byte-identically from the result files.
    first = generate(tmp_path / "lb")
    plots = {p.name: p.read_bytes() for p in (tmp_path / "lb" / "plots").iterdir()}
    assert generate(tmp_path / "lb") == first and "toy-default" in first
    assert plots == {p.name: p.read_bytes() for p in (tmp_path / "lb" / "plots").iterdir()}


def test_two_cell_sweep_on_a_dask_local_cluster(tmp_path):
    from distributed import LocalCluster

    cells = bench.plan("sweep", robots=["a2"], modes=["kinematic"], seeds=1, scales=(0.5, 1.0),
                       calibrators=["zero"], collect_overrides=TINY)
    assert len(cells) == 2
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cluster:
        counts = bench.run(cells, tmp_path / "data", tmp_path / "results", scheduler=cluster.scheduler_address,
                           progress=False)
    assert counts["computed"] == 2
    deltas = [json.loads(c.path(tmp_path / "results").read_text())["paired_delta_rms_deg"] for c in cells]
    assert deltas[1] == pytest.approx(2 * deltas[0], rel=1e-9)  # zero estimate: delta = -scale x injection
