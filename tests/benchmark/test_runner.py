"""The runner, the registry's entry-point group, honest resume and the Dask executor."""

import json
import sys
import textwrap
from pathlib import Path
from concurrent.futures import ThreadPoolExecutor
from importlib import invalidate_caches

import numpy as np
import pytest

from legcal_bench.benchmark import plan as planning
from legcal_bench.benchmark.leaderboard import generate
from legcal_bench.benchmark.runner import is_done, run
from legcal_bench.calibrators.registry import available_calibrators
from legcal_bench.provenance import RESULTS_VERSION

TINY = dict(stance_s=3.0, heldout_s=2.0, standing_s=1.0, heldout=1)


@pytest.fixture
def toy_calibrator(tmp_path, monkeypatch):
    """A third-party package, installed the way pip would: a module and a dist-info
    whose entry_points.txt registers it in the group."""
    (tmp_path / "toy_cal.py").write_text(textwrap.dedent('''
        from legcal_bench.calibrators.base import CalibrationResult, Calibrator

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
    cells = planning.plan("smoke", robots=["a3"], modes=["kinematic"], seeds=1, calibrators=["toy", "zero"],
                          collect_overrides=TINY)
    assert {(c.calibrator, c.variant) for c in cells} == {("toy", "default"), ("zero", "default")}
    results = tmp_path / "lb" / "results"
    with ThreadPoolExecutor(2) as ex:
        counts = run(cells, tmp_path / "data", results, executor=ex, progress=False)
    assert counts == {"cells": 2, "computed": 2, "skipped": 0}
    toy = json.loads(cells[0].path(results).read_text())
    assert toy["cell"]["calibrator"] == "toy"
    assert toy["injected"]["offsets_rad"]["left_knee_joint"] == 0.001
    # The same constant estimate on both sets: paired delta = -injection, whose RMS over
    # the six roles (0.03, 0.04, 0.02, 0.04, 0.02, 0.03 rad) is sqrt(58/6) cdeg-rad.
    assert toy["paired_delta_rms_deg"] == pytest.approx(np.rad2deg(0.01 * np.sqrt(58 / 6)), rel=1e-12)
    assert toy["paired_delta_rms_deg"] == pytest.approx(1.78140, abs=5e-6)
    # Every cell records the code that made it and its resume key.
    assert toy["provenance"]["results_version"] == RESULTS_VERSION and toy["provenance"]["package"]
    assert toy["key"] == cells[0].key()
    # Resumable: nothing is recomputed.
    with ThreadPoolExecutor(2) as ex:
        assert run(cells, tmp_path / "data", results, executor=ex, progress=False)["computed"] == 0
    # The leaderboard regenerates byte-identically from the result files.
    first = generate(tmp_path / "lb")
    plots = {p.name: p.read_bytes() for p in (tmp_path / "lb" / "plots").iterdir()}
    assert generate(tmp_path / "lb") == first and "toy-default" in first
    assert plots == {p.name: p.read_bytes() for p in (tmp_path / "lb" / "plots").iterdir()}


def test_two_cell_sweep_on_a_dask_local_cluster(tmp_path):
    from distributed import LocalCluster

    cells = planning.plan("sweep", robots=["a2"], modes=["kinematic"], seeds=1, scales=(0.5, 1.0),
                          calibrators=["zero"], collect_overrides=TINY)
    assert len(cells) == 2
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cluster:
        counts = run(cells, tmp_path / "data", tmp_path / "results", scheduler=cluster.scheduler_address,
                     progress=False)
    assert counts["computed"] == 2
    deltas = [json.loads(c.path(tmp_path / "results").read_text())["paired_delta_rms_deg"] for c in cells]
    assert deltas[1] == pytest.approx(2 * deltas[0], rel=1e-9)  # zero estimate: delta = -scale x injection


def test_resume_recomputes_partial_empty_and_stale_cells(tmp_path):
    cells = planning.plan("sweep", robots=["a3"], modes=["kinematic"], seeds=1, calibrators=["zero"],
                          collect_overrides=TINY)
    results = tmp_path / "results"
    with ThreadPoolExecutor(1) as ex:
        run(cells, tmp_path / "data", results, executor=ex, progress=False)
    cell = cells[0]
    path = cell.path(results)
    whole = json.loads(path.read_text())
    assert is_done(cell, results)
    for broken in ("{}", "", '{"cell": {}', json.dumps({**whole, "key": "0" * 16}),
                   json.dumps({k: v for k, v in whole.items() if k != "injected"}),
                   json.dumps({"key": whole["key"], "cell": whole["cell"], "error": "a stale session set"})):
        path.write_text(broken)
        assert not is_done(cell, results), broken[:40]
    with ThreadPoolExecutor(1) as ex:
        assert run(cells, tmp_path / "data", results, executor=ex, progress=False)["computed"] == 1
    assert json.loads(path.read_text())["paired_delta_rms_deg"] == whole["paired_delta_rms_deg"]


def test_the_key_follows_settings_data_and_results_version(monkeypatch):
    base = planning.Cell("x", "a3", "weld", 0, 1.0, "interfoot", "matched", (("setting", "matched"),))
    other_setting = planning.Cell("x", "a3", "weld", 0, 1.0, "interfoot", "matched", (("setting", "sensor"),))
    other_data = planning.Cell("x", "a3", "weld", 1, 1.0, "interfoot", "matched", (("setting", "matched"),))
    assert len({base.key(), other_setting.key(), other_data.key()}) == 3
    key = base.key()
    planning._cell_key.cache_clear()
    monkeypatch.setattr(planning, "RESULTS_VERSION", RESULTS_VERSION + 1)
    assert base.key() != key
    planning._cell_key.cache_clear()


def test_a_suite_robot_without_its_model_is_skipped_with_its_path(tmp_path):
    import yaml

    from legcal_bench.robots import ASSETS

    d = yaml.safe_load((ASSETS / "a3.legmap.yaml").read_text())
    d["mjcf"] = str(tmp_path / "nowhere" / "robot.xml")
    lm = tmp_path / "ghost.legmap.yaml"
    lm.write_text(yaml.safe_dump(d))
    with pytest.warns(planning.MissingRobotWarning, match=r"ghost.*nowhere/robot\.xml"):
        cells = planning.plan("sweep", robots=["a3", str(lm)], modes=["weld"], seeds=1, calibrators=["zero"])
    assert {c.robot for c in cells} == {"a3"}


def test_a_stale_cached_session_set_is_collected_again(tmp_path):
    """A cached set is reused only if its manifest records the dataset's config and the
    results version: one collected with other offsets (e.g. before the native offsets
    changed) is replaced, not silently scored."""
    import json

    from legcal_bench.benchmark.plan import Dataset
    from legcal_bench.benchmark.tasks import collect_dataset, is_current

    ds = Dataset("a3", "kinematic", 0, 1.0, "native", (("heldout", 0), ("stance_s", 1.0), ("standing_s", 0.0),
                                                         ("stances", ("I",))))
    out = Path(collect_dataset(ds, str(tmp_path)))
    assert is_current(out, ds)
    man = json.loads((out / "session.json").read_text())
    man["config"]["offsets"] = [0.0] * 12
    (out / "session.json").write_text(json.dumps(man))
    assert not is_current(out, ds)
    collect_dataset(ds, str(tmp_path))
    assert is_current(out, ds)
    assert json.loads((out / "session.json").read_text())["config"]["offsets"] == list(ds.config().offsets)
