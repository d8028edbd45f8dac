"""Each concept is written once: no module but its home restates it.

A row: the concept, a pattern that restating it would contain, and the one module
allowed to. Patterns are searched in the package's source (legcal_bench/, envs/,
calibrators/, policies/)."""

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SOURCES = [p for folder in ("legcal_bench", "envs", "calibrators", "policies") for p in (REPO / folder).rglob("*.py")]

CONCEPTS = [
    ("the paper's injection", r"""["']hip_pitch["']\s*:\s*0?\.03\b""", "legcal_bench/paper.py"),
    ("the injection vector by role", r"INJECTION_RAD\[", "legcal_bench/sim/offsets.py"),
    ("the paper's operating weights", r"lambda_g\s*=\s*(10|100)(\.0)?\b", "legcal_bench/paper.py"),
    ("the flat-ground height row", r"p_L\s*-\s*[\w.]*p_R|translation\s*-\s*\w+\.translation", "legcal_bench/estimation/problem/residuals.py"),
    ("the IMU frame at zero pose", r"imu_pose\(np\.zeros\((12|self\.n_joints)\)\)", "legcal_bench/robots/kinematics.py"),
    ("an RMS", r"np\.sqrt\(np\.mean\(", "legcal_bench/evaluation/metrics.py"),
    ("the pitch roles", r"""\(\s*["']hip_pitch["']\s*,\s*["']knee["']\s*,\s*["']ankle_pitch["']\s*\)""", "legcal_bench/robots/design.py"),
    ("a robot label from a leg-map path", r"""replace\(\s*["']\.legmap\.yaml""", None),
    ("headless plot set-up", r"matplotlib\.use\(", "legcal_bench/files/plots.py"),
    ("saving a figure", r"\.savefig\(", "legcal_bench/files/plots.py"),
    ("a report's two files", r"""(report|\{name\})\.(md|json)["']""", "legcal_bench/files/reports.py"),
    ("an atomic rename", r"os\.replace\(", "legcal_bench/files/atomic.py"),
    ("MuJoCo's quaternion order", r"as_quat\(|from_quat\(", "legcal_bench/geometry/poses.py"),
    ("an error class", r"^class \w+Error\(", "legcal_bench/errors.py"),
    ("the posture bounds", r"0\.25 \* L", "legcal_bench/protocol/stances.py"),
]


@pytest.mark.parametrize("concept, pattern, home", CONCEPTS, ids=[c[0] for c in CONCEPTS])
def test_concept_is_written_once(concept, pattern, home):
    rx = re.compile(pattern, re.MULTILINE)
    found = sorted(str(p.relative_to(REPO)) for p in SOURCES if rx.search(p.read_text()))
    assert found == ([home] if home else []), f"{concept}: restated in {found} (home: {home})"


def test_the_concept_check_sees_a_restatement():
    """The checker itself: a second injection literal would be caught."""
    rx = re.compile(CONCEPTS[0][1])
    assert rx.search('INJ = {"hip_pitch": 0.03, "hip_roll": 0.04}')
    assert not rx.search('INJ = {"hip_pitch": 0.031}')
