"""The training recipe's settings (`legcal_bench.evaluation.distill`, which runs it):
standard library only, so that `legcal-bench train-policy --help` shows its defaults
without loading the simulation."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DistillConfig:
    iterations: int = 7
    rollouts: int = 16  # per iteration
    seconds: float = 20.0  # per rollout
    offsets_deg: float = 3.0  # training offsets: uniform +- per joint
    friction: tuple[float, float] = (0.7, 1.3)  # floor sliding friction range
    mass_jitter: float = 0.05  # body masses x (1 +- this)
    beta_decay: float = 0.5  # teacher share in DAgger iteration i: beta_decay ** i
    hidden: tuple[int, ...] = (256, 128)
    train_steps: int = 1500  # Adam steps per iteration
    batch: int = 512
    lr: float = 1e-3
    action_scale: float = 0.25  # target = default_q + action_scale * action
    eval_rollouts: int = 6  # random patterns in the selection set
    eval_deg: float = 3.0  # the selection set's paper@<deg>
    seed: int = 0
