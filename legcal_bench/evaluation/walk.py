"""Walks: a policy run in the walking env, what it did, and how far two walks differ.

`walk` runs one episode (a policy from its spec, `PolicyRunner`, in `WalkingEnv`) and
keeps the truth a closed-loop evaluation needs: the pelvis trajectory at the policy
rate, every foot strike, mean torque and power, and whether and when it fell.
`deviation` compares a walk with the same seed's nominal one as the paper does: the
pelvis-trajectory RMS deviation (horizontal distance between the two pelvis positions
at the same times, over the common duration) and the foot-strike RMS deviation (the
k-th touchdown of each foot paired, over the common count, horizontal distance).
"""

from __future__ import annotations

import time as _time
from dataclasses import asdict, dataclass, field

import numpy as np

from legcal_bench.evaluation.metrics import mean_std, rms
from legcal_bench.robots.legmap import SIDES


@dataclass
class Walk:
    seed: int
    seconds: float  # asked for
    offsets_rad: list[float]
    correction_rad: list[float]
    time: np.ndarray  # (n,) s
    pelvis: np.ndarray  # (n, 7) [x y z qw qx qy qz]
    strikes: dict  # side -> {"time": [...], "position": [[x, y, z], ...]}
    torque_mean: float  # N m, mean |tau| over joints and steps
    power_mean: float  # W, mean sum |tau qdot|
    fallen_at: float | None
    wall_s: float
    privileged: list[str] = field(default_factory=list)  # observation terms read from the simulator
    q_enc: np.ndarray | None = None  # (n, n_joints) the encoders the software read (with `log`)
    loads: np.ndarray | None = None  # (n, 2) per-foot load: ankle force magnitude (N), else the contact load
    gravity: np.ndarray | None = None  # (n, 3) the IMU filter's gravity direction, base frame
    ang_vel: np.ndarray | None = None  # (n, 3) the gyro's rate, base frame
    ft: np.ndarray | None = None  # (n, 2, 6) ankle wrenches, where the robot has the sensors

    @property
    def upright(self) -> bool:
        return self.fallen_at is None

    def summary(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if k not in ("time", "pelvis", "strikes", "q_enc", "loads", "gravity",
                                                               "ang_vel", "ft")}
        d.update(upright=self.upright, duration_s=float(self.time[-1]) if len(self.time) else 0.0,
                 distance_m=float(np.linalg.norm(self.pelvis[-1, :2] - self.pelvis[0, :2])) if len(self.pelvis) else 0.0,
                 strike_counts={s: len(self.strikes[s]["time"]) for s in SIDES})
        return d


def walk(env, runner, seconds: float, seed: int, options: dict | None = None, on_step=None,
         log: bool = False) -> Walk:
    """One episode of `seconds` (stopping early if the robot falls). `on_step(env)`
    is called after each step (e.g. to render frames); `log` keeps the encoders and
    per-foot loads of every step (for leg odometry)."""
    u = env.unwrapped
    obs, info = env.reset(seed=seed, options=options)
    runner.reset()
    n = int(round(seconds / u.dt))
    t, pelvis = np.empty(n), np.empty((n, 7))
    logs = {"q_enc": np.empty((n, u.legmap.n_joints)), "loads": np.empty((n, 2)), "gravity": np.empty((n, 3)),
            "ang_vel": np.empty((n, 3))} if log else {}
    if log and "ft" in u.observation_space.spaces:
        logs["ft"] = np.empty((n, 2, 6))
    t0 = _time.perf_counter()
    if _direct(env, runner, on_step):
        steps, torque, power, fallen_at = _walk_sim(u, runner, obs, n, t, pelvis, logs)
    else:
        steps, torque, power, fallen_at = _walk_env(env, runner, obs, info, n, t, pelvis, logs, on_step)
    wall = _time.perf_counter() - t0
    return Walk(seed, seconds, u.offsets.tolist(), u.correction.tolist(), t[:steps], pelvis[:steps],
                u.sim.strikes.to_dict(), torque / steps, power / steps, fallen_at, wall,
                runner.privileged, **{k: v[:steps] for k, v in logs.items()})


def _direct(env, runner, on_step) -> bool:
    """True if the walk may step the simulator itself (`_walk_sim`): our walking env,
    unwrapped, driven by a policy that reads no simulator truth, nothing called per step."""
    from legcal_bench.envs.walking import WalkingEnv
    from legcal_bench.policies.runner import PolicyRunner

    return (on_step is None and env is env.unwrapped and type(env) is WalkingEnv and type(runner) is PolicyRunner
            and not runner.privileged)


def _log_step(logs: dict, k: int, obs: dict, foot_loads) -> None:
    logs["q_enc"][k], logs["gravity"][k], logs["ang_vel"][k] = obs["q_enc"], obs["gravity"], obs["ang_vel"]
    logs["loads"][k] = np.linalg.norm(obs["ft"][:, :3], axis=1) if "ft" in obs else foot_loads
    if "ft" in logs:
        logs["ft"][k] = obs["ft"]


def _walk_env(env, runner, obs, info, n, t, pelvis, logs, on_step):
    """The walk through `env.step` (any env, runner and per-step hook): (steps, summed
    mean |torque|, summed power, fall time)."""
    u = env.unwrapped
    torque, power = 0.0, 0.0
    k = 0
    for k in range(n):
        obs, _, terminated, _, info = env.step(runner.act(obs, info, u.sim.time))
        t[k], pelvis[k] = info["time"], info["pelvis_pose"]
        if logs:
            _log_step(logs, k, obs, info["foot_loads"])
        torque += float(np.abs(info["torque"]).mean())
        power += info["power"]
        if on_step is not None:
            on_step(env)
        if terminated:
            break
    return k + 1, torque, power, info["fallen_at"]


def _walk_sim(u, runner, obs, n, t, pelvis, logs):
    """`_walk_env`'s walk with the same numbers, stepping the env's simulator directly:
    the same `WalkingSim.step` and observation per control step (`WalkingEnv.advance`:
    `step` without its info dict, which the policy does not read), the truth the walk keeps read
    from the simulator (`WalkingSim.truth`'s), its torque and power sums reduced once
    at the end (the same per-step reductions, summed in the same order)."""
    from legcal_bench.sim.walking import servo_power

    sim = u.sim
    d, sc = sim.data, sim.scene
    f, dof = sc.free_qpos_adr, sc.dof_adr
    servo = sc.servo[0] if sim.body_act is None else sim.body_act[:u.legmap.n_joints]  # `WalkingSim.torques`
    tau, qvel = np.empty((n, u.legmap.n_joints)), np.empty((n, u.legmap.n_joints))
    k = 0
    for k in range(n):
        obs = u.advance(runner.act(obs, None, sim.time))
        t[k], pelvis[k], tau[k], qvel[k] = sim.time, d.qpos[f:f + 7], d.actuator_force[servo], d.qvel[dof]
        if logs:
            _log_step(logs, k, obs, sim.loads)
        if sim.fallen_at is not None:
            break
    steps = k + 1
    tau, qvel = tau[:steps], qvel[:steps]
    # per step: `np.abs(tau).mean()` and `WalkingSim.power`; summed one step after another as `_walk_env` does
    torque = float(np.add.accumulate(np.abs(tau).mean(axis=1))[-1])
    power = float(np.add.accumulate(servo_power(tau, qvel))[-1])
    return steps, torque, power, sim.fallen_at


def deviation(a: Walk, nominal: Walk) -> dict:
    """Pelvis-trajectory and foot-strike RMS deviation (mm) of `a` from `nominal`."""
    n = min(len(a.time), len(nominal.time))
    pelvis = rms(np.linalg.norm(a.pelvis[:n, :2] - nominal.pelvis[:n, :2], axis=1)) if n else np.nan
    d = []
    for s in SIDES:
        pa, pb = np.asarray(a.strikes[s]["position"]), np.asarray(nominal.strikes[s]["position"])
        m = min(len(pa), len(pb))
        if m:
            d.extend(np.linalg.norm(pa[:m, :2] - pb[:m, :2], axis=1))
    return {"pelvis_rms_mm": 1e3 * pelvis, "foot_strike_rms_mm": 1e3 * rms(d) if d else np.nan,
            "strikes_paired": len(d)}


PATTERN_SEED_BASE = 20_000  # the random:<deg> pattern of trial s comes from default_rng(PATTERN_SEED_BASE + s)


def trial_offsets(spec: str, legmap, seed: int) -> np.ndarray:
    """The offsets of trial `seed`: a fixed pattern (`paper@3`, one radian per leg joint...) is the
    same in every trial; `random:<deg>` draws one pattern per trial, trial s's from
    `default_rng(PATTERN_SEED_BASE + s)`; `random:<deg>@<seed>` fixes the patterns' seed:
    trial s's from `default_rng(<seed> + s)` (so `random:3@20000` is `random:3`)."""
    from legcal_bench.sim.offsets import parse_random, random_pattern, resolve_offsets

    if isinstance(spec, str) and spec.strip().startswith("random:"):
        deg, base = parse_random(spec)
        return random_pattern(deg, legmap, np.random.default_rng((PATTERN_SEED_BASE if base is None else base) + seed))
    return resolve_offsets(spec, legmap, np.random.default_rng(PATTERN_SEED_BASE + seed))


def walk_trials(env, runner, offsets: str, trials: int, seconds: float = 20.0, correction=None, first_seed: int = 0,
                progress: bool = True) -> dict:
    """`trials` paired walks: per seed the nominal walk (no offsets) and the walk with
    `offsets` (with `correction` applied, if given), the same seed driving noise and
    initial jitter. Returns per-trial summaries and deviations, and the aggregate."""
    from tqdm import tqdm

    rows = []
    u = env.unwrapped
    for seed in tqdm(range(first_seed, first_seed + trials), desc=f"walk {u.legmap.name} {offsets}", unit="trial",
                     disable=not progress):
        nominal = walk(env, runner, seconds, seed, {"offsets": np.zeros(u.legmap.n_joints), "correction": None})
        dq = trial_offsets(offsets, u.legmap, seed)
        w = walk(env, runner, seconds, seed, {"offsets": dq, "correction": correction})
        dev = deviation(w, nominal) if w.upright and nominal.upright else {}
        rows.append({"seed": seed, "nominal": nominal.summary(), "offsets": w.summary(), **dev})
    up_nom = sum(r["nominal"]["upright"] for r in rows)
    up = sum(r["offsets"]["upright"] for r in rows)
    both = [r for r in rows if "pelvis_rms_mm" in r]

    return {"offsets": offsets, "trials": trials, "seconds": seconds, "upright_nominal": up_nom, "upright": up,
            "pelvis_rms_mm": mean_std([r["pelvis_rms_mm"] for r in both]),
            "foot_strike_rms_mm": mean_std([r["foot_strike_rms_mm"] for r in both]),
            "wall_s_per_walk": float(np.mean([r[k]["wall_s"] for r in rows for k in ("nominal", "offsets")])),
            "privileged": runner.privileged, "rows": rows}
