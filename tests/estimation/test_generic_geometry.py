"""The generic geometry (`LegGeometry`) reads an edited robot as its own parameters
(`LegGeometry.values`): at those values, its chain is the edited robot's."""

import copy
from dataclasses import replace

import numpy as np
import pytest

from legcal_bench.estimation.modelgap.effects import EffectModel
from legcal_bench.estimation.modelgap.signatures import LegGeometry, generic_effects
from legcal_bench.geometry.lie import Ad, Exp
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.sim.effects import build_reality
from legcal_bench.sim.sensors import sim_sensors

EDITS = ["link_twist:link=right_shank,deg=1", "mount_offset:side=left,axis=y,mm=4",
         "joint_offset:joint=left_ankle_roll,axis=z,mm=1.5", "joint_axis:joint=left_knee,about=x,deg=0.5",
         "hip_axis:joint=right_hip_pitch,about=z,deg=0.5"]


@pytest.fixture(scope="module")
def a3():
    lm = load_robot("a3")
    return lm, LegKinematics(lm)


def _read(kin, edited):
    """The generic geometry's model on `kin` and its parameters (beyond the offsets) at `edited`."""
    model = EffectModel(kin, generic_effects())
    n_q = model.n_offsets
    return model, model.vector({"offsets": np.zeros(n_q), **{e.name: e.values(kin, edited) for e in model.effects
                                                             if isinstance(e, LegGeometry)}})[n_q:]


def _postures(kin, n=40):
    return 0.5 * np.random.default_rng(0).uniform(kin.q_lower, kin.q_upper, (n, kin.n_joints))


def _poe_soles(poe, Q):
    """Sole poses of one leg by its product of exponentials, written out here."""
    out = []
    for q in Q:
        T = np.eye(4)
        for k, col in enumerate(poe.cols):
            T = T @ poe.M[k] @ Exp(poe.S[k] * q[col])
        out.append(T @ poe.M_sole)
    return np.array(out)


@pytest.mark.parametrize("spec", EDITS)
def test_the_generic_geometry_at_an_edits_values_is_the_edited_robot(a3, tmp_path, spec):
    # Sole poses over random postures: a moved or turned link is its place's twist (the
    # log of its constant transform's change), an axis turned in its body a tilt about
    # its anchor; both exact. The other leg reads nothing.
    lm, kin = a3
    edited = LegKinematics(build_reality(lm, lm, [spec], sim_sensors("zero"), tmp_path).sim_legmap)
    model, p = _read(kin, edited)
    Q = _postures(kin)
    legs = model.chain.legs(Q, p)
    for side, nominal, real in zip(("left", "right"), kin.sole_poses_batch(Q), edited.sole_poses_batch(Q)):
        err, change = np.abs(legs[side][0] - real).max(), np.abs(nominal - real).max()
        assert change == 0 or change > 1e-3, (side, change)
        assert err < 1e-12, (side, err, change)


def test_a_turned_mount_and_an_axis_tilted_off_its_frame_are_read_exactly(a3):
    # Chains changed here (their sole poses by a product of exponentials written out in
    # the test): the mount turned and moved (the A3-like's mounts are unrotated, so a
    # twist on the wrong side of M_0 would show), and a knee whose frame sits off its
    # axis (the same chain re-expressed 2 cm away, so the axis's twist has a moment)
    # with the axis tilted about its anchor.
    lm, kin = a3
    side = "left"
    poe = kin.poe[side]
    M = poe.M.copy()
    M[0] = M[0] @ Exp(np.array([0.002, -0.001, 0.003, 0.01, -0.02, 0.015]))
    turned = copy.copy(kin)
    turned.poe = {**kin.poe, side: replace(poe, M=M)}
    model, p = _read(kin, turned)
    Q = _postures(kin)
    assert np.abs(model.chain.legs(Q, p)[side][0] - _poe_soles(turned.poe[side], Q)).max() < 1e-12

    k = [lm.joint_roles[int(c)] for c in poe.cols].index("knee")
    shift = np.eye(4)
    shift[:3, 3] = [0.0, 0.02, 0.01]
    M, S = poe.M.copy(), poe.S.copy()
    M[k], S[k] = M[k] @ shift, Ad(np.linalg.inv(shift)) @ S[k]
    if k + 1 < len(M):
        M[k + 1] = np.linalg.inv(shift) @ M[k + 1]
    off = copy.copy(kin)
    off.poe = {**kin.poe, side: replace(poe, M=M, S=S)}
    assert np.abs(_poe_soles(off.poe[side], Q) - _poe_soles(poe, Q)).max() < 1e-12  # the same chain
    assert np.abs(S[k][:3]).max() > 1e-3  # a moment
    w = S[k][3:]
    anchor = np.cross(w, S[k][:3])
    r = np.deg2rad(0.5) * np.cross(w, [1.0, 0.0, 0.0]) / np.linalg.norm(np.cross(w, [1.0, 0.0, 0.0]))
    tilted = copy.copy(off)
    tilted.poe = {**off.poe, side: replace(off.poe[side], S=S.copy())}
    tilted.poe[side].S[k] = Ad(Exp(np.concatenate([np.cross(anchor, r), r]))) @ S[k]
    model, p = _read(off, tilted)
    assert np.abs(model.chain.legs(Q, p)[side][0] - _poe_soles(tilted.poe[side], Q)).max() < 1e-12
    # The axis moved off its anchor: no tilt says that, and it is refused.
    moved = copy.copy(off)
    moved.poe = {**off.poe, side: replace(off.poe[side], S=S.copy())}
    moved.poe[side].S[k][:3] += 0.001 * np.cross(w, [0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match=f"{side} knee: its motion changed"):
        _read(off, moved)
