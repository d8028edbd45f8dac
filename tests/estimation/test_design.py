"""Stance design, first part (issue #12): the predicted information of a protocol and a
greedy E-optimal choice of stances."""

from __future__ import annotations

import numpy as np

from legcal_bench.cli import main
from legcal_bench.estimation.information.design import StanceInfo, greedy_design, stance_information
from legcal_bench.protocol.stances import STANCES
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics


def test_information_grows_with_frames_and_a_single_stance_leaves_weak_directions():
    kin = LegKinematics(load_robot("a2"))
    one = stance_information(kin, STANCES["I"], 600)
    two = stance_information(kin, STANCES["I"], 1200)
    assert np.allclose(one.H, one.H.T) and np.linalg.eigvalsh(one.H)[0] > 0
    # Twice the frames of the same periodic motion: about twice the information.
    assert 1.5 < np.trace(two.H) / np.trace(one.H) < 2.5
    four = sum(stance_information(kin, s, 600).H for s in STANCES.values())
    assert np.linalg.eigvalsh(four)[0] > 3 * np.linalg.eigvalsh(one.H)[0]


def test_greedy_design_picks_what_fills_the_weakest_direction():
    e = np.eye(12)
    strong = StanceInfo(STANCES["I"], 100 * np.diag([1.0] * 11 + [0.0]) + 1e-6 * e, 1.0)
    weak_fix = StanceInfo(STANCES["II"], np.diag([0.0] * 11 + [5.0]) + 1e-6 * e, 1.0)
    more_strong = StanceInfo(STANCES["III"], 200 * np.diag([1.0] * 11 + [0.0]) + 1e-6 * e, 1.0)
    chosen = greedy_design([strong, more_strong, weak_fix], 2)
    # The two with the most information in all (0 and 1) leave the last direction empty;
    # E-optimal choice takes the one that fills it.
    assert 2 in chosen and len(set(chosen)) == 2


def test_greedy_design_takes_only_what_the_screen_passes_and_says_when_too_few_do():
    import pytest

    from legcal_bench.errors import ConfigError

    e = np.eye(12)
    infos = [StanceInfo(STANCES["I"], (j + 1) * e, 1.0) for j in range(4)]
    asked = []

    def accept(j):
        asked.append(j)
        return j != 3

    # The best (3) fails the screen: the next best two are taken; each is asked once.
    assert sorted(greedy_design(infos, 2, accept)) == [1, 2] and sorted(asked) == [1, 2, 3]
    with pytest.raises(ConfigError, match="only 1 of 4 candidate stances pass the hold screen"):
        greedy_design(infos, 2, lambda j: j == 0)


def test_exchange_repairs_a_greedy_choice():
    # Greedy takes the uniform stance first (the others each leave six directions empty)
    # and is stuck with it; exchanging it for the complement of the second choice
    # raises the smallest eigenvalue tenfold.
    uniform = StanceInfo(STANCES["I"], np.eye(12), 1.0)
    first = StanceInfo(STANCES["II"], np.diag([10.0] * 6 + [0.0] * 6), 1.0)
    second = StanceInfo(STANCES["III"], np.diag([0.0] * 6 + [10.0] * 6), 1.0)
    assert 0 in greedy_design([uniform, first, second], 2, exchange=False)
    assert sorted(greedy_design([uniform, first, second], 2)) == [1, 2]


def test_hold_screen_passes_stance_one_and_fails_a_motion_the_robot_cannot_hold():
    from dataclasses import replace

    import pytest

    from legcal_bench.protocol.screen import HoldScreen

    screen = HoldScreen(load_robot("a2"), "random:1.2", contact_seeds=1, weld_seeds=1, duration_s=4.0)
    ok = screen(STANCES["I"])
    assert ok.held and set(ok.reports) == {"weld", "contact"} and len(screen.cases["weld"]) == 3
    # Weld holds the pelvis within 0.75 of its limit (5 % of the leg length); contact at the limit.
    L = screen.sims["weld", 0].true_kin.dims.leg_length
    assert ok.reports["weld"].pelvis_limit_m == pytest.approx(0.75 * 0.05 * L)
    assert ok.reports["contact"].pelvis_limit_m == pytest.approx(0.05 * L)
    # Stance I's motion five times over, in a deep squat: the robot tips over in contact mode.
    wild = replace(STANCES["I"], name="wild", depth=0.2, amplitude=tuple(5 * a for a in STANCES["I"].amplitude))
    bad = screen(wild)
    assert not bad.held and any(f.startswith("contact:") for f in bad.failures())


def test_design_command_reports_default_and_designed(capsys):
    # 400 frames for the 2 stances: every stance screened (the 4 default ones too) is
    # simulated for 4 s in each case, as in the hold-screen test above (the default
    # 2400 frames would simulate 24 s each).
    assert main(["design", "--robot", "a2", "--candidates", "12", "--count", "2", "--frames", "400",
                 "--contact-seeds", "1", "--weld-seeds", "1", "--json"]) == 0
    import json

    d = json.loads(capsys.readouterr().out)
    assert set(d) >= {"default", "designed", "designed_stances", "frames"} and len(d["designed_stances"]) == 2
    assert d["designed"]["eigenvalues"][0] > 0 and len(d["designed"]["std_deg"]) == 12
    # Every chosen stance passed the hold screen in both modes.
    for st in d["designed_stances"]:
        rep = d["screened"][st["name"]]
        assert rep["held"] and rep["weld"]["pelvis_mm"] <= rep["weld"]["pelvis_limit_mm"] and "contact" in rep
    assert set(d["default_screen"]) == set(STANCES)
    assert main(["design", "--robot", "a3", "--count", "5", "--candidates", "3"]) == 2


def test_design_plot(tmp_path, capsys):
    png = tmp_path / "design.png"
    assert main(["design", "--robot", "a2", "--candidates", "8", "--count", "2", "--no-screen", "--plot", str(png)]) == 0
    assert png.stat().st_size > 10_000 and f"wrote {png}" in capsys.readouterr().out


def test_a_protocol_file_round_trips_and_collects(tmp_path):
    import pytest

    from legcal_bench.data.recording import load_session
    from legcal_bench.errors import ConfigError
    from legcal_bench.protocol.collect import CollectConfig, collect
    from legcal_bench.protocol.stances import Stance, load_protocol, write_protocol

    st = [Stance("D1", "designed", left_x=0.05, right_x=-0.05, depth=0.1), Stance("D2", "designed", toe_out=0.1)]
    path = write_protocol(tmp_path / "p.yaml", st, {"robot": "a3"})
    assert list(load_protocol(path).values()) == st
    out = tmp_path / "set"
    collect(CollectConfig(robot="a3", mode="kinematic", protocol=str(path), stance_s=2.0, heldout=1, heldout_s=1.0,
                          standing_s=0.0), out, progress=False)
    recs = load_session(out)
    assert [r.stance for r in recs] == ["D1", "D2", recs[2].stance] and recs[2].stance in ("D1", "D2")
    text = path.read_text()
    for bad, message in ((text.replace("depth: 0.1", "depth: abc"), r"stances\[0\]: field 'depth' must be a finite"),
                         (text.replace("name: D1", "name: II"), r"name 'II' is taken"),
                         ("format: x\n", "field 'format' must be 'legcal-protocol'")):
        (tmp_path / "bad.yaml").write_text(bad)
        with pytest.raises(ConfigError, match=message):
            load_protocol(tmp_path / "bad.yaml")


def test_excite_learns_on_the_env_reward_and_reports_the_three_motions(tmp_path, capsys):
    import json

    out = tmp_path / "excite.json"
    assert main(["excite", "--robot", "a2", "--frames", "150", "--iterations", "2", "--population", "3",
                 "--elite", "1", "--out", str(out), "--json"]) == 0
    d = json.loads(out.read_text())
    assert json.loads(capsys.readouterr().out)["learned"] == d["learned"]
    # Motion gathers information that standing still does not; the learned motion is
    # the best held episode, never worse than the protocol's it starts from.
    assert d["protocol"]["episode_return"] > d["still"]["episode_return"]
    assert d["learned"]["held"] and d["learned"]["episode_return"] >= d["protocol"]["episode_return"]
    assert d["still"]["factors"] == [0.0] * 6 and len(d["history"]) == 2 and "commit" in d["code"]
    assert main(["excite", "--robot", "a2", "--population", "2", "--elite", "2"]) == 2
    assert "--elite 2" in capsys.readouterr().err


def test_the_screen_rejects_a_stance_out_of_reach_and_design_goes_on_within_its_budget():
    from dataclasses import replace

    import pytest

    from legcal_bench.errors import ConfigError
    from legcal_bench.estimation.information.design import design
    from legcal_bench.protocol.screen import HoldScreen

    screen = HoldScreen(load_robot("a2"), "random:1.2", contact_seeds=1, weld_seeds=1, duration_s=2.0)
    far = replace(STANCES["II"], name="far", left_x=3.0, right_x=-3.0)  # soles three leg lengths apart
    report = screen(far)
    assert not report.held and report.unreachable and "does not fit this robot" in report.unreachable
    assert report.failures()[0].startswith("unreachable: ") and report.to_dict()["unreachable"]
    # A design out of time says how far it got instead of running on (a screen that takes no time).
    kin = LegKinematics(load_robot("a3"))
    with pytest.raises(ConfigError, match=r"time budget of 0 s ran out after the hold screen of 0 of \d+ fitting"):
        design(kin, list(STANCES.values()), k=2, candidates=4, frames=400, screen=lambda s: None, budget_s=0)
