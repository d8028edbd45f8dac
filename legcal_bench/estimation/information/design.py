"""Stance design (issue #12, first part): the information a stance protocol gives about
the offsets, predicted from the kinematics, and a greedy E-optimal choice of stances.

A stance (`legcal_bench.protocol.stances.Stance`: foot placement, squat depth, posture
motion amplitudes) is fitted to the robot and its posture motion made reachable and
balanced exactly as `collect` does (`fit_stance`, `feasible_trajectory`). Its
information matrix is the noise-whitened data rows of the inter-foot calibration at
the true offsets, on a level floor with the IMU's true vertical:

    H_s = sum_k G_k^T W_f G_k - N gbar^T W_f gbar + sum_k F_k^T W_g F_k

(the inter-foot rows about the stance's mean transform, which the calibration
estimates, hence the Schur complement; the flat-ground rows as they are), whitened by
the declared sensor model (`noise_sigmas`). A protocol's information is the sum over
its stances; its predicted standard deviations are sqrt(diag(H^-1)). Predicted, not
measured: whether the robot holds a stance is asked of the physics by a screen
(`legcal_bench.protocol.screen.HoldScreen`, passed as `screen`): the greedy choice takes
the best candidate that passes it, and an exchange pass then swaps chosen stances for
passing candidates while the smallest eigenvalue grows (Fedorov's exchange). The
recovery over seeds comes with the collected protocol (`bench --protocol`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
from tqdm import tqdm

from legcal_bench.errors import ConfigError, IKError
from legcal_bench.estimation.imu.levelling import levelling_rotations
from legcal_bench.estimation.information.noise import noise_sigmas
from legcal_bench.estimation.problem.residuals import flat_residuals
from legcal_bench.geometry.poses import posture_poses
from legcal_bench.protocol.stances import Stance, feasible_trajectory, fit_stance, settled_placement
from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics, pitch_sums
from legcal_bench.sim.sensors import sensor_model

# Ranges of the sampled candidates (leg lengths, rad; amplitudes as factors on stance I's):
# "default" stays near the paper's stances; "wide" allows larger placements and up to
# three times stance I's motion (whether the robot holds those is for the collected
# protocol's hold check to say).
CANDIDATE_RANGES = {
    "default": dict(x=(-0.15, 0.15), extra_width=(-0.02, 0.12), toe_out=(-0.1, 0.25), depth=(0.04, 0.16),
                    amplitude=(0.3, 1.6)),
    "wide": dict(x=(-0.2, 0.2), extra_width=(-0.03, 0.16), toe_out=(-0.2, 0.35), depth=(0.03, 0.22),
                 amplitude=(0.5, 3.0)),
}
EVAL_STEP = 4  # information from every 4th frame, scaled back up (the motion is smooth)


@dataclass
class StanceInfo:
    stance: Stance  # as fitted to the robot
    H: np.ndarray  # (n, n) whitened information, n the leg joints
    motion_scale: float


def stance_information(kin: LegKinematics, stance: Stance, frames: int, rate_hz: float = 50.0, seed: int = 0,
                       sensors: str = "realistic") -> StanceInfo:
    """The whitened information of `frames` frames of `stance` on this robot."""
    sig = noise_sigmas(sensor_model(sensors), kin.dims.leg_length)
    if sig is None:
        raise ValueError("stance design needs a sensor model with noise (its information is relative to it)")
    fitted = fit_stance(stance, kin).stance
    placement = settled_placement(fitted, kin)
    motion = feasible_trajectory(kin, placement, frames / rate_hz, rate_hz, np.random.default_rng(seed),
                                 return_q=True)
    Q = motion.q[::EVAL_STEP]
    fk = frame_kinematics(kin, Q)
    up = np.einsum("nji,j->ni", posture_poses(motion.postures[::EVAL_STEP])[:, :3, :3], [0.0, 0.0, 1.0])
    _, F = flat_residuals(fk, up, levelling_rotations(up))
    wf = np.array([1 / sig["feet_translation"]] * 3 + [1 / sig["feet_rotation"]] * 3)
    wg = np.array([1 / sig["flat_height"]] + [1 / sig["flat_normal"]] * 4)
    G, F = wf[None, :, None] * fk.G, wg[None, :, None] * F
    g = G.sum(axis=0)
    H = np.einsum("nij,nik->jk", G, G) - g.T @ g / len(G) + np.einsum("nij,nik->jk", F, F)
    return StanceInfo(fitted, H * EVAL_STEP, motion.scale)


def sample_stances(n: int, rng: np.random.Generator, ranges: str = "default",
                   soles_under_hips: bool = False) -> list[Stance]:
    """`n` candidate stances drawn from `ranges`; with `soles_under_hips` (legs that do not
    reach every sole pose: without ankle roll a sole stands flat only under its hip, at
    the leg's own yaw) no extra width and no toe-out (the same draws)."""
    r = CANDIDATE_RANGES[ranges]
    if soles_under_hips:
        r = {**r, "extra_width": (0.0, 0.0), "toe_out": (0.0, 0.0)}
    base = np.array(Stance("I", "").amplitude)
    return [Stance(f"D{i}", "designed", left_x=rng.uniform(*r["x"]), right_x=rng.uniform(*r["x"]),
                   extra_width=rng.uniform(*r["extra_width"]), toe_out=rng.uniform(*r["toe_out"]),
                   depth=rng.uniform(*r["depth"]),
                   amplitude=tuple(float(a) for a in base * rng.uniform(*r["amplitude"], 6)))
            for i in range(n)]


def _lambda_min(H: np.ndarray) -> float:
    return float(np.linalg.eigvalsh(H)[0])


def greedy_design(candidates: list[StanceInfo], k: int, accept: Callable[[int], bool] | None = None,
                  exchange: bool = True) -> list[int]:
    """Indices of `k` candidates chosen one at a time, each maximizing the smallest
    eigenvalue of the summed information (E-optimal) among those `accept` passes
    (asked lazily, best first, each index at most once); then, with `exchange`, any
    chosen stance is swapped for a passing candidate while that raises the smallest
    eigenvalue. Raises ConfigError if fewer than `k` candidates pass."""
    verdict: dict[int, bool] = {}

    def ok(j: int) -> bool:
        if j not in verdict:
            verdict[j] = True if accept is None else bool(accept(j))
        return verdict[j]

    chosen: list[int] = []
    n = len(candidates[0].H) if candidates else 0
    H = np.zeros((n, n))
    for _ in range(k):
        order = sorted((j for j in range(len(candidates)) if j not in chosen and verdict.get(j, True)),
                       key=lambda j: -_lambda_min(H + candidates[j].H))
        best = next((j for j in order if ok(j)), None)
        if best is None:
            raise ConfigError(f"stance design: only {len(chosen)} of {len(candidates)} candidate stances pass the hold "
                              f"screen and {k} are asked for; sample more (--candidates), narrower ones "
                              "(--ranges default), or fewer (--count)")
        chosen.append(best)
        H = H + candidates[best].H
    improved = exchange
    while improved:
        improved = False
        for slot in range(k):
            rest = H - candidates[chosen[slot]].H
            order = sorted((j for j in range(len(candidates)) if j not in chosen and verdict.get(j, True)
                            and _lambda_min(rest + candidates[j].H) > _lambda_min(H) * (1 + 1e-9)),
                           key=lambda j: -_lambda_min(rest + candidates[j].H))
            best = next((j for j in order if ok(j)), None)
            if best is not None:
                chosen[slot], H, improved = best, rest + candidates[best].H, True
    return chosen


def summary(kin: LegKinematics, H: np.ndarray) -> dict:
    """Smallest eigenvalues, condition number and predicted standard deviations (deg)
    per offset and pitch sum."""
    w = np.linalg.eigvalsh(H)
    cov = np.linalg.inv(H)
    signs = kin.pitch_signs()
    ps = {}
    for key in ("left", "right", "right_minus_left"):
        a = np.array([pitch_sums(e, signs)[key] for e in np.eye(kin.legmap.n_joints)])
        ps[key] = float(np.degrees(np.sqrt(a @ cov @ a)))
    return {"eigenvalues": w[:3].tolist(), "kappa": float(w[-1] / w[0]),
            "std_deg": dict(zip(kin.legmap.joint_names, np.degrees(np.sqrt(np.diag(cov))).tolist())),
            "pitch_sum_std_deg": ps}


class _OutOfTime(Exception):
    pass


def design(kin: LegKinematics, default: list[Stance], k: int = 4, candidates: int = 60, frames: int = 2400,
           seed: int = 0, sensors: str = "realistic", ranges: str = "default",
           screen: Callable[[Stance], object] | None = None, progress: bool = False,
           budget_s: float | None = None) -> dict:
    """The default protocol against `k` stances chosen from `candidates` sampled ones,
    at the same total frame count; candidates that do not fit the robot are skipped,
    and with `screen` (stance -> a report with `.held` and `.to_dict()`, e.g.
    `HoldScreen`) those the robot does not hold or cannot take (rejected, the search
    goes on). With `budget_s`, no stance is screened after that many seconds: the
    design then stops with a ConfigError saying how far it got."""
    t0 = time.monotonic()
    rng = np.random.default_rng(seed)
    default_info = [stance_information(kin, s, frames // len(default), seed=seed, sensors=sensors) for s in default]
    pool = []
    for st in tqdm(sample_stances(candidates, rng, ranges, not kin.reaches_any_sole_pose), desc="stance information", disable=not progress):
        try:
            pool.append(stance_information(kin, st, frames // k, seed=seed, sensors=sensors))
        except IKError:
            continue
    screened: dict[str, dict] = {}

    def accept(j: int) -> bool:
        if budget_s is not None and time.monotonic() - t0 > budget_s:
            raise _OutOfTime
        report = screen(pool[j].stance)
        screened[pool[j].stance.name] = report.to_dict()
        if progress:
            verdict = "held" if report.held else ("unreachable" if getattr(report, "unreachable", None) else "failed")
            tqdm.write(f"  hold screen {pool[j].stance.name}: {verdict}")
        return report.held

    try:
        chosen = [pool[j] for j in greedy_design(pool, k, accept if screen is not None else None)]
    except _OutOfTime:
        held = sum(r["held"] for r in screened.values())
        raise ConfigError(
            f"stance design: the time budget of {budget_s:g} s ran out after the hold screen of {len(screened)} "
            f"of {len(pool)} fitting candidates ({held} held, {k} asked for); give more time (--budget), fewer "
            "screen cases (--weld-seeds, --contact-seeds), or choose from the kinematics alone (--no-screen)"
        ) from None
    # The default stances through the same screen, for comparison (never rejected).
    default_screen = {s.name: screen(s).to_dict() for s in default} if screen is not None else {}
    return {"default_screen": default_screen,"default": summary(kin, sum(s.H for s in default_info)),
            "designed": summary(kin, sum(s.H for s in chosen)),
            "designed_stances": [c.stance for c in chosen], "motion_scales": [c.motion_scale for c in chosen],
            "candidates_fitting": len(pool), "frames": frames, "screened": screened}
