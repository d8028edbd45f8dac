"""The robot variations third parties build (issue #37: mirrored pitch servos, hips
canted 45 degrees, a kid-size robot with 0.3 m legs, legs of five joints), each through
its leg map alone:
collected at zero noise with the paper's offsets (the same physical pattern on each),
the default calibration recovers them to 1e-9 deg with no data-check warning."""

from __future__ import annotations

import numpy as np
import pytest

from legcal_bench.calibrators.base import calibrate_training
from legcal_bench.calibrators.registry import get_calibrator
from legcal_bench.data.recording import load_session
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import VARIATIONS
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.sim.offsets import resolve_offsets


def test_the_variations_are_what_they_say(tmp_path):
    kin = {d.name: LegKinematics(load_robot(str(write_robot(d, tmp_path)))) for d in VARIATIONS}
    assert set(kin) == {"a3_mirrored_pitch", "a3_canted_hips", "kid_size", "five_joint"}
    assert kin["five_joint"].legmap.absent_roles == ("ankle_roll",) and kin["five_joint"].n_joints == 10
    assert kin["kid_size"].dims.leg_length == pytest.approx(0.30, abs=0.005)
    for name in ("a3_mirrored_pitch", "kid_size"):
        assert (kin[name].physical_signs() < 0).sum() == 3  # the right leg's hip pitch, knee, ankle pitch
    assert np.degrees(kin["a3_canted_hips"].role_axes()[1]).max() == pytest.approx(45.0)


@pytest.mark.parametrize("design", VARIATIONS, ids=lambda d: d.name)
def test_zero_noise_kinematic_recovery_on_each_variation(design, tmp_path):
    robot = str(write_robot(design, tmp_path / "robot"))
    lm = load_robot(robot)
    collect(CollectConfig(robot=robot, mode="kinematic", sensors="zero", offsets="paper"), tmp_path / "data",
            progress=False)
    res = calibrate_training(get_calibrator("interfoot"), lm, load_session(tmp_path / "data", lm.joint_names))
    error = res.offsets_vector(lm.joint_names) - resolve_offsets("paper", lm)
    assert np.degrees(np.abs(error)).max() <= 1e-9
    assert res.warnings == []


def test_placement_jitter_is_written_for_the_a3_like_leg_and_scales_below_it(tmp_path):
    from legcal_bench.protocol.stances import JITTER_REFERENCE_LEG_M, jitter_scale

    dims = {r: LegKinematics(load_robot(r)).dims for r in ("a3", "a2", "pair_ryp", "pair_pry")}
    assert JITTER_REFERENCE_LEG_M == dims["a3"].leg_length
    assert all(jitter_scale(d) == 1.0 for d in dims.values())  # the built-ins' placements as they were
    kid = LegKinematics(load_robot(str(write_robot(VARIATIONS[2], tmp_path)))).dims
    assert jitter_scale(kid) == pytest.approx(kid.leg_length / dims["a3"].leg_length) and jitter_scale(kid) < 0.33

