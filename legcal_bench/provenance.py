"""Which code made a result: package version, git commit, and the results version.

`RESULTS_VERSION` is bumped on purpose, in the same commit, whenever a change is
meant to move benchmark numbers; result cells are keyed on it (and on their
settings and data), so a bump recomputes them. The git commit is recorded, not
keyed: a commit that changes no number keeps every finished cell.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
from functools import lru_cache
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

# History: 1 = the static half as first built (through the package layout);
# 2 = the calibration core rebuilt (residual terms, batched kinematics and Lie tools):
#     Yamane's trust-region steps now solved to convergence (its answers move by up to
#     ~1e-4 relative, its paired deltas by up to ~1e-2), the paper's alternation (15
#     outer iterations, not converged) moves by up to ~2e-3 relative, inter-foot by
#     rounding (< 4e-6 relative on its smallest figures);
# 3 = Yamane solved by variable projection (per-frame tilts eliminated): the same optimum
#     to ~1e-9 rad (its weak directions are that flat), which moves its smallest figures
#     by up to ~1e-6 relative;
# 4 = IMU motion compensation by default (issue #11): every calibrator's accelerometer,
#     and the sensor-based held-out metric's, has the IMU's acceleration predicted from
#     the leg angles removed (zero-noise weld floor 0.27/0.41 deg -> 0.013/0.016 deg on
#     A3-like/A2-like); kinematic-mode recordings are declared static and untouched;
# 5 = the benchmark's native (factory) offsets drawn in +-1.2 deg per joint (0.69 deg
#     RMS, real-robot scale) instead of +-0.3 deg (issue #11).
# 6 = the inter-foot `sensor` setting ends with generalized least squares (every frame
#     whitened by its declared covariance) and its posterior is that fit's information
#     (issue #16): clean A3-like offsets error 2-3x lower.
# 7 = the `sensor` setting's generalized least squares only where the declared noise
#     holds (whitened chi2/dof <= 1.5); where the data reject it (contact floors: 2.2-129)
#     the row-weighted fit of version 5 is kept.
# 8 = placement jitter scaled by leg length below the A3-like robot's (issue #37): the
#     built-ins' data are unchanged; the 12-joint G1 (0.79 m legs) and shorter robots
#     get their soles placed within 0.85x (G1) of the metres they were; the paper's
#     presets signed by each joint's axis (unchanged on every robot whose axes point
#     along their roles' pelvis axes, the built-ins and the G1 among them).
# 9 = the static contact floor's parameters are the floor's own (geom priority, issue
#     #38): MuJoCo had averaged them with the robots' foot geoms' defaults, and the soles
#     sank 265 um instead of 32 um (A3-like); every contact-mode set changes (kinematic and
#     weld do not). Legs without ankle roll record the wide squat with the toes out
#     (issue #37): their sets change, the built-ins' and the G1's do not.
# 10 = the standing controller also yields the legs to each sole's shear and twist
#     (foot damping control, issue #38): every contact-mode set recorded with it (the
#     default on a contact floor for robots with ankle force/torque sensors) changes.
# 11 = the standing controller also holds the centre of mass at the plan's while each
#     stance settles, and its authority per joint is 10 deg instead of 5 (issue #38):
#     every contact-mode set recorded with it changes again.
# 12 = every joint the leg map does not list is held (issue #59), rigidly with its own
#     actuators switched off, or on a servo with the leg map's gains: sets of robots with
#     such joints change (the whole-body G1's: its held arms and waist no longer pulled
#     toward 0 by their position actuators); the built-ins' and the 12-joint G1's do not.
RESULTS_VERSION = 12
PACKAGE = "legcal-bench"


def package_version() -> str:
    try:
        return version(PACKAGE)
    except PackageNotFoundError:
        return "unknown"


def _git(*args: str) -> str | None:
    try:
        out = subprocess.run(["git", *args], cwd=Path(__file__).resolve().parent, capture_output=True, text=True,
                             timeout=10, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


# What "the code" is: result files, reports and docs changing beside it do not make it dirty.
CODE_PATHS = ("legcal_bench", "envs", "calibrators", "policies", "examples", "pyproject.toml")


@lru_cache(maxsize=1)
def code_version() -> dict[str, Any]:
    """{"package", "commit" (None outside a git checkout), "dirty" (uncommitted changes
    to the code, CODE_PATHS), "results_version"}."""
    commit = _git("rev-parse", "HEAD")
    dirty = None
    if commit is not None:
        status = _git("status", "--porcelain", "--untracked-files=no", "--",
                      *(f":(top){path}" for path in CODE_PATHS))
        dirty = bool(status) if status is not None else None
    return {"package": package_version(), "commit": commit, "dirty": dirty, "results_version": RESULTS_VERSION}


def describe(v: dict[str, Any]) -> str:
    """One line for a report: 'legcal-bench 0.2.0, commit 1a2b3c4 (dirty), results version 2'."""
    commit = "commit unknown" if not v.get("commit") else f"commit {v['commit'][:7]}" + (
        " (uncommitted changes)" if v.get("dirty") else "")
    return f"legcal-bench {v.get('package', 'unknown')}, {commit}, results version {v.get('results_version', '?')}"


def stable_hash(obj: Any) -> str:
    """A short hash of a JSON-able object, independent of key order."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]
