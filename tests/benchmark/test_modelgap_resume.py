"""The model-gap suite resumes case by case (issue #36): each finished case is a file
with its key and provenance, written whole as it finishes; a rerun computes only the
cases missing, broken or made under another key (code or options), and the report is
assembled from the files."""

import json

import pytest

from legcal_bench.benchmark import modelgap as mg
from legcal_bench.provenance import RESULTS_VERSION

CODE = {"package": "0.1.0", "commit": "c0ffee", "results_version": 7}


@pytest.fixture
def fixed_code(monkeypatch):
    """The code identity held fixed (others may edit the tree while a test runs)."""
    monkeypatch.setattr(mg, "code_identity", lambda code: dict(CODE))


@pytest.fixture
def fake_cases(monkeypatch, fixed_code):
    """run_case replaced by a counter: the jobs it was asked, in order; `fail_at` makes
    the n-th call raise (a crash mid-run)."""
    calls, fail_at = [], []

    def fake(robot, kind, name, seed, stances=None, calibrator=mg.DEFAULT_CALIBRATOR, collect=None):
        if fail_at and len(calls) + 1 == fail_at[0]:
            raise RuntimeError("crash in the middle of a case")
        calls.append((kind, name, seed))
        return {"robot": "A3", "kind": kind, "name": name, "seed": seed, "selected": [name] if name else [],
                "ambiguous": [], "verdict": "selected" if name else "explained", "p_value": 0.5, "z": 0.0,
                "scale": None, "confounded": [], "at_truth": {"training": 1.0},
                "offsets_rms_deg": {"before": 0.1, "after": 0.02}}

    monkeypatch.setattr(mg, "run_case", fake)
    return calls, fail_at


def _run(out, **kw):
    return mg.run(["a3"], seeds=1, clean_seeds=1, cases=("clean", "library"), workers=1, progress=False, out=out,
                  **kw)


def test_a_rerun_computes_only_the_cases_missing_broken_or_stale(tmp_path, fake_cases, monkeypatch):
    calls, _ = fake_cases
    first = _run(tmp_path)
    assert len(calls) == 7 and first["cases"] == {"total": 7, "computed": 7, "kept": 0}
    files = sorted(tmp_path.rglob("*.json"))
    assert len(files) == 7 and not list(tmp_path.rglob("*.tmp"))
    case = json.loads(mg.case_path(tmp_path, ("a3", "library", "hip_axis", 0, None, mg.DEFAULT_CALIBRATOR)).read_text())
    assert case["case"]["kind"] == "library" and case["case"]["name"] == "hip_axis" and case["case"]["seed"] == 0
    assert case["case"]["calibrator"]["name"] == "interfoot" and case["provenance"]["code"]["results_version"] == RESULTS_VERSION
    assert "cases=['clean', 'library']" in case["provenance"]["command"]
    # The same command again: every case kept, the report the same.
    calls.clear()
    assert _run(tmp_path, command="legcal-bench bench --suite modelgap")["rows"] == first["rows"] and calls == []
    # One case deleted, one cut short (not JSON), one with another key: only those three.
    mg.case_path(tmp_path, ("a3", "library", "compliance", 0, None, mg.DEFAULT_CALIBRATOR)).unlink()
    clean = mg.case_path(tmp_path, ("a3", "clean", None, 0, None, mg.DEFAULT_CALIBRATOR))
    clean.write_text(clean.read_text()[:50])
    stale = mg.case_path(tmp_path, ("a3", "library", "imu_tilt", 0, None, mg.DEFAULT_CALIBRATOR))
    stale.write_text(json.dumps({**json.loads(stale.read_text()), "key": "another"}))
    again = _run(tmp_path)
    assert sorted(calls) == [("clean", None, 0), ("library", "compliance", 0), ("library", "imu_tilt", 0)]
    assert again["rows"] == first["rows"] and again["cases"]["kept"] == 4
    # Other code (another commit, or other uncommitted changes): every case again.
    calls.clear()
    monkeypatch.setattr(mg, "code_identity", lambda code: {**CODE, "commit": "decaf"})
    assert _run(tmp_path)["cases"]["computed"] == 7 and len(calls) == 7
    # Other options (shorter sessions): a case's key holds them.
    calls.clear()
    monkeypatch.setattr(mg, "COLLECT", {"stance_s": 3.0})
    _run(tmp_path)
    assert len(calls) == 7
    assert json.loads(clean.read_text())["case"]["collect"] == {"stance_s": 3.0}


def test_a_crash_keeps_the_finished_cases_and_the_rerun_does_the_rest(tmp_path, fake_cases):
    calls, fail_at = fake_cases
    fail_at.append(3)
    with pytest.raises(RuntimeError, match="crash in the middle"):
        _run(tmp_path)
    assert len(calls) == 2 and len(list(tmp_path.rglob("*.json"))) == 2  # the two finished, whole
    done = list(calls)
    fail_at.clear()
    calls.clear()
    assert _run(tmp_path)["cases"] == {"total": 7, "computed": 5, "kept": 2}
    assert len(calls) == 5 and not set(calls) & set(done)


def test_cases_of_other_stances_or_calibrators_are_files_of_their_own(tmp_path):
    base = ("a3", "library", "imu_tilt", 3, None, mg.DEFAULT_CALIBRATOR)
    paths = {mg.case_path(tmp_path, base), mg.case_path(tmp_path, (*base[:4], ("I", "II"), base[5])),
             mg.case_path(tmp_path, (*base[:5], ("spy", ()))), mg.case_path(tmp_path, (*base[:5], ("spy", (("a", 1),))))}
    assert len(paths) == 4
    assert mg.case_path(tmp_path, base) == tmp_path / "a3" / "library_imu_tilt" / "seed03.json"


def test_the_code_identity_holds_uncommitted_changes():
    clean = mg.code_identity({**CODE, "dirty": False})
    assert clean == CODE
    dirty = mg.code_identity({**CODE, "dirty": True})
    assert set(dirty) == set(CODE) | {"changes"}


def test_a_tiny_suite_recomputes_one_deleted_case_to_the_same_row(tmp_path, fixed_code, monkeypatch):
    # The real cases, on short sessions of two stances: the deleted one alone is
    # recomputed, to the same row (the suite is deterministic per seed).
    monkeypatch.setattr(mg, "COLLECT", {"stance_s": 2.0, "standing_s": 0.5})
    real, calls = mg.run_case, []
    monkeypatch.setattr(mg, "run_case", lambda *a, **kw: calls.append(a[:4]) or real(*a, **kw))

    def run():
        return mg.run(["a3"], seeds=1, clean_seeds=1, cases=("clean",), stances=("I", "II"), workers=1,
                      progress=False, out=tmp_path)

    first = run()
    assert [r["kind"] for r in first["rows"]] == ["clean", "clean_kinematic"] and len(calls) == 2
    mg.case_path(tmp_path, ("a3", "clean_kinematic", None, 0, ("I", "II"), mg.DEFAULT_CALIBRATOR)).unlink()
    calls.clear()
    assert run()["rows"] == first["rows"] and calls == [("a3", "clean_kinematic", None, 0)]
