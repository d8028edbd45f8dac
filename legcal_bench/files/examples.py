"""The examples by the part each plays (`examples/cases.yaml`).

The suites and report commands that run examples by default name a role here, never a
robot (a test holds the code to it): which robot stands for "a third-party 12-joint
humanoid" or "a whole-body humanoid with a torso IMU" is a fact of the examples folder,
kept in one file beside them.
"""

from __future__ import annotations

from functools import cache

from legcal_bench.errors import ConfigError
from legcal_bench.files.packaged import examples_dir

INDEX = "cases.yaml"


@cache
def _index() -> dict:
    import yaml

    return yaml.safe_load((examples_dir() / INDEX).read_text()) or {}


def example_roles() -> dict[str, dict]:
    """Every role of the examples' index with its entry."""
    return dict(_index())


def example_entry(role: str) -> dict:
    """The entry of `role` in the examples' index (its files and settings)."""
    index = _index()
    if role not in index:
        raise ConfigError(f"examples/{INDEX} has no role {role!r}; it has {', '.join(sorted(index))}")
    return index[role]


def example(role: str, key: str = "legmap") -> str:
    """The file `key` of `role`, as a robot or policy reference (`examples/<file>`), which
    `legcal_bench.files.packaged` resolves in a checkout and in an installed wheel alike."""
    entry = example_entry(role)
    if key not in entry:
        raise ConfigError(f"examples/{INDEX}: role {role!r} has no {key!r}")
    return f"examples/{entry[key]}"
