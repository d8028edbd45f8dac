"""Model-gap effects in the assembled problem (issue #16): each library effect's
Jacobian (inter-foot and flat-ground rows, every block) against central differences at
non-zero parameters, the extended kinematics against the plain path at zero, and the
registry and its errors; on legs of six joints and of five (no ankle roll)."""

import numpy as np
import pytest

from legcal_bench.errors import CalibrationError
from legcal_bench.estimation.modelgap.effects import EffectModel, EffectSegment, SegmentData, load_effects, registry
from legcal_bench.estimation.imu.levelling import levelling_rotations, up_in_base
from legcal_bench.estimation.problem.problem import Block, Problem
from legcal_bench.estimation.problem.terms import OFFSETS, FlatGroundTerm, InterFootTerm, SegmentKinematics
from legcal_bench.robots import load_robot
from legcal_bench.robots.build import write_robot
from legcal_bench.robots.design import VARIATIONS
from legcal_bench.robots.kinematics import LegKinematics

LIBRARY = ("leg_length", "encoder_scale", "compliance", "imu_tilt", "hip_axis")


@pytest.fixture(scope="module", params=["a3", "a2", "five_joint"])
def data(request, tmp_path_factory):
    robot = request.param
    if robot not in ("a3", "a2"):
        design = next(d for d in VARIATIONS if d.name == robot)
        robot = str(write_robot(design, tmp_path_factory.mktemp(robot)))
    kin = LegKinematics(load_robot(robot))
    rng = np.random.default_rng(5)
    q = kin.q_init() + rng.normal(0, 0.08, (15, kin.legmap.n_joints))
    acc = np.array([0.2, -0.3, 9.8]) + rng.normal(0, 0.2, (15, 3))
    ft = np.concatenate([rng.normal(0, 20, (15, 2, 3)) + [0, 0, -250], rng.normal(0, 5, (15, 2, 3))], axis=2)
    up = up_in_base(acc, kin.R_BI)
    return kin, SegmentData(q, ft, up), up


def _problem(kin, seg, up, effects):
    model = EffectModel(kin, load_effects(effects))
    es = EffectSegment(model, seg)
    feet = InterFootTerm("feet", es, np.arange(1, 7.0), "projected")
    flat = FlatGroundTerm("flat", es, up, levelling_rotations(up), np.arange(1, 6.0) * 100)
    blocks = [Block(OFFSETS, model.n_offsets)] + [Block(n, k) for n, k in model.blocks]
    return Problem(blocks, [feet, flat]), model


def test_the_library_is_registered_as_plug_ins():
    assert set(LIBRARY) <= set(registry())
    with pytest.raises(CalibrationError, match="'shank': unknown effect; installed: compliance"):
        load_effects(["shank"])


@pytest.mark.parametrize("effect", LIBRARY)
def test_each_effect_jacobian_matches_central_differences(data, effect):
    kin, seg, up = data
    problem, model = _problem(kin, seg, up, [effect])
    n_q = model.n_offsets
    rng = np.random.default_rng(1)
    x = np.r_[rng.normal(0, 0.02, n_q), rng.normal(0, 1, model.n - n_q) * _scale(effect)]
    _, J = problem.evaluate(x)
    h = 1e-6 * np.r_[np.ones(n_q), np.full(model.n - n_q, _scale(effect))]
    fd = np.empty_like(J)
    for j in range(model.n):
        e = np.zeros(model.n)
        e[j] = h[j]
        fd[:, j] = (problem.evaluate(x + e)[0] - problem.evaluate(x - e)[0]) / (2 * h[j])
    scale = np.abs(fd).max(axis=0) + 1e-12
    assert np.abs(J - fd).max(axis=0).max() < 1e-6 * max(1.0, scale.max())
    assert (np.abs(J - fd).max(axis=0) / scale).max() < 1e-5  # every column, relative to its size


def _scale(effect):
    return {"leg_length": 2e-3, "encoder_scale": 5e-3, "compliance": 1e-4, "imu_tilt": 1e-2, "hip_axis": 1e-2}[effect]


def test_at_zero_parameters_the_extended_kinematics_is_the_plain_one(data):
    kin, seg, up = data
    problem, model = _problem(kin, seg, up, list(LIBRARY))
    n_q = model.n_offsets
    x = np.r_[np.full(n_q, 0.01), np.zeros(model.n - n_q)]
    plain = SegmentKinematics(kin, seg.q_enc)
    ref = Problem([Block(OFFSETS, n_q)], [InterFootTerm("feet", plain, np.arange(1, 7.0), "projected"),
                                        FlatGroundTerm("flat", plain, up, levelling_rotations(up),
                                                       np.arange(1, 6.0) * 100)])
    r0, J0 = ref.evaluate(x[:n_q])
    r1, J1 = problem.evaluate(x)
    assert np.abs(r1 - r0).max() < 1e-12 and np.abs(J1[:, :n_q] - J0).max() < 1e-9


def test_an_effect_reads_its_frames_timestamps(tmp_path):
    """Issue #61: an effect of motion or time needs the frames' times, in order; the
    frames the selection kept are not always consecutive samples, so the index is no clock."""
    import numpy as np

    from legcal_bench.data.recording import load_session
    from legcal_bench.estimation.modelgap.effects import Effect, EffectModel
    from legcal_bench.estimation.problem.stance import StanceProblem, prepare_sensor
    from legcal_bench.protocol.collect import CollectConfig, collect
    from legcal_bench.robots import load_robot

    seen = []

    class Clock(Effect):
        name = "clock"

        def parameters(self, kin):
            return [("rate", "rad/s")]

        def joint_map(self, kin, seg):
            seen.append(seg.time)
            return np.zeros((len(seg.q_enc), kin.legmap.n_joints, 1))

    lm = load_robot("a3")
    collect(CollectConfig(robot="a3", mode="kinematic", seed=0, stance_s=4.0, heldout=0), tmp_path / "s",
            progress=False)
    recs = load_session(tmp_path / "s", robot=lm)
    prep = prepare_sensor(lm, [r for r in recs if r.kind in ("stance", "standing")])
    times = {r.name: np.asarray(r.time) for r in recs}
    for seg in prep.segments:
        assert np.array_equal(seg.time, times[seg.recording][seg.frames])
        assert np.all(np.diff(seg.time) > 0)
    StanceProblem(prep.kin, prep.segments, prep.w, model=EffectModel(prep.kin, [Clock()]), q_ref=np.zeros(lm.n_joints))
    assert len(seen) == len(prep.segments)
    assert all(np.array_equal(t, s.time) for t, s in zip(seen, prep.segments))
