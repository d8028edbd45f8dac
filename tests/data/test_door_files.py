"""Every file a user gives is checked at the door (issue #42): leg maps, walking-policy
specs, protocol files and log mapping files, each mutated in one field from a shipped,
valid file, are refused with a `LegcalError` naming the file and the field, never with
a traceback (TypeError, KeyError, UnicodeDecodeError, ...) or silently accepted; and
every shipped file still loads, with no warning."""

from __future__ import annotations

import copy
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

from legcal_bench.errors import ConfigError, LegcalError, LegMapError, LogImportError
from legcal_bench.logs.mapping import example_mapping, load_mapping
from legcal_bench.policies.spec import load_policy_spec
from legcal_bench.protocol.stances import load_protocol
from legcal_bench.robots import BUILTIN, load_robot
from legcal_bench.robots.legmap import load_legmap

REPO = Path(__file__).resolve().parents[2]
ASSETS = REPO / "legcal_bench" / "robots" / "assets"
A3_SPEC = REPO / "policies" / "walkers" / "a3" / "policy.yaml"
A3_PROTOCOL = REPO / "reports" / "design" / "a3_wide.protocol.yaml"
TRACEBACKS = (TypeError, KeyError, AttributeError, UnicodeDecodeError, ValueError, IndexError, OverflowError,
              RecursionError)
HUGE = 10**400  # a YAML integer too large for a float


# ----------------------------------------------------------------- valid bases
def legmap_doc() -> dict:
    """The packaged A3-like leg map with every optional field: servo gains, F/T frames."""
    d = yaml.safe_load((ASSETS / "a3.legmap.yaml").read_text())
    d["mjcf"] = str(ASSETS / "a3.xml")
    for side in ("left", "right"):
        d["legs"][side]["ft"] = {"body": f"{side}_foot_link", "pos": [0.0, 0.0, -0.03]}
    d["servo_gains"] = {j["name"]: [1500.0, 60.0] for side in ("left", "right") for j in d["legs"][side]["joints"]}
    return d


def spec_doc() -> dict:
    """Our shipped A3-like walking policy's spec (its network by absolute path)."""
    d = yaml.safe_load(A3_SPEC.read_text())
    d["model"]["file"] = str(A3_SPEC.parent / d["model"]["file"])
    return d


def protocol_doc() -> dict:
    """The designed protocol for the A3-like robot (reports/design)."""
    return yaml.safe_load(A3_PROTOCOL.read_text())


@pytest.fixture(scope="module")
def a3():
    return load_robot("a3")


def mapping_doc(legmap) -> dict:
    """The commented example mapping file `legcal-bench import --example-map` prints."""
    return yaml.safe_load(example_mapping(legmap))


def _set(doc: dict, dotted: str, value) -> dict:
    """`doc` with the field at `dotted` (keys and list indices) set to `value`."""
    *parents, last = dotted.split(".")
    node = doc
    for k in parents:
        node = node[int(k)] if isinstance(node, list) else node[k]
    if isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value
    return doc


def _drop(doc: dict, dotted: str) -> dict:
    *parents, last = dotted.split(".")
    node = doc
    for k in parents:
        node = node[int(k)] if isinstance(node, list) else node[k]
    del node[last]
    return doc


def _rename(doc: dict, dotted: str, new: str) -> dict:
    *parents, last = dotted.split(".")
    node = doc
    for k in parents:
        node = node[int(k)] if isinstance(node, list) else node[k]
    node[new] = node.pop(last)
    return doc


def S(field, value):
    return lambda d, tmp: _set(d, field, value)


def D(field):
    return lambda d, tmp: _drop(d, field)


def R(field, new):
    return lambda d, tmp: _rename(d, field, new)


def FOLDER(field):
    return lambda d, tmp: _set(d, field, str(tmp))


# Whole-file cases, the same for every format: (id, bytes, the words the message must carry).
FILE_CASES = [
    ("latin-1 bytes", b"name: caf\xe9\n", "UTF-8"),
    ("empty file", b"", None),
    ("a top-level list", b"- 1\n- 2\n", None),
    ("broken YAML", b"a: [1, 2\nb: {\n", "YAML"),
    ("nesting 3000 deep", b"a: " + b"[" * 3000 + b"]" * 3000 + b"\n", "YAML"),
]

# (id, edit, the field the message names)
LEGMAP_CASES = [
    ("legs.left null", S("legs.left", None), "legs.left"),
    ("legs.right a list", S("legs.right", [1, 2]), "legs.right"),
    ("legs null", S("legs", None), "legs"),
    ("legs a third side", S("legs.middle", {}), "legs"),
    ("mjcf null", S("mjcf", None), "mjcf"),
    ("mjcf a number", S("mjcf", 42), "mjcf"),
    ("mjcf empty", S("mjcf", ""), "mjcf"),
    ("mjcf a folder", FOLDER("mjcf"), "mjcf"),
    ("mjcf missing", S("mjcf", "nowhere/robot.xml"), "mjcf"),
    ("mjcf a NUL byte", S("mjcf", "a\0b.xml"), "mjcf"),
    ("schema null", S("schema", None), "schema"),
    ("name null", S("name", None), "name"),
    ("name a mapping", S("name", {"a": 1}), "name"),
    ("pelvis a list", S("pelvis", []), "pelvis"),
    ("pelvis missing", D("pelvis"), "pelvis"),
    ("imu null", S("imu", None), "imu"),
    ("imu site null", S("imu", {"site": None}), "imu.site"),
    ("imu pos two numbers", S("imu", {"body": "pelvis", "pos": [0, 0]}), "imu.pos"),
    ("imu misspelt pos", S("imu", {"body": "pelvis", "postion": [0, 0, 0]}), "postion"),
    ("misspelt top-level key", R("pelvis", "pelivs"), "pelivs"),
    ("misspelt leg key", R("legs.left.joints", "jionts"), "jionts"),
    ("leg joints null", S("legs.left.joints", None), "legs.left.joints"),
    ("a joint null", S("legs.left.joints.0", None), "legs.left.joints[0]"),
    ("a joint name null", S("legs.left.joints.0.name", None), "legs.left.joints[0].name"),
    ("a joint role a list", S("legs.left.joints.2.role", ["hip_yaw"]), "legs.left.joints[2].role"),
    ("a joint extra key", S("legs.right.joints.1.axis", [1, 0, 0]), "legs.right.joints[1]"),
    ("corners null", S("legs.left.corners", None), "legs.left.corners"),
    ("a corner NaN", S("legs.left.corners.toe_left", [float("nan"), 0.0, 0.0]), "legs.left.corners.toe_left"),
    ("a corner too large", S("legs.left.corners.toe_left", [HUGE, 0, 0]), "legs.left.corners.toe_left"),
    ("a corner strings", S("legs.right.corners.heel_left", ["a", "b", "c"]), "legs.right.corners.heel_left"),
    ("a corner booleans", S("legs.right.corners.heel_left", [True, 0, 0]), "legs.right.corners.heel_left"),
    ("sole a string", S("legs.left.sole", "left_sole"), "legs.left.sole"),
    ("ft body null", S("legs.right.ft", {"body": None}), "legs.right.ft.body"),
    ("ft rpy infinite", S("legs.right.ft.rpy", [0, float("inf"), 0]), "legs.right.ft.rpy"),
    ("kp = -500", S("servo_gains.left_knee_joint", [-500, 16]), "servo_gains.left_knee_joint"),
    ("kp = 0", S("servo_gains.left_knee_joint", [0, 16]), "servo_gains.left_knee_joint"),
    ("kd negative", S("servo_gains.right_hip_yaw_joint", [800, -1]), "servo_gains.right_hip_yaw_joint"),
    ("kp NaN", S("servo_gains.right_hip_yaw_joint", [float("nan"), 1]), "servo_gains.right_hip_yaw_joint"),
    ("gains one number", S("servo_gains.right_hip_yaw_joint", [800]), "servo_gains.right_hip_yaw_joint"),
    ("gains a list", S("servo_gains", [[1, 2]]), "servo_gains"),
    ("held angle a string", S("held_joints_rad", {"waist": "x"}), "held_joints_rad.waist"),
    ("held angle a list", S("held_joints_rad", {"waist": [0.1]}), "held_joints_rad.waist"),
    ("held angles a list", S("held_joints_rad", [0.1]), "held_joints_rad"),
    ("knee straight infinite", S("knee_straight_rad", float("inf")), "knee_straight_rad"),
    ("knee straight quoted", S("knee_straight_rad", "0"), "knee_straight_rad"),
    ("knee straight too large", S("knee_straight_rad", HUGE), "knee_straight_rad"),
    ("absent roles nested", S("absent_roles", [["ankle_roll"]]), "absent_roles"),
]

SPEC_CASES = [
    ("format missing", D("format"), "format"),
    ("misspelt top-level key", R("command", "comand"), "comand"),
    ("name null", S("name", None), "name"),
    ("notes a list", S("notes", [1]), "notes"),
    ("model null", S("model", None), "model"),
    ("model file null", S("model.file", None), "model"),
    ("model file a folder", FOLDER("model.file"), "model.file"),
    ("model misspelt key", S("model.fromat", "onnx"), "fromat"),
    ("model format a list", S("model.format", ["onnx"]), "model.format"),
    ("joints null", S("joints", None), "joints"),
    ("joints with a number", S("joints.3", 7), "joints"),
    ("default_q NaN", S("default_q.0", float("nan")), "default_q"),
    ("default_q too large", S("default_q.0", HUGE), "default_q"),
    ("default_q strings", S("default_q", ["a"] * 12), "default_q"),
    ("default_q a mapping", S("default_q", {"a": 1}), "default_q"),
    ("action null", S("action", None), "action"),
    ("action scale a string", S("action.scale", "big"), "action.scale"),
    ("action clip negative", S("action.clip", -1.0), "action.clip"),
    ("action misspelt key", R("action.scale", "sclae"), "sclae"),
    ("kp = -500", S("pd.kp.0", -500), "pd.kp"),
    ("kp = 0", S("pd.kp.0", 0), "pd.kp"),
    ("kd negative", S("pd.kd.3", -1), "pd.kd"),
    ("pd misspelt key", R("pd.kd", "kdd"), "kdd"),
    ("torque limit zero", S("pd.torque_limit", [0.0] * 12), "pd.torque_limit"),
    ("pd null", S("pd", None), "pd"),
    ("physics_hz negative", S("rates.physics_hz", -500), "rates.physics_hz"),
    ("control_hz zero", S("rates.control_hz", 0), "rates.control_hz"),
    ("physics_hz absurd", S("rates.physics_hz", 1e300), "rates.physics_hz"),
    ("rates misspelt key", R("rates.control_hz", "control_rate"), "control_rate"),
    ("command two numbers", S("command", [0.1, 0.0]), "command"),
    ("command schedule a number", S("command_schedule", 5), "command_schedule"),
    ("observation null", S("observation", None), "observation"),
    ("a term a list", S("observation.0.term", ["ang_vel"]), "observation[0]"),
    ("a term misspelt key", R("observation.0.scale", "scael"), "scael"),
    ("a period negative", S("observation.5.period", -0.8), "observation[5]"),
    ("a clip zero", S("observation.6.clip", 0.0), "observation[6]"),
    ("gait flag a string", S("observation.1", {"term": "gait_phase", "frequency": 1.5,
                                               "stop_at_zero_command": "yes"}), "stop_at_zero_command"),
    ("hold kp negative", S("hold", {"waist_yaw_joint": {"q": 0.0, "kp": -1, "kd": 1}}), "hold.waist_yaw_joint.kp"),
    ("hold a list", S("hold", ["waist_yaw_joint"]), "hold"),
    ("keyframe negative", S("sim", {"keyframe": -1}), "sim.keyframe"),
]

PROTOCOL_CASES = [
    ("format wrong", S("format", "legcal-protocol/2"), "format"),
    ("version 2", S("version", 2), "version"),
    ("misspelt top-level key", S("stnaces", []), "stnaces"),
    ("stances null", S("stances", None), "stances"),
    ("a stance a string", S("stances.0", "I"), "stances[0]"),
    ("a name null", S("stances.0.name", None), "name"),
    ("misspelt stance key", R("stances.1.depth", "depht"), "depht"),
    ("depth negative", S("stances.0.depth", -0.1), "depth"),
    ("depth a string", S("stances.0.depth", "abc"), "depth"),
    ("left_x too large", S("stances.2.left_x", HUGE), "left_x"),
    ("left_x NaN", S("stances.2.left_x", float("nan")), "left_x"),
    ("toe_out a boolean", S("stances.3.toe_out", True), "toe_out"),
    ("amplitude null", S("stances.0.amplitude", None), "amplitude"),
    ("amplitude negative", S("stances.0.amplitude.2", -0.01), "amplitude"),
    ("push five values", S("stances.0.push", [0.0] * 5), "push"),
    ("label a list", S("stances.0.label", ["a"]), "label"),
]

MAPPING_CASES = [
    ("format wrong", S("format", "legcal-log-map/2"), "format"),
    ("misspelt top-level key", R("time_source", "time_sourse"), "time_sourse"),
    ("time unit a list", S("time", {"unit": ["s"]}), "time.unit"),
    ("acc unit a mapping", S("imu.acc_unit", {"g": 1}), "imu.acc_unit"),
    ("joint unit a list", S("joints.map.left_knee_joint.unit", ["deg"]), "joints.map.left_knee_joint.unit"),
    ("joint sign 2", S("joints.map.left_knee_joint.sign", 2), "joints.map.left_knee_joint.sign"),
    ("joint source null", S("joints.map.left_knee_joint.source", None), "joints.map.left_knee_joint"),
    ("gap tolerance too large", S("gap_tolerance_s", HUGE), "gap_tolerance_s"),
    ("gap tolerance negative", S("gap_tolerance_s", -1), "gap_tolerance_s"),
    ("detection NaN", S("detection", {"min_duration_s": float("nan")}), "detection.min_duration_s"),
    ("rotation too large", S("imu.rotation.rpy_deg", [HUGE, 0, 0]), "imu.rotation.rpy_deg"),
    ("sensor value too large", S("sensor_model.encoder_noise_std", HUGE), "sensor_model.encoder_noise_std"),
    ("sensor field misspelt", R("sensor_model.gyro_noise_std", "gyro_noise_sd"), "gyro_noise_sd"),
    ("joints null", S("joints", None), "joints"),
    ("imu topic null", S("imu.topic", None), "imu.topic"),
    ("clock negative", S("clock", -50), "clock"),
]


def _refusal(load, path: Path, family: type) -> str:
    """The message of the LegcalError `load(path)` raises; fails on acceptance or on any
    other exception."""
    try:
        load(path)
    except LegcalError as e:
        assert isinstance(e, family), f"{type(e).__name__} is not a {family.__name__}: {e}"
        return str(e)
    except TRACEBACKS as e:  # pragma: no cover - the failure being tested for
        pytest.fail(f"{path.name}: a traceback-type {type(e).__name__} escaped: {e}")
    pytest.fail(f"{path.name}: the bad file was accepted")


def _write(tmp_path: Path, name: str, doc) -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _check(message: str, path: Path, field: str | None):
    assert path.name in message, f"the file is not named: {message}"
    if field is not None:
        assert field in message, f"the field {field!r} is not named: {message}"


@pytest.mark.parametrize("case, edit, field", LEGMAP_CASES, ids=[c[0] for c in LEGMAP_CASES])
def test_bad_leg_maps_are_refused_naming_file_and_field(tmp_path, case, edit, field):
    path = _write(tmp_path, "robot.legmap.yaml", edit(legmap_doc(), tmp_path))
    _check(_refusal(load_legmap, path, LegMapError), path, field)


@pytest.mark.parametrize("case, edit, field", SPEC_CASES, ids=[c[0] for c in SPEC_CASES])
def test_bad_policy_specs_are_refused_naming_file_and_field(tmp_path, case, edit, field):
    path = _write(tmp_path, "walker.policy.yaml", edit(spec_doc(), tmp_path))
    _check(_refusal(load_policy_spec, path, ConfigError), path, field)


@pytest.mark.parametrize("case, edit, field", PROTOCOL_CASES, ids=[c[0] for c in PROTOCOL_CASES])
def test_bad_protocols_are_refused_naming_file_and_field(tmp_path, case, edit, field):
    path = _write(tmp_path, "mine.protocol.yaml", edit(protocol_doc(), tmp_path))
    _check(_refusal(load_protocol, path, ConfigError), path, field)


@pytest.mark.parametrize("case, edit, field", MAPPING_CASES, ids=[c[0] for c in MAPPING_CASES])
def test_bad_log_mappings_are_refused_naming_file_and_field(tmp_path, a3, case, edit, field):
    path = _write(tmp_path, "log.map.yaml", edit(mapping_doc(a3), tmp_path))
    _check(_refusal(lambda p: load_mapping(p, a3, table=False), path, LogImportError), path, field)


def _loaders(a3):
    return {"leg map": (load_legmap, LegMapError), "policy spec": (load_policy_spec, ConfigError),
            "protocol": (load_protocol, ConfigError),
            "mapping": (lambda p: load_mapping(p, a3, table=False), LogImportError)}


@pytest.mark.parametrize("what", ["leg map", "policy spec", "protocol", "mapping"])
@pytest.mark.parametrize("case, content, words", FILE_CASES, ids=[c[0] for c in FILE_CASES])
def test_bad_files_are_refused_naming_the_file(tmp_path, a3, what, case, content, words):
    load, family = _loaders(a3)[what]
    path = tmp_path / "given.yaml"
    path.write_bytes(content)
    _check(_refusal(load, path, family), path, words)


@pytest.mark.parametrize("what", ["leg map", "policy spec", "protocol", "mapping"])
def test_a_folder_or_a_missing_file_is_named_as_such(tmp_path, a3, what):
    load, family = _loaders(a3)[what]
    folder = tmp_path / "robots"
    folder.mkdir()
    message = _refusal(load, folder, family)
    assert "is a folder" in message and str(folder) in message, message
    message = _refusal(load, tmp_path / "none.yaml", family)
    assert "no such" in message and "none.yaml" in message, message


def test_the_bases_the_cases_mutate_load(tmp_path, a3):
    """Each refusal above is its mutation's: the unmutated documents load."""
    lm = load_legmap(_write(tmp_path, "robot.legmap.yaml", legmap_doc()))
    assert lm.servo_gains["left_knee_joint"] == (1500.0, 60.0) and lm.legs["left"].ft is not None
    assert load_policy_spec(_write(tmp_path, "walker.policy.yaml", spec_doc())).name == "legcal_a3_walker"
    assert len(load_protocol(_write(tmp_path, "mine.protocol.yaml", protocol_doc()))) == 4
    assert load_mapping(_write(tmp_path, "log.map.yaml", mapping_doc(a3)), a3, table=False).robot == "a3"
    held = copy.deepcopy(legmap_doc())
    held["held_joints_rad"] = {"waist": 0.1}
    held["absent_roles"] = None  # optional fields given as null mean none
    assert load_legmap(_write(tmp_path, "held.legmap.yaml", held)).held_joints_rad == {"waist": 0.1}


def test_every_shipped_file_loads_without_a_warning(tmp_path):
    """The packaged robots, the example robots and policies, our walkers, the designed
    protocols and each built-in robot's example mapping."""
    external = []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name in BUILTIN:
            assert load_robot(name).name == name
        for path in sorted((REPO / "examples").glob("*.legmap.yaml")):
            model = yaml.safe_load(path.read_text()).get("mjcf")
            if model and not (path.parent / model).is_file():
                external.append(path.name)  # an external robot that is not on this machine
                continue
            load_legmap(path)
        for path in sorted((REPO / "examples").glob("*.policy.yaml")):
            model = yaml.safe_load(path.read_text())["model"]["file"]
            if not (path.parent / model).is_file():
                external.append(path.name)
                continue
            load_policy_spec(path)
        walkers = sorted((REPO / "policies" / "walkers").glob("*/policy*.yaml"))
        assert len(walkers) >= 4
        for path in walkers:
            load_policy_spec(path)
        protocols = sorted((REPO / "reports" / "design").glob("*.protocol.yaml"))
        assert protocols
        for path in protocols:
            assert load_protocol(path)
        for name in BUILTIN:
            legmap = load_robot(name)
            path = tmp_path / f"{name}.map.yaml"
            path.write_text(example_mapping(legmap))
            assert load_mapping(path, legmap, table=False).robot == name
    assert len(external) <= 4, external


# Recordings: the message names what is wrong, not a guess (issue #42's misdirected messages).
def _recording_file(tmp_path, change):
    from legcal_bench.data.recording import Recording
    from legcal_bench.sim.sensors import SensorModel

    n = 200
    t = np.arange(n) / 50.0
    q = np.tile(np.array([0.1, 0.05, -0.02, 0.6, -0.3, 0.01]), (n, 2))
    rec = Recording(name="stance_I", kind="stance", stance="I", robot="a3",
                    joint_names=[f"j{i}" for i in range(12)], time=t, q_enc=q,
                    imu_acc=np.tile([0.0, 0.0, 9.81], (n, 1)), imu_gyro=np.zeros((n, 3)),
                    sensor_model=SensorModel.unknown())
    change(rec)
    return rec.save(tmp_path / "stance_I.npz")


@pytest.mark.parametrize("change, message", [
    (lambda r: r.q_enc.__setitem__((slice(100, None), 3), r.q_enc[100:, 3] + 2 * np.pi),
     r"joint j3: 100 of 200 frame\(s\) \(first 100\) beyond a full turn.*jumping by whole turns.*numpy.unwrap"),
    (lambda r: r.q_enc.__setitem__((57, 3), 1e6),
     r"joint j3: 1 of 200 frame\(s\) \(first 57\) beyond a full turn, up to 1e\+06, while the others stay within "
     r"0.6 rad: spikes"),
    (lambda r: r.q_enc.__setitem__(slice(None), np.rad2deg(r.q_enc)),
     r"joint j3: 200 of 200 .* which looks like degrees"),
])
def test_an_angle_beyond_a_turn_is_named_for_what_it_is(tmp_path, change, message):
    from legcal_bench.data.recording import load_recording
    from legcal_bench.errors import RecordingError

    with pytest.raises(RecordingError, match=message):  # refused when saved, as when loaded
        _recording_file(tmp_path, change)
    np.savez(tmp_path / "raw.npz", **{k: v for k, v in np.load(_clean(tmp_path)).items()})
    with np.load(tmp_path / "raw.npz") as z:
        arrays = dict(z)
    q = arrays["q_enc"].copy()

    class R:  # the array, changed as the recording's
        q_enc = q
    change(R)
    np.savez(tmp_path / "bad.npz", **{**arrays, "q_enc": R.q_enc})
    with pytest.raises(RecordingError, match=message):
        load_recording(tmp_path / "bad.npz")


def _clean(tmp_path):
    (tmp_path / "clean").mkdir(exist_ok=True)
    return _recording_file(tmp_path / "clean", lambda r: None)


def test_a_npy_saved_as_npz_and_a_folder_given_as_a_recording_are_named(tmp_path):
    from legcal_bench.data.recording import load_recording
    from legcal_bench.errors import RecordingError

    with open(tmp_path / "r.npz", "wb") as f:
        np.save(f, np.zeros(3))
    with pytest.raises(RecordingError, match=r"holds one array \(a .npy file\), not a .npz archive"):
        load_recording(tmp_path / "r.npz")
    (tmp_path / "d.npz").mkdir()
    with pytest.raises(RecordingError, match="is a folder, not a recording file"):
        load_recording(tmp_path / "d.npz")


def test_a_gyro_in_degrees_per_second_is_asked_about_and_a_good_one_is_not():
    from legcal_bench.estimation.problem.preprocess import FilterReport

    deg = FilterReport("stance_I", raw=500, gyro=480, kept=0)
    assert "is imu_gyro in deg/s? It must be rad/s" in deg.text()
    assert "deg/s" not in FilterReport("stance_I", raw=500, gyro=20, kept=480).text()


@pytest.mark.parametrize("fmt", ["onnx", "torchscript", "torch.export"])
def test_a_bad_model_file_is_one_clean_message_without_a_logged_traceback(tmp_path, fmt, capfd):
    from legcal_bench.policies.models import load_model

    bad = tmp_path / "policy.bin"
    bad.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(ConfigError, match=rf"policy: {bad} is not an? (ONNX|{fmt}) model .*check model.format"):
        load_model(bad, fmt, 10, 3)
    assert "Traceback" not in capfd.readouterr().err
