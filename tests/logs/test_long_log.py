"""The simulated long robot log (issue 39): standing, the four stances, walking and
stepping in place, joined by transitions on one clock. What a detector of static double
support relies on must hold in it: both feet loaded and the feet fixed to each other in
the stances, a foot unloaded and the feet moving when walking or stepping, and neither
static nor double support in the transitions."""

from __future__ import annotations

import numpy as np
import pytest

from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics

pytestmark = pytest.mark.xdist_group("long_log")  # one process simulates the log (tests/conftest.py) for all

STATIC = ("standing", "stance_I", "stance_II", "stance_III", "stance_IV")
ORDER = ["standing", "transition", "stance_I", "transition", "stance_II", "transition", "stance_III", "transition",
         "stance_IV", "transition", "walking", "transition", "stepping", "transition", "standing"]


@pytest.fixture(scope="module")
def log(long_log):
    return long_log


@pytest.fixture(scope="module")
def translations(log):
    """Per frame, the inter-foot translation (m) from forward kinematics of the corrected encoders."""
    kin = LegKinematics(load_robot(log.robot))
    return np.array([kin.inter_foot(q).translation for q in log.q_enc + log.offsets])


def shares(log, a, b):
    """(frames, 2) each foot's share of the vertical load (a loaded foot reads fz < 0)."""
    fz = -log.ft[a:b, :, 2]
    return fz / fz.sum(axis=1, keepdims=True)


def runs(log, label):
    return [(a, b) for lab, a, b in log.segments() if lab == label]


def test_the_labels_cover_one_clock_in_order(log):
    segs = log.segments()
    assert [s[0] for s in segs] == ORDER
    n = log.n_frames
    assert np.allclose(log.time, np.arange(n) / log.rate_hz) and log.rate_hz == 50.0
    assert log.q_enc.shape == (n, 12) and log.joint_names == load_robot("a3").joint_names
    assert log.imu_acc.shape == log.imu_gyro.shape == (n, 3) and log.ft.shape == (n, 2, 6) and log.labels.shape == (n,)
    assert all(np.isfinite(x).all() for x in (log.q_enc, log.imu_acc, log.imu_gyro, log.ft))
    for label, a, b in segs:
        seconds = (b - a) / log.rate_hz
        if label in STATIC:
            assert seconds == pytest.approx(8.0)
        elif label == "transition":
            assert 1.0 <= seconds <= 2.0
        else:  # walking and stepping: 6 s, ending on the last double support
            assert 5.0 <= seconds <= 6.1
    # One set of offsets and encoders everywhere: q_enc + offsets is the true angle, to the noise.
    assert np.abs(log.q_enc + log.offsets - log.truth["q_true"]).max() < 1e-3
    assert np.abs(log.offsets).max() > np.deg2rad(1.0)
    assert log.without_ft().ft is None and log.without_ft().q_enc is log.q_enc


def test_both_feet_carry_the_robot_in_double_support_and_not_when_walking(log):
    for label in STATIC:
        for a, b in runs(log, label):
            assert shares(log, a, b).min() > 0.2, label
            # Static: the gyro reads the posture motion's slow rates, the accelerometer gravity.
            assert np.abs(log.imu_gyro[a:b]).max() < 0.2, label
            assert np.linalg.norm(log.imu_acc[a:b], axis=1).mean() == pytest.approx(9.81, abs=0.05)
    for label in ("walking", "stepping"):
        (a, b), = runs(log, label)
        s = shares(log, a, b)
        # Each foot in turn carries (almost) nothing: a step.
        assert s[:, 0].min() < 0.05 and s[:, 1].min() < 0.05, label
        assert np.abs(log.imu_gyro[a:b]).max() > 0.3, label
    for a, b in runs(log, "transition"):
        mid = slice(a + (b - a) * 3 // 8, a + (b - a) * 5 // 8)
        assert shares(log, mid.start, mid.stop).min() < 0.05  # a foot repositioned, not double support
        assert np.abs(log.imu_gyro[a:b]).max() > 0.05


def test_the_feet_are_fixed_to_each_other_only_in_the_stances(log, translations):
    for label in STATIC:
        for a, b in runs(log, label):
            p = translations[a:b]
            assert np.linalg.norm(p - p.mean(axis=0), axis=1).max() < 0.003 / 2, label  # spread < 3 mm
    (a, b), = runs(log, "walking")
    assert np.ptp(translations[a:b, 0]) > 0.05  # the feet pass each other
    # The stances differ from each other: each transition moves a foot.
    means = [translations[a:b].mean(axis=0) for label in STATIC[1:] for a, b in runs(log, label)]
    assert min(np.linalg.norm(means[i + 1] - means[i]) for i in range(len(means) - 1)) > 0.005


def test_stepping_lifts_the_feet_in_place(log, translations):
    (a, b), = runs(log, "stepping")
    assert np.ptp(translations[a:b, 2]) > 0.02  # a foot lifts above the other (plan: 32 mm)
    period = int(round(0.75 * log.rate_hz))  # about two steps

    def travel(a, b):
        p = log.truth["pelvis_pose"][a:b, :2]
        return float(np.linalg.norm(p[-period:].mean(axis=0) - p[:period].mean(axis=0)))

    walked = travel(*runs(log, "walking")[0])
    assert walked > 0.5  # about 0.75 m in 6 s
    assert travel(a, b) < 0.1  # about 0.05 m, a slow sideways drift
