"""Applying a result on the robot: offsets in its joint names, and its MJCF with the
correction folded into each joint's reference, reproducing the calibrated kinematics."""

import json
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np
import pytest
import yaml

from legcal_bench.cli import main
from legcal_bench.errors import ConfigError
from legcal_bench.robots import load_robot
from legcal_bench.robots.export import fold_into_mjcf, write_offsets_yaml
from legcal_bench.robots.kinematics import LegKinematics

G1_LEGMAP = str(Path(__file__).resolve().parents[2] / "examples" / "unitree_g1.legmap.yaml")


def _body_poses(xml: Path, names: list[str], q: np.ndarray) -> np.ndarray:
    m = mujoco.MjModel.from_xml_path(str(xml))
    d = mujoco.MjData(m)
    for name, v in zip(names, q):
        d.qpos[m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)]] = v
    mujoco.mj_kinematics(m, d)
    return np.concatenate([d.xpos.ravel(), d.xmat.ravel()])


def _degree_copy_of_a3(tmp_path: Path):
    lm = load_robot("a3")
    xml = tmp_path / "a3_degrees.xml"
    xml.write_text(Path(lm.mjcf).read_text().replace('angle="radian"', 'angle="degree"'))
    return replace(lm, mjcf=xml)


@pytest.mark.parametrize("robot", ["a3", "a3-degrees", G1_LEGMAP])
def test_the_folded_model_fed_raw_encoders_has_the_calibrated_kinematics(tmp_path, robot):
    lm = _degree_copy_of_a3(tmp_path) if robot == "a3-degrees" else load_robot(robot)
    rng = np.random.default_rng(4)
    dq = rng.uniform(-0.03, 0.03, 12)
    new_xml = fold_into_mjcf(lm, dict(zip(lm.joint_names, dq)), tmp_path / "corrected")
    assert new_xml.is_file() and new_xml.parent == tmp_path / "corrected"
    kin_old, kin_new = LegKinematics(lm), LegKinematics(replace(lm, mjcf=new_xml))
    for _ in range(5):
        q_enc = kin_old.q_init() + rng.normal(0, 0.1, 12)
        # MuJoCo: every body of the corrected model at q_enc sits where the original's does at q_enc + dq.
        np.testing.assert_allclose(_body_poses(new_xml, lm.joint_names, q_enc),
                                   _body_poses(lm.mjcf, lm.joint_names, q_enc + dq), atol=1e-12)
        # Pinocchio (the calibrators' kinematics) agrees.
        for T_new, T_old in zip(kin_new.sole_poses(q_enc), kin_old.sole_poses(q_enc + dq)):
            np.testing.assert_allclose(T_new.homogeneous, T_old.homogeneous, atol=1e-12)
    # Without the correction the two models differ, so the check above can fail.
    assert np.abs(_body_poses(new_xml, lm.joint_names, q_enc) - _body_poses(lm.mjcf, lm.joint_names, q_enc)).max() > 1e-3


def test_export_command_writes_offsets_in_the_robots_joint_names(tmp_path, capsys):
    lm = load_robot("a2")
    dq = np.linspace(-0.02, 0.02, 12)
    result = tmp_path / "r.json"
    result.write_text(json.dumps({"format": "legcal-calibration-result", "version": 1, "calibrator": "x",
                                  "robot": "a2", "offsets_rad": dict(zip(lm.joint_names, dq.tolist())),
                                  "settings": {"robot_spec": "a2"}}))
    out = tmp_path / "offsets.yaml"
    assert main(["export", "--result", str(result), "--out", str(out), "--mjcf-out", str(tmp_path / "m")]) == 0
    doc = yaml.safe_load(out.read_text())
    assert doc["robot"] == "a2" and doc["convention"].startswith("q = q_enc + offset")
    assert list(doc["offsets_rad"]) == lm.joint_names
    np.testing.assert_allclose(list(doc["offsets_rad"].values()), dq)
    np.testing.assert_allclose(list(doc["offsets_deg"].values()), np.rad2deg(dq))
    assert (tmp_path / "m" / "a2.xml").is_file()
    # An existing folder is refused before anything is written.
    assert main(["export", "--result", str(result), "--out", str(out), "--mjcf-out", str(tmp_path / "m")]) == 2
    assert "exists: give a new folder" in capsys.readouterr().err


def test_offsets_must_cover_every_leg_joint(tmp_path):
    lm = load_robot("a3")
    with pytest.raises(ConfigError, match="no value for leg joints"):
        write_offsets_yaml(tmp_path / "x.yaml", lm, {lm.joint_names[0]: 0.01})
    assert not (tmp_path / "x.yaml").exists()
