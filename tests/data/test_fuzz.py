"""Fuzzed recordings (issue #10): 300 derandomized mutations of a valid recording's
arrays and keys, each loaded and, when it loads, calibrated. Anything but a
`LegcalError` (a traceback) fails; so does a result with non-finite offsets."""

from __future__ import annotations

import io
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import check_against_robot, load_recording
from legcal_bench.errors import LegcalError
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot

ARRAYS = ("time", "q_enc", "imu_acc", "imu_gyro", "ft")
META = ("format", "version", "name", "kind", "stance", "robot", "joint_names", "sensor_model", "source", "session",
        "motion")
OUTCOMES = {"refused": 0, "calibrated": 0}
# Both tests in one process, in order: the second reads the outcomes the first counted
# (spread over pytest-xdist's processes, it would run the 300 mutations again).
pytestmark = pytest.mark.xdist_group("fuzz")


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    out = tmp_path_factory.mktemp("fuzzbase") / "set"
    collect(CollectConfig(robot="a3", mode="kinematic", stances=("II",), stance_s=2.0, heldout=0, standing_s=0.0),
            out, progress=False)
    with np.load(out / "stance_II.npz") as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(str(arrays.pop("meta")))
    # The robot, loaded once (a frozen leg map; loading it was a fifth of each example).
    return arrays, meta, tmp_path_factory.mktemp("fuzz"), load_robot("a3")


json_values = st.recursive(st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats(allow_nan=True)
                           | st.text(max_size=8), lambda c: st.lists(c, max_size=3) | st.dictionaries(
                               st.text(max_size=6), c, max_size=3), max_leaves=6)

special = st.sampled_from([np.nan, np.inf, -np.inf, 0.0, 1e300, -1e-300, 7.0, 1e3])


@st.composite
def mutations(draw):
    """A list of edits, each a (kind, args) pair applied in order."""
    edits = []
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["drop_array", "drop_meta", "meta_value", "extra_key", "dtype", "reshape",
                                     "truncate", "values", "time", "scale", "columns"]))
        if kind in ("drop_array", "dtype", "reshape", "truncate", "values", "scale"):
            key = draw(st.sampled_from(ARRAYS))
        elif kind in ("drop_meta", "meta_value"):
            key = draw(st.sampled_from(META))
        else:
            key = None
        arg = {
            "meta_value": lambda: draw(json_values),
            "extra_key": lambda: draw(st.sampled_from(["extra", "q_true", "offsets", "meta2"])),
            "dtype": lambda: draw(st.sampled_from(["int32", "uint8", "bool", "float16", "complex128", "<U3",
                                                   "float32"])),
            "reshape": lambda: draw(st.sampled_from(["flatten", "transpose", "add_axis", "scalar", "empty"])),
            "truncate": lambda: draw(st.integers(0, 120)),
            "values": lambda: (draw(st.integers(0, 200)), draw(st.integers(1, 20)), draw(special)),
            "time": lambda: draw(st.sampled_from(["reverse", "duplicate", "ms", "ns", "constant", "negative",
                                                  "jitter", "gap"])),
            "scale": lambda: draw(st.sampled_from([0.0, -1.0, 1e-3, 57.3, 1e6])),
            "columns": lambda: draw(st.permutations(range(12))),
        }.get(kind, lambda: None)()
        edits.append((kind, key, arg))
    return edits


def _apply(arrays: dict, meta: dict, edits) -> tuple[dict, dict]:
    a = {k: v.copy() for k, v in arrays.items()}
    m = json.loads(json.dumps(meta))
    for kind, key, arg in edits:
        if kind == "drop_array":
            a.pop(key, None)
        elif kind == "drop_meta":
            m.pop(key, None)
        elif kind == "meta_value":
            m[key] = arg
        elif kind == "extra_key":
            a[arg] = np.zeros(3)
        elif key not in a or (a[key].ndim == 0 and kind in ("reshape", "truncate")):
            continue
        elif kind == "dtype":
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    a[key] = a[key].astype(arg)
                except (ValueError, OverflowError):  # not representable: leave the array as it is
                    pass
        elif kind == "reshape":
            x = a[key]
            a[key] = {"flatten": lambda: x.ravel(), "transpose": lambda: x.T, "add_axis": lambda: x[..., None],
                      "scalar": lambda: np.asarray(x.ravel()[0] if x.size else 0.0), "empty": lambda: x[:0]}[arg]()
        elif kind == "truncate":
            a[key] = a[key][:arg]
        elif kind == "values":
            start, n, v = arg
            if a[key].dtype.kind in "fc" and a[key].ndim >= 1:
                a[key][start:start + n] = v
        elif kind == "scale":
            if a[key].dtype.kind in "fc":
                a[key] = a[key] * arg
        elif kind == "time" and "time" in a and a["time"].ndim == 1 and a["time"].dtype.kind == "f":
            t = a["time"]
            a["time"] = {"reverse": t[::-1], "duplicate": np.r_[t[:1], t[:-1]], "ms": t * 1e3, "ns": t * 1e9,
                         "constant": np.zeros_like(t), "negative": -t, "jitter": t + 0.03 * np.sin(t * 97.0),
                         "gap": np.where(np.arange(t.size) > t.size // 2, t + 100.0, t)}[arg]
    for kind, key, arg in edits:
        if kind == "columns" and "q_enc" in a and a["q_enc"].ndim == 2 and a["q_enc"].shape[1] == 12:
            a["q_enc"] = a["q_enc"][:, list(arg)]
    return a, m


@settings(max_examples=300, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                 HealthCheck.data_too_large])
@given(edits=mutations())
def test_fuzzed_recordings_end_in_a_legcal_error_or_a_finite_result(base, edits):
    arrays, meta, folder, lm = base
    a, m = _apply(arrays, meta, edits)
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(m)), **a)
    path = Path(folder) / "fuzzed.npz"
    path.write_bytes(buf.getvalue())
    try:
        rec = load_recording(path, lm.joint_names)
        check_against_robot([rec], lm)
        res = get_calibrator("interfoot", n_max=100).calibrate(lm, [rec])
    except LegcalError as e:
        assert str(e), "an error without a message"
        OUTCOMES["refused"] += 1
        return
    assert np.isfinite(res.offsets_vector(lm.joint_names)).all()
    OUTCOMES["calibrated"] += 1


def test_the_fuzz_run_both_refused_and_calibrated(base):
    """A mutation set that only ever refused (or never did) would test nothing. Reads the
    fuzz test's outcomes (it runs first); run alone, it runs the fuzz test itself."""
    if sum(OUTCOMES.values()) == 0:
        test_fuzzed_recordings_end_in_a_legcal_error_or_a_finite_result(base=base)
    print(OUTCOMES)
    assert OUTCOMES["refused"] > 50 and OUTCOMES["calibrated"] > 10, OUTCOMES
