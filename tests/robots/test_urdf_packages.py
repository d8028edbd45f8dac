"""A URDF as robot teams ship it (issue #59): inside a ROS package, its meshes named by
`package://` URIs, found by the leg map's `packages`, the environment's package paths,
the folder above the URDF or an installed Python package; a xacro expanded; an
unresolved URI refused naming the package and the ways to give it."""

from __future__ import annotations

import shutil
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

from legcal_bench.calibrators.base import calibrate_training
from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import load_session
from legcal_bench.errors import LegMapError
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots.samples import PACKAGE, ros_package

PKG = PACKAGE


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    """Converted URDFs go to this test's folder; no package path of the machine's."""
    monkeypatch.setenv("LEGCAL_CACHE", str(tmp_path / "cache"))
    for var in ("ROS_PACKAGE_PATH", "AMENT_PREFIX_PATH"):
        monkeypatch.delenv(var, raising=False)


def _package(root: Path) -> Path:
    """The A3-like URDF twin as a vendor ships it (`legcal_bench.robots.samples.ros_package`)."""
    return ros_package(root)


def _copy_out(legmap_path: Path, where: Path, **fields) -> Path:
    """The package's URDF and leg map copied out of the package (its URIs unresolvable
    by the folder rule), the leg map given `fields`."""
    where.mkdir(parents=True)
    shutil.copy(legmap_path.parent.parent / "urdf" / "a3.urdf", where / "a3.urdf")
    d = yaml.safe_load(legmap_path.read_text())
    d.update(urdf="a3.urdf", **fields)
    (where / "a3.legmap.yaml").write_text(yaml.safe_dump(d, sort_keys=False))
    return where / "a3.legmap.yaml"


def test_a_urdf_in_its_ros_package_runs_unedited(tmp_path):
    path = _package(tmp_path)
    lm = load_robot(str(path))
    mjcf = lm.mjcf.read_text()
    assert "package://" not in mjcf and ".dae" not in mjcf and str(tmp_path / "src" / PKG / "meshes") in mjcf
    ref = load_robot("a3")
    q = np.random.default_rng(0).uniform(-0.4, 0.4, (3, 12))
    for qi in q:
        np.testing.assert_allclose(LegKinematics(lm).inter_foot(qi).homogeneous,
                                   LegKinematics(ref).inter_foot(qi).homogeneous, atol=1e-12)
    collect(CollectConfig(robot=str(path), mode="kinematic", heldout=0, stance_s=2.0, standing_s=1.0),
            tmp_path / "kinematic", progress=False)
    got = [calibrate_training(get_calibrator("interfoot"), m, load_session(tmp_path / "kinematic", m.joint_names))
           .offsets_vector(m.joint_names) for m in (lm, ref)]
    assert np.abs(got[0] - got[1]).max() <= 1e-9
    s = collect(CollectConfig(robot=str(path), mode="weld", stances=("I",), heldout=0, stance_s=2.0, standing_s=1.0),
                tmp_path / "weld", progress=False)  # the soles' STL meshes on the weld floor
    assert len(s.segments) == 2


def test_an_unresolved_package_is_named_with_the_ways_to_give_it(tmp_path):
    out = _copy_out(_package(tmp_path), tmp_path / "elsewhere")
    with pytest.raises(LegMapError) as e:
        load_robot(str(out))
    text = str(e.value)
    for part in (f"package://{PKG}/meshes/left_foot_link.stl", f"ROS package '{PKG}'", f"packages: {{{PKG}:",
                 "ROS_PACKAGE_PATH", "AMENT_PREFIX_PATH", "inside that package's folder", "Python package"):
        assert part in text, text


def test_the_leg_map_and_the_environment_give_the_package(tmp_path, monkeypatch):
    path = _package(tmp_path)
    pkg = path.parent.parent
    given = load_robot(str(_copy_out(path, tmp_path / "given", packages={PKG: str(pkg)})))
    assert given.packages == {PKG: pkg} and str(pkg / "meshes") in given.mjcf.read_text()
    assert yaml.safe_load(yaml.safe_dump(given.to_dict()))["packages"] == {PKG: str(pkg)}
    bare = _copy_out(path, tmp_path / "bare")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(pkg.parent))  # ROS 1: the folders holding packages
    assert str(pkg / "meshes") in load_robot(str(bare)).mjcf.read_text()
    monkeypatch.delenv("ROS_PACKAGE_PATH")
    prefix = tmp_path / "install"
    shutil.copytree(pkg, prefix / "share" / PKG)  # ROS 2: <prefix>/share/<package>
    monkeypatch.setenv("AMENT_PREFIX_PATH", f"{tmp_path / 'nothing'}:{prefix}")
    assert str(prefix / "share" / PKG / "meshes") in load_robot(str(bare)).mjcf.read_text()


def test_an_installed_python_package_gives_the_package(tmp_path, monkeypatch):
    path = _package(tmp_path)
    site = tmp_path / "site"
    shutil.copytree(path.parent.parent, site / PKG)  # a robot-description package from PyPI
    (site / PKG / "__init__.py").write_text("")
    monkeypatch.syspath_prepend(str(site))
    bare = _copy_out(path, tmp_path / "bare")
    assert str(site / PKG / "meshes") in load_robot(str(bare)).mjcf.read_text()


def test_leg_map_packages_mistakes_are_named(tmp_path):
    path = _package(tmp_path)
    with pytest.raises(LegMapError, match=r"packages.a3_description = 'nowhere': .* is not a folder"):
        load_robot(str(_copy_out(path, tmp_path / "a", packages={PKG: "nowhere"})))
    (tmp_path / "other").mkdir()
    with pytest.raises(LegMapError, match=r"package 'a3_description' is .*other, which has no file meshes/"):
        load_robot(str(_copy_out(path, tmp_path / "b", packages={PKG: str(tmp_path / "other")})))


def test_a_collada_collision_mesh_is_named(tmp_path):
    path = _package(tmp_path)
    urdf = path.parent.parent / "urdf" / "a3.urdf"
    dae = path.parent.parent / "meshes" / "left_foot_link.dae"
    dae.write_text("<COLLADA/>")
    urdf.write_text(urdf.read_text().replace("meshes/left_foot_link.stl", "meshes/left_foot_link.dae"))
    with pytest.raises(LegMapError, match=r"MuJoCo reads STL, OBJ and MSH meshes, not COLLADA: convert the "
                                          r"collision meshes .*left_foot_link.dae"):
        load_robot(str(path))


def test_a_xacro_is_expanded_or_refused_with_the_fix(tmp_path, monkeypatch):
    path = _package(tmp_path)
    urdf = path.parent.parent / "urdf" / "a3.urdf"
    root = ET.parse(urdf).getroot()
    root.set("xmlns:xacro", "http://www.ros.org/wiki/xacro")
    mass = next(root.iter("mass"))
    text = ET.tostring(root, encoding="unicode").replace(f'<mass value="{mass.get("value")}"', '<mass value="${m}"', 1)
    text = text.replace(">", f'><xacro:property name="m" value="{mass.get("value")}"/>', 1)
    assert "${m}" in text
    (urdf.parent / "a3.urdf.xacro").write_text(text)
    d = yaml.safe_load(path.read_text())
    d["urdf"] = "../urdf/a3.urdf.xacro"
    path.write_text(yaml.safe_dump(d, sort_keys=False))
    lm = load_robot(str(path))
    assert lm.urdf.name == "a3.urdf.xacro"
    q = np.random.default_rng(1).uniform(-0.4, 0.4, 12)
    np.testing.assert_allclose(LegKinematics(lm).inter_foot(q).homogeneous,
                               LegKinematics(load_robot("a3")).inter_foot(q).homogeneous, atol=1e-12)
    monkeypatch.setitem(sys.modules, "xacro", None)  # as if not installed
    with pytest.raises(LegMapError, match=r"a xacro file and the xacro package is not installed: install it "
                                          r"\(pip install xacro\) or expand it yourself"):
        LegKinematics(lm)
