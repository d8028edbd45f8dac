from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import legcal_bench  # noqa: E402,F401  (first: its OpenBLAS kernel choice must precede numpy's loading)

import pytest

REPO = Path(__file__).resolve().parents[1]
G1_LEGMAP = REPO / "examples" / "unitree_g1.legmap.yaml"
BUILTIN = ["a2", "a3", "pair_ryp", "pair_pry"]


@pytest.fixture(scope="session")
def testbot_legmap(tmp_path_factory) -> Path:
    """A small synthetic robot: held waist/arm joints, soles given as poses relative to a
    foot body whose frame is rotated away from the sole."""
    from dataclasses import replace

    from legcal_bench.robots.build import write_robot
    from legcal_bench.robots.design import BASE

    design = replace(BASE.scaled("testbot", length=0.6, mass=0.5), hip_order=("hip_roll", "hip_pitch", "hip_yaw"))
    return write_robot(design, tmp_path_factory.mktemp("testbot"), upper_body=True, sole_sites=False,
                       foot_frame_rpy=(0.1, -0.2, 0.3))


@pytest.fixture(scope="session")
def all_robots(testbot_legmap) -> list[str]:
    return BUILTIN + [str(G1_LEGMAP), str(testbot_legmap)]
