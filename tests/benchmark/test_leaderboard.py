"""The committed leaderboard is exactly what its rows generate."""

import shutil
from pathlib import Path

import pytest

from legcal_bench.benchmark.leaderboard import DESIGNED, generate, rows_path

LEADERBOARD = Path(__file__).resolve().parents[2] / "leaderboard"


def _copy_rows(root: Path, to: Path) -> None:
    """The rows of `root`'s results (and of its designed protocols', which the protocol
    comparison reads), without any cell files a run left beside them in a checkout."""
    for results in (root / "results", root / DESIGNED / "results"):
        if rows_path(results).is_file():
            (to / results.relative_to(root)).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(rows_path(results), to / rows_path(results).relative_to(root))


def test_committed_leaderboard_regenerates_byte_identically(tmp_path):
    _copy_rows(LEADERBOARD, tmp_path)
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
    assert rows_path(tmp_path / "results").read_text() == rows_path(LEADERBOARD / "results").read_text()
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


@pytest.mark.parametrize("name", ["designed", "calibrated_imu"])
def test_every_other_leaderboard_regenerates_byte_identically(tmp_path, name):
    """The leaderboards kept beside the main one (the designed protocols', the
    `calibrated-imu` sensors'): README, rows and plots are what their rows generate."""
    root = LEADERBOARD / name
    _copy_rows(root, tmp_path)
    assert generate(tmp_path) == (root / "README.md").read_text()
    assert rows_path(tmp_path / "results").read_text() == rows_path(root / "results").read_text()
    assert sorted(p.name for p in (tmp_path / "plots").iterdir()) == sorted(p.name for p in (root / "plots").iterdir())
    for png in (tmp_path / "plots").iterdir():
        assert png.read_bytes() == (root / "plots" / png.name).read_bytes(), png.name


def _full_cell(seed: int, variant: str = "sensor", **extra) -> dict:
    """A cell as `bench` writes it, with more in it than the leaderboard reads."""
    names = ["left_knee_joint", "right_knee_joint"]
    return {"cell": {"suite": "s", "mode": "weld", "seed": seed, "calibrator": "interfoot", "variant": variant,
                     "scale": 1.0, "robot": "a2", "options": [["setting", variant]], "collect": []},
            "robot": "a2", "joint_names": names, "key": "k", "provenance": {"commit": "abc", "results_version": 7},
            "paired_delta_rms_deg": 0.01 * seed, "paired_delta_deg": {n: 0.1 for n in names},
            "native": {"score": {"heldout": {"foot_height_rms_true_mm": {"after": 0.1 + seed, "before": 9.0},
                                             "foot_height_rms_mm": {"after": 0.5, "before": 0.6},
                                             "sole_normal_rms_deg": {"after": 0.08, "before": 1.0}, "frames": 10},
                                 "recovery": {"rms_error_deg": 0.02, "max_error_deg": 0.1}},
                       "heldout_foot_height_hist": {"edges_mm": [-4.0, 4.0, 8], "before": [0, 1, 2, 0, 3, 0, 0, 0],
                                                    "after": [0, 0, 0, 0, 0, 0, 0, 0]},
                       "offsets_rad": {n: 0.0 for n in names}, "timing_s": {"total": 1.0}},
            "injected": {"score": {"recovery": {"rms_error_deg": 0.03, "max_error_deg": 0.05,
                                                "pitch_sum_error_deg": {"left": 0.004, "right": -0.002},
                                                "per_joint_error_deg": {"right_knee_joint": -0.01,
                                                                        "left_knee_joint": 0.02},
                                                "vs_imu_vertical": {"rms_error_deg": 0.015}, "imu_tilt_mrad": [1, 2]}},
                         "conditioning": {"kappa_H_data": 12.5, "eigenvalues_H_data": [1.0, 12.5], "kappa_J_data": 3.5},
                         "timing_s": {"total": 0.5, "preprocess": 0.1}, "warnings": [], "offsets_rad": {}},
            **extra}


def test_a_row_keeps_what_the_leaderboard_reads_of_its_cell(tmp_path):
    from legcal_bench.benchmark.leaderboard import METRICS, read_rows, write_rows

    cells = [_full_cell(1), _full_cell(0, variant="matched"),
             {"cell": {"suite": "s", "mode": "weld", "seed": 2, "calibrator": "interfoot", "variant": "sensor"},
              "robot": "a2", "provenance": {"commit": "abc", "results_version": 7}, "error": "HoldError: ..."}]
    del cells[1]["injected"]["score"]["recovery"]["vs_imu_vertical"], cells[1]["injected"]["conditioning"]
    cells[1]["injected"]["conditioning"] = {}
    write_rows(tmp_path / "rows.json", cells)
    back = read_rows(tmp_path / "rows.json")
    assert [c["cell"]["seed"] for c in back] == [0, 1, 2]  # in identity order: matched before sensor
    for c, b in zip([cells[1], cells[0]], back):
        for name, (_, get, _) in METRICS.items():
            assert repr(get(b)) == repr(get(c)), name  # the same number to the last bit (nan where absent)
        assert b["native"]["heldout_foot_height_hist"] == c["native"]["heldout_foot_height_hist"]
        assert b["injected"]["score"]["recovery"]["per_joint_error_deg"] == \
            c["injected"]["score"]["recovery"]["per_joint_error_deg"]
        assert b["injected"]["conditioning"].get("eigenvalues_H_data") == \
            c["injected"]["conditioning"].get("eigenvalues_H_data")
        assert b["joint_names"] == c["joint_names"] and b["provenance"] == c["provenance"]
    assert back[2]["error"] == "HoldError: ..." and "native" not in back[2]
    assert "offsets_rad" not in back[0]["injected"] and "paired_delta_deg" not in back[0]  # the raw rest stays out


def test_a_cell_file_replaces_its_row_and_the_other_rows_stay(tmp_path):
    import json as _json

    from legcal_bench.benchmark.leaderboard import read_cells, write_rows

    write_rows(rows_path(tmp_path / "results"), [_full_cell(0), _full_cell(1)])
    rerun = _full_cell(1, paired_delta_rms_deg=0.5)
    d = tmp_path / "results" / "s" / "a2" / "weld" / "interfoot-sensor"
    d.mkdir(parents=True)
    (d / "seed01.json").write_text(_json.dumps(rerun))
    (d / "seed00_x0.5.json").write_text(_json.dumps(_full_cell(0, paired_delta_rms_deg=9.0) | {
        "cell": {**_full_cell(0)["cell"], "scale": 0.5}}))  # another scale: not a leaderboard row
    cells = read_cells(tmp_path / "results")
    assert [(c["cell"]["seed"], c["paired_delta_rms_deg"]) for c in cells] == [(0, 0.0), (1, 0.5)]
    assert "offsets_rad" in cells[1]["injected"]  # the cell file itself, whole


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


def test_the_closed_loop_result_holds_its_summary_and_its_trials_go_beside_it(tmp_path, monkeypatch):
    """What the leaderboard shows of the closed-loop suite (committed) is its summary;
    the per-trial rows are raw output in `closed_loop/trials/` (not committed)."""
    import json as _json

    import legcal_bench.benchmark.closed_loop as cl

    calls = []

    def fake(cfg, executor=None, progress=True):
        calls.append(cfg.offsets)
        return {"config": {"robot": cfg.robot}}, [{"seed": 0, "nominal": {"path": [[0.0, 0.0]]}, "estimate_rad": [0.1]}]

    monkeypatch.setattr(cl, "evaluate", fake)
    files = cl.run_closed_loop_suite(tmp_path, trials=1, robots=["a3"], progress=False)
    assert [f.name for f in files] == ["a3_paper3.json", "a3_random3.json"] and len(calls) == 2
    for f in files:
        assert set(_json.loads(f.read_text())) == {"key", "provenance", "summary"}
        assert _json.loads(cl.trials_path(f).read_text())["trials"] == [{"seed": 0, "estimate_rad": [0.1]}]
    assert sorted(p.name for p in (tmp_path / cl.RESULTS_DIR).glob("*.json")) == [f.name for f in files]
    cl.run_closed_loop_suite(tmp_path, trials=1, robots=["a3"], progress=False)
    assert len(calls) == 2  # kept: the same key
