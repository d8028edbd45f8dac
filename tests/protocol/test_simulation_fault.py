"""A simulation that shakes or diverges is reported as a simulation fault (issue #59),
naming the segment and the body that moved, never as the recording's units and never
naming a temporary path."""

from __future__ import annotations

import yaml

import pytest

from legcal_bench.cli import main
from legcal_bench.errors import SimulationError
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import ASSETS


@pytest.fixture
def shaky(tmp_path):
    """The A3-like robot with servo gains far too stiff for the simulation's time step
    (kp 1e9 N m/rad): its weld collection shakes (the IMU reads ~4 g)."""
    d = yaml.safe_load((ASSETS / "a3.legmap.yaml").read_text())
    d["mjcf"] = str(ASSETS / d["mjcf"])
    d["servo_gains"] = {j["name"]: [1e9, 0.0] for s in ("left", "right") for j in d["legs"][s]["joints"]}
    path = tmp_path / "shaky.legmap.yaml"
    path.write_text(yaml.safe_dump(d))
    return str(path)


def test_a_shaking_simulation_is_a_simulation_fault_naming_the_body(shaky, tmp_path):
    with pytest.raises(SimulationError) as e:
        collect(CollectConfig(robot=shaky, mode="weld", stances=("I",), heldout=0, stance_s=1.0, standing_s=1.0),
                tmp_path / "out", progress=False)
    text = str(e.value)
    assert text.startswith("segment standing, stance standing (weld mode): a simulation fault"), text
    assert "moved fastest" in text and "body '" in text and "servo_gains" in text, text
    assert "Convert from g" not in text and ".tmp" not in text and str(tmp_path) not in text, text
    assert not (tmp_path / "out").exists()  # nothing half-written


def test_the_command_says_it_in_one_line(shaky, tmp_path, capsys):
    code = main(["collect", "--robot", shaky, "--mode", "weld", "--stances", "I", "--heldout", "0", "--quiet",
                 "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1 and "a simulation fault" in err[0] and "Traceback" not in err[0], err
