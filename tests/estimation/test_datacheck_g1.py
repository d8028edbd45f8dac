"""The data checks on the 12-joint G1 (test_datacheck.py has the A3-like robot's and
the others'): every planted defect named by both calibrators, clean recordings without a
warning. A module and an xdist group of its own, so its cases run beside the A3-like
robot's under pytest-xdist, its recordings collected once. The defects at the Yamane
calibrator's estimate are `slow` (`make test-slow`): the checks are the same function at
another estimate, and both calibrators run every defect on the A3-like robot in the test
command."""

from __future__ import annotations

import pytest

from tests.estimation.test_datacheck import DEFECTS, G1, check_clean, check_defect, sessions  # noqa: F401 (fixture)

pytestmark = pytest.mark.xdist_group("datacheck_g1")


@pytest.mark.parametrize("calibrator", ["interfoot", pytest.param("yamane", marks=pytest.mark.slow)])
@pytest.mark.parametrize("defect, edit, expected", DEFECTS, ids=[d[0] for d in DEFECTS])
def test_each_defect_is_named_by_both_calibrators_on_the_g1(sessions, calibrator, defect, edit, expected):
    check_defect(sessions, G1, calibrator, edit, expected)


@pytest.mark.parametrize("calibrator", ["interfoot", "yamane"])
def test_clean_g1_recordings_get_no_data_warning(sessions, calibrator):
    check_clean(sessions, G1, {}, calibrator)
