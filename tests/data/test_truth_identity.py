"""A ground-truth file carries its session set's identity (issue #42): `score` with truth
files copied from another session set used to report that set's recovery with no word
(1.815 deg against a true 0.183 deg); now it refuses naming both sessions. Truth files
written before the identity are read with a warning."""

from __future__ import annotations

import io
import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from legcal_bench.calibrators.base import CalibrationResult
from legcal_bench.cli import main
from legcal_bench.data.recording import UncheckedTruthWarning, list_segments, load_recording, load_truth, truth_path
from legcal_bench.errors import RecordingError
from legcal_bench.evaluation.scoring import score
from legcal_bench.protocol.collect import CollectConfig, collect, session_id
from legcal_bench.robots import load_robot

TINY = dict(robot="a3", mode="kinematic", stances=("I",), stance_s=0.4, standing_s=0.2, heldout=1, heldout_s=0.2)


@pytest.fixture(scope="module")
def sets(tmp_path_factory) -> dict:
    """Two session sets of the same robot, floor and seed, other offsets; a zero result."""
    root = tmp_path_factory.mktemp("identity")
    collect(CollectConfig(**TINY), root / "a", progress=False)
    collect(CollectConfig(**TINY, offsets="random:2"), root / "b", progress=False)
    names = load_robot("a3").joint_names
    CalibrationResult("zero", "a3", {n: 0.0 for n in names}).save(root / "zero.json")
    return {"root": root, "a": root / "a", "b": root / "b", "result": root / "zero.json"}


def _session(path: Path) -> str:
    return load_recording(path).session


def test_collect_writes_one_identity_into_recordings_truth_and_manifest(sets):
    a, b = sets["a"], sets["b"]
    ids = {_session(p) for p in list_segments(a)}
    assert len(ids) == 1
    (sid,) = ids
    assert sid.startswith("a3-kinematic-seed0-")
    assert {load_truth(p).meta["session"] for p in list_segments(a)} == {sid}
    assert json.loads((a / "session.json").read_text())["session"] == sid
    assert _session(list_segments(b)[0]) != sid  # same robot, floor and seed; other offsets
    cfg = CollectConfig(**TINY)
    offsets = load_truth(list_segments(a)[0]).offsets
    assert session_id(cfg, offsets, "a3") == sid  # deterministic: the config, offsets and results version
    assert session_id(cfg, offsets + 1e-3, "a3") != sid


def test_score_refuses_truth_from_another_session_set_naming_both(sets, tmp_path, capsys):
    mixed = tmp_path / "mixed"
    shutil.copytree(sets["a"], mixed)
    for p in sets["b"].glob("*.truth.npz"):
        shutil.copy(p, mixed / p.name)
    theirs, ours = _session(list_segments(sets["b"])[0]), _session(list_segments(sets["a"])[0])
    with pytest.raises(RecordingError, match=f"ground truth is of session '{theirs}' but its recording "
                                             rf"\S+ is of session '{ours}'"):
        score(str(mixed), CalibrationResult.load(sets["result"]), load_robot("a3"))
    assert main(["score", "--bags", str(mixed), "--result", str(sets["result"])]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and theirs in err[0] and ours in err[0] and "legcal-bench score: error:" in err[0]


def test_a_truth_file_without_its_identity_is_read_with_a_warning(sets, tmp_path, capsys):
    old = tmp_path / "old"
    shutil.copytree(sets["a"], old)
    for p in old.glob("*.truth.npz"):  # as written before the identity
        with np.load(p) as z:
            arrays = {k: z[k] for k in z.files}
        meta = json.loads(str(arrays.pop("meta")))
        del meta["session"]
        buf = io.BytesIO()
        np.savez(buf, meta=np.array(json.dumps(meta)), **arrays)
        p.write_bytes(buf.getvalue())
    with pytest.warns(UncheckedTruthWarning, match="name no session set"):
        s = score(str(old), CalibrationResult.load(sets["result"]), load_robot("a3"))
    assert "recovery" in s
    assert main(["score", "--bags", str(old), "--result", str(sets["result"]), "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["recovery"]["rms_error_deg"] > 0
    warned = [line for line in captured.err.splitlines() if "warning:" in line]
    assert len(warned) == 1 and "legcal-bench score: warning:" in warned[0]  # said once, not per file


def test_matching_truth_loads_silently(sets):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for p in list_segments(sets["a"]):
            assert truth_path(p).is_file()
            load_truth(p)
        score(str(sets["a"]), CalibrationResult.load(sets["result"]), load_robot("a3"))
