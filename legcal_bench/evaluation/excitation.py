"""A learned excitation policy in miniature: the static env's reward as the objective.

The static double-support env rewards each frame with its information gain about the
offsets, one per leg joint (the increase of log det(H_data + εI), `InformationGain`), so an episode's
return is the log-determinant of the information its motion collected (less the reset
frame's): a D-optimal
design objective that any policy learner can maximize without knowing the calibration.
This example learns the smallest policy there is, open-loop: the stance's posture
motion (`posture_trajectory`: sinusoids with the protocol's periods) with six learned
amplitudes, each a factor in [0, `MAX_FACTOR`] on the stance's own, trained by the
cross-entropy method on the episode return. The hold check is the constraint: an
episode whose pelvis strays beyond the hold limit, or with a posture out of reach, scores
-inf (a robot team cannot record it). It reports, for the same stance, frames and noise
seed: no motion, the protocol's motion (factors 1) and the learned one, with the
smallest eigenvalue of the information each gathered (`legcal-bench excite`).

A richer policy (closed-loop on the observations, several stances, the contact floor)
plugs into the same env and reward; `legcal-bench design` solves the related problem by
selection instead of learning (E-optimal, across stances).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from tqdm import tqdm

from legcal_bench.errors import ConfigError
from legcal_bench.protocol.stances import ALL_STANCES, posture_trajectory
from legcal_bench.sim.hold import HOLD_LIMITS

MAX_FACTOR = 3.0  # the learned amplitudes: up to three times the stance's (as `design --ranges wide`)


@dataclass
class Episode:
    factors: list[float]  # amplitude factors on the stance's (x, y, z, roll, pitch, yaw)
    episode_return: float  # sum of rewards = log det(H + εI) gained since the reset frame
    lambda_min: float  # smallest eigenvalue of the information gathered (mm, mrad units)
    pelvis_mm: float  # the largest pelvis hold error
    reachable: bool
    held: bool


@dataclass
class ExcitationResult:
    robot: str
    stance: str
    mode: str
    frames: int
    still: Episode
    protocol: Episode
    learned: Episode
    history: list[float] = field(default_factory=list)  # best return after each iteration

    def to_dict(self) -> dict:
        from dataclasses import asdict

        return asdict(self)


def run_episode(env, factors: np.ndarray, stance: str, frames: int, seed: int) -> Episode:
    """One episode of the open-loop motion with these amplitude factors, on `env`
    (a static double-support env), reset with `seed` and no placement jitter."""
    u = env.unwrapped
    env.reset(seed=seed, options={"stance": stance, "jitter_m": 0.0, "jitter_rad": 0.0})
    placement = u.placement
    dims = u.sim.nominal.dims
    scaled = replace(placement, stance=replace(placement.stance, amplitude=tuple(
        float(a * f) for a, f in zip(placement.stance.amplitude, factors))))
    postures = posture_trajectory(scaled, dims, frames / u.sim.rate_hz, u.sim.rate_hz, np.random.default_rng(seed))
    total, pelvis, reachable = 0.0, 0.0, True
    for p in postures:
        _, r, _, _, info = env.step(p)
        total += r
        pelvis = max(pelvis, float(info["pelvis_hold_error_m"]))
        reachable &= bool(info["posture_reachable"])
    limit = HOLD_LIMITS.pelvis_leg_fraction * dims.leg_length
    lam = float(np.linalg.eigvalsh(u.information_matrix)[0])
    return Episode([float(f) for f in factors], float(total), lam, pelvis * 1e3, reachable,
                   reachable and pelvis <= limit)


def learn_excitation(robot: str = "a2", stance: str = "I", mode: str = "weld", frames: int = 600,
                     iterations: int = 6, population: int = 12, elite: int = 3, seed: int = 0,
                     progress: bool = True, mjcf: str | None = None) -> ExcitationResult:
    """Cross-entropy method over the six amplitude factors (Gaussian, clipped to
    [0, MAX_FACTOR]), all episodes on the same noise seed so they differ only by the
    motion. Returns the three episodes compared and the best return per iteration."""
    import gymnasium as gym

    from legcal_bench.envs import env_id  # noqa: F401  (registers the ids)

    if stance not in ALL_STANCES or stance == "standing":
        raise ConfigError(f"--stance {stance!r}: use one of {[s for s in ALL_STANCES if s != 'standing']}")
    if iterations < 1 or population < 2 or not 1 <= elite < population or frames < 50:
        raise ConfigError(f"--iterations {iterations} / --population {population} / --elite {elite} / --frames "
                          f"{frames}: need iterations >= 1, 1 <= elite < population, frames >= 50")
    env = gym.make("legcal/StaticDoubleSupport-Path-v0", robot=robot, mode=mode, offsets="paper",
                   sensors="realistic", mjcf=mjcf, max_episode_steps=frames + 1)
    rng = np.random.default_rng(seed)
    still = run_episode(env, np.zeros(6), stance, frames, seed)
    protocol = run_episode(env, np.ones(6), stance, frames, seed)
    mean, std = np.ones(6), np.full(6, 0.8)
    best, history = protocol, []
    bar = tqdm(total=iterations * population, desc=f"excite {robot} ({mode})", unit="episode", disable=not progress)
    for _ in range(iterations):
        eps = [run_episode(env, np.clip(mean + std * rng.standard_normal(6), 0, MAX_FACTOR), stance, frames, seed)
               for _ in range(population) if not bar.update(1)]
        scored = sorted(eps, key=lambda e: e.episode_return if e.held else -np.inf, reverse=True)
        top = [e for e in scored[:elite] if e.held]
        if top:
            mean = np.mean([e.factors for e in top], axis=0)
            std = np.maximum(np.std([e.factors for e in top], axis=0), 0.05)
            if top[0].episode_return > best.episode_return:
                best = top[0]
        else:
            std = std * 0.7  # nothing held: search closer to the current mean
        history.append(best.episode_return)
        bar.set_postfix_str(f"best return {best.episode_return:.2f}")
    bar.close()
    env.close()
    return ExcitationResult(robot, stance, mode, frames, still, protocol, best, history)
