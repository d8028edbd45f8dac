"""contact-table's cases and summary (no simulation): a case's sensors come from its
name, and the summary's chi2/dof and true departure are the stances' statistics."""

import numpy as np
import pytest

from legcal_bench.reports.contact_table import KNOWN_CASES, case_sensors, case_spec, markdown, summarize


def test_a_realistic_case_is_its_base_case_with_realistic_sensors():
    assert "contact realistic" in KNOWN_CASES and "wedge 0.05 realistic" in KNOWN_CASES
    assert case_sensors("contact realistic") == "realistic" and case_sensors("contact") == "calibrated-imu"
    for seed in range(4):
        assert case_spec("wedge 0.05 realistic", seed) == case_spec("wedge 0.05", seed)
    assert case_spec("contact realistic", 0)[0] == "contact" and case_spec("clean realistic", 0)[0] == "weld"


def _row(chi2s, truths):
    stances = [{"recording": f"stance_{i}", "flagged": False, "sole": "unclear", "chi2": c, "dof": 3,
                "truth": t, "tilt_error_deg": 0.0, "height_error_mm": 0.0} for i, (c, t) in enumerate(zip(chi2s, truths))]
    return {"robot": "r", "case": "contact realistic", "seed": 0, "mode": "contact", "wedge_stance": None,
            "wedge_side": None, "truly_off": [], "flagged": [], "stances": stances,
            "offsets_rms_deg": {"flag": 0.1, "drop": 0.1}}


def test_the_summary_reads_the_tests_calibration_and_the_truths_departure():
    t = np.deg2rad(0.002)
    rows = [_row([3.0, 6.0, 30.0], [[t, 0.0, 1e-5], [0.0, t, -1e-5], [t, t, 0.0]])]
    s = summarize(rows)[0]
    assert s["median_chi2_per_dof"] == pytest.approx(2.0)  # median of 1, 2, 10
    # RMS per tilt axis over the stances: sqrt(mean(|tilt|^2 / 2)) = sqrt((1 + 1 + 2) / 6) * 0.002 deg.
    assert s["true_tilt_rms_deg"] == pytest.approx(np.sqrt(4 / 6) * 0.002, rel=1e-9)
    assert s["true_height_rms_mm"] == pytest.approx(1e3 * np.sqrt(2e-10 / 3), rel=1e-9)
    assert "| 2.00 | 0.0016, 0.008 |" in markdown({"summary": [s]}, "cmd", "code")


def test_the_cases_name_their_floor_and_offsets_and_the_rates_count_sets():
    # Issue #60's grid: kinematic and random:3 cases; false alarms counted per set (a
    # stance flagged the truth does not put off one plane), wedges caught per set.
    from legcal_bench.reports.contact_table import case_offsets, rates_lines

    assert case_spec("kinematic random:3 realistic", 3)[0] == "kinematic"
    assert case_offsets("kinematic random:3 realistic", 3) == "random:3@3" and case_offsets("clean", 3) == "paper"
    assert case_spec("wedge 0.3 random:3", 1)[1] == ("shim:side=right,roll=0.3,stance=II",)
    clean = _row([3.0, 3.0], [[0.0, 0.0, 0.0]] * 2)
    alarmed = dict(clean, seed=1, flagged=["stance_0"])
    wedge = dict(clean, case="wedge 0.05 realistic", wedge_stance="stance_1", wedge_side="left",
                 truly_off=["stance_1"], flagged=["stance_1"])
    missed = dict(wedge, seed=1, flagged=[])
    s = summarize([clean, alarmed, wedge, missed])
    assert (s[0]["sets_alarmed"], s[0]["sets"]) == (1, 2) and s[1]["wedge_caught"] == 1
    text = "\n".join(rates_lines(s))
    assert "alarmed (a stance flagged the truth does not put off one plane): 1/2 (50.0%): contact 1/2" in text
    assert "0.05 deg wedges caught: 1/2 (50.0%)" in text
