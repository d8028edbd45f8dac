"""Issue #58's "warned but still written" cases, built on simulated data: each comes out
`do-not-apply`, and the clean set they are made from does not.

One short realistic weld set of the A3-like robot (seed 0, 4 s stances, no held-out
session) is collected once; each case corrupts its recordings (or the leg map it is
calibrated with) and calibrates with the interfoot calibrator through the framework's
door (`calibrate_training`), as `calibrate` does:

- the left and right legs' encoder columns exchanged; the hip roll and hip yaw columns
  exchanged on both legs;
- the IMU read in a frame its mount rotation was left out of (90° about z, upside down)
  or got wrong by a few degrees;
- a sole frame on the wrong place of the foot (the foot body given without its pose) or
  rotated on it; a sole on the shank's body, which the leg map refuses;
- a model that is not the robot's: the thigh 10 cm longer (an edited copy of the MJCF,
  `legcal_bench.sim.effects`' link_length edit, calibrated on the nominal robot's data);
- offsets at the solver's bound (bound 0.01 rad, the gross-offset stage off).

A case the verdict does not yet refuse is marked xfail (strict) with the verdict and
the warnings measured; the classes are the checks' (`legcal_bench.estimation.verdict`).
Run with `-s` to see each case's verdict, reasons and recovery error.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import yaml

from legcal_bench.calibrators.base import calibrate_training
from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import list_segments, load_session, load_truth
from legcal_bench.errors import LegMapError
from legcal_bench.estimation.verdict import DO_NOT_APPLY, INVALIDATES
from legcal_bench.robots import ASSETS, load_robot
from legcal_bench.robots.kinematics import LegKinematics

pytestmark = pytest.mark.xdist_group("verdict_cases")  # one process collects the set

SET = dict(robot="a3", mode="weld", sensors="realistic", seed=0, stance_s=4.0, standing_s=2.0, heldout=0)


def _rot(axis: str, deg: float) -> np.ndarray:
    c, s = np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    r = np.eye(3)
    r[i, i] = r[j, j] = c
    r[i, j], r[j, i] = -s, s
    return r


@pytest.fixture(scope="module")
def clean(collected):
    folder = collected(**SET)
    return folder, load_robot("a3"), load_truth(list_segments(folder)[0]).offsets


def _calibrate(legmap, recs, **options):
    return calibrate_training(get_calibrator("interfoot", **options), legmap, recs)


def _show(case: str, result, legmap, truth) -> str:
    err = np.rad2deg(result.offsets_vector(legmap.joint_names) - truth)
    lines = [f"{case}: {result.decision}, recovery error max {np.abs(err).max():.2f}° "
             f"RMS {np.sqrt(np.mean(err ** 2)):.2f}°, {len(result.verdict['reasons'])} warnings"]
    lines += [f"  {r['meaning']}: {r['text'][:150]}" for r in result.verdict["reasons"]]
    text = "\n".join(lines)
    print(text)
    return text


def _assert_refused(case, result, legmap, truth):
    text = _show(case, result, legmap, truth)
    assert result.decision == DO_NOT_APPLY, text
    assert any(r["meaning"] == INVALIDATES for r in result.verdict["reasons"]), text


@pytest.mark.slow
def test_the_clean_set_is_not_refused(clean):
    folder, lm, truth = clean
    result = _calibrate(lm, load_session(folder, robot=lm))
    text = _show("clean", result, lm, truth)
    assert result.decision != DO_NOT_APPLY, text
    assert np.abs(np.rad2deg(result.offsets_vector(lm.joint_names) - truth)).max() < 0.5, text


def _swap_legs(name: str) -> str:
    return name.replace("left_", "@").replace("right_", "left_").replace("@", "right_")


def _swap_hip_roll_yaw(name: str) -> str:
    if "_hip_" not in name:
        return name
    return name.replace("roll", "@").replace("yaw", "roll").replace("@", "yaw")


@pytest.mark.slow
@pytest.mark.parametrize("case, swap", [pytest.param("left/right legs swapped", _swap_legs, id="left-right"),
                                        pytest.param("hip roll/yaw swapped", _swap_hip_roll_yaw, id="hip-roll-yaw")])
def test_exchanged_encoder_columns_are_refused(clean, case, swap):
    folder, lm, truth = clean
    names = lm.joint_names
    cols = [names.index(swap(n)) for n in names]
    assert sorted(cols) == list(range(len(names))) and cols != list(range(len(names)))
    recs = [dataclasses.replace(r, q_enc=r.q_enc[:, cols]) for r in load_session(folder, robot=lm)]
    _assert_refused(case, _calibrate(lm, recs), lm, truth)


@pytest.mark.slow
@pytest.mark.parametrize("axis, deg", [
    ("z", 90.0),  # the mount's rotation left out of the log mapping
    ("x", 180.0),  # an IMU mounted upside down, read as if upright
    pytest.param("x", 3.0, marks=pytest.mark.xfail(strict=True, reason=(
        "measured review, 2.66° off (RMS 1.68°): no invalidating finding; doubts only: 'soles were not on "
        "one plane' in stance_I/II (0.02-0.04° tilts, under 0.1 mm), GLS not used (whitened chi2/dof 63 > 1.5); "
        "limits: IMU pitch tilt not separable; harmless: contact_check hint, gross offsets (left hip roll +4.67°, "
        "right knee -4.89°). The IMU's vertical, 3° (52 mrad) off its declared ±5 mrad mount tilt, raises no "
        "IMU-vertical finding"))),
    pytest.param("y", 3.0, marks=pytest.mark.xfail(strict=True, reason=(
        "measured apply, 3.17° off (RMS 1.29°): the only warnings are 'IMU tilt not separable' (limits) and "
        "'gross offsets: left/right hip pitch +4.88°' (harmless); an IMU pitch error is the same data as a "
        "common pitch-sum offset of both legs, so nothing in this set's residuals can show it"))),
])
def test_a_wrong_imu_rotation_is_refused(clean, axis, deg):
    folder, lm, truth = clean
    r = _rot(axis, deg)  # the frame the IMU's samples are read in, against the one the leg map declares
    recs = [dataclasses.replace(rec, imu_acc=rec.imu_acc @ r.T, imu_gyro=rec.imu_gyro @ r.T)
            for rec in load_session(folder, robot=lm)]
    _assert_refused(f"IMU rotated {deg:g}° about {axis}", _calibrate(lm, recs), lm, truth)


def _legmap_with_sole(tmp_path, sole: dict, side: str = "left"):
    d = yaml.safe_load((ASSETS / "a3.legmap.yaml").read_text())
    d["mjcf"] = str(ASSETS / d["mjcf"])
    d["legs"][side]["sole"] = sole
    path = tmp_path / "a3_wrong_sole.legmap.yaml"
    path.write_text(yaml.safe_dump(d))
    return str(path)


@pytest.mark.slow
@pytest.mark.parametrize("case, sole", [
    # The left sole given as its foot body with the pose left out: the body's origin on
    # the ankle roll axis, 58 mm above and 35 mm behind the sole.
    pytest.param("left sole: the foot body without its pose", {"body": "left_foot_link"}, id="pose-left-out"),
    pytest.param("left sole rotated 3° about x on the foot",
                 {"body": "left_foot_link", "pos": [0.035, 0.001, -0.058], "rpy": [0.05236, 0.0, 0.0]},
                 marks=pytest.mark.xfail(strict=True, reason=(
                     "measured apply, 3.00° off (RMS 0.87°): warnings only 'IMU tilt not separable' (limits); a sole "
                     "frame rolled on its foot is the same data as that leg's ankle roll offset, so the fit absorbs "
                     "it whole")), id="rolled-3deg"),
])
def test_a_wrong_sole_frame_is_refused(clean, tmp_path, case, sole):
    folder, _, truth = clean
    lm = load_robot(_legmap_with_sole(tmp_path, sole))
    _assert_refused(case, _calibrate(lm, load_session(folder, robot=lm)), lm, truth)


@pytest.mark.slow
def test_a_sole_on_the_shank_is_refused_by_the_leg_map(tmp_path):
    """The sole on the shank's body (its pose there at zero ankle angles): the ankle
    joints are not between the pelvis and the sole, and the leg map says so."""
    path = _legmap_with_sole(tmp_path, {"body": "left_knee_link", "pos": [0.034, -0.002, -0.44]})
    with pytest.raises(LegMapError, match="not on the chain: .*left_ankle_pitch_joint"):
        LegKinematics(load_robot(path))


@pytest.mark.slow
@pytest.mark.parametrize("links", [
    pytest.param(("left_thigh",), id="left-thigh"),
    pytest.param(("left_thigh", "right_thigh"), id="both-thighs", marks=pytest.mark.xfail(strict=True, reason=(
        "measured review, 5.37° off (RMS 2.71°), 8 warnings, none invalidating; doubts: 'the soles were not on "
        "one plane' in all four stances (0.02-0.74° tilts, 1.7-4.7 mm), GLS not used (whitened chi2/dof 66 > 1.5), "
        "'stance_II: the feet moved 2.3 mm relative to each other'; limits: IMU pitch tilt not separable; "
        "harmless: contact_check hint"))),
])
def test_a_model_that_is_not_the_robots_is_refused(clean, tmp_path, links):
    """Calibrated with an edited copy of the robot's MJCF whose thigh(s) are 10 cm longer
    (the nominal robot's data): the model does not fit the data."""
    from legcal_bench.sim.effects import build_reality
    from legcal_bench.sim.sensors import sim_sensors

    folder, lm, truth = clean
    specs = [f"link_length:link={link},mm=100" for link in links]
    wrong = build_reality(lm, lm, specs, sim_sensors("zero"), tmp_path / "model").sim_legmap
    assert wrong.name == lm.name and wrong.mjcf != lm.mjcf
    _assert_refused(f"{' and '.join(links)} 10 cm longer in the model",
                    _calibrate(wrong, load_session(folder, robot=wrong)), wrong, truth)


@pytest.mark.slow
def test_offsets_at_the_bound_are_refused(clean):
    folder, lm, truth = clean
    result = _calibrate(lm, load_session(folder, robot=lm), bound=0.01, gross="off")
    _assert_refused("bound 0.01 rad, gross stage off", result, lm, truth)
    assert any("offsets at the bound" in r["text"] and r["meaning"] == INVALIDATES for r in result.verdict["reasons"])
