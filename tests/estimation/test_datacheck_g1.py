"""The data checks on the 12-joint G1 (test_datacheck.py has the A3-like robot's and
the others'): every planted defect named by both calibrators, clean recordings without a
warning. A module and an xdist group of its own, so its cases run beside the A3-like
robot's under pytest-xdist, its recordings collected once. The defects at the Yamane
calibrator's estimate are `slow` (`make test-slow`): the checks are the same function at
another estimate, and both calibrators run every defect on the A3-like robot in the test
command. A reversed knee and the IMU's axis defects are `slow` on the G1
(`defects_on_another_robot`)."""

from __future__ import annotations

import pytest

from tests.estimation.test_datacheck import (G1, check_clean, check_defect, defects_on_another_robot,  # noqa: F401
                                             sessions)

pytestmark = pytest.mark.xdist_group("datacheck_g1")


@pytest.mark.parametrize("calibrator", ["interfoot", pytest.param("yamane", marks=pytest.mark.slow)])
# The G1's kinematics (a 6-joint leg as the A3-like robot's) do not bear on a reversed knee
# or the IMU's axes (mounted unrotated on the pelvis, as the A3-like robot's): those are
# `slow` here.
@pytest.mark.parametrize("defect, edit, expected", defects_on_another_robot(("knee reversed", "IMU x<->z", "IMU x<->y",
                                                                             "IMU x reversed")))
def test_each_defect_is_named_by_both_calibrators_on_the_g1(sessions, calibrator, defect, edit, expected):
    check_defect(sessions, G1, calibrator, edit, expected)


@pytest.mark.parametrize("calibrator", ["interfoot", "yamane"])
def test_clean_g1_recordings_get_no_data_warning(sessions, calibrator):
    check_clean(sessions, G1, {}, calibrator)
