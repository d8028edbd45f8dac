"""Gymnasium environments, registered in one loop with string entry points.

Either import the package, or let Gymnasium import it from the id:

    import gymnasium as gym
    env = gym.make("legcal_bench.envs:legcal/StaticDoubleSupport-A3-v0", mode="weld")

    import legcal_bench.envs
    gym.register_envs(legcal_bench.envs)  # no-op that keeps linters from dropping the import
    env = gym.make("legcal/StaticDoubleSupport-Path-v0", robot="path/to/robot.legmap.yaml")
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

NAMESPACE = "legcal"
STATIC_ENTRY_POINT = "legcal_bench.envs.static_double_support:StaticDoubleSupportEnv"
# id suffix -> default robot (None: the robot is given by path, `robot=...`, and is required).
STATIC_ROBOTS = {"A2": "a2", "A3": "a3", "PairRYP": "pair_ryp", "PairPRY": "pair_pry", "Path": None}
WALKING_ENTRY_POINT = "legcal_bench.envs.walking:WalkingEnv"
# The walking env: the A2-like and A3-like robots, and any robot by path with a policy spec (`policy=...`).
WALKING_ROBOTS = {"A2": "a2", "A3": "a3", "Path": None}
MAX_EPISODE_STEPS = 1000  # static: 20 s at 50 Hz; walking: 20 s at a 50 Hz policy


def env_id(suffix: str, kind: str = "StaticDoubleSupport") -> str:
    return f"{NAMESPACE}/{kind}-{suffix}-v0"


def register_envs() -> None:
    for kind, entry, robots in (("StaticDoubleSupport", STATIC_ENTRY_POINT, STATIC_ROBOTS),
                                ("Walking", WALKING_ENTRY_POINT, WALKING_ROBOTS)):
        for suffix, robot in robots.items():
            if env_id(suffix, kind) not in registry:
                register(id=env_id(suffix, kind), entry_point=entry,
                         kwargs={} if robot is None else {"robot": robot}, max_episode_steps=MAX_EPISODE_STEPS)


register_envs()

__all__ = ["STATIC_ROBOTS", "WALKING_ROBOTS", "env_id", "register_envs"]
