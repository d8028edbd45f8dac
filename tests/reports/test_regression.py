"""The regression fixture: today's code reproduces the numbers the fixture pins
(A2-like and A3-like standard-suite cells at seed 0 for every calibrator variant, and
the zero-noise rows of `reproduce`) to 1e-5 relative (the alternating solver's rows 1e-4: what
the same code moves by from one CPU to another, `regression.REL_TOL`) or 1e-9 deg absolute."""

import copy
from pathlib import Path

from legcal_bench.reports import regression

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "regression.json"


def test_the_code_reproduces_the_regression_fixture(tmp_path, pool_workers):
    expected = regression.load_fixture(FIXTURE)
    actual = regression.compute(tmp_path, workers=pool_workers)  # 2, or 1 beside another test process
    assert len(actual["cells"]) == len(expected["cells"]) == 12
    assert len(actual["reproduce_zero_noise"]) == len(expected["reproduce_zero_noise"]) == 10
    problems = regression.compare(expected, actual)
    assert not problems, "\n".join(problems)


def test_compare_flags_a_moved_value_and_spares_a_tiny_one():
    expected = regression.load_fixture(FIXTURE)
    moved = copy.deepcopy(expected)
    cell = moved["cells"][0]["values"]
    cell["injected.offsets_rad"][3] *= 1 + 3e-5
    cell["native.recovery.rms_error_deg"] *= 1 + 3e-6
    zero = moved["reproduce_zero_noise"][0]["values"]
    zero["rms_error_deg"] += 5e-10  # below the 1e-9 deg floor
    problems = regression.compare(expected, moved)
    assert len(problems) == 1 and "injected.offsets_rad[3]" in problems[0]
    zero["rms_error_deg"] += 2e-9
    assert len(regression.compare(expected, moved)) == 2
