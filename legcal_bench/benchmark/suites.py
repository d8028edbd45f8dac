"""Benchmark suites, registered by name with tags (dm_control's suite registry).

A suite names its robots, floor modes, number of seeds and any collection overrides.
Robots are references as `legcal_bench.robots.resolve_robot` takes them; a robot whose
model is missing on this machine (the external robot example outside a checkout with
../shared)
is skipped by the planner with a message naming the path.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from legcal_bench.errors import ConfigError
from legcal_bench.files.examples import example

EXTERNAL_ROBOT = example("external_robot")  # a third-party 12-joint humanoid (examples/cases.yaml)


@dataclass(frozen=True)
class Suite:
    name: str
    robots: tuple[str, ...]
    modes: tuple[str, ...]
    seeds: int
    collect: dict = field(default_factory=dict)
    tags: tuple[str, ...] = ()
    description: str = ""


SUITES: dict[str, Suite] = {
    s.name: s
    for s in (
        Suite("smoke", ("a2", "a3"), ("weld",), 1, dict(stance_s=6.0, heldout_s=4.0, standing_s=2.0, heldout=2),
              ("fast", "static"), "A2-like and A3-like, weld floor, one seed, short sessions (~15 s)"),
        Suite("standard", ("a2", "a3", "pair_ryp", "pair_pry"), ("weld",), 10, {},
              ("static", "leaderboard"), "the built-in robots, weld floor, 10 seeds (~8 min on 2 cores)"),
        Suite("full", ("a2", "a3", "pair_ryp", "pair_pry", EXTERNAL_ROBOT), ("kinematic", "weld", "contact"), 10, {},
              ("static", "leaderboard", "external_robot", "all_floors"),
              "adds the external robot example (a third-party 12-joint humanoid) through its leg map and the "
              "kinematic and contact floors (~30 min)"),
        # Walking, not static cells: run by `legcal_bench.benchmark.closed_loop` (seeds = trials).
        Suite("closed-loop", ("a3", "a2"), ("walking",), 35, {}, ("closed_loop", "leaderboard"),
              "every calibrator variant's estimate walked by our own policies on the A3-like and A2-like robots at "
              "paper@3 and random:3, 35 trials"),
        Suite("closed-loop-full", ("a3", "a2", EXTERNAL_ROBOT), ("walking",), 35, {},
              ("closed_loop", "leaderboard", "external_robot"),
              "closed-loop, plus the external robot example walked by its published policy through its leg map "
              "and spec"),
        # The model-gap loop scored: run by `legcal_bench.benchmark.modelgap` (seeds per library effect).
        Suite("modelgap", ("a3", "a2", EXTERNAL_ROBOT), ("weld",), 10, {}, ("modelgap", "leaderboard", "external_robot"),
              "the model-gap loop: each library effect (seeded realistic magnitudes), clean data (false alarms) and "
              "three physical edits outside the library (A3-like), diagnosed (~40 min on 2 cores)"),
    )
}


def get_suite(name: str) -> Suite:
    if name not in SUITES:
        raise ConfigError(f"--suite {name!r}: use one of {list(SUITES)}")
    return SUITES[name]

