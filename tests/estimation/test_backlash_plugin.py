"""The second worked example of the effect plug-in guide (issue #61): gear backlash
(docs/examples/backlash_plugin), a motion-dependent encoder effect whose physics is a
reading law. Its law and its fitting model are one law (the model undoes the law on
noise-free readings); simulated through the reading laws, the recordings and the
truth's clean readings carry it alike; `diagnose` names it on its own data and recovers
its width, and scores the held-out sessions through the law."""

import numpy as np
import pytest

from legcal_bench.errors import ConfigError
from tests.estimation.plugin_install import REPO_EXAMPLES, install_example

EXAMPLE = REPO_EXAMPLES / "backlash_plugin"


@pytest.fixture
def backlash(tmp_path, monkeypatch):
    install_example(EXAMPLE, "legcal_backlash", "backlash", tmp_path / "site", monkeypatch)
    import legcal_backlash

    return legcal_backlash


def test_the_law_and_the_fitting_model_are_one_law(backlash):
    from legcal_bench.estimation.modelgap.effects import SegmentData
    from legcal_bench.robots import load_robot
    from legcal_bench.robots.kinematics import LegKinematics

    time = np.arange(600) * 0.02
    # two joints moving up and down at different rates: several reversals each
    e = np.stack([0.2 * np.sin(0.9 * time), 0.1 * np.sin(0.35 * time + 1.0)], axis=1)
    d = backlash.direction(e)
    assert d[0].tolist() == [0.0, 0.0] and d[10:].all()  # no direction before the first dead band of motion
    turns = time[1:][np.diff(d[:, 0]) != 0]
    extremes = (np.pi / 2 + np.pi * np.arange(3)) / 0.9  # sin(0.9 t)'s, t < 12 s
    assert len(turns) == 1 + len(extremes) and d[1, 0] == 1.0  # the first motion, then each reversal ...
    assert np.all((turns[1:] > extremes) & (turns[1:] < extremes + 0.5))  # ... read once past the dead band
    width = np.deg2rad(0.2)
    read = backlash.BacklashLaw(1, width)(e, time)
    assert np.array_equal(read[:, 0], e[:, 0])  # the other joint's reading untouched
    true_d = backlash.direction(e[:, [1]], 1e-7)[:, 0]  # the true angle turns at its extremes
    assert np.allclose(read[:, 1] - e[:, 1], 0.5 * width * true_d, rtol=0, atol=1e-15)
    # The play's jump at a reversal is wider than the dead band: the readings turn on the same frame.
    # The fitting model on those readings: q = q_enc - (b / 2) d recovers the true angle.
    kin = LegKinematics(load_robot("a3"))
    n = kin.legmap.n_joints
    q = np.zeros((len(time), n))
    q[:, 3] = e[:, 1]  # a knee, say
    q_enc = q.copy()
    q_enc[:, 3] = read[:, 1]
    A = backlash.Backlash().joint_map(kin, SegmentData(q_enc=q_enc, time=time))
    b = np.zeros(n)
    b[3] = width
    assert np.abs(q_enc + A @ b - q).max() < 1e-12
    # A width at its physical limit, 0, sits within the bound's margin (the guide's rule).
    low, high = backlash.Backlash().bounds(kin)[0]
    assert low < 0 < high


def test_a_backlash_beyond_a_gear_is_refused(backlash, tmp_path):
    from legcal_bench.benchmark.modelgap import _collect, _config
    from legcal_bench.sim.effects import parse_effect

    parse_effect("backlash:joint=left_knee,deg=0.2")  # a gear's play parses
    with pytest.raises(ConfigError, match=r"deg=5.0: a backlash is a play in \(0, 2\] deg"):
        _collect(_config("a3", ("backlash:joint=left_knee,deg=5",), 0, collect_overrides={"stance_s": 2.0}), tmp_path)
    assert not (tmp_path / "set" / "session.json").exists()  # refused before any recording


def test_diagnose_names_the_backlash_recovers_its_width_and_scores_through_it(backlash, tmp_path):
    from legcal_bench.benchmark.modelgap import _collect, _config
    from legcal_bench.evaluation.modelgap import diagnose
    from legcal_bench.evaluation.scoring import heldout_scores

    spec = "backlash:joint=left_knee,deg=0.2"
    lm, recs, truth = _collect(_config("a3", (spec,), 0, collect_overrides={"stance_s": 8.0}), tmp_path)
    assert truth.meta["reality"]["effects"] == [{"effect": spec, "kind": "backlash", "joint": "left_knee_joint",
                                                 "width_rad": pytest.approx(np.deg2rad(0.2))}]
    rep = diagnose(lm, recs)
    assert rep["verdict"] == "selected" and rep["selected"] == ["backlash"], rep["summary"]
    w = rep["parameters"]["backlash.left_knee_joint_width"]
    assert abs(w["value"] - np.deg2rad(0.2)) < 0.05 * np.deg2rad(0.2), w  # within 5 % of the play
    others = [p["value"] for k, p in rep["parameters"].items() if k.startswith("backlash.") and "left_knee" not in k]
    assert max(np.abs(others)) < 0.1 * np.deg2rad(0.2)
    err = np.rad2deg(np.sqrt(np.mean((np.array(list(rep["offsets_rad"].values())) - truth.offsets) ** 2)))
    before = np.rad2deg(np.sqrt(np.mean((np.array(list(rep["offsets_only_rad"].values())) - truth.offsets) ** 2)))
    assert err < 0.1 * before, (before, err)
    held = heldout_scores(rep, lm, tmp_path / "set")
    assert held["after"] < 0.2 * held["before"], held  # the truth's clean readings go through the law
