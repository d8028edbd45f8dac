"""The committed leaderboard is exactly what its result files generate."""

import shutil
from pathlib import Path

import pytest

from legcal_bench.benchmark.leaderboard import generate

LEADERBOARD = Path(__file__).resolve().parents[2] / "leaderboard"


def test_committed_leaderboard_regenerates_byte_identically(tmp_path):
    shutil.copytree(LEADERBOARD / "results", tmp_path / "results")
    text = generate(tmp_path)
    assert text == (LEADERBOARD / "README.md").read_text()
    for png in (tmp_path / "plots").iterdir():
        assert png.read_bytes() == (LEADERBOARD / "plots" / png.name).read_bytes(), png.name
    # Rows the leaderboard must have.
    for robot in ("a2", "a3"):
        section = text[text.index(f"## {robot} — weld — suite `standard`"):]
        for row in ("zero-default", "interfoot-operating", "interfoot-matched", "yamane-default"):
            assert f"| {row} |" in section.split("## ")[1]


def test_beats_zero_counts_seeds_on_the_same_sessions():
    from legcal_bench.benchmark.leaderboard import _beats_baseline

    def cell(seed, h):
        return {"cell": {"seed": seed}, "native": {"score": {"heldout": {"foot_height_rms_true_mm": {"after": h}}}}}

    zero = [cell(0, 1.0), cell(1, 1.0), cell(2, 1.0)]
    assert _beats_baseline([cell(0, 0.5), cell(1, 2.0), cell(2, 0.9), cell(3, 0.1)], zero) == "2/3"
    assert _beats_baseline([cell(0, 0.5)], []) == "–"


def test_compare_pairs_two_result_folders_by_seed(tmp_path):
    import json as _json

    from legcal_bench.benchmark.leaderboard import compare

    def write(root, seed, rec):
        d = root / "s" / "a2" / "weld" / "interfoot-sensor"
        d.mkdir(parents=True, exist_ok=True)
        cell = {"cell": {"suite": "s", "mode": "weld", "seed": seed, "calibrator": "interfoot", "variant": "sensor"},
                "robot": "a2", "injected": {"score": {"recovery": {"rms_error_deg": rec}}}}
        (d / f"seed{seed:02d}.json").write_text(_json.dumps(cell))

    for seed, rec in ((0, 0.1), (1, 0.3), (2, 0.2)):
        write(tmp_path / "a", seed, rec)
    for seed, rec in ((0, 0.2), (1, 0.2), (3, 0.9)):
        write(tmp_path / "b", seed, rec)
    [row] = compare(tmp_path / "a", tmp_path / "b", "a2", "weld")
    assert row["seeds"] == [0, 1] and row["a_lower"] == 1
    assert row["a_mean"] == pytest.approx(0.2) and row["b_mean"] == pytest.approx(0.2)
