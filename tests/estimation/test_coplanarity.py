"""The per-stance contact check (issue #16): a wedge under one sole in one stance is
flagged, its size and sole read right, the stance dropped on request; clean data of the
same seed is not flagged."""

import numpy as np
import pytest

from legcal_bench.calibrators.interfoot import InterFootCalibrator
from legcal_bench.data.recording import list_segments, load_session, load_truth
from legcal_bench.errors import CalibrationError, ConfigError
from legcal_bench.estimation.checks.coplanarity import coplanarity
from legcal_bench.geometry.lie import Exp
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.reports.contact_table import true_departures
from legcal_bench.robots import load_robot

pytestmark = pytest.mark.xdist_group("coplanarity")  # one process collects `sets` for all


def test_the_departure_jacobian_matches_finite_differences():
    M = Exp(np.r_[0.01, 0.25, 0.003, 0.02, -0.015, 0.4])
    _, D = coplanarity(M)
    eps = 1e-7
    num = np.empty((3, 6))
    for i in range(6):
        xi = np.zeros(6)
        xi[i] = eps
        num[:, i] = (coplanarity(M @ Exp(xi))[0] - coplanarity(M @ Exp(-xi))[0]) / (2 * eps)
    assert np.allclose(num, D, atol=1e-8)
    # A wedge of a about x under the left sole puts the right sole at -a about x.
    a = np.deg2rad(0.3)
    c, _ = coplanarity(Exp(np.r_[0, 0.2, 0, -a, 0, 0]))
    assert np.isclose(c[0], -np.sin(a), rtol=1e-12) and abs(c[1]) < 1e-12


@pytest.fixture(scope="module")
def sets(tmp_path_factory):
    out = {}
    for name, effects in (("clean", ()), ("wedge", ("shim:side=left,roll=0.3,stance=II",))):
        d = tmp_path_factory.mktemp(name)
        collect(CollectConfig(robot="a3", mode="weld", sensors="calibrated-imu", seed=3, effects=effects), d,
                progress=False)
        out[name] = d
    return out


def test_a_wedge_in_one_stance_sits_only_in_that_stance(sets):
    truth = true_departures(list_segments(sets["wedge"]))
    assert np.isclose(np.rad2deg(truth["stance_II"][0]), -0.3, atol=1e-3)
    for name in ("stance_I", "stance_III", "stance_IV"):
        assert np.rad2deg(np.abs(truth[name][:2])).max() < 1e-3
    held = [p for p in list_segments(sets["wedge"]) if p.stem.startswith("heldout")]
    assert all(load_truth(p).meta["reality"]["effects"][0]["stance"] == "II" for p in held)


def test_the_wedged_stance_is_flagged_read_right_and_dropped(sets):
    legmap = load_robot("a3")
    recs = load_session(sets["wedge"], robot=legmap)
    res = InterFootCalibrator().calibrate(legmap, recs)
    check = {c["recording"]: c for c in res.diagnostics["contact_check"]["stances"]}
    assert [n for n, c in check.items() if c["flagged"]] == ["stance_II"]
    c = check["stance_II"]
    assert c["sole"] == "left"
    # The estimate against the truth (-0.3 deg, 1.52 mm); its std is ~0.004 deg, 0.03 mm.
    assert abs(np.rad2deg(c["tilt_rad"][0]) + 0.3) < 0.02 and abs(np.rad2deg(c["tilt_rad"][1])) < 0.02
    assert any("stance_II: the soles were not on one plane" in w for w in res.warnings)
    dropped = InterFootCalibrator(contact_check="drop").calibrate(legmap, recs)
    assert dropped.diagnostics["contact_check"]["dropped"] == ["stance_II"]
    assert "stance_II" not in dropped.diagnostics["segments"]
    with_effect = InterFootCalibrator(contact_check="drop", effects="imu_tilt").calibrate(legmap, recs)
    assert with_effect.diagnostics["effects"]["frames_used"] == dropped.diagnostics["frames_used"]  # same stances
    injected = np.asarray(load_truth(list_segments(sets["wedge"])[0]).offsets)

    def err(r):
        return np.sqrt(np.mean((np.array([r.offsets_rad[n] for n in legmap.joint_names]) - injected) ** 2))

    assert err(dropped) < 0.7 * err(res)  # measured 0.150 deg vs 0.28 deg (contact-table)


def test_clean_data_of_the_same_seed_is_not_flagged(sets):
    legmap = load_robot("a3")
    res = InterFootCalibrator().calibrate(legmap, load_session(sets["clean"], robot=legmap))
    check = res.diagnostics["contact_check"]["stances"]
    assert len(check) == 4 and not any(c["flagged"] for c in check)


def test_bad_options_are_refused(tmp_path):
    with pytest.raises(CalibrationError, match="contact_check"):
        InterFootCalibrator(contact_check="maybe")
    with pytest.raises(ConfigError, match="stance 'V' is not recorded"):
        collect(CollectConfig(robot="a3", mode="weld", seed=0, effects=("shim:side=left,roll=0.3,stance=V",)),
                tmp_path / "x", progress=False)


def test_a_realistic_imu_on_a_yaw_first_hip_is_no_wedge_and_a_small_wedge_still_is(tmp_path):
    """The IMU's declared tilt (mount and bias, realistic sensors) is a nuisance of the
    check: on this yaw-first robot it flagged a clean stance (chi2 46 on 3 dof, stance
    IV) before; a 0.05 deg wedge is still found (chi2 ~430)."""
    from legcal_bench.robots.build import write_robot
    from legcal_bench.robots.design import GENERATED

    design = next(d for d in GENERATED if d.hip_order == ("hip_yaw", "hip_pitch", "hip_roll"))
    robot = str(write_robot(design, tmp_path / "robot"))
    legmap = load_robot(robot)
    flagged = {}
    for name, effects in (("clean", ()), ("wedge", ("shim:side=left,roll=0.05,stance=II",))):
        collect(CollectConfig(robot=robot, mode="kinematic", seed=0, effects=effects, heldout=0), tmp_path / name,
                progress=False)
        res = InterFootCalibrator().calibrate(legmap, load_session(tmp_path / name, robot=legmap))
        flagged[name] = [c["recording"] for c in res.diagnostics["contact_check"]["stances"] if c["flagged"]]
    assert flagged == {"clean": [], "wedge": ["stance_II"]}


def test_a_clean_realistic_set_reads_as_noise_and_a_small_wedge_still_stands_out(tmp_path):
    """The stance left out is predicted by the other stances' whitened estimate, whose
    covariance the test uses. Before, that estimate was the row-weighted one (two to three
    times the spread, more where a stance extrapolates the others): this clean A2-like
    weld set (realistic IMU, seed 3) read stance IV as soles off one plane (chi2 23 on 3
    dof even with the spread taken 3x); now every stance's chi2 is of its 3-dof
    distribution, and a 0.05 deg wedge under stance II is found, its size read to 0.01 deg."""
    from scipy.stats import chi2 as chi2_dist

    legmap = load_robot("a2")
    found = {}
    for name, effects in (("clean", ()), ("wedge", ("shim:side=left,roll=0.05,stance=II",))):
        collect(CollectConfig(robot="a2", mode="weld", sensors="realistic", seed=3, effects=effects, heldout=0),
                tmp_path / name, progress=False)
        res = InterFootCalibrator().calibrate(legmap, load_session(tmp_path / name, robot=legmap))
        found[name] = res.diagnostics["contact_check"]["stances"]
    clean = found["clean"]
    assert len(clean) == 4 and not any(c["flagged"] for c in clean)
    # Measured 0.5-4.0 (p 0.26-0.92); 1e-3 family-wise over four stances: 18.4.
    assert max(c["chi2"] for c in clean) < chi2_dist.isf(1e-3 / 4, 3)
    flagged = [c for c in found["wedge"] if c["flagged"]]
    assert [c["recording"] for c in flagged] == ["stance_II"] and flagged[0]["sole"] == "left"
    assert abs(np.rad2deg(flagged[0]["tilt_rad"][0]) + 0.05) < 0.01


def test_check_runs_the_calibrators_contact_test(sets, capsys):
    """One test for both (issue #60): `legcal-bench check` flags the stance the calibrator
    flags, with the calibrator's chi2 to within the two fits' trimming, and nothing on
    the clean set of the same seed."""
    import json

    from legcal_bench.cli import main

    legmap = load_robot("a3")
    for name, expect in (("wedge", ["stance_II"]), ("clean", [])):
        res = InterFootCalibrator(setting="sensor").calibrate(legmap, load_session(sets[name], robot=legmap))
        calib = {c["recording"]: c for c in res.diagnostics["contact_check"]["stances"]}
        assert main(["check", "--bags", str(sets[name]), "--robot", "a3", "--json"]) == 0
        out = json.loads(capsys.readouterr().out)
        check = {c["recording"]: c for c in out["contact_check"]}
        assert [n for n, c in check.items() if c["flagged"]] == expect
        assert [n for n, c in calib.items() if c["flagged"]] == expect
        for n in check:
            assert np.isclose(check[n]["chi2"], calib[n]["chi2"], rtol=0.05, atol=0.5)
        assert any(w.startswith("stance stance_II: the soles were not on one plane") for w in out["warnings"]) \
            == bool(expect)


def test_a_misfit_every_stance_shares_is_noise_not_soles_off_one_plane(tmp_path):
    """On a contact floor the soles rock and give under a load that changes with the
    posture: every stance's chi2 is outside the declared noise (here 89-211 on 3 dof), no
    single stance is off one plane (the truth: < 0.003 deg). Judged at the declared noise,
    three of this clean 12-joint G1 set's four stances were flagged (issue #60,
    `reports/contact_check_realistic`); judged at the other stances' shared misfit
    (`shared_misfit`), none is, and the scale says by how much the noise model was off."""
    from pathlib import Path

    legmap = load_robot("examples/unitree_g1.legmap.yaml")
    robot = str(Path(__file__).parents[2] / "examples" / "unitree_g1.legmap.yaml")
    collect(CollectConfig(robot=robot, mode="contact", sensors="realistic", seed=1, heldout=0), tmp_path / "s",
            progress=False)
    res = InterFootCalibrator().calibrate(legmap, load_session(tmp_path / "s", robot=legmap))
    check = res.diagnostics["contact_check"]["stances"]
    assert len(check) == 4 and not any(c["flagged"] for c in check)
    # Without the scale, three stances are significant at the family-wise 1 %.
    from scipy.stats import chi2 as chi2_dist

    assert sum(chi2_dist.sf(c["chi2"], c["dof"]) < 0.01 / 4 for c in check) >= 3
    assert all(c["noise_scale"] > 10 for c in check)
    assert not any("not on one plane" in w for w in res.warnings)
