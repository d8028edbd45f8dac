"""The optional load-varied protocol (issue #16): stances whose servo targets are solved
for soles displaced from where they stand, so the legs push against the floor; the F/T
sensors see the loads vary apart from the posture, which parts a knee's compliance from
its encoder scale."""

import numpy as np
import pytest

from legcal_bench.data.recording import load_session
from legcal_bench.errors import ConfigError
from legcal_bench.estimation.modelgap.effects import joint_loads
from legcal_bench.estimation.imu.levelling import up_in_base
from legcal_bench.geometry.lie import Log, inverse
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.protocol.stances import (LOAD_STANCES, PUSH_PERIOD_S, STANCES, commanded_soles, load_protocol,
                                           place, write_protocol)
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics

RATE = 50.0


def test_the_commanded_soles_scissor_by_the_push_and_start_at_rest():
    kin = LegKinematics(load_robot("a3"))
    L = kin.dims.leg_length
    for st in LOAD_STANCES.values():
        pl = place(st, kin.dims)
        n = int(3 * PUSH_PERIOD_S * RATE)
        left, right = commanded_soles(pl, kin.dims, n, RATE, np.random.default_rng(0))
        np.testing.assert_allclose(left[0], pl.left.homogeneous, atol=1e-12)  # faded in from rest
        rel = Log(inverse(np.broadcast_to(pl.left.homogeneous, left.shape)) @ left)  # left sole's own frame
        rer = Log(inverse(np.broadcast_to(pl.right.homogeneous, right.shape)) @ right)
        fx, fy, fz, pitch = st.push
        # Half the push on each sole, opposite ways (lateral and vertical: both out, one down one up).
        assert np.abs(left[:, 0, 3] - pl.left.translation[0]).max() == pytest.approx(0.5 * fx * L, rel=1e-3, abs=1e-9)
        assert np.abs(left[:, 1, 3] - pl.left.translation[1]).max() == pytest.approx(0.5 * fy * L, rel=1e-3, abs=1e-9)
        assert np.abs(left[:, 2, 3]).max() == pytest.approx(0.5 * fz * L, rel=1e-3, abs=1e-9)
        np.testing.assert_allclose(left[:, 2, 3], -right[:, 2, 3], atol=1e-12)
        np.testing.assert_allclose(left[:, 1, 3] - pl.left.translation[1], -(right[:, 1, 3] - pl.right.translation[1]),
                                   atol=1e-12)
        assert np.abs(rel[:, 4]).max() == pytest.approx(0.5 * pitch, rel=1e-3, abs=1e-9)  # about the sole's y
        np.testing.assert_allclose(rel[:, 4], -rer[:, 4], atol=1e-12)


def test_a_protocol_file_carries_the_push_and_names_a_bad_one(tmp_path):
    path = write_protocol(tmp_path / "p.yaml", [STANCES["I"].__class__("mine", "x", push=(0.0, 0.02, 0.0, 0.05))])
    assert load_protocol(path)["mine"].push == (0.0, 0.02, 0.0, 0.05)
    text = path.read_text().replace("- 0.02", "- 0.5")
    path.write_text(text)
    with pytest.raises(ConfigError, match="field 'push' must be 4 numbers in"):
        load_protocol(path)


def _set(tmp_path, stances, robot="a3"):
    out = tmp_path / "_".join(stances)
    collect(CollectConfig(robot=robot, mode="weld", sensors="calibrated-imu", seed=0, heldout=0, stances=stances),
            out, progress=False)
    legmap = load_robot(robot)
    return legmap, load_session(out, robot=legmap)


def test_the_pushing_stances_vary_the_loads_and_part_knee_compliance_from_encoder_scale(tmp_path):
    from legcal_bench.estimation.problem.fit import fit_model, start_confounds
    from legcal_bench.estimation.problem.stance import prepare_sensor

    def knee_cosine(stances):
        legmap, recs = _set(tmp_path, stances)
        prep = prepare_sensor(legmap, recs)
        dq0 = fit_model(prep).x
        rep = start_confounds(prep, ("compliance", "encoder_scale"), dq0)
        p = rep["effects"]["compliance"]["parameters"]["compliance.left_knee"]["closest_beyond_offsets"]
        return p, legmap, recs

    base, _, _ = knee_cosine(("I", "II", "III", "IV"))
    pushed, legmap, recs = knee_cosine(("I", "II", "III", "IV", "push", "press"))
    assert base["parameter"] == "encoder_scale.left_knee"  # the close pair, as the issue measured
    assert base["cosine"] > 0.65
    assert pushed["cosine"] < base["cosine"] - 0.1, (base, pushed)
    # The loads behind it: the push moves the left hip roll's, the press its hip and ankle pitch's,
    # far beyond what stance I's own posture motion does (ankle F/T through the leg).
    kin = LegKinematics(legmap)
    std = {r.stance: joint_loads(kin, r.q_enc, r.ft, up_in_base(r.imu_acc, kin.R_BI)).std(axis=0) for r in recs
           if r.kind == "stance"}
    roles = {n.replace("left_", "").replace("_joint", ""): i for i, n in enumerate(legmap.joint_names[:6])}
    assert std["push"][roles["hip_roll"]] > 3 * std["I"][roles["hip_roll"]]
    assert std["press"][roles["ankle_pitch"]] > 3 * std["I"][roles["ankle_pitch"]]
