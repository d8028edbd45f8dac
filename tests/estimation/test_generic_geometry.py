"""The generic geometry (`LegGeometry`) reads an edited robot as its own parameters
(`LegGeometry.values`): at those values, its chain is the edited robot's."""

import numpy as np
import pytest

from legcal_bench.estimation.modelgap.effects import EffectModel
from legcal_bench.estimation.modelgap.signatures import LegGeometry, generic_effects
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.sim.effects import build_reality
from legcal_bench.sim.sensors import sim_sensors

PLACES = ["link_twist:link=right_shank,deg=1", "mount_offset:side=left,axis=y,mm=4",
          "joint_offset:joint=left_ankle_roll,axis=z,mm=1.5"]
TILTS = ["joint_axis:joint=left_knee,about=x,deg=0.5", "hip_axis:joint=right_hip_pitch,about=z,deg=0.5"]


@pytest.fixture(scope="module")
def a3():
    lm = load_robot("a3")
    return lm, LegKinematics(lm)


@pytest.mark.parametrize("spec", PLACES + TILTS)
def test_the_generic_geometry_at_an_edits_values_is_the_edited_robot(a3, tmp_path, spec):
    # Sole poses over random postures: a change of a link's constant transform is its
    # place's twist exactly (the log of the change); an axis turned in its body is a tilt
    # to first order (0.5 deg: second-order terms ~1e-5 of the change).
    lm, kin = a3
    edited = LegKinematics(build_reality(lm, lm, [spec], sim_sensors("zero"), tmp_path).sim_legmap)
    model = EffectModel(kin, generic_effects())
    n_q = model.n_offsets
    p = model.vector({"offsets": np.zeros(n_q), **{e.name: e.values(kin, edited) for e in model.effects
                                                   if isinstance(e, LegGeometry)}})[n_q:]
    Q = 0.5 * np.random.default_rng(0).uniform(kin.q_lower, kin.q_upper, (40, kin.n_joints))
    legs = model.chain.legs(Q, p)
    for side, nominal, real in zip(("left", "right"), kin.sole_poses_batch(Q), edited.sole_poses_batch(Q)):
        err, change = np.abs(legs[side][0] - real).max(), np.abs(nominal - real).max()
        if change == 0:
            assert err < 1e-14, (side, err)  # the other leg: nothing moved, nothing read
        else:
            assert change > 1e-3 and err < (1e-12 if spec in PLACES else 1e-4 * change), (side, err, change)
