"""Bad input refused with its field and fix; uncertainty instead of silence (issue #10,
first part: options, sensor models, metadata, manifests, result files, ground truth,
units, robot mismatch; posterior standard deviations)."""

from __future__ import annotations

import io
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from legcal_bench.calibrators.base import CalibrationResult

from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.cli import main
from legcal_bench.data.recording import load_recording, load_session
from legcal_bench.errors import CalibrationError, LegMapError, RecordingError, SensorModelError
from legcal_bench.evaluation.scoring import score
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.sim.sensors import sensor_model

pytestmark = pytest.mark.xdist_group("bad_inputs")  # one process collects `session` (and `a3_result`) for all


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("good") / "set"
    collect(CollectConfig(robot="a3", mode="kinematic", stance_s=3.0, heldout=1, heldout_s=1.0, standing_s=1.0),
            out, progress=False)
    return out


def _rewrite(path: Path, arrays=None, meta=None) -> None:
    """Rewrite a recording's arrays/metadata in place, bypassing the writer's checks."""
    with np.load(path) as z:
        a = {k: z[k] for k in z.files}
    m = json.loads(str(a.pop("meta")))
    if arrays:
        arrays(a)
    if meta:
        meta(m)
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(m)), **a)
    path.write_bytes(buf.getvalue())


@pytest.mark.parametrize("option, message", [
    (dict(foo=1), r"calibrator 'interfoot' has no option \['foo'\].*its options: setting"),
    (dict(trim_fraction=1), r"option trim_fraction=1: must be a number in \[0, 0.5\]"),
    (dict(lambda_q="abc"), r"option lambda_q='abc': expected a number"),
    (dict(lambda_q=-1), r"option lambda_q=-1: must be a number in \[0, inf\]"),
    (dict(n_max=0), r"option n_max=0: must be an integer in \[1, inf\]"),
    (dict(n_max=2.5), r"option n_max=2.5: expected an integer"),
    (dict(bound=0), r"option bound=0: must be a number in \(0, 3.14159\]"),
    (dict(tol=float("nan")), r"option tol=nan"),
    (dict(lambda_f=True), r"option lambda_f=True: expected a number"),
])
def test_interfoot_options_are_checked(option, message):
    with pytest.raises(CalibrationError, match=message):
        get_calibrator("interfoot", **option)


@pytest.mark.parametrize("option, message", [
    (dict(setting="matched"), r"calibrator 'yamane' has no option \['setting'\] \(--setting"),
    (dict(w_h=-1), r"option w_h=-1"), (dict(w_imu="x"), r"option w_imu='x'"), (dict(n_max=0), r"option n_max=0"),
])
def test_yamane_options_are_checked(option, message):
    with pytest.raises(CalibrationError, match=message):
        get_calibrator("yamane", **option)


def test_an_explicit_zero_weight_is_kept():
    cal = get_calibrator("yamane", w_h=0)
    assert cal.settings()["w_h"] == 0.0


@pytest.mark.parametrize("field, value", [
    ("encoder_noise_std", "a"), ("encoder_noise_std", [1, 2]), ("encoder_noise_std", -1e-3),
    ("encoder_noise_std", True), ("gyro_noise_std", float("nan")), ("accel_bias_bound", "abc"),
    ("accel_bias_bound", [1, 2]), ("accel_bias_bound", float("inf")), ("imu_mount_bound", None),
    ("imu_mount_bound", -1e-3), ("gyro_noise_std", 10**400), ("accel_bias_bound", -10**400),  # beyond any float
])
def test_sensor_model_fields_are_checked(field, value):
    with pytest.raises(SensorModelError, match=f"field '{field}'"):
        sensor_model({field: value})


@pytest.mark.parametrize("edit, message", [
    (dict(meta=lambda m: m.update(joint_names=True)), "field 'joint_names' must be a list"),
    (dict(meta=lambda m: m.update(joint_names=7)), "field 'joint_names' must be a list"),
    (dict(meta=lambda m: m.update(sensor_model=[1, 2])), "field 'sensor_model' must be a JSON object"),
    (dict(meta=lambda m: m.update(sensor_model={"accel_noise_std": "x"})), "field 'sensor_model' is invalid"),
    (dict(meta=lambda m: m.update(sensor_model={"accel_bias": [0.02, 0, 0]})),
     r"fields \['accel_bias'\] are realized values .* cannot know; declare bounds instead \(accel_bias_bound\)"),
    (dict(meta=lambda m: m.update(robot=3)), "metadata field 'robot' must be a string"),
    (dict(arrays=lambda a: a.update(time=a["time"] * 1e3)), r"field 'time' gives a logging rate of 0.05 Hz.*"
                                                            r"milliseconds or nanoseconds"),
    (dict(arrays=lambda a: a.update(time=a["time"] * 1e9)), "milliseconds or nanoseconds"),
    (dict(arrays=lambda a: a.update(time=a["time"] / 3600)), "minutes or hours"),
    (dict(arrays=lambda a: a.update(q_enc=np.round(a["q_enc"] * 1000).astype(np.int32))), "integer array"),
    (dict(arrays=lambda a: a.update(time=np.r_[a["time"][:1], a["time"][:-1]])), "not strictly increasing"),
    (dict(arrays=lambda a: a.update(time=np.zeros_like(a["time"]))), "not strictly increasing"),
    (dict(arrays=lambda a: a["q_enc"].__setitem__((5, 3), np.nan)), r"field 'q_enc' has NaN/inf in 1 frame\(s\), "
                                                                    r"first at frame 5"),
    (dict(arrays=lambda a: a["imu_acc"].__setitem__((7, 0), np.inf)), r"field 'imu_acc' has NaN/inf"),
    (dict(arrays=lambda a: a.update(q_enc=a["q_enc"][:, :11])), r"field 'q_enc' has shape \(\d+, 11\), expected "
                                                               r"\(N, 12\)"),
    (dict(arrays=lambda a: a.update(imu_acc=a["imu_acc"][:, :2])), r"field 'imu_acc' has shape"),
    (dict(arrays=lambda a: a.update(imu_gyro=a["imu_gyro"][:-3])), r"field 'imu_gyro' has \d+ frames but 'time'"),
    (dict(arrays=lambda a: a.update({k: a[k][:0] for k in ("time", "q_enc", "imu_acc", "imu_gyro")})), "no frames"),
    (dict(arrays=lambda a: a.update(q_enc=a["q_enc"].astype(complex))), r"field 'q_enc' must be numeric"),
    (dict(arrays=lambda a: a.update(imu_gyro=a["imu_gyro"] > 0)), r"field 'imu_gyro' must be numeric"),
    (dict(arrays=lambda a: a.pop("q_enc")), r"missing field 'q_enc'"),
    (dict(arrays=lambda a: a.update(imu_acc=a["imu_acc"] / 9.81)), r"mean norm 1; .*Convert from g"),
    (dict(arrays=lambda a: a.update(q_enc=np.rad2deg(a["q_enc"]))), r"looks like degrees"),
    (dict(arrays=lambda a: a.update(ft=np.zeros((len(a["time"]), 6)))), r"field 'ft' has shape"),
    (dict(meta=lambda m: m.pop("kind")), r"missing metadata field 'kind'"),
    (dict(meta=lambda m: m.update(kind="walking")), r"field 'kind' is 'walking'; use one of"),
    (dict(meta=lambda m: m.update(format="rosbag")), r"field 'format' is 'rosbag'"),
    (dict(meta=lambda m: m.update(version=3)), r"format version 3 is not supported"),
    (dict(meta=lambda m: m.update(joint_names=m["joint_names"][:11])), r"must list the robot's leg joints, left leg "
                                                                        r"then right \(the same number per leg\), got 11"),
    (dict(meta=lambda m: m.update(name=["stance"])), r"metadata field 'name' must be a string"),
    (dict(meta=lambda m: m.update(sensor_model={"gyro_noise": 0.1})), r"unknown fields \['gyro_noise'\]"),
])
def test_bad_recordings_are_refused_naming_the_field(session, tmp_path, edit, message):
    path = tmp_path / "stance_I.npz"
    shutil.copy(session / "stance_I.npz", path)
    _rewrite(path, **edit)
    with pytest.raises(RecordingError, match=message):
        load_recording(path)


def _copy(session: Path, tmp_path: Path) -> Path:
    out = tmp_path / "copy"
    shutil.copytree(session, out)
    return out


def test_recordings_of_another_robot_are_refused(session):
    recs = load_session(session, robot=load_robot("a3"))
    assert len(recs) == 6
    with pytest.raises(RecordingError, match=r"field 'robot' is 'a3' but the leg map is 'pair_pry'.*--robot"):
        load_session(session, robot=load_robot("pair_pry"))


@pytest.mark.parametrize("edit, joint", [
    (lambda q: q.__setitem__((slice(None), 3), q[:, 3] - 2 * np.pi), "left_knee_joint"),  # wrapped by 2 pi
    (lambda q: q.__setitem__((slice(None), 0), np.rad2deg(q[:, 0]) * 0 + 3.0), "left_hip_pitch_joint"),
    (lambda q: q.__setitem__((slice(None), slice(None)), q[:, [6, 7, 8, 9, 10, 11, 0, 1, 2, 3, 4, 5]] * 0 + 2.0),
     "left_hip_pitch_joint"),
])
def test_angles_no_joint_can_reach_are_refused(session, tmp_path, edit, joint):
    d = _copy(session, tmp_path)

    def arrays(a):
        q = a["q_enc"].copy()
        edit(q)
        a["q_enc"] = q
    _rewrite(d / "stance_I.npz", arrays=arrays)
    with pytest.raises(RecordingError, match=f"joint {joint}: .*degrees, a wrapped angle"):
        load_session(d, robot=load_robot("a3"))


@pytest.mark.parametrize("text, message", [
    ("not json", "not valid JSON"), ("[1, 2]", "field 'files' must list"), ('{"files": []}', "field 'files' must"),
    ('{"files": ["nope.npz"]}', r"not in the folder: \['nope.npz'\]"),
])
def test_bad_manifests_are_named(session, tmp_path, text, message):
    d = _copy(session, tmp_path)
    (d / "session.json").write_text(text)
    with pytest.raises(RecordingError, match=message):
        load_session(d)


def test_a_folder_without_manifest_needs_allow_partial(session, tmp_path, capsys):
    d = _copy(session, tmp_path)
    (d / "session.json").unlink()
    with pytest.raises(RecordingError, match="no session.json: .*--allow-partial"):
        load_session(d)
    assert len(load_session(d, allow_partial=True)) == 6
    assert main(["calibrate", "--robot", "a3", "--bags", str(d), "--out", str(tmp_path / "r.json")]) == 2
    assert "--allow-partial" in capsys.readouterr().err
    assert main(["calibrate", "--robot", "a3", "--bags", str(d), "--allow-partial", "--out",
                 str(tmp_path / "r.json")]) == 0


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.update(extra=1), r"unknown fields \['extra'\]"),
    (lambda d: d["offsets_rad"].update(left_knee_joint="0.1"), "offsets_rad.left_knee_joint must be a finite number"),
    (lambda d: d["offsets_rad"].update(left_knee_joint=float("nan")), "offsets_rad.left_knee_joint"),
    (lambda d: d.update(offsets_rad=[0.0] * 12), "field 'offsets_rad' must map joint names"),
    (lambda d: d.update(warnings="x"), "field 'warnings' must be a JSON list"),
    (lambda d: d.clear(), "field 'format' must be"),
])
def test_bad_result_files_are_refused(tmp_path, edit, message):
    names = load_robot("a3").joint_names
    d = CalibrationResult("interfoot", "a3", {n: 0.0 for n in names}).to_dict()
    edit(d)
    path = tmp_path / "r.json"
    path.write_text(json.dumps(d))
    with pytest.raises(CalibrationError, match=message):
        CalibrationResult.load(path)


def test_score_checks_its_ground_truth(session, tmp_path):
    lm = load_robot("a3")
    res = get_calibrator("interfoot").calibrate(lm, load_session(session, robot=lm))
    d = _copy(session, tmp_path)
    for p in d.glob("*.truth.npz"):
        p.unlink()
    s = score(str(d), res, lm)
    assert "recovery" not in s and "recovery needs the simulator's truth" in s["recovery_unavailable"]
    d2 = tmp_path / "mixed"
    shutil.copytree(session, d2)
    _rewrite(d2 / "stance_I.truth.npz", arrays=lambda a: a.update(offsets=a["offsets"] + 0.01))
    with pytest.raises(RecordingError, match="declare other offsets than the rest"):
        score(str(d2), res, lm)
    d3 = tmp_path / "truncated"
    shutil.copytree(session, d3)
    _rewrite(d3 / "stance_I.truth.npz", arrays=lambda a: a.update(q_true=a["q_true"][:-5]))
    with pytest.raises(RecordingError, match="frames but its recording"):
        score(str(d3), res, lm)


def test_an_unwritable_out_fails_before_the_solve(session, capsys):
    assert main(["calibrate", "--robot", "a3", "--bags", str(session), "--out", "/proc/no/r.json"]) == 2
    assert "cannot create its folder" in capsys.readouterr().err


def test_knee_straight_outside_the_knee_range_is_refused():
    from dataclasses import replace

    with pytest.raises(LegMapError, match="knee_straight_rad 5.0 is outside the knees' range"):
        LegKinematics(replace(load_robot("a3"), knee_straight_rad=5.0))


@pytest.mark.parametrize("name", ["interfoot", "yamane"])
def test_posterior_names_what_a_short_single_stance_does_not_determine(tmp_path, name):
    lm = load_robot("a3")
    short = tmp_path / "short"
    collect(CollectConfig(robot="a3", mode="kinematic", stances=("I",), stance_s=1.0, heldout=0, standing_s=1.0),
            short, progress=False)
    res = get_calibrator(name).calibrate(lm, load_session(short, robot=lm))
    undetermined = [w for w in res.warnings if w.startswith("not determined by the data")]
    assert undetermined and all("(1 sigma, limit 0.1°)" in w for w in undetermined)
    post = res.diagnostics["posterior"]
    assert set(post["pitch_sum_std_rad"]) == {"left", "right", "right_minus_left"}
    assert max(u["std_rad"] for u in post["undetermined"]) > np.deg2rad(0.1)


G1_LEGMAP = str(Path(__file__).resolve().parents[2] / "examples" / "unitree_g1.legmap.yaml")


@pytest.mark.parametrize("robot", ["a3", "pair_pry", G1_LEGMAP])
def test_the_four_default_stances_leave_nothing_undetermined(tmp_path, robot):
    lm = load_robot(robot)
    out = tmp_path / lm.name
    collect(CollectConfig(robot=robot, mode="kinematic", heldout=0), out, progress=False)
    res = get_calibrator("interfoot").calibrate(lm, load_session(out, robot=lm))
    assert not [w for w in res.warnings if "not determined" in w or "at the bound" in w], res.warnings
    post = res.diagnostics["posterior"]
    assert max(post["std_rad"].values()) < np.deg2rad(0.1)


# ----------------------------------------------------------------- the CLI's refusals
# Each bad invocation exits 2 with a message naming the field and the fix, never a
# traceback, and writes no result.
@pytest.mark.parametrize("args, message", [
    (["--calibrator", "yamane", "--setting", "matched"], r"calibrator 'yamane' has no option \['setting'\]"),
    (["--option", "foo=1"], r"has no option \['foo'\].*its options: setting"),
    (["--option", "trim_fraction=1"], r"option trim_fraction=1: must be a number in \[0, 0.5\]"),
    (["--option", "lambda_q=abc"], r"option lambda_q='abc': expected a number"),
    (["--option", "lambda_q=-1"], r"option lambda_q=-1: must be a number in \[0, inf\]"),
    (["--option", "n_max=0"], r"option n_max=0: must be an integer in \[1, inf\]"),
    (["--option", "bound=0"], r"option bound=0: must be a number in \(0"),
    (["--option", "lambda_q"], r"--option 'lambda_q': write key=value"),
    (["--calibrator", "yamane", "--option", "w_h=-1"], r"option w_h=-1"),
    (["--calibrator", "yamane", "--option", "n_max=0"], r"option n_max=0"),
    (["--calibrator", "yamane", "--solver", "lm"], r"solver 'lm': use one of projected, sparse"),
    (["--setting", "best"], r"setting 'best': use one of sensor, operating"),
    (["--solver", "newton"], r"solver 'newton': use projected \(default\) or alternating"),
    (["--calibrator", "nope"], r"unknown calibrator 'nope'; registered: \["),
    (["--robot", "a9"], r"unknown robot 'a9': use a built-in name .* or the path of a leg-map YAML"),
])
def test_bad_calibrate_invocations_exit_2_naming_the_field(session, tmp_path, capsys, args, message):
    out = tmp_path / "r.json"
    assert main(["calibrate", "--bags", str(session), "--out", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert re.search(message, err), err
    assert "Traceback" not in err and not out.exists()


@pytest.mark.parametrize("edit, message", [
    (lambda d: (d / "session.json").write_text("{garbage"), r"session.json: not valid JSON .*--allow-partial"),
    (lambda d: (d / "session.json").write_text("[1, 2]"), r"field 'files' must list"),
    (lambda d: _rewrite(d / "stance_I.npz", meta=lambda m: m["sensor_model"].update(gyro_noise_std=float("nan"))),
     r"stance_I.npz: field 'sensor_model' is invalid .*field 'gyro_noise_std'"),
    (lambda d: _rewrite(d / "stance_I.npz", meta=lambda m: m.update(robot="pair_pry")),
     r"field 'robot' is 'pair_pry' but the leg map is 'a3'"),
    (lambda d: (d / "stance_I.npz").write_bytes(b"not a zip"), r"stance_I.npz: not a readable .npz file"),
    (lambda d: _rewrite(d / "stance_II.npz", arrays=lambda a: a.update(time=a["time"][::-1].copy())),
     r"stance_II.npz: field 'time' is not strictly increasing .*sort the frames"),
])
def test_bad_session_sets_exit_2_naming_the_file_and_field(session, tmp_path, capsys, edit, message):
    d = _copy(session, tmp_path)
    edit(d)
    out = tmp_path / "r.json"
    assert main(["calibrate", "--robot", "a3", "--bags", str(d), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert re.search(message, err), err
    assert not out.exists()


@pytest.fixture(scope="module")
def a3_result(session, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("result") / "r.json"
    lm = load_robot("a3")
    get_calibrator("interfoot").calibrate(lm, load_session(session, robot=lm)).save(out)
    return out


@pytest.mark.parametrize("setup, args, message", [
    (None, ["--result", "{tmp}/none.json"], r"none.json: not a readable result JSON"),
    (lambda tmp, res: (tmp / "bad.json").write_text("{"), ["--result", "{tmp}/bad.json"],
     r"bad.json: not a readable result JSON"),
    (None, ["--robot", "pair_pry"], r"calibrated for robot 'a3', but the robot here is 'pair_pry'"),
    (lambda tmp, res: (tmp / "pp.json").write_text(json.dumps({**json.loads(res.read_text()), "robot": "pair_pry"})),
     ["--result", "{tmp}/pp.json"], r"field 'robot' is 'a3' but the leg map is 'pair_pry'"),
])
def test_bad_score_invocations_exit_2_naming_the_field(session, a3_result, tmp_path, capsys, setup, args, message):
    if setup:
        setup(tmp_path, a3_result)
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    if "--result" not in args:
        args += ["--result", str(a3_result)]
    assert main(["score", "--bags", str(session), *args]) == 2
    err = capsys.readouterr().err
    assert re.search(message, err), err


@pytest.mark.parametrize("edit, message", [
    (lambda p: p.write_bytes(b"garbage"), r"stance_I.truth.npz: not a readable .npz file"),
    (lambda p: _rewrite(p, arrays=lambda a: a.update(offsets=np.full(12, np.nan))), r"field 'offsets' must be 12 finite"),
    (lambda p: _rewrite(p, arrays=lambda a: a.update(offsets=np.zeros(11))), r"field 'offsets' must be 12 finite"),
    (lambda p: _rewrite(p, arrays=lambda a: a.pop("q_true")), r"missing ground-truth fields \['q_true'\]"),
])
def test_bad_ground_truth_is_refused_by_score(session, a3_result, tmp_path, edit, message):
    d = _copy(session, tmp_path)
    edit(d / "stance_I.truth.npz")
    with pytest.raises(RecordingError, match=message):
        score(str(d), CalibrationResult.load(a3_result), load_robot("a3"))


# -------------------------------------------------------------- arrays and metadata
def test_a_recording_with_another_joint_count_is_refused_naming_the_robots(session, tmp_path):
    path = tmp_path / "stance_I.npz"
    shutil.copy(session / "stance_I.npz", path)
    names = load_robot("a3").joint_names
    with pytest.raises(RecordingError, match=f"must list the robot's {len(names) - 2} leg joints, got {len(names)}"):
        load_recording(path, names[1:len(names) // 2] + names[len(names) // 2 + 1:])
    _rewrite(path, arrays=lambda a: a.update(q_enc=a["q_enc"][:, :-2]))
    with pytest.raises(RecordingError, match=rf"expected \(N, {len(names)}\): one column per leg joint"):
        load_recording(path, names)


def test_joint_names_in_another_order_are_refused_with_the_fix(session, tmp_path):
    path = tmp_path / "stance_I.npz"
    shutil.copy(session / "stance_I.npz", path)
    _rewrite(path, meta=lambda m: m.update(joint_names=m["joint_names"][6:] + m["joint_names"][:6]))
    with pytest.raises(RecordingError, match="same names in another order: reorder the q_enc columns"):
        load_recording(path, load_robot("a3").joint_names)


@pytest.mark.parametrize("calibrator", ["interfoot", "yamane"])
def test_a_standing_phase_in_degrees_below_2pi_is_flagged(session, calibrator):
    """Degrees that stay below 2 pi pass the loader's unit check; the straight-leg
    phase then reads bent knees and soles off one plane, and both calibrators say so."""
    lm = load_robot("a3")
    recs = load_session(session, robot=lm)
    standing = [r for r in recs if r.kind == "standing"][0]
    standing.q_enc = np.rad2deg(standing.q_enc)
    assert np.abs(standing.q_enc).max() < 2 * np.pi
    res = get_calibrator(calibrator).calibrate(lm, recs)
    text = "\n".join(res.warnings)
    assert re.search(r"standing: left_knee_joint reads \+\d+\.\d deg from straight .*not in radians", text), text
    assert re.search(r"standing: the soles are not on one plane: the right sole sits \d+ mm", text), text
