"""The committed leaderboard is exactly what its result files generate."""

import shutil
from pathlib import Path

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
