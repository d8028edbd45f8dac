"""Gymnasium environments. Ids are registered in one loop below.

    import gymnasium as gym, legcal_bench.envs
    env = gym.make("legcal/StaticDoubleSupport-A3-v0", mode="weld")
    env = gym.make("legcal/StaticDoubleSupport-Path-v0", robot="path/to/robot.legmap.yaml")
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from legcal_bench.envs.static_double_support import StaticDoubleSupportEnv

# id suffix -> default robot (None: the robot is given by path, `robot=...`).
STATIC_ROBOTS = {"A2": "a2", "A3": "a3", "PairRYP": "pair_ryp", "PairPRY": "pair_pry", "Path": None}
MAX_EPISODE_STEPS = 1000


def env_id(suffix: str) -> str:
    return f"legcal/StaticDoubleSupport-{suffix}-v0"


def register_envs() -> None:
    for suffix, robot in STATIC_ROBOTS.items():
        if env_id(suffix) in registry:
            continue
        kwargs = {} if robot is None else {"robot": robot}
        register(id=env_id(suffix), entry_point=StaticDoubleSupportEnv, kwargs=kwargs,
                 max_episode_steps=MAX_EPISODE_STEPS)


register_envs()

__all__ = ["StaticDoubleSupportEnv", "STATIC_ROBOTS", "env_id", "register_envs"]
