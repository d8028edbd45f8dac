"""Legs of five joints (no ankle roll, issue #37): the calibrators take the robot's joint
count from its leg map. Exact static postures of the `five_joint` variation (the soles
placed by stances I-III, moved along the posture axes both legs follow as collect moves
them, each posture solved by `reachable_postures`), encoders reading the truth minus the paper's offsets: both
calibrators recover them, and the diagnostics are sized by the robot's joints."""

from __future__ import annotations

import numpy as np
import pytest

from legcal_bench.calibrators.base import calibrate_training
from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import Recording
from legcal_bench.geometry.poses import posture_poses
from legcal_bench.protocol.stances import ALL_STANCES, fit_stance, followable_axes, place
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import VARIATIONS
from legcal_bench.robots.kinematics import LegKinematics, reachable_postures
from legcal_bench.sim.offsets import resolve_offsets
from legcal_bench.sim.sensors import SensorModel, sensor_model

G = 9.81
# Stance IV (the wide squat) needs an ankle roll to keep the soles flat: it does not fit.
STANCES = ("I", "II", "III", "standing")


@pytest.fixture(scope="module")
def robot(tmp_path_factory):
    design = next(d for d in VARIATIONS if d.name == "five_joint")
    lm = load_robot(str(write_robot(design, tmp_path_factory.mktemp("five_joint"))))
    return lm, LegKinematics(lm), resolve_offsets("paper", lm)


def _recordings(lm, kin, dq, sensors: SensorModel) -> list[Recording]:
    rng = np.random.default_rng(0)
    out = []
    for name in STANCES:
        fitted = fit_stance(ALL_STANCES[name], kin).stance
        placement = place(fitted, kin.dims)
        n = 50 if name == "standing" else 150
        t = np.arange(n) / 50.0
        sway = np.sin(2 * np.pi * np.outer(t, [0.11, 0.13, 0.17, 0.19, 0.23, 0.29]) + np.arange(6))
        axes = followable_axes(kin, placement)  # the posture axes both legs follow, as collect moves them
        commanded = placement.nominal + (0.0 if name == "standing" else np.array(fitted.amplitude) * axes) * sway
        postures, q = reachable_postures(kin, placement.left, placement.right, commanded)
        R_WI = posture_poses(postures)[:, :3, :3] @ kin.R_BI
        out.append(Recording(
            name=name if name == "standing" else f"stance_{name}", kind="standing" if name == "standing" else "stance",
            stance=name, robot=lm.name, joint_names=lm.joint_names, time=t, q_enc=q - dq,
            imu_acc=np.einsum("nji,j->ni", R_WI, [0.0, 0.0, G]), imu_gyro=rng.normal(0, 1e-4, (n, 3)),
            sensor_model=sensors, motion="static"))
    return out


@pytest.mark.parametrize("calibrator", ["interfoot", "yamane"])
def test_zero_noise_recovery_on_five_joint_legs(robot, calibrator):
    lm, kin, dq = robot
    res = calibrate_training(get_calibrator(calibrator), lm, _recordings(lm, kin, dq, SensorModel()))
    assert list(res.offsets_rad) == lm.joint_names and len(dq) == lm.n_joints == 10
    assert np.degrees(np.abs(res.offsets_vector(lm.joint_names) - dq)).max() <= 1e-9
    assert res.warnings == []


def test_declared_noise_diagnostics_are_sized_by_the_leg_map(robot):
    """The generalized least squares, the posterior and the IMU-tilt response on exact
    data that declare realistic sensors."""
    lm, kin, dq = robot
    res = calibrate_training(get_calibrator("interfoot"), lm, _recordings(lm, kin, dq, sensor_model("realistic")))
    assert np.degrees(np.abs(res.offsets_vector(lm.joint_names) - dq)).max() <= 1e-9
    assert list(res.diagnostics["posterior"]["std_rad"]) == lm.joint_names
    assert np.shape(res.diagnostics["imu_tilt_response"]) == (lm.n_joints, 2)
