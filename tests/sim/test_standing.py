"""The standing controller (issue #38, `legcal_bench.sim.standing`): centre-of-pressure
regulation with the ankles from the ankle force/torque sensors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from legcal_bench.data.recording import list_segments, load_truth
from legcal_bench.errors import ConfigError, HoldError
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.reports.contact_floor import PARTS, sole_departure
from legcal_bench.robots import load_robot
from legcal_bench.sim.double_support import DoubleSupportSim
from legcal_bench.sim.sensors import sim_sensors

G1 = str(Path(__file__).resolve().parents[2] / "examples" / "unitree_g1.legmap.yaml")
SHORT = dict(mode="contact", sensors="zero", seed=0, heldout=0, stances=("I",), standing_s=0.0)


def _rocking_deg(folder) -> float:
    deps = [sole_departure(load_truth(p)) for p in list_segments(folder) if Path(p).stem.startswith("stance_")]
    return max(float(np.rad2deg(np.linalg.norm(PARTS["rocking"](d)[..., 3:5], axis=-1).max())) for d in deps)


def test_the_ankles_keep_the_g1_soles_from_rocking_onto_an_edge(tmp_path):
    """The G1 stands on four 5 mm spheres per foot; with the paper's offsets the closed
    chain's strain loads one edge of each sole and the soles rock 0.4-0.6 deg as the
    posture moves. Yielding the ankles to that strain keeps them within a few
    hundredths of a degree."""
    collect(CollectConfig(robot=G1, standing="none", **SHORT), tmp_path / "none", progress=False)
    collect(CollectConfig(robot=G1, standing="cop", **SHORT), tmp_path / "cop", progress=False)
    none, cop = _rocking_deg(tmp_path / "none"), _rocking_deg(tmp_path / "cop")
    assert none > 0.2, none
    assert cop < 0.05, cop


def test_the_default_runs_the_controller_on_a_contact_floor_only():
    from legcal_bench.protocol.collect import standing_controller

    a3 = load_robot("a3")
    assert standing_controller(CollectConfig(mode="contact"), a3) == "cop"
    assert standing_controller(CollectConfig(mode="weld"), a3) == "none"
    assert standing_controller(CollectConfig(mode="contact", standing="none"), a3) == "none"


def test_a_robot_without_ankle_sensors_is_refused_the_controller_naming_the_fix(tmp_path):
    text = yaml.safe_load(Path(load_robot("a3").source).read_text())
    for side in ("left", "right"):
        text["legs"][side].pop("ft")
    text["mjcf"] = str(Path(load_robot("a3").source).parent / text["mjcf"])
    (tmp_path / "no_ft.legmap.yaml").write_text(yaml.safe_dump(text))
    lm = load_robot(str(tmp_path / "no_ft.legmap.yaml"))
    with pytest.raises(ConfigError, match=r"standing_controller 'cop' .*has none: give legs.left.ft and legs.right.ft"):
        DoubleSupportSim(lm, "contact", np.zeros(lm.n_joints), sim_sensors("zero"), standing_controller="cop")
    from legcal_bench.protocol.collect import standing_controller

    assert standing_controller(CollectConfig(mode="contact"), lm) == "none"


def test_the_legs_yield_to_a_twist_the_hip_yaw_offsets_put_on_the_soles(tmp_path):
    """Hip-yaw offsets of opposite sign (+-3.5 deg) make the legs disagree about the
    soles' heading by 7 deg; stiff yaw servos then twist a sole on the floor beyond
    friction. The controller's shear and yaw part (foot damping control) yields the
    legs to the twist: the soles stay put. The message names the twist."""
    a3 = load_robot("a3")
    offsets = np.zeros(a3.n_joints)
    names = list(a3.joint_names)
    offsets[names.index("left_hip_yaw_joint")], offsets[names.index("right_hip_yaw_joint")] = np.deg2rad([3.5, -3.5])
    cfg = dict(robot="a3", offsets=tuple(offsets), **{k: v for k, v in SHORT.items() if k != "sensors"},
               sensors="zero")
    with pytest.raises(HoldError, match=r"the \w+ sole twisted on the floor: it turned 1\.\d\d deg, 1\.\d\d of it "
                                        r"about its normal .*Likely cause: the legs disagree .*Fix: stand with the "
                                        r"standing controller \(--standing cop\)"):
        collect(CollectConfig(standing="none", **cfg), tmp_path / "none", progress=False)
    held = collect(CollectConfig(standing="cop", **cfg), tmp_path / "cop", progress=False)
    worst = max(max(g.hold["sole_tilt_deg"]) for g in held.segments)
    assert worst < 0.05, worst
