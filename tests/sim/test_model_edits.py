"""Geometric edits of the simulated robot (issue #41): a hip's mounting point and any leg
joint's body moved by a vector, checked by the edited model's forward kinematics; the
`ModelEdit` that effect plug-ins get (a sole frame and its collision geoms turned
together, seen by Pinocchio and MuJoCo alike); plug-ins found by their entry points."""

import importlib
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from legcal_bench.errors import ConfigError
from legcal_bench.robots import available, load_robot
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.sim.effects import ModelEdit, build_reality, parse_effect
from legcal_bench.sim.sensors import sim_sensors

G1 = str(Path(__file__).resolve().parents[2] / "examples" / "unitree_g1.legmap.yaml")
ROBOTS = ["a3", "a2", pytest.param(G1, marks=pytest.mark.skipif(available(G1) is not None, reason=str(available(G1))),
                                   id="g1")]


def _soles(lm, q):
    L, R = LegKinematics(lm).sole_poses_batch(q[None])
    return L[0], R[0]


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("spec, side, vector, first", [
    ("mount_offset:side=left,axis=y,mm=4", "left", [0, 0.004, 0], "hip"),
    ("mount_offset:side=right,axis=z,mm=-2", "right", [0, 0, -0.002], "hip"),
    ("joint_offset:joint=left_ankle_roll,axis=x,mm=3", "left", [0.003, 0, 0], "ankle_roll"),
])
def test_a_moved_mounting_point_or_joint_moves_that_sole_by_the_vector_and_nothing_else(tmp_path, robot, spec, side,
                                                                                       vector, first):
    lm = load_robot(robot)
    r = build_reality(lm, lm, [spec], sim_sensors("zero"), tmp_path / "model")
    q = np.zeros(lm.n_joints)
    moved, still = (0, 1) if side == "left" else (1, 0)
    before, after = _soles(lm, q), _soles(r.sim_legmap, q)
    assert after[moved][:3, 3] - before[moved][:3, 3] == pytest.approx(vector, abs=1e-9)
    assert np.abs(after[moved][:3, :3] - before[moved][:3, :3]).max() < 1e-12
    assert np.abs(after[still] - before[still]).max() < 1e-12
    truth = r.truth[0]
    assert truth["kind"] == spec.partition(":")[0] and truth["offset_m"] == pytest.approx(sum(vector))
    chain = LegKinematics(lm).poe[side].cols
    if first == "hip":  # the first joint of the chain, whichever hip joint it is on this robot
        assert truth["joint"] == f"{side}_{lm.joint_roles[int(chain[0])]}" and truth["side"] == side
        bent = LegKinematics(lm).q_init()  # the whole leg moved: the same vector in any posture
        b, a = _soles(lm, bent), _soles(r.sim_legmap, bent)
        assert a[moved][:3, 3] - b[moved][:3, 3] == pytest.approx(vector, abs=1e-9)
    else:
        assert truth["joint"] == "left_ankle_roll"


def test_the_first_hip_joint_is_the_chains_own(tmp_path):
    """A3-like hangs the leg from hip pitch, A2-like from hip roll: the mounting point is
    the first joint's body on each (the G1's, hip pitch, in the test above)."""
    firsts = {}
    for robot in ("a3", "a2"):
        lm = load_robot(robot)
        r = build_reality(lm, lm, ["mount_offset:side=left,mm=1"], sim_sensors("zero"), tmp_path / robot)
        firsts[robot] = (r.truth[0]["joint"], r.truth[0]["body"])
    assert firsts == {"a3": ("left_hip_pitch", "left_hip_pitch_link"), "a2": ("left_hip_roll", "left_hip_roll_link")}


def _zero_mujoco(path, legmap):
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    for name in legmap.joint_names:
        data.qpos[model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)]] = 0.0
    mujoco.mj_kinematics(model, data)
    return model, data


def _pose(R, p):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def _sole_world(model, data, legmap, side):
    spec = legmap.legs[side].sole
    if spec.site is not None:
        i = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, spec.site)
        return _pose(data.site_xmat[i].reshape(3, 3), data.site_xpos[i])
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, spec.body)
    return _pose(data.xmat[b].reshape(3, 3), data.xpos[b]) @ _pose(Rotation.from_euler("xyz", spec.rpy).as_matrix(),
                                                                    spec.pos)


def _geoms_world(model, data, body):
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
    ids = [g for g in range(model.ngeom) if model.geom_bodyid[g] == b and (model.geom_contype[g] or
                                                                             model.geom_conaffinity[g])]
    return [_pose(data.geom_xmat[g].reshape(3, 3), data.geom_xpos[g]) for g in ids]


@pytest.mark.parametrize("robot", ["a3", pytest.param(G1, marks=pytest.mark.skipif(available(G1) is not None,
                                                                                   reason=str(available(G1))),
                                                      id="g1")])
def test_a_sole_and_its_collision_geoms_turned_about_the_sole_stay_together(tmp_path, robot):
    """What a bent-sole plug-in does (a site sole on A3-like, a body pose on the G1): the
    sole frame pitched by 1 deg about its own y axis, the foot's contact geoms with it."""
    lm = load_robot(robot)
    edit = ModelEdit(lm, sim_sensors("zero"), np.random.default_rng(0), "test")
    sole = edit.sole("left")
    geoms = edit.collision_geoms(sole.body)
    assert len(geoms) == (1 if robot == "a3" else 4)  # A3's sole box; the G1's four contact spheres
    angle = np.deg2rad(1.0)
    for g in geoms:
        edit.rotate(g, sole.pose[:3, 1] * angle, sole.pose[:3, 3])
    edit.rotate(sole, sole.pose[:3, 1] * angle, sole.pose[:3, 3])
    bent = edit.sole("left").pose
    assert bent[:3, 3] == pytest.approx(sole.pose[:3, 3], abs=1e-12)
    assert np.abs(bent[:3, :3] - sole.pose[:3, :3] @ Rotation.from_rotvec([0, angle, 0]).as_matrix()).max() < 1e-12
    sim = edit.export(tmp_path / "model")
    # Pinocchio (the simulator's true kinematics): that sole pitched about its y, the other untouched.
    (L0, R0), (L1, R1) = _soles(lm, np.zeros(lm.n_joints)), _soles(sim, np.zeros(lm.n_joints))
    assert L1[:3, 3] == pytest.approx(L0[:3, 3], abs=1e-9) and np.abs(R1 - R0).max() < 1e-12
    assert Rotation.from_matrix(L0[:3, :3].T @ L1[:3, :3]).as_rotvec() == pytest.approx([0, angle, 0], abs=1e-9)
    # MuJoCo: each contact geom sits where it sat in the sole's frame (the plate turned whole).
    m0, d0 = _zero_mujoco(lm.mjcf, lm)
    m1, d1 = _zero_mujoco(sim.mjcf, sim)
    S0, S1 = _sole_world(m0, d0, lm, "left"), _sole_world(m1, d1, sim, "left")
    G0, G1_ = _geoms_world(m0, d0, sole.body), _geoms_world(m1, d1, sole.body)
    assert len(G0) == len(G1_) == len(geoms)
    for a, b in zip(G0, G1_):
        assert np.abs(np.linalg.inv(S0) @ a - np.linalg.inv(S1) @ b).max() < 1e-9
        assert np.abs(a - b).max() > 1e-5  # and it did move in the robot
    assert np.abs(_sole_world(m1, d1, sim, "right") - _sole_world(m0, d0, lm, "right")).max() < 1e-12


NUDGE = '''
import numpy as np


class Nudge:  # duck-typed: the simulation layer needs no Effect base class
    sim_keys = {"mm": ("number", None), "side": ("text", "left")}

    def simulate(self, values, edit):
        side = edit.choose(values["side"], ("left", "right"), "side")
        vector = np.array([0.0, 0.0, values["mm"] * 1e-3])
        edit.translate(edit.sole(side), vector)
        return {"side": side, "vector_m": vector}  # NumPy values: the truth file gets plain ones


class FitOnly:
    sim_keys = None
'''


@pytest.fixture
def nudge(tmp_path, monkeypatch):
    """A plug-in registered as an installed distribution would be: a module and its
    dist-info (entry points) on a new import path."""
    site = tmp_path / "site"
    info = site / "legcal_test_nudge-0.1.dist-info"
    info.mkdir(parents=True)
    (site / "legcal_test_nudge.py").write_text(NUDGE)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: legcal_test_nudge\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[legcal_bench.effects]\nnudge = legcal_test_nudge:Nudge\n"
                                           "fit_only = legcal_test_nudge:FitOnly\n"
                                           "broken = legcal_test_nudge_missing:Broken\n")
    monkeypatch.syspath_prepend(str(site))
    importlib.invalidate_caches()
    sys.modules.pop("legcal_test_nudge", None)


def test_an_installed_plugin_with_physics_is_an_effect_of_the_simulation(tmp_path, nudge):
    lm = load_robot("a3")
    r = build_reality(lm, lm, ["nudge:mm=2,side=right"], sim_sensors("zero"), tmp_path / "model")
    assert r.truth == [{"effect": "nudge:mm=2,side=right", "kind": "nudge", "side": "right", "vector_m": [0, 0, 0.002]}]
    q = np.zeros(lm.n_joints)
    (L0, R0), (L1, R1) = _soles(lm, q), _soles(r.sim_legmap, q)
    assert R1[:3, 3] - R0[:3, 3] == pytest.approx([0, 0, 0.002], abs=1e-12) and np.abs(L1 - L0).max() < 1e-12
    with pytest.raises(ConfigError, match=r"unknown effect 'nudgee'.*link_offset.*Installed plug-ins with physics: "
                                          r"nudge \(mm, side\)"):
        parse_effect("nudgee:mm=2")
    with pytest.raises(ConfigError, match="'fit_only' is installed .* for fitting only"):
        parse_effect("fit_only:mm=2")
    with pytest.raises(ConfigError, match="'broken' .* failed to load: ModuleNotFoundError"):
        parse_effect("broken:mm=2")
    with pytest.raises(ConfigError, match=r"'deg=1' is not key=value with a key of nudge \(mm, side\)"):
        parse_effect("nudge:deg=1")
    with pytest.raises(ConfigError, match="give mm"):
        parse_effect("nudge:side=left")
    with pytest.raises(ConfigError, match="side 'middle' is not one of"):
        build_reality(lm, lm, ["nudge:mm=1,side=middle"], sim_sensors("zero"), tmp_path / "x")


@pytest.mark.skipif(available(G1) is not None, reason=str(available(G1)))
def test_an_edited_model_links_its_unchanged_meshes_to_the_source_models(tmp_path):
    # The edited G1 (the meshes of its whole body) links the source model's mesh files
    # instead of copying them (19.5 MB a session set), and MuJoCo reads the same meshes.
    import mujoco

    lm = load_robot(G1)
    r = build_reality(lm, lm, ["mount_offset:side=left,axis=y,mm=4"], sim_sensors("zero"), tmp_path / "model")
    folder = Path(r.sim_legmap.mjcf).parent
    meshes = [p for p in folder.iterdir() if p.suffix.lower() == ".stl"]
    assert len(meshes) > 20 and all(p.is_symlink() and p.resolve().parent != folder for p in meshes)
    edited, source = (mujoco.MjModel.from_xml_path(str(p)) for p in (r.sim_legmap.mjcf, lm.mjcf))
    for field in ("mesh_vert", "mesh_face", "mesh_normal"):
        assert np.array_equal(getattr(edited, field), getattr(source, field)), field
    assert not np.array_equal(edited.body_pos, source.body_pos)  # the edit itself is in the copy
