"""Posterior uncertainty of a fit: what the data determine, and what they do not.

From the data-only information matrix H of the offsets, with every residual row
divided by its declared noise level (`legcal_bench.estimation.information.noise`), the posterior
covariance is H^-1 (first order, frames taken as independent). Reported: the standard
deviation of each offset, of each leg's pitch sum and of their difference, and every
combination (eigenvector of H^-1) whose standard deviation exceeds `STD_LIMIT_RAD`:
those the data do not determine, named with what would determine them.
"""

from __future__ import annotations

import numpy as np

from legcal_bench.estimation.information.observability import describe_combination
from legcal_bench.estimation.verdict import INVALIDATES, LIMITS, Finding
from legcal_bench.robots.design import PITCH_ROLES
from legcal_bench.robots.kinematics import pitch_sums

STD_LIMIT_RAD = float(np.deg2rad(0.1))  # a combination known worse than this is "not determined"
NO_NOISE = "the recordings declare no sensor noise: no posterior standard deviations"
BOUND_FRACTION = 0.99  # an offset this close to the bound ended at it


def pitch_sum_vectors(signs: np.ndarray, roles: list[str]) -> dict[str, np.ndarray]:
    """Row vectors a with a . dq = each pitch sum (left, right) and right_minus_left."""
    pitch_signs = np.where(np.array([r in PITCH_ROLES for r in roles]), signs, 0.0)
    sums = [pitch_sums(e, pitch_signs) for e in np.eye(len(roles))]  # each leg's columns as pitch_sums takes them
    left, right = (np.array([s[key] for s in sums]) for key in ("left", "right"))
    return {"left": left, "right": right, "right_minus_left": right - left}


def _hint(v: np.ndarray, roles: list[str]) -> str:
    pitch = np.array([r in PITCH_ROLES for r in roles])
    share = float(np.sum(v[pitch] ** 2))
    if share > 0.8:
        return ("add lunges (stances II, III) that bend each leg's pitch joints differently, or a knee prior "
                "(a straight-leg standing recording)")
    if share < 0.2:
        return "add postures with more hip roll and yaw (the wide squat, stance IV, and more sway)"
    return "add more varied stances (the four default stances I-IV, longer)"


def posterior(H: np.ndarray, names: list[str], roles: list[str], signs: np.ndarray) -> dict:
    """Standard deviations (rad) from the noise-whitened data information `H` (n, n), n the leg joints."""
    w, V = np.linalg.eigh(0.5 * (H + H.T))
    floor = max(float(w[-1]), 1e-300) * 1e-15
    inv = np.where(w > floor, 1.0 / np.maximum(w, floor), np.inf)
    std_dir = np.sqrt(inv)

    def std_of(a: np.ndarray) -> float:
        c = V.T @ a
        return float(np.sqrt(np.sum(np.where(np.abs(c) > 1e-12, c * c * inv, 0.0))))

    out = {
        "std_rad": {n: std_of(np.eye(len(H))[i]) for i, n in enumerate(names)},
        "pitch_sum_std_rad": {k: std_of(a) for k, a in pitch_sum_vectors(signs, roles).items()},
        "undetermined": [],
    }
    for i in np.argsort(-std_dir):
        if std_dir[i] <= STD_LIMIT_RAD:
            break
        out["undetermined"].append({"combination": describe_combination(V[:, i], names), "vector": V[:, i].tolist(),
                                    "std_rad": float(std_dir[i]), "fix": _hint(V[:, i], roles)})
    return out


def uncertainty_warnings(post: dict) -> list[str]:
    """One warning per combination the data do not determine."""
    out = []
    for u in post["undetermined"]:
        std = np.rad2deg(u["std_rad"])
        size = f"±{std:.2f}°" if np.isfinite(std) else "unbounded"
        out.append(Finding(f"not determined by the data: {u['combination']}: {size} (1 sigma, limit "
                           f"{np.rad2deg(STD_LIMIT_RAD):g}°); {u['fix']}", LIMITS))
    return out


def at_bound_mask(dq: np.ndarray, bound: float) -> np.ndarray:
    """Which offsets sit at `bound` (within `BOUND_FRACTION` of it): the one rule."""
    return np.abs(np.asarray(dq, dtype=float)) >= BOUND_FRACTION * bound


def bound_warnings(dq: np.ndarray, bound: float, names: list[str]) -> list[str]:
    at = [n for n, hit in zip(names, at_bound_mask(dq, bound)) if hit]
    return ([Finding(f"offsets at the bound ±{np.rad2deg(bound):.2f}°: {at}: the data push them further than the "
                     "bound allows (offsets that large, data that do not determine them, or the wrong robot/leg "
                     "map); the values are not estimates", INVALIDATES)] if at else [])


def imu_tilt_warnings(response: np.ndarray, tilt_bound: float, signs: np.ndarray) -> list[str]:
    """What the IMU's declared tilt bound leaves undetermined: a fixed error of its
    vertical moves the offsets by `response` (n, 2) per rad (about the pelvis x, y
    axes), which no static level-ground data can tell apart. A warning when the bound
    moves a pitch sum by more than `STD_LIMIT_RAD`."""
    if tilt_bound <= 0:
        return []
    moved = {k: max(abs(v) for v in pitch_sums(response[:, a] * tilt_bound, signs).values()) for k, a in
             (("roll", 0), ("pitch", 1))}
    out = []
    for axis, size in moved.items():
        if size > STD_LIMIT_RAD:
            out.append(Finding(
                f"IMU tilt not separable: the IMU's {axis} tilt, declared within ±{tilt_bound * 1e3:.2f} mrad (mount "
                f"plus bias over g), moves the pitch sums by up to ±{np.rad2deg(size):.2f}° (limit "
                f"{np.rad2deg(STD_LIMIT_RAD):g}°): static level-ground data cannot tell a fixed IMU tilt from offsets; "
                "calibrate the IMU (its mounting and accelerometer bias) and declare the smaller bound", LIMITS))
    return out
