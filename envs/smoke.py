"""Smoke tests of every registered env, for anyone's pytest: `pytest --pyargs
legcal_bench.envs.smoke` (installed with the package, so it runs against whatever
legcal-bench is installed, a wheel included).

Each id is made with its defaults (the `-Path-` ids with a built-in robot and, for
walking, its shipped policy), checked by Gymnasium's own env checker (spaces, seeding,
reset and step signatures, determinism under a seed), reset and stepped; the metrics
each env puts in `info` are there and finite."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from legcal_bench.envs import STATIC_ROBOTS, WALKING_ROBOTS, env_id

# The `-Path-` ids take the robot (and the walking one its policy) by name or path.
PATH_KWARGS = {"StaticDoubleSupport": {"robot": "a3"}, "Walking": {"robot": "a3", "policy": "a3"}}
# Gymnasium's checker advises bounded observations and actions normalized to [-1, 1];
# these envs observe physical quantities (rad, m/s^2, N) and take postures (m, rad) or
# joint targets (rad) by design: its advice is not a failure, and is not repeated here.
pytestmark = [pytest.mark.filterwarnings("ignore:.*Box observation space m:UserWarning"),
              pytest.mark.filterwarnings("ignore:.*For Box action spaces, we recommend:UserWarning")]
IDS = [(kind, suffix) for kind, robots in (("StaticDoubleSupport", STATIC_ROBOTS), ("Walking", WALKING_ROBOTS))
       for suffix in robots]


def _make(kind: str, suffix: str):
    return gym.make(env_id(suffix, kind), **(PATH_KWARGS[kind] if suffix == "Path" else {}))


@pytest.mark.parametrize("kind, suffix", IDS, ids=[env_id(s, k) for k, s in IDS])
def test_each_env_passes_gymnasiums_checker_and_steps(kind, suffix):
    env = _make(kind, suffix)
    try:
        check_env(env.unwrapped, skip_render_check=True)
        obs, info = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        for _ in range(3):
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample() * 0.0
                                                                if kind == "Walking" else info["posture"])
            assert np.isfinite(reward) and not terminated
        assert info, "an env reports its metrics in info"
    finally:
        env.close()
