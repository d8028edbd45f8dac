"""Fuzzed files at the door (issue #42): valid leg maps, policy specs, protocol files and
log mapping files, mutated one to three times (a key dropped; a value set to null, a
wrong type, a huge, negative or non-finite number, a random string or nested junk; an
unknown key added), each written as YAML and loaded. The loader returns a valid object
or raises a `LegcalError`: any other exception (a traceback) fails, and so does an
accepted file that breaks what the object promises (finite numbers, gains > 0, ...).
Derandomized: the same examples on every run."""

from __future__ import annotations

import copy
import math
from collections import Counter
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from legcal_bench.errors import LegcalError
from legcal_bench.logs.mapping import LogMapping, example_mapping, load_mapping
from legcal_bench.policies.spec import PolicySpec, load_policy_spec
from legcal_bench.protocol.stances import load_protocol
from legcal_bench.robots import load_robot
from legcal_bench.robots.legmap import LegMap, load_legmap

REPO = Path(__file__).resolve().parents[2]
ASSETS = REPO / "legcal_bench" / "robots" / "assets"
A3_SPEC = REPO / "policies" / "walkers" / "a3" / "policy.yaml"
A3_PROTOCOL = REPO / "reports" / "design" / "a3_wide.protocol.yaml"
DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)  # libyaml's, when there: 4x faster
FUZZ = dict(deadline=None, derandomize=True, database=None,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much])


def legmap_base() -> dict:
    d = yaml.safe_load((ASSETS / "a3.legmap.yaml").read_text())
    d["mjcf"] = str(ASSETS / "a3.xml")
    for side in ("left", "right"):
        d["legs"][side]["ft"] = {"body": f"{side}_foot_link", "pos": [0.0, 0.0, -0.03], "rpy": [0.0, 0.0, 0.0]}
    d["servo_gains"] = {j["name"]: [1500.0, 60.0] for side in ("left", "right") for j in d["legs"][side]["joints"]}
    d["held_joints_rad"] = {"waist_yaw_joint": 0.1}
    d["absent_roles"] = []
    return d


def spec_base() -> dict:
    """Our A3-like walker's spec with every optional field the format has."""
    d = yaml.safe_load(A3_SPEC.read_text())
    d["model"]["file"] = str(A3_SPEC.parent / d["model"]["file"])
    d["action"]["clip"] = [1.0] * 12
    d["pd"]["torque_limit"] = [100.0] * 12
    d["hold"] = {"waist_yaw_joint": {"q": 0.0, "kp": 100.0, "kd": 2.0}}
    d["sim"] = {"floor_friction": [0.8, 0.005, 0.0001], "keyframe": "home"}
    d["command_schedule"] = [{"t": 0.0, "command": [0.0, 0.0, 0.0]}, {"t": 1.0, "command": [0.3, 0.0, 0.0]}]
    d["observation"] += [
        {"term": "gait_phase", "frequency": 1.5, "initial": [0.0, 3.14], "layout": "grouped",
         "stop_at_zero_command": True},
        {"term": "foot_phase", "period": 0.8, "offsets": [0.0, 0.5]},
        {"term": "sensor", "name": "velocimeter", "size": 3},
        {"term": "joint_pos", "mask": d["joints"][:2], "history": 2, "scale": 0.5, "clip": 3.0},
    ]
    return d


def protocol_base() -> dict:
    """The designed A3-like protocol without its free-form prediction and screen metadata."""
    d = yaml.safe_load(A3_PROTOCOL.read_text())
    del d["predicted"], d["hold_screen"]
    return d


LEGMAP_BASE, SPEC_BASE, PROTOCOL_BASE = legmap_base(), spec_base(), protocol_base()

SPECIAL = st.sampled_from([None, float("nan"), float("inf"), -float("inf"), 10**400, -10**400, 1e308, -1e308, 0,
                           -1, -500, 1e-300, "", "0", "\x00", "a\x00b", [], {}, True, False, [None], {"": None}])
JUNK = st.recursive(
    st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8),
    lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=6), c, max_size=3), max_leaves=6)


def _places(node, at=()):
    """Every (path, value) below `node`: the keys and list indices that reach it."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in items:
        yield at + (k,), v
        yield from _places(v, at + (k,))


def _parent(doc, path):
    node = doc
    for k in path[:-1]:
        node = node[k]
    return node


@st.composite
def mutated(draw, base: dict):
    """`base` with one to three edits, each at a random place of the document."""
    doc = copy.deepcopy(base)
    rnd = draw(st.randoms(use_true_random=False))  # places and edits drawn evenly (not the first ones mostly)
    for _ in range(rnd.randint(1, 3)):
        places = list(_places(doc))
        if not isinstance(doc, dict) or not places:
            break
        path, value = rnd.choice(places)
        parent, key = _parent(doc, path), path[-1]
        op = rnd.choice(["drop", "null", "special", "junk", "negate", "huge", "string", "extra", "type", "root"])
        if op == "drop":
            del parent[key]
        elif op == "null":
            parent[key] = None
        elif op == "special":
            parent[key] = draw(SPECIAL)
        elif op == "junk":
            parent[key] = draw(JUNK)
        elif op == "negate":
            parent[key] = -value if isinstance(value, (int, float)) and not isinstance(value, bool) else -1
        elif op == "huge":
            parent[key] = rnd.choice([10**400, 1e300, -1e300, float("nan")])
        elif op == "string":
            parent[key] = draw(st.text(max_size=12))
        elif op == "extra":
            target = value if isinstance(value, dict) else parent if isinstance(parent, dict) else doc
            target[draw(st.text(min_size=1, max_size=8))] = draw(JUNK)
        elif op == "type":  # the same content as another type: a list as a mapping, a number as a string, ...
            parent[key] = ({str(i): v for i, v in enumerate(value)} if isinstance(value, list)
                           else list(value.values()) if isinstance(value, dict)
                           else str(value) if isinstance(value, (int, float)) else [value])
        elif rnd.random() < 0.2:  # now and then not a mapping at all
            doc = draw(JUNK)
    return doc


def _load(load, path: Path, doc, outcomes: Counter):
    """`load(path)` on `doc` written as YAML: the object, or None when refused with a
    LegcalError (counted); any other exception propagates and fails the test."""
    path.write_text(yaml.dump(doc, Dumper=DUMPER, sort_keys=False))
    try:
        out = load(path)
    except LegcalError:
        outcomes["refused"] += 1
        return None
    outcomes["loaded"] += 1
    return out


def _finite(*values) -> bool:
    return all(math.isfinite(float(v)) for v in values)


def check_legmap(lm: LegMap):
    assert isinstance(lm, LegMap) and lm.n_joints in (10, 12) and len(set(lm.joint_names)) == lm.n_joints
    assert lm.mjcf.is_file() and isinstance(lm.name, str) and lm.name and isinstance(lm.pelvis, str) and lm.pelvis
    assert all(isinstance(n, str) and n for n in lm.joint_names)
    for leg in lm.legs.values():
        assert set(leg.corners) == {"toe_left", "toe_right", "heel_left", "heel_right"}
        assert all(_finite(*c) for c in leg.corners.values())
        for frame in (leg.sole, leg.ft):
            assert frame is None or (_finite(*frame.pos, *frame.rpy) and (frame.site or frame.body))
    assert _finite(*lm.imu.pos, *lm.imu.rpy, lm.knee_straight_rad, *lm.held_joints_rad.values())
    assert all(kp > 0 and kd >= 0 and _finite(kp, kd) for kp, kd in lm.servo_gains.values())
    # leg joints by name; held joints by name or pattern, checked against the model when held (`joint_holds`)
    assert all(isinstance(k, str) and k.strip() for k in lm.servo_gains)
    lm.to_dict()


def check_spec(spec: PolicySpec):
    n = len(spec.joints)
    assert isinstance(spec, PolicySpec) and n >= 1 and all(isinstance(j, str) and j for j in spec.joints)
    assert len(spec.default_q) == len(spec.kp) == len(spec.kd) == n
    assert _finite(*spec.default_q, *spec.kp, *spec.kd, spec.action_scale, *spec.command)
    assert spec.actuators == "model" or all(k > 0 for k in spec.kp)
    assert spec.physics_hz > 0 and spec.control_hz > 0 and spec.decimation >= 1
    assert all(_finite(*t.scale) for t in spec.observation)
    assert all(t.clip is None or t.clip > 0 for t in spec.observation)
    assert all(t0 < t1 for (t0, _), (t1, _) in zip(spec.command_schedule, spec.command_schedule[1:]))
    assert isinstance(spec.settings, str) and isinstance(spec.notes, dict)
    assert all(h.kp is None or h.kp > 0 for h in spec.hold)


def check_protocol(stances: dict):
    assert stances and all(isinstance(k, str) and k for k in stances)
    for st_ in stances.values():
        assert _finite(st_.left_x, st_.right_x, st_.extra_width, st_.toe_out, st_.depth, *st_.amplitude, *st_.push)
        assert 0 <= st_.depth <= 1 and all(a >= 0 for a in st_.amplitude + st_.push)
        assert isinstance(st_.label, str)


def _fuzz(base: dict, load, check, tmp_path: Path, name: str, examples: int) -> Counter:
    outcomes: Counter = Counter()
    path = tmp_path / name

    @settings(max_examples=examples, **FUZZ)
    @given(doc=mutated(base))
    def run(doc):
        out = _load(load, path, doc, outcomes)
        if out is not None:
            check(out)

    run()
    return outcomes


def test_fuzzed_leg_maps_load_or_are_refused(tmp_path):
    outcomes = _fuzz(LEGMAP_BASE, load_legmap, check_legmap, tmp_path, "robot.legmap.yaml", 300)
    assert outcomes["refused"] > 150 and outcomes["loaded"] >= 3, outcomes


def test_fuzzed_policy_specs_load_or_are_refused(tmp_path):
    outcomes = _fuzz(SPEC_BASE, load_policy_spec, check_spec, tmp_path, "walker.policy.yaml", 300)
    assert outcomes["refused"] > 150 and outcomes["loaded"] >= 3, outcomes


def test_fuzzed_protocols_load_or_are_refused(tmp_path):
    outcomes = _fuzz(PROTOCOL_BASE, load_protocol, check_protocol, tmp_path, "mine.protocol.yaml", 150)
    assert outcomes["refused"] > 75 and outcomes["loaded"] >= 3, outcomes


def check_mapping(m: LogMapping):
    assert isinstance(m, LogMapping) and m.gap_tolerance_s > 0 and m.time_scale > 0
    assert all(abs(s.sign) == 1 and s.scale > 0 for s in m.joint_map.values())
    assert _finite(m.acc_scale, m.gyro_scale, *(v for v in vars(m.detection).values()))
    for stream in (m.imu, *m.ft.values()):
        assert stream.rotation.shape == (3, 3) and _finite(*stream.rotation.ravel())


@pytest.fixture(scope="module")
def a3():
    return load_robot("a3")


def test_fuzzed_log_mappings_load_or_are_refused(tmp_path, a3):
    base = yaml.safe_load(example_mapping(a3))
    base["ft"] = {"left": {"topic": "/ft/left", "rotation": {"rpy_deg": [0, 0, 0]}}, "right": {"topic": "/ft/right"}}
    base["detection"] = {"min_duration_s": 3.0, "still_speed": 0.01}
    outcomes = _fuzz(base, lambda p: load_mapping(p, a3, table=False), check_mapping, tmp_path, "log.map.yaml", 150)
    assert outcomes["refused"] > 75 and outcomes["loaded"] >= 3, outcomes
