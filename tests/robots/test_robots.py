from dataclasses import fields
from pathlib import Path

import pinocchio as pin
import pytest
import yaml

from legcal_bench.robots import BUILTIN, load_robot
from legcal_bench.robots.build import ASSETS, write_robot
from legcal_bench.robots.design import DESIGNS, PAIR_PRY, PAIR_RYP
from legcal_bench.errors import LegMapError
from legcal_bench.robots.legmap import load_legmap


def test_committed_assets_are_what_the_design_generates(tmp_path):
    for design in DESIGNS.values():
        write_robot(design, tmp_path)
        for suffix in (".xml", ".legmap.yaml"):
            name = design.name + suffix
            assert (tmp_path / name).read_text() == (ASSETS / name).read_text(), (
                f"{name} is stale: run python -m legcal_bench.robots.build")


def test_matched_pair_differs_only_in_hip_order():
    differing = [f.name for f in fields(PAIR_RYP) if getattr(PAIR_RYP, f.name) != getattr(PAIR_PRY, f.name)]
    assert differing == ["name", "hip_order"]
    assert load_robot("pair_ryp").hip_order == ("hip_roll", "hip_yaw", "hip_pitch")
    assert load_robot("pair_pry").hip_order == ("hip_pitch", "hip_roll", "hip_yaw")


def test_builtin_orders():
    assert load_robot("a2").hip_order == ("hip_roll", "hip_yaw", "hip_pitch")
    assert load_robot("a3").hip_order == ("hip_pitch", "hip_roll", "hip_yaw")
    assert set(BUILTIN) == {"a2", "a3", "pair_ryp", "pair_pry"}


def _write(tmp_path: Path, data: dict) -> Path:
    p = tmp_path / "robot.legmap.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


@pytest.fixture
def a3_dict():
    d = yaml.safe_load((ASSETS / "a3.legmap.yaml").read_text())
    d["mjcf"] = str(ASSETS / "a3.xml")
    return d


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.pop("pelvis"), "missing field 'pelvis'"),
    (lambda d: d.update(mjcf="nowhere.xml"), "field 'mjcf' points to"),
    (lambda d: d["legs"]["left"]["joints"][0].update(role="hip_twist"), "legs.left.joints[0].role"),
    (lambda d: d["legs"]["left"]["joints"].pop(), "legs.left.joints: 5 joints listed; this leg map describes legs "
                                                   "of 6 joints"),
    (lambda d: d["legs"]["left"]["joints"].pop(), "declares it with absent_roles: [ankle_roll]"),
    (lambda d: d.update(absent_roles=["ankle_roll"]), "legs.left.joints: 6 joints listed; this leg map describes "
                                                      "legs of 5 joints"),
    (lambda d: d.update(absent_roles=["knee"]), "absent_roles: ['knee']; the roles a leg may lack are"),
    (lambda d: d["legs"]["left"]["joints"].append({"name": "toe", "role": "knee"}), "7 joints listed"),
    (lambda d: d["legs"]["left"].update(joints="all of them"), "list the leg's joints from pelvis to foot"),
    (lambda d: d["legs"]["left"]["corners"].pop("toe_left"), "legs.left.corners"),
    (lambda d: d["legs"]["right"].update(sole={"site": "x", "body": "y"}), "exactly one of 'site"),
    (lambda d: d.update(schema="v0"), "field 'schema'"),
])
def test_bad_legmap_names_the_field(tmp_path, a3_dict, edit, message):
    edit(a3_dict)
    with pytest.raises(LegMapError, match=message.replace("[", r"\[").replace("]", r"\]").replace("(", r"\(")):
        load_legmap(_write(tmp_path, a3_dict))


def test_legmap_joint_not_in_mjcf(tmp_path, a3_dict):
    from legcal_bench.robots.kinematics import LegKinematics

    a3_dict["legs"]["left"]["joints"][0]["name"] = "left_hip_pitch"
    with pytest.raises(LegMapError, match="'left_hip_pitch' is not in"):
        LegKinematics(load_legmap(_write(tmp_path, a3_dict)))


def test_unknown_robot_name():
    with pytest.raises(LegMapError, match="unknown robot 'a4'"):
        load_robot("a4")


def test_example_robots_resolve_from_any_folder(tmp_path, monkeypatch):
    from legcal_bench.files.packaged import examples_dir
    from legcal_bench.robots import resolve_robot, robot_label

    monkeypatch.chdir(tmp_path)  # not a checkout: examples/ must come from the package
    ref = resolve_robot("examples/unitree_g1.legmap.yaml")
    assert Path(ref).is_absolute() and Path(ref).parent == examples_dir()
    assert robot_label(ref) == "unitree_g1" and robot_label("a3") == "a3"
    assert load_robot("examples/unitree_g1.legmap.yaml").name == "unitree_g1"
    with pytest.raises(LegMapError, match="unknown robot 'a4'"):
        resolve_robot("a4")


def test_a_missing_mjcf_is_its_own_error_naming_the_path(tmp_path, a3_dict):
    from legcal_bench.errors import MissingModelError
    from legcal_bench.robots import available

    a3_dict["mjcf"] = "missing/robot.xml"
    path = _write(tmp_path, a3_dict)
    with pytest.raises(MissingModelError, match=r"missing/robot\.xml, which does not exist"):
        load_legmap(path)
    assert "missing/robot.xml" in available(str(path)) and available("a3") is None


def test_leg_map_frames_are_resolved_by_type(tmp_path, a3_dict):
    """A site and a body may share a name in an MJCF: the leg map's field says which."""
    from legcal_bench.robots.kinematics import LegKinematics

    xml = Path(a3_dict["mjcf"]).read_text()
    # A site named like the pelvis body, inside it.
    xml = xml.replace('<site name="imu"', '<site name="pelvis" pos="0 0 0"/>\n      <site name="imu"', 1)
    assert xml.count('name="pelvis"') == 2
    (tmp_path / "robot.xml").write_text(xml)
    a3_dict["mjcf"] = str(tmp_path / "robot.xml")
    kin = LegKinematics(load_legmap(_write(tmp_path, a3_dict)))
    assert kin.model.frames[kin.pelvis_frame].type == pin.FrameType.BODY
    a3_dict["imu"] = {"site": "pelvis"}
    kin = LegKinematics(load_legmap(_write(tmp_path, a3_dict)))
    assert kin.model.frames[kin.imu_frame].type == pin.FrameType.OP_FRAME
    a3_dict["imu"] = {"site": "left_knee_joint"}  # a joint, not a site
    with pytest.raises(LegMapError, match=r"imu.site names site 'left_knee_joint', which is not a site .*only a "
                                          r"frame of type JOINT"):
        LegKinematics(load_legmap(_write(tmp_path, a3_dict)))
