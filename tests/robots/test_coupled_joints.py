"""A leg joint turned through a drive joint (an MJCF joint equality; a URDF mimic compiles
to one): not simulated yet, and said so by name with the coupling and the fix; the drive
is not held (it would lock the leg); a calibration on such a robot says its encoder
columns were read as the joints' own angles."""

import shutil

import pytest
import yaml

from legcal_bench import api
from legcal_bench.errors import LegMapError
from legcal_bench.estimation.verdict import DOUBTS
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import ASSETS
from legcal_bench.robots.holds import joint_couplings, joint_holds
from legcal_bench.sim.scene import build_scene

ROTOR = ('<body name="left_hip_yaw_rotor" pos="0 0 -0.05"><joint name="left_hip_yaw_drive" axis="0 0 1" '
         'range="-2 2"/><inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/></body>\n')


@pytest.fixture
def coupled(tmp_path):
    """The A3-like robot with its left hip yaw turned by a drive joint on a rotor body, at
    a 1:2 ratio: the actuator on the drive, the joint equality hip_yaw = 0.5 drive."""
    xml = (ASSETS / "a3.xml").read_text()
    anchor = '<body name="left_hip_yaw_link" pos="0 0 -0.075">'
    assert anchor in xml
    xml = xml.replace(anchor, ROTOR + anchor, 1)
    xml = xml.replace('joint="left_hip_yaw_joint" kp="800" kv="32"', 'joint="left_hip_yaw_drive" kp="200" kv="8"')
    xml = xml.replace("</actuator>", "</actuator>\n  <equality><joint joint1=\"left_hip_yaw_joint\" "
                      "joint2=\"left_hip_yaw_drive\" polycoef=\"0 0.5 0 0 0\"/></equality>", 1)
    (tmp_path / "a3.xml").write_text(xml)
    shutil.copy(ASSETS / "a3.legmap.yaml", tmp_path / "a3.legmap.yaml")
    d = yaml.safe_load((tmp_path / "a3.legmap.yaml").read_text())
    d["name"] = "a3_coupled"
    (tmp_path / "a3.legmap.yaml").write_text(yaml.safe_dump(d))
    return tmp_path / "a3.legmap.yaml"


def test_the_coupling_is_read_and_the_drive_not_held(coupled):
    lm = load_robot(str(coupled))
    (c,) = joint_couplings(lm.mjcf)
    assert (c.joint, c.drive, c.polycoef[:2]) == ("left_hip_yaw_joint", "left_hip_yaw_drive", (0.0, 0.5))
    assert joint_holds(lm) == ()


def test_simulating_it_is_refused_naming_the_coupling_and_the_fix(coupled):
    with pytest.raises(LegMapError, match=r"leg joint 'left_hip_yaw_joint' has neither a position actuator nor a "
                                          r"motor in the MJCF; it is coupled to joint 'left_hip_yaw_drive' .*"
                                          r"left_hip_yaw_joint = 0 \+ 0.5 left_hip_yaw_drive.*own actuator"):
        build_scene(load_robot(str(coupled)), "weld")


def test_a_calibration_says_the_columns_were_read_as_the_joints(coupled, tmp_path):
    out = tmp_path / "k"
    collect(CollectConfig(robot=str(coupled), mode="kinematic", sensors="zero", offsets="paper", seed=0), out,
            progress=False)
    result = api.calibrate(out, str(coupled))
    found = [r for r in result.verdict["reasons"] if "coupled to joint left_hip_yaw_drive" in r["text"]]
    assert len(found) == 1 and found[0]["meaning"] == DOUBTS
    assert result.decision == "review"
