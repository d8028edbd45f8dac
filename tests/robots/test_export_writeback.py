"""Write-back (issue #39, item 4): the offsets as a ROS 2 parameter file, and a copy of
a URDF robot's URDF whose leg joint origins fold the offsets in, so the copy fed the raw
encoder readings has the calibrated kinematics (test (e)); the fold checks itself with
Pinocchio and refuses to write a wrong copy."""

from __future__ import annotations

import math
import struct
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
import pytest
import yaml

from legcal_bench.calibrators.base import CalibrationResult
from legcal_bench.cli import main
from legcal_bench.errors import ConfigError, LegMapError
from legcal_bench.robots import export, load_robot
from legcal_bench.robots.build import write_urdf_robot
from legcal_bench.robots.design import A3
from legcal_bench.robots.export import check_urdf_fold, fold_into_urdf, write_ros2_params
from legcal_bench.robots.kinematics import LegKinematics


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    """Converted URDFs go to this test's folder."""
    monkeypatch.setenv("LEGCAL_CACHE", str(tmp_path / "cache"))


def _box_stl(path: Path) -> None:
    """A 10 cm cube as a binary STL."""
    v = [(x, y, z) for x in (-0.05, 0.05) for y in (-0.05, 0.05) for z in (-0.05, 0.05)]
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        f.write(b"\0" * 80 + struct.pack("<I", len(faces)))
        for a, b, c in faces:
            f.write(struct.pack("<12fH", 0, 0, 0, *v[a], *v[b], *v[c], 0))


def _urdf_robot(where: Path, edit=None) -> Path:
    """The A3 URDF twin in `where`, a collision mesh (meshes/box.stl, a relative path) on
    the pelvis, and `edit(text) -> text` applied; returns the leg map's path."""
    legmap = write_urdf_robot(A3, where)
    _box_stl(where / "meshes" / "box.stl")
    urdf = where / "a3.urdf"
    text = urdf.read_text().replace('<link name="pelvis">', '<link name="pelvis"><collision><origin xyz="0 0 0.3" '
                                    'rpy="0 0 0" /><geometry><mesh filename="meshes/box.stl" /></geometry></collision>', 1)
    urdf.write_text(edit(text) if edit else text)
    return legmap


def _offsets(lm, seed: int = 0) -> dict[str, float]:
    return dict(zip(lm.joint_names, np.deg2rad(np.random.default_rng(seed).uniform(-3, 3, lm.n_joints))))


def _frames(model, q: np.ndarray) -> np.ndarray:
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return np.array([T.homogeneous for T in data.oMf])


def _q(model, values: dict[str, float]) -> np.ndarray:
    q = pin.neutral(model)
    for name, v in values.items():
        q[model.joints[model.getJointId(name)].idx_q] = v
    return q


def _joints(urdf: Path) -> dict[str, ET.Element]:
    return {j.get("name"): j for j in ET.parse(urdf).getroot().iter("joint")}


def _body_poses(xml: Path, values: dict[str, float]) -> np.ndarray:
    m = mujoco.MjModel.from_xml_path(str(xml))
    d = mujoco.MjData(m)
    for name, v in values.items():
        d.qpos[m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)]] = v
    mujoco.mj_kinematics(m, d)
    return np.concatenate([d.xpos.ravel(), d.xmat.ravel()])


def _copied_legmap(legmap: Path, urdf: Path) -> Path:
    """The robot's leg map beside `urdf`, naming it."""
    d = yaml.safe_load(legmap.read_text())
    d["urdf"] = urdf.name
    out = urdf.parent / legmap.name
    out.write_text(yaml.safe_dump(d, sort_keys=False))
    return out


def test_the_folded_urdf_fed_raw_encoders_has_the_calibrated_kinematics(tmp_path):
    legmap = _urdf_robot(tmp_path / "robot")
    lm = load_robot(str(legmap))
    dq = _offsets(lm)
    out = fold_into_urdf(lm, dq, tmp_path / "export" / "a3_calibrated.urdf")  # another folder than the robot's
    assert out.is_file() and check_urdf_fold(lm, dq, out) <= 1e-12

    # (e) Pinocchio, independently of the fold's own check: every frame of the copy at raw encoder readings
    # sits where the original's does at q_enc + dq.
    old, new = pin.buildModelFromUrdf(str(lm.urdf)), pin.buildModelFromUrdf(str(out))
    assert [f.name for f in old.frames] == [f.name for f in new.frames]
    rng, worst = np.random.default_rng(7), 0.0
    for _ in range(5):
        q_enc = dict(zip(lm.joint_names, rng.uniform(-0.5, 0.5, lm.n_joints)))
        q_cal = {n: q_enc[n] + dq[n] for n in lm.joint_names}
        diff = np.abs(_frames(new, _q(new, q_enc)) - _frames(old, _q(old, q_cal))).max()
        worst = max(worst, diff)
        # Without the correction the two differ, so the check above can fail.
        assert np.abs(_frames(new, _q(new, q_enc)) - _frames(old, _q(old, q_enc))).max() > 1e-3
    assert worst <= 1e-12
    print(f"max frame difference over 5 random encoder readings: {worst:.2e}")

    # Limits keep meaning the same physical angles: moved by -dq; nothing else about the joints changed.
    before, after = _joints(lm.urdf), _joints(out)
    for name in lm.joint_names:
        for side in ("lower", "upper"):
            assert float(after[name].find("limit").get(side)) == float(before[name].find("limit").get(side)) - dq[name]
        assert after[name].find("origin").get("xyz") == before[name].find("origin").get("xyz")
        assert after[name].find("axis").get("xyz") == before[name].find("axis").get("xyz")
    assert {n: ET.tostring(j) for n, j in after.items() if n not in dq} == \
        {n: ET.tostring(j) for n, j in before.items() if n not in dq}

    # The mesh path is rewritten relative to the copy's folder: Pinocchio finds it (relative paths resolve
    # against the package folders: the copy's), and MuJoCo through load_robot with a leg map beside the copy.
    mesh = ET.parse(out).getroot().find("link/collision/geometry/mesh").get("filename")
    assert mesh == "../robot/meshes/box.stl"
    geom = pin.buildGeomFromUrdf(new, str(out), pin.GeometryType.COLLISION, package_dirs=[str(out.parent)])
    assert Path(geom.geometryObjects[0].meshPath).resolve() == (tmp_path / "robot" / "meshes" / "box.stl").resolve()
    twin = load_robot(str(_copied_legmap(legmap, out)))
    assert twin.urdf == out.resolve() and mujoco.MjModel.from_xml_path(str(twin.mjcf)).nmesh == 1
    q_enc = dict(zip(lm.joint_names, LegKinematics(lm).q_init() + rng.normal(0, 0.1, lm.n_joints)))
    # MuJoCo agrees to the precision of the URDF's conversion (robots/urdf.py saves the compiled MJCF, whose body
    # quaternions carry 6 significant digits: ~1e-7 m here); Pinocchio (the calibrators' kinematics) to 1e-12.
    mj_new, mj_old = _body_poses(twin.mjcf, q_enc), _body_poses(lm.mjcf, {n: q_enc[n] + dq[n] for n in lm.joint_names})
    np.testing.assert_allclose(mj_new, mj_old, atol=1e-6)
    assert np.abs(mj_new - _body_poses(lm.mjcf, q_enc)).max() > 1e-3
    kin_old, kin_new = LegKinematics(lm), LegKinematics(twin)
    q = np.array(list(q_enc.values()))
    for T_new, T_old in zip(kin_new.sole_poses(q), kin_old.sole_poses(q + np.array(list(dq.values())))):
        np.testing.assert_allclose(T_new.homogeneous, T_old.homogeneous, atol=1e-12)

    with pytest.raises(ConfigError, match="--urdf-out .* exists: give a new file name"):
        fold_into_urdf(lm, dq, out)


def test_a_wrong_fold_is_caught_and_not_written(tmp_path, monkeypatch):
    lm = load_robot(str(_urdf_robot(tmp_path / "robot")))
    dq = _offsets(lm, 1)
    right = export._folded_urdf_text
    wrong = right(lm, {n: -v for n, v in dq.items()}, tmp_path)  # the sign flipped
    assert export._urdf_fk_error(lm.urdf.read_text(), wrong, dq) > 1e-3
    monkeypatch.setattr(export, "_folded_urdf_text", lambda lm, off, d: right(lm, {n: -v for n, v in off.items()}, d))
    with pytest.raises(LegMapError, match=r"does not reproduce the calibrated kinematics .*nothing written"):
        fold_into_urdf(lm, dq, tmp_path / "wrong.urdf")
    assert not (tmp_path / "wrong.urdf").exists()


def test_gimbal_lock_prismatic_continuous_mimic_and_joint_coordinates(tmp_path):
    """Origins at pitch +-pi/2, a rotated prismatic joint, an unaligned and unnormalised
    axis, a continuous joint, a mimic of a leg joint and the other angles a URDF states in
    joint coordinates."""
    def edit(t: str) -> str:
        def joint(name: str, old: str, new: str) -> str:
            i = t.index(f'<joint name="{name}"')
            j = t.index("</joint>", i)
            assert old in t[i:j], (name, old)
            return t[:i] + t[i:j].replace(old, new, 1) + t[j:]
        t = joint("left_hip_roll_joint", 'rpy="0 0 0"', f'rpy="0.3 {math.pi / 2!r} -0.2"')
        t = joint("right_hip_roll_joint", 'rpy="0 0 0"', f'rpy="-0.4 {-math.pi / 2!r} 0.7"')
        t = joint("left_hip_yaw_joint", '<axis xyz="0 0 1" />', '<axis xyz="0.3 -0.4 1.2" />')
        t = joint("right_knee_joint", 'type="revolute"', 'type="prismatic"')
        t = joint("right_knee_joint", 'rpy="0 0 0"', 'rpy="0.2 -0.3 0.5"')
        t = joint("left_ankle_roll_joint", 'type="revolute"', 'type="continuous"')
        t = joint("left_knee_joint", "<dynamics", '<safety_controller soft_lower_limit="-0.05" soft_upper_limit="2.5" '
                  'k_position="10" k_velocity="1" /><calibration rising="0.5" /><dynamics')
        t = t.replace("</robot>", '<link name="linkage"><inertial><origin xyz="0 0 0" rpy="0 0 0" /><mass value="0.1" />'
                      '<inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4" /></inertial></link>'
                      '<joint name="linkage_joint" type="revolute"><parent link="left_knee_link" />'
                      '<child link="linkage" /><origin xyz="0 0 -0.1" rpy="0 0 0" /><axis xyz="0 1 0" />'
                      '<limit lower="-3" upper="3" effort="1" velocity="1" />'
                      '<mimic joint="left_knee_joint" multiplier="-0.5" offset="0.1" /></joint></robot>')
        return t
    lm = load_robot(str(_urdf_robot(tmp_path / "robot")))
    edited = tmp_path / "robot" / "edited.urdf"  # Pinocchio only (the fold and its check): not simulated
    edited.write_text(edit(lm.urdf.read_text()))
    lm = replace(lm, urdf=edited)
    dq = _offsets(lm, 2)
    out = fold_into_urdf(lm, dq, tmp_path / "calibrated.urdf")  # checked inside, mimic joints following (Pinocchio)
    assert check_urdf_fold(lm, dq, out) <= 1e-12
    before, after = _joints(lm.urdf), _joints(out)
    r_rpy = [float(x) for x in after["right_knee_joint"].find("origin").get("rpy").split()]
    assert r_rpy == [0.2, -0.3, 0.5]  # prismatic: the rotation stays, the origin moves along the axis
    assert after["right_knee_joint"].find("origin").get("xyz") != before["right_knee_joint"].find("origin").get("xyz")
    assert after["left_ankle_roll_joint"].find("limit").attrib == before["left_ankle_roll_joint"].find("limit").attrib
    sc, cal = after["left_knee_joint"].find("safety_controller"), after["left_knee_joint"].find("calibration")
    k = dq["left_knee_joint"]
    assert (float(sc.get("soft_lower_limit")), float(sc.get("soft_upper_limit"))) == (-0.05 - k, 2.5 - k)
    assert sc.get("k_position") == "10" and float(cal.get("rising")) == 0.5 - k and cal.get("falling") is None
    assert float(after["linkage_joint"].find("mimic").get("offset")) == 0.1 - 0.5 * k


def test_the_ros2_parameter_file_round_trips_the_offsets(tmp_path):
    lm = load_robot(str(write_urdf_robot(A3, tmp_path / "robot")))
    dq = _offsets(lm, 3)
    dq[lm.joint_names[0]] = 0.0  # a zero is still a double (0.0), not an integer
    path = write_ros2_params(tmp_path / "offsets.ros2.yaml", lm, dq, source="/results/r.json")
    text = path.read_text()
    assert "# Convention: q = q_enc + offset" in text
    doc = yaml.safe_load(text)
    assert list(doc) == ["joint_offsets"] and list(doc["joint_offsets"]) == ["ros__parameters"]
    p = doc["joint_offsets"]["ros__parameters"]
    assert p["robot"] == "a3" and p["units"] == "rad" and p["convention"] == "q = q_enc + offset"
    assert p["source"] == "/results/r.json" and p["joint_names"] == lm.joint_names
    assert all(type(v) is float for v in p["offsets"])  # a ROS 2 double array, not mixed
    assert dict(zip(p["joint_names"], p["offsets"])) == dq  # exactly
    assert all("." not in k for k in p)  # no nested parameter namespaces
    doc = yaml.safe_load(write_ros2_params(tmp_path / "ns.yaml", lm, dq, node="/robot/joint_offsets").read_text())
    assert list(doc) == ["/robot/joint_offsets"] and "source" not in doc["/robot/joint_offsets"]["ros__parameters"]
    with pytest.raises(ConfigError, match="ROS 2 node name 'bad name'"):
        write_ros2_params(tmp_path / "x.yaml", lm, dq, node="bad name")
    with pytest.raises(ConfigError, match="no value for leg joints"):
        write_ros2_params(tmp_path / "x.yaml", lm, {lm.joint_names[0]: 0.01})
    with pytest.raises(ConfigError, match="must be a finite number"):
        write_ros2_params(tmp_path / "x.yaml", lm, {**dq, lm.joint_names[1]: float("nan")})
    assert not (tmp_path / "x.yaml").exists()


def test_export_command_writes_ros2_params_and_the_folded_urdf(tmp_path, capsys):
    legmap = _urdf_robot(tmp_path / "robot")
    lm = load_robot(str(legmap))
    dq = _offsets(lm, 4)
    result = CalibrationResult(calibrator="interfoot", robot=lm.name, offsets_rad=dq,
                               settings={"robot_spec": str(legmap)}).save(tmp_path / "result.json")
    out, params, urdf = tmp_path / "offsets.yaml", tmp_path / "offsets.ros2.yaml", tmp_path / "out" / "a3_cal.urdf"
    args = ["export", "--result", str(result), "--out", str(out), "--ros2-params", str(params), "--urdf-out", str(urdf)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert f"wrote {params}" in printed and f"wrote {urdf}" in printed and "max difference" in printed
    p = yaml.safe_load(params.read_text())["joint_offsets"]["ros__parameters"]
    assert dict(zip(p["joint_names"], p["offsets"])) == dq and p["source"] == str(result.resolve())
    assert check_urdf_fold(lm, dq, urdf) <= 1e-12
    assert main(args) == 2  # the URDF copy is never replaced
    assert "--urdf-out" in capsys.readouterr().err

    # A robot described by an MJCF has no URDF to fold into: said before anything is written.
    mjcf = load_robot("a3")
    r2 = CalibrationResult(calibrator="x", robot="a3", offsets_rad=dict(zip(mjcf.joint_names, dq.values())),
                           settings={"robot_spec": "a3"}).save(tmp_path / "r2.json")
    assert main(["export", "--result", str(r2), "--out", str(tmp_path / "o2.yaml"),
                 "--urdf-out", str(tmp_path / "x.urdf")]) == 2
    err = capsys.readouterr().err
    assert "--urdf-out: robot a3 is described by an MJCF" in err and "use --mjcf-out" in err
    assert not (tmp_path / "o2.yaml").exists() and not (tmp_path / "x.urdf").exists()
    with pytest.raises(LegMapError, match="not a URDF .*--mjcf-out"):
        fold_into_urdf(mjcf, dict(zip(mjcf.joint_names, dq.values())), tmp_path / "y.urdf")
