"""The committed leaderboard is exactly what its result files generate."""

import shutil
from pathlib import Path

import pytest

from legcal_bench.benchmark.leaderboard import generate

LEADERBOARD = Path(__file__).resolve().parents[2] / "leaderboard"


def test_committed_leaderboard_regenerates_byte_identically(tmp_path):
    shutil.copytree(LEADERBOARD / "results", tmp_path / "results")
    if (LEADERBOARD / "designed" / "results").is_dir():  # the protocol comparison reads it
        shutil.copytree(LEADERBOARD / "designed" / "results", tmp_path / "designed" / "results")
    if (LEADERBOARD / "closed_loop").is_dir():  # and the closed-loop section this
        shutil.copytree(LEADERBOARD / "closed_loop", tmp_path / "closed_loop")
    if (LEADERBOARD / "modelgap" / "modelgap.json").is_file():  # and the model-gap suite this
        (tmp_path / "modelgap").mkdir()
        shutil.copy(LEADERBOARD / "modelgap" / "modelgap.json", tmp_path / "modelgap")
    from legcal_bench.benchmark.leaderboard import REPORT_SECTIONS

    reports = [(folder, name) for folder, name, _, _ in REPORT_SECTIONS
               if (LEADERBOARD / folder / f"{name}.json").is_file()]
    for folder, name in reports:  # the contact floor's and holds' sections read their rows
        (tmp_path / folder).mkdir()
        shutil.copy(LEADERBOARD / folder / f"{name}.json", tmp_path / folder)
    text = generate(tmp_path)
    assert text == (LEADERBOARD / "README.md").read_text()
    for folder, stem in [("modelgap", "modelgap"), *reports]:  # each page, rebuilt from its rows, is the committed one
        if (tmp_path / folder).is_dir():
            for name in (f"{stem}.md", f"{stem}.json"):
                assert (tmp_path / folder / name).read_text() == (LEADERBOARD / folder / name).read_text()
    for png in (tmp_path / "plots").iterdir():
        assert png.read_bytes() == (LEADERBOARD / "plots" / png.name).read_bytes(), png.name
    # Rows the leaderboard must have.
    for robot in ("a2", "a3"):
        section = text[text.index(f"## {robot} — weld — suite `standard`"):]
        for row in ("zero-default", "interfoot-operating", "interfoot-matched", "yamane-default"):
            assert f"| {row} |" in section.split("## ")[1]


def test_every_other_model_gap_root_regenerates_byte_identically(tmp_path):
    """Model-gap runs kept beside the main one (e.g. a `--cases clean library` run with
    more seeds per effect): each root's README and page are what its rows generate."""
    for rows in sorted(LEADERBOARD.glob("*/modelgap/modelgap.json")):
        root = rows.parents[1]
        (tmp_path / root.name / "modelgap").mkdir(parents=True)
        shutil.copy(rows, tmp_path / root.name / "modelgap")
        assert generate(tmp_path / root.name) == (root / "README.md").read_text(), root.name
        for name in ("modelgap.md", "modelgap.json"):
            assert ((tmp_path / root.name / "modelgap" / name).read_text()
                    == (root / "modelgap" / name).read_text()), (root.name, name)


def test_beats_zero_counts_seeds_on_the_same_sessions():
    from legcal_bench.benchmark.leaderboard import _beats_baseline

    def cell(seed, h):
        return {"cell": {"seed": seed}, "native": {"score": {"heldout": {"foot_height_rms_true_mm": {"after": h}}}}}

    zero = [cell(0, 1.0), cell(1, 1.0), cell(2, 1.0)]
    assert _beats_baseline([cell(0, 0.5), cell(1, 2.0), cell(2, 0.9), cell(3, 0.1)], zero) == "2/3"
    assert _beats_baseline([cell(0, 0.5)], []) == "–"


def _write_cell(root, seed, rec, error=None, vs_imu=None):
    import json as _json

    d = root / "s" / "a2" / "weld" / "interfoot-sensor"
    d.mkdir(parents=True, exist_ok=True)
    cell = {"cell": {"suite": "s", "mode": "weld", "seed": seed, "calibrator": "interfoot", "variant": "sensor"},
            "robot": "a2", "injected": {"score": {"recovery": {"rms_error_deg": rec, "vs_imu_vertical": {
                "rms_error_deg": vs_imu if vs_imu is not None else (rec or 0) / 2}}}}}
    if error:
        cell = {"cell": cell["cell"], "robot": "a2", "error": error}
    (d / f"seed{seed:02d}.json").write_text(_json.dumps(cell))


def test_compare_pairs_two_result_folders_by_seed(tmp_path):
    from legcal_bench.benchmark.leaderboard import compare

    write = _write_cell

    for seed, rec in ((0, 0.1), (1, 0.3), (2, 0.2)):
        write(tmp_path / "a", seed, rec)
    for seed, rec in ((0, 0.2), (1, 0.2), (3, 0.9)):
        write(tmp_path / "b", seed, rec)
    [row] = compare(tmp_path / "a", tmp_path / "b", "a2", "weld")
    assert row["seeds"] == [0, 1] and row["a_lower"] == 1
    assert row["a_mean"] == pytest.approx(0.2) and row["b_mean"] == pytest.approx(0.2)


def test_the_leaderboard_puts_a_designed_protocol_beside_the_default_stances(tmp_path):
    from legcal_bench.benchmark.leaderboard import DESIGNED, _protocol_comparison

    for seed, rec in ((0, 0.10), (1, 0.30), (2, 0.20)):
        _write_cell(tmp_path / "results", seed, rec)
    for seed, rec in ((0, 0.05), (1, 0.40)):
        _write_cell(tmp_path / DESIGNED / "results", seed, rec)
    _write_cell(tmp_path / DESIGNED / "results", 2, None, error="HoldError: segment stance_D1 ...")
    rows = [r for r in _protocol_comparison(tmp_path) if r.startswith("| a2 |")]
    # Seeds 0 and 1 pair up: default 0.20 -> designed 0.225 mean, lower in 1 of 2; seed 2 failed.
    assert rows == ["| a2 | interfoot-sensor | 2 | 0.200 → 0.225 | 1/2 | 0.1000 → 0.1125 | 1/2 | 1 |"]
    assert _protocol_comparison(tmp_path / "nothing") == []
