"""Collect a session set: straight-leg standing, the stances, and held-out sessions.

The collector drives the static double-support simulator (the core the Gymnasium env
wraps) with the stance protocol's posture motion and writes one recording (plus its
ground truth) per segment, then a manifest. Every segment's randomness (placement,
motion phases, sensor noise) comes from one seed; a segment recorded here equals an
env episode reset with the same seed and stepped with the same postures.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from legcal_bench.data.recording import Recording, Truth, truth_path, write_manifest
from legcal_bench.errors import ConfigError, IKError
from legcal_bench.protocol.stances import ALL_STANCES, STANCES, feasible_trajectory, place, posture_bounds
from legcal_bench.robots import load_robot
from legcal_bench.sim.double_support import DoubleSupportSim
from legcal_bench.sim.offsets import resolve_offsets
from legcal_bench.sim.scene import MODES
from legcal_bench.sim.sensors import sensor_model


@dataclass
class CollectConfig:
    robot: str = "a3"
    mjcf: str | None = None
    sim_robot: str | None = None  # simulate this robot; calibrators get `robot`
    mode: str = "weld"
    stances: tuple[str, ...] = ("I", "II", "III", "IV")
    offsets: str | tuple[float, ...] = "paper"  # a preset, or 12 radians
    sensors: str = "realistic"
    seed: int = 0
    heldout: int = 3
    rate_hz: float = 50.0
    stance_s: float = 12.0
    heldout_s: float = 10.0
    standing_s: float = 5.0
    knee_straight_error_rad: float = 0.005
    jitter_m: float = 0.015
    jitter_rad: float = 0.05
    heldout_jitter_m: float = 0.04
    heldout_jitter_rad: float = 0.1


@dataclass
class SegmentSummary:
    name: str
    kind: str
    stance: str
    frames: int
    max_gyro: float
    joint_range_deg: list[float]
    max_sole_drift_mm: float
    max_sole_drift_deg: float
    unreachable: int


@dataclass
class CollectSummary:
    out_dir: str
    config: dict
    offsets_rad: list[float]
    joint_names: list[str]
    segments: list[SegmentSummary] = field(default_factory=list)
    wall_s: float = 0.0
    sim_s: float = 0.0


def _segments(cfg: CollectConfig, rng: np.random.Generator):
    if cfg.standing_s > 0:
        yield "standing", "standing", "standing", cfg.standing_s, 0.0, 0.0
    for s in cfg.stances:
        if s not in STANCES:
            raise ConfigError(f"stance {s!r}: use stances from {list(STANCES)}")
        yield f"stance_{s}", "stance", s, cfg.stance_s, cfg.jitter_m, cfg.jitter_rad
    # Held-out sessions are drawn from the stances being recorded (a robot that cannot
    # hold a lunge is not asked for one in its held-out sessions either).
    for i in range(cfg.heldout):
        s = str(rng.choice(list(cfg.stances)))
        yield f"heldout_{i + 1}", "heldout", s, cfg.heldout_s, cfg.heldout_jitter_m, cfg.heldout_jitter_rad


def record_segment(sim: DoubleSupportSim, stance: str, duration: float, seed: int, jitter_m: float,
                   jitter_rad: float, progress=None) -> tuple[dict, dict]:
    """Run one segment; returns stacked observations and ground truth. The posture
    motion's IK is solved once, in one batch (`feasible_trajectory`), and handed to the
    simulator (`DoubleSupportSim.run`)."""
    rng = np.random.default_rng(seed)  # the stream Gymnasium's reset(seed=seed) gives the env
    placement = place(ALL_STANCES[stance], sim.true_kin.dims, rng, jitter_m, jitter_rad)
    try:
        sim.reset(placement.left, placement.right, placement.nominal, standing=stance == "standing")
    except IKError as e:
        raise IKError(f"stance {stance} ({ALL_STANCES[stance].label}): its nominal posture is out of this robot's "
                      f"reach ({e}); record the other stances (--stances), or widen the joint's range in the MJCF "
                      "if the real robot allows it") from None
    sim.observe(rng)  # the reset observation (not logged; its noise draws keep the env's stream)
    n = int(round(duration * sim.rate_hz))
    low, high = posture_bounds(sim.nominal.dims)
    if stance == "standing":
        return sim.run(np.clip(np.repeat(sim.posture[None], n, axis=0), low, high), rng, progress=progress)
    traj, q_cmd = feasible_trajectory(sim.nominal, placement, duration, sim.rate_hz,
                                      np.random.default_rng(seed + 7919), return_q=True)
    clipped = np.clip(traj, low, high)
    q_cmd[(clipped != traj).any(axis=1)] = np.nan  # a clipped posture is solved by the simulator's step
    return sim.run(clipped, rng, q_cmd=q_cmd, progress=progress)


def collect(cfg: CollectConfig, out_dir: str | Path, progress: bool = True) -> CollectSummary:
    out_dir = Path(out_dir)
    if cfg.mode not in MODES:
        raise ConfigError(f"mode {cfg.mode!r}: use one of {MODES}")
    legmap = load_robot(cfg.robot, cfg.mjcf)
    sim = DoubleSupportSim(
        legmap, cfg.mode, resolve_offsets(cfg.offsets, legmap, np.random.default_rng(cfg.seed)),
        sensor_model(cfg.sensors), sim_legmap=None if cfg.sim_robot is None else load_robot(cfg.sim_robot),
        rate_hz=cfg.rate_hz, knee_straight_error_rad=cfg.knee_straight_error_rad)
    ss = np.random.SeedSequence(cfg.seed)
    plan = list(_segments(cfg, np.random.default_rng(ss.spawn(1)[0])))
    seeds = [int(s.generate_state(1)[0]) for s in ss.spawn(len(plan) + 1)[1:]]
    total = sum(int(round(duration * cfg.rate_hz)) for _, _, _, duration, _, _ in plan)
    summary = CollectSummary(str(out_dir), asdict(cfg), sim.offsets.tolist(), legmap.joint_names)
    session = f"{legmap.name}-{cfg.mode}-seed{cfg.seed}"
    files = []
    t0 = time.perf_counter()
    bar = tqdm(total=total, desc=f"collect {legmap.name} ({cfg.mode})", unit="frame", disable=not progress)
    for (name, kind, stance, duration, jm, jr), seed in zip(plan, seeds):
        bar.set_postfix_str(name)
        obs, tr = record_segment(sim, stance, duration, seed, jm, jr, bar)
        rec = Recording(
            name=name, kind=kind, stance=stance, robot=legmap.name, joint_names=legmap.joint_names,
            time=tr["time"], q_enc=obs["q_enc"], imu_acc=obs["imu_acc"], imu_gyro=obs["imu_gyro"],
            sensor_model=sim.sensor, ft=obs.get("ft"), source=f"sim:{cfg.mode}", session=session)
        path = rec.save(out_dir / f"{name}.npz")
        Truth(
            q_true=tr["q_true"], offsets=sim.offsets, sole_poses_world=tr["sole_poses_world"],
            pelvis_pose_world=tr["pelvis_pose_world"], posture=tr["posture"],
            posture_reachable=tr["posture_reachable"], imu_true_acc=tr["imu_true_acc"],
            imu_true_gyro=tr["imu_true_gyro"],
            meta={"mode": cfg.mode, "sim_robot": sim.sim_legmap.name, "seed": seed,
                  "knee_straight_error_rad": cfg.knee_straight_error_rad if kind == "standing" else None,
                  "knee_straight_rad": sim.sim_legmap.knee_straight_rad, "offsets_spec": str(cfg.offsets)},
        ).save(truth_path(path))
        files.append(path.name)
        summary.segments.append(SegmentSummary(
            name=name, kind=kind, stance=stance, frames=rec.n_frames,
            max_gyro=float(np.abs(rec.imu_gyro).max()),
            joint_range_deg=np.rad2deg(np.ptp(tr["q_true"], axis=0)).round(2).tolist(),
            max_sole_drift_mm=float(tr["sole_drift_m"].max() * 1e3),
            max_sole_drift_deg=float(np.rad2deg(tr["sole_drift_rad"].max())),
            unreachable=int((~tr["posture_reachable"]).sum())))
    bar.close()
    summary.wall_s = time.perf_counter() - t0
    summary.sim_s = total / cfg.rate_hz
    write_manifest(out_dir, {"robot": legmap.name, "mode": cfg.mode, "seed": cfg.seed,
                             "sensor_model": sim.sensor.to_dict(), "files": files, "config": asdict(cfg)})
    return summary


def format_summary(s: CollectSummary) -> str:
    lines = [
        f"wrote {len(s.segments)} recordings to {s.out_dir}  "
        f"({sum(g.frames for g in s.segments)} frames, {s.sim_s:.0f} s simulated in {s.wall_s:.1f} s wall, "
        f"{s.sim_s / max(s.wall_s, 1e-9):.1f}x real time)",
        "injected offsets (deg): " + ", ".join(
            f"{n.replace('_joint', '')} {np.rad2deg(v):+.3f}" for n, v in zip(s.joint_names, s.offsets_rad)),
        f"{'segment':<12} {'kind':<9} {'stance':<9} {'frames':>6} {'max|gyro|':>10} {'sole drift':>18} "
        f"{'joint range (deg, min..max over 12)':>36}",
    ]
    for g in s.segments:
        lines.append(
            f"{g.name:<12} {g.kind:<9} {g.stance:<9} {g.frames:>6} {g.max_gyro:>8.3f}/s "
            f"{g.max_sole_drift_mm:>8.4f} mm {g.max_sole_drift_deg:>6.4f}° "
            f"{min(g.joint_range_deg):>15.2f} .. {max(g.joint_range_deg):.2f}"
            + (f"  ({g.unreachable} unreachable postures held)" if g.unreachable else "")
            + ("  WARNING: a sole moved more than 5 mm (slip or fall): not static contact"
               if g.max_sole_drift_mm > 5.0 else ""))
    return "\n".join(lines)
