"""The hold check names the cause that fits the numbers (issue #38 item 4): what the
offsets' strain of the closed chain does to the pelvis is predicted from the targets and
the servo gains and not held against the robot; what is left (sag, folding) is."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import legcal_bench.protocol.collect as collect_module
from legcal_bench.errors import HoldError
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import VARIATIONS

ONE_LUNGE = dict(mode="weld", sensors="zero", seed=0, heldout=0, stances=("III",), standing_s=0.0)


def test_a_kid_size_robot_at_5_deg_offsets_holds_its_strained_pose(tmp_path):
    """0.3 m legs, 5 deg offsets: the pelvis ends 16.3 mm from the targets' pose, over 5 %
    of the leg (15.0 mm), which used to fail as soft servos. 8.2 mm of it is the offsets'
    strain; 12.3 mm is left (docs/contact-floor.md quotes these figures)."""
    robot = str(write_robot(next(d for d in VARIATIONS if d.name == "kid_size"), tmp_path / "robot"))
    summary = collect(CollectConfig(robot=robot, offsets="paper@5", **ONE_LUNGE), tmp_path / "set", progress=False)
    hold = summary.segments[-1].hold
    assert hold["held"]
    assert hold["pelvis_mm"] > hold["pelvis_limit_mm"]
    assert hold["pelvis_beyond_strain_mm"] < hold["pelvis_limit_mm"]
    assert [round(hold[k], 1) for k in ("pelvis_mm", "pelvis_strain_mm", "pelvis_beyond_strain_mm",
                                        "pelvis_limit_mm")] == [16.3, 8.2, 12.3, 15.0]


def test_servos_too_soft_are_named_with_what_the_strain_does_not_explain(tmp_path, monkeypatch):
    """The A3-like robot with a quarter of its gains folds in the right lunge: nearly all
    of the pelvis's error is beyond the strained pose, and the message says so."""
    gains = collect_module.servo_gains

    def soft(lm):
        g = gains(lm)
        return dataclasses.replace(g, kp=tuple(np.array(g.kp) / 4), kd=tuple(np.array(g.kd) / 2))

    monkeypatch.setattr(collect_module, "servo_gains", soft)
    with pytest.raises(HoldError, match=r"the pelvis was \d+\.\d mm from its commanded pose, \d+\.\d mm from where "
                                        r"the offsets' strain of the closed chain puts it \(\d\.\d mm from that pose\)"
                                        r".*Likely cause: the servos are too soft"):
        collect(CollectConfig(robot="a3", offsets="paper", **ONE_LUNGE), Path(tmp_path) / "set", progress=False)


def test_a_fall_is_called_a_fall_not_a_twist_or_soft_servos():
    """A sole hundreds of millimetres away and turned over fell with the robot: the
    message says so, not that it twisted on the floor or that the servos sag."""
    from legcal_bench.sim.hold import HoldReport

    fallen = HoldReport(0.34, 0.0468, (0.374, 0.0003), (np.deg2rad(179.1), np.deg2rad(0.2)),
                        pelvis_excess_m=0.34, sole_turn_rad=(np.deg2rad(123.2), 0.0))
    assert fallen.fell and fallen.failures() == [
        "the robot fell: the left sole moved 374 mm and turned 179 deg, the pelvis ended 340 mm from its commanded pose"]
    twisted = HoldReport(0.01, 0.0468, (0.0029, 0.0), (np.deg2rad(1.83), 0.0), sole_turn_rad=(np.deg2rad(1.83), 0.0))
    assert not twisted.fell and twisted.soles_twisted and "twisted on the floor" in twisted.failures()[1]


def test_contact_holds_counts_a_failure_by_what_the_hold_check_found(monkeypatch):
    """A set that fails is counted under the soles or the pelvis from the hold check's
    report, not from the message's words (a twist or a fall reads differently)."""
    import legcal_bench.protocol.collect as collect_module
    from legcal_bench.errors import HoldError
    from legcal_bench.reports import contact_holds
    from legcal_bench.sim.hold import HoldReport

    reports = {"twist": HoldReport(0.01, 0.0468, (0.0, 0.0), (np.deg2rad(1.8), 0.0), sole_turn_rad=(np.deg2rad(1.8), 0.0)),
               "fold": HoldReport(0.3, 0.0468, (0.0, 0.0), (0.0, 0.0))}
    for kind, report in reports.items():
        def refuse(*args, **kwargs):
            raise HoldError(f"segment stance_I: {'; '.join(report.failures())}", report)

        monkeypatch.setattr(collect_module, "collect", refuse)
        row = contact_holds.run_case("a3", "cop", 0)
        assert not row["held"] and row["why"] == {"twist": "sole", "fold": "pelvis"}[kind], row
