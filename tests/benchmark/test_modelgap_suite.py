"""The model-gap suite's cases (issue #17): the near-threshold band and the several-
effects case draw valid, seeded specs; the summary scores a selection of an effect that
was not injected as a confident wrong attribution."""

import pytest

from legcal_bench.benchmark.modelgap import (LIBRARY, MULTI_COUNT, NEAR_SCALES, jobs, library_spec, markdown,
                                             multi_effects, multi_specs, near_scale, summarize)
from legcal_bench.errors import ConfigError
from legcal_bench.sim.effects import parse_effect


def test_cases_draw_valid_seeded_specs():
    for seed in range(12):
        s = near_scale(seed)
        assert NEAR_SCALES[0] <= s <= NEAR_SCALES[1] and s == near_scale(seed)
        picked = multi_effects(seed)
        assert len(set(picked)) == MULTI_COUNT and set(picked) <= set(LIBRARY)
        for spec in multi_specs(seed) + tuple(library_spec(e, seed, s) for e in LIBRARY):
            parse_effect(spec)  # raises on a malformed spec
    # The scale multiplies the size (compliance: divides the stiffness).
    full, tenth = library_spec("imu_tilt", 4), library_spec("imu_tilt", 4, 0.1)
    assert float(tenth.split("=")[1]) == pytest.approx(0.1 * float(full.split("=")[1]), rel=1e-3)
    k_full = float(library_spec("compliance", 4).split("k=")[1])
    assert float(library_spec("compliance", 4, 0.5).split("k=")[1]) == pytest.approx(2 * k_full, abs=1)


def test_every_case_records_the_stances_asked_and_each_kind_its_seeds():
    todo = jobs(["a3"], 20, 4, ["a3"], 3, 2, 1, stances=["I", "II", "III", "IV", "tall"])
    assert {j[4] for j in todo} == {("I", "II", "III", "IV", "tall")}
    kinds = [j[1] for j in todo]
    assert kinds.count("library") == 20 * len(LIBRARY) and kinds.count("clean") == 4
    assert kinds.count("near") == 2 * len(LIBRARY) and kinds.count("multi") == 1 and kinds.count("outside") == 9
    assert {j[4] for j in jobs(["a3"], 1, 1, [], 0)} == {None}


def test_cases_run_only_the_groups_asked_each_with_its_companions():
    todo = jobs(["a3"], 20, 4, ["a3"], 3, 2, 1, cases=("clean", "library"))
    kinds = [j[1] for j in todo]
    assert set(kinds) == {"clean", "clean_kinematic", "library"} and kinds.count("library") == 20 * len(LIBRARY)
    assert {j[1] for j in jobs(["a3"], 1, 1, ["a3"], 1, cases=("outside",))} == {"outside", "reference"}
    with pytest.raises(ConfigError, match="--cases: librari unknown.*clean, library, near, multi, outside"):
        jobs(["a3"], 1, 1, [], 0, cases=("librari",))
    # Without the clean cases there is no floor: the table says so instead of printing nan.
    md = markdown({"summary": summarize([_row("library", "imu_tilt", ["imu_tilt"]),
                                         _row("multi", "imu_tilt+leg_length+hip_axis", ["imu_tilt"])])}, "m", "c")
    assert "nan" not in md
    assert "| r | imu_tilt | 1 | 1/1 | 1/1 | 0 | 0.1000 | 0.0200 | – | – | selected 1 |" in md


def _row(kind, name, selected, verdict="selected", seed=0, **kw):
    return {"robot": "r", "kind": kind, "name": name, "selected": selected, "ambiguous": [], "verdict": verdict,
            "seed": seed, "p_value": 0.5, "z": kw.pop("z", 0.0), "scale": kw.pop("scale", None),
            "offsets_rms_deg": {"before": 0.1, "after": 0.02}, "confounded": [], **kw}


def test_summary_scores_the_several_effects_and_near_cases():
    rows = [_row("clean", None, [], "explained", at_truth={"training": 1.0}),
            _row("multi", "imu_tilt+leg_length+hip_axis", ["imu_tilt", "leg_length"]),
            _row("multi", "imu_tilt+leg_length+hip_axis", ["compliance"], seed=1),
            _row("near", "imu_tilt", ["imu_tilt"], z=5.0, scale=0.1),
            _row("near", "imu_tilt", [], "explained", z=1.0, scale=0.03),
            _row("near", "imu_tilt", ["leg_length"], z=12.0, scale=0.2)]
    by = {s["case"]: s for s in summarize(rows)}
    multi = next(v for k, v in by.items() if k.startswith("multi"))
    assert (multi["effects_selected_right"], multi["wrong_confident"], multi["effects_injected"]) == (2, 1, 6)
    near = by["near: imu_tilt"]
    assert (near["in_band"], near["correct_in_band"], near["correct"], near["wrong_confident"]) == (1, 1, 1, 1)
    assert by["clean"]["detected"] == 0 and by["clean"]["chi2_per_dof_at_truth"]["training"]["mean"] == 1.0
    # Nothing kept (a poor fit): the recommended offsets are the offsets-only ones.
    poor = summarize([_row("library", "compliance", [], "unexplained")])
    assert poor[0]["offsets_rms_deg_after"] == 0.1


def test_the_leaderboard_shows_the_suite_from_its_rows(tmp_path):
    import json

    from legcal_bench.benchmark.leaderboard import generate

    (tmp_path / "results").mkdir()
    (tmp_path / "modelgap").mkdir()
    rows = [_row("clean", None, [], "explained", at_truth={"training": 1.0}),
            _row("library", "imu_tilt", ["leg_length"])]
    (tmp_path / "modelgap" / "modelgap.json").write_text(json.dumps(
        {"rows": rows, "made_by": "legcal-bench bench --suite modelgap", "code": {"commit": "abc", "dirty": False}}))
    text = generate(tmp_path)
    assert "[modelgap/modelgap.md](modelgap/modelgap.md)" in text
    line = next(ln for ln in text.splitlines() if ln.startswith("| r | imu_tilt |"))
    assert "| 0/1 | 1 |" in line  # attributed wrongly, with confidence: counted as such
