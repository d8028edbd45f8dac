"""The closed-loop evaluation (issue #15): one short trial end to end on the G1."""

from __future__ import annotations

import pytest

from tests.conftest import G1_LEGMAP
from tests.envs.test_walking import G1_POLICY, needs_g1

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


@needs_g1
def test_one_trial_calibrates_then_walks_four_conditions(tmp_path, capsys):
    from legcal_bench.cli import main

    assert main(["walk-eval", "--robot", str(G1_LEGMAP), "--policy", str(G1_POLICY), "--offsets", "paper@3",
                 "--trials", "1", "--seconds", "4", "--workers", "1", "--out", str(tmp_path), "--quiet"]) == 0
    import json

    d = json.loads((tmp_path / "report.json").read_text())
    s, [t] = d["summaries"][0], d["trials"][0]
    c = s["conditions"]
    assert all(c[k]["upright"] == 1 for k in ("nominal", "uncorrected", "corrected", "oracle"))
    unc, cor, ora = (c[k]["pelvis_rms_mm"]["mean"] for k in ("uncorrected", "corrected", "oracle"))
    # 3 deg on every joint moves the walk by decimetres in 4 s; the static calibration
    # (0.01-0.02 deg) leaves millimetres; the true correction repeats the nominal walk.
    assert unc > 300 and cor < 0.05 * unc and ora < 1.0
    assert t["recovery_rms_deg"] < 0.05 and t["static_s"] > 0 and s["config"]["options"] == {"setting": "sensor"}
    assert s["nominal_spread"]["pelvis_rms_mm"]["n"] == 1
    assert (tmp_path / "paths_paper_3.png").stat().st_size > 10_000
    assert "| corrected | 1/1 |" in (tmp_path / "report.md").read_text()
