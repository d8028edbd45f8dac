"""The model-based teacher of our walking policy (issue #14): its recipe file is
checked field by field, and on the A3-like robot it walks forward, upright, with the
feedback reading only the robot's sensors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from legcal_bench.errors import ConfigError
from legcal_bench.policies.zmp_walker import ZmpWalker, load_teacher_recipe
from legcal_bench.robots import load_robot

TEACHERS = Path(__file__).resolve().parents[2] / "policies" / "teachers"


def write(tmp_path, text: str) -> Path:
    p = tmp_path / "t.yaml"
    p.write_text(text)
    return p


def test_a_recipe_is_checked_field_by_field(tmp_path):
    with pytest.raises(ConfigError, match="field 'format'"):
        load_teacher_recipe(write(tmp_path, "gait: {}\n"))
    with pytest.raises(ConfigError, match=r"gait: unknown fields \['stride'\]"):
        load_teacher_recipe(write(tmp_path, "format: legcal-teacher/1\ngait: {stride: 0.1}\n"))
    with pytest.raises(ConfigError, match="feedback: every value must be a finite number"):
        load_teacher_recipe(write(tmp_path, "format: legcal-teacher/1\nfeedback: {roll_p: fast}\n"))
    with pytest.raises(ConfigError, match="whole multiple"):
        load_teacher_recipe(write(tmp_path, "format: legcal-teacher/1\nrates: {physics_hz: 500, control_hz: 300}\n"))
    with pytest.raises(ConfigError, match="double_support"):
        load_teacher_recipe(write(tmp_path, "format: legcal-teacher/1\ngait: {double_support: 1.5}\n"))
    r = load_teacher_recipe(write(tmp_path, "format: legcal-teacher/1\nrates: {physics_hz: 500, control_hz: 50}\n"))
    assert r.gait.dt == pytest.approx(0.02)  # the plan runs at the control rate


@pytest.mark.parametrize("robot", ["a3", "a2"])
def test_the_built_in_teacher_walks_forward_upright(robot):
    from legcal_bench.envs.walking import WalkingEnv, teacher_walking_config
    from legcal_bench.evaluation.walk import walk

    lm = load_robot(robot)
    recipe = load_teacher_recipe(TEACHERS / f"{robot}.yaml")
    teacher = ZmpWalker(lm, 6.0, recipe.gait, recipe.feedback)
    cfg = teacher_walking_config(lm, recipe, teacher)
    assert cfg.control_dt == pytest.approx(recipe.gait.dt)  # the plan's samples are the control steps
    env = WalkingEnv(robot=lm, sensors="realistic", walking=cfg)
    w = walk(env, teacher, 6.0, seed=1)
    assert w.upright
    # It walks: forward about as far as planned (steps from start_s on), both feet striking.
    planned = recipe.gait.step_length * (6.0 - recipe.gait.start_s) / recipe.gait.step_period
    assert 0.6 * planned < w.pelvis[-1, 0] - w.pelvis[0, 0] < 1.4 * planned
    assert min(len(w.strikes[s]["time"]) for s in ("left", "right")) >= 3
    # The feedback is on: a rolled gravity reading moves each loaded leg's roll joints.
    obs = {"gravity": np.array([0.0, -np.sin(0.05), -np.cos(0.05)]), "ang_vel": np.array([0.2, 0.0, 0.0])}
    level = {"gravity": np.array([0.0, 0.0, -1.0]), "ang_vel": np.zeros(3)}
    teacher.reset()
    tilted = teacher.act(obs, {}, 0.0)
    teacher.reset()
    d = tilted - teacher.act(level, {}, 0.0)
    roll = [i for i, r in enumerate(lm.joint_roles) if r in ("hip_roll", "ankle_roll")]
    assert np.abs(d[[i for i in roll if i < 6]]).max() > 0.01 and np.abs(d[[i for i in roll if i >= 6]]).max() > 0.01
    assert np.abs(np.delete(d, roll + [i for i, r in enumerate(lm.joint_roles) if "pitch" in r])).max() == 0


def test_walk_runs_the_teacher_from_its_recipe(capsys):
    from legcal_bench.cli import main

    assert main(["walk", "--robot", "a3", "--teacher", str(TEACHERS / "a3.yaml"), "--seconds", "2", "--json"]) == 0
    import json

    s = json.loads(capsys.readouterr().out)
    assert s["policy"] == "zmp_teacher" and s["upright"] and "--teacher" in s["made_by"]
    assert main(["walk", "--robot", "a3", "--seconds", "2"]) == 2
    assert "--policy SPEC" in capsys.readouterr().err


def test_width_moves_the_soles_apart():
    from legcal_bench.policies.zmp_walker import GaitParams, plan_gait
    from legcal_bench.robots.kinematics import LegKinematics

    kin = LegKinematics(load_robot("a3"))
    narrow, wide = (plan_gait(kin, 4, GaitParams(width=w)) for w in (0.0, 0.03))
    assert np.allclose(wide.left[:, 1] - narrow.left[:, 1], 0.03)
    assert np.allclose(wide.right[:, 1] - narrow.right[:, 1], -0.03)
    assert np.allclose(wide.left[:, [0, 2]], narrow.left[:, [0, 2]])  # only the lateral placement changes
    assert np.abs(wide.zmp[:, 1]).max() == pytest.approx(kin.dims.foot_y + 0.03)  # the ZMP reaches the stance sole
