"""A model-based walker for robots without a policy of their own: footsteps, a ZMP
reference, the CoM from ZMP preview control, swing-foot arcs, and the joint targets by
closed-chain IK (issue #14, started: open loop, no feedback yet).

The gait: from a standing squat (`GaitParams.depth` below straight legs), steps of
`step_length` every `step_period`, the right foot first; each step begins with a double
support share in which the ZMP shifts to the stance foot, then the swing foot travels
on a cycloid (`lift` high). The CoM follows the ZMP through `zmp_preview.track` (height:
the pelvis's), the pelvis is the CoM less its offset at the starting pose, and the
joint targets come from `posture_ik` with both soles where the plan puts them, so the
targets always close the chain. Open loop, it walks the A3-like robot when the encoders
are right and falls within seconds with `paper@1` (measured by the test and
`legcal-bench walk`): feedback on the IMU and stiffer ankles come next.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from legcal_bench.geometry.poses import pose_xyz_rpy
from legcal_bench.policies.zmp_preview import preview_gains, track
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.sim.double_support import posture_ik


@dataclass(frozen=True)
class GaitParams:
    step_length: float = 0.12  # m
    step_period: float = 0.5  # s per step
    double_support: float = 0.2  # share of a step with both feet down
    lift: float = 0.04  # m, swing-foot height
    depth: float = 0.08  # squat depth, leg lengths
    start_s: float = 1.0  # standing before the first step
    end_s: float = 1.5  # standing after the last
    dt: float = 0.01  # s, the plan's (and the walker's control) period
    com_x_bias: float = 0.0  # m, the planned CoM ahead (+) or behind (-) of the ZMP reference


@dataclass
class Gait:
    time: np.ndarray  # (n,)
    zmp: np.ndarray  # (n, 2) reference
    left: np.ndarray  # (n, 3) sole positions (flat soles)
    right: np.ndarray
    distance: float  # planned forward distance (m)


def plan_gait(kin: LegKinematics, n_steps: int, p: GaitParams = GaitParams()) -> Gait:
    """Footsteps and the ZMP reference for `n_steps` steps (the last one closes the feet)."""
    y0, dt = kin.dims.foot_y, p.dt
    n = int(round((p.start_s + n_steps * p.step_period + p.end_s) / dt))
    t = np.arange(n) * dt
    feet = {"left": np.zeros((n, 3)), "right": np.zeros((n, 3))}
    feet["left"][:, 1], feet["right"][:, 1] = y0, -y0
    zmp = np.zeros((n, 2))
    x = {"left": 0.0, "right": 0.0}
    for i in range(n_steps):
        swing = "right" if i % 2 == 0 else "left"
        stance = "left" if swing == "right" else "right"
        start = x[swing]
        target = max(x.values()) if i == n_steps - 1 else x[stance] + p.step_length
        t0 = p.start_s + i * p.step_period
        k0, k1 = int(round(t0 / dt)), int(round((t0 + p.step_period) / dt))
        s = (t[k0:k1] - t0) / p.step_period
        mid = np.array([(x["left"] + x["right"]) / 2, 0.0])
        foot = np.array([x[stance], y0 if stance == "left" else -y0])
        a = np.clip(s / p.double_support, 0, 1)[:, None]
        zmp[k0:k1] = mid + a * (foot - mid)
        b = np.clip((s - p.double_support) / (1 - p.double_support), 0, 1)
        feet[swing][k0:k1, 0] = start + (target - start) * (b - np.sin(2 * np.pi * b) / (2 * np.pi))
        feet[swing][k0:k1, 2] = p.lift * (1 - np.cos(2 * np.pi * b)) / 2
        x[swing] = target
        feet[swing][k1:, 0] = target
    end = int(round((p.start_s + n_steps * p.step_period) / dt))
    zmp[end:] = [(x["left"] + x["right"]) / 2, 0.0]
    return Gait(t, zmp, feet["left"], feet["right"], max(x.values()))


def joint_targets(kin: LegKinematics, gait: Gait, p: GaitParams = GaitParams()) -> np.ndarray:
    """(n, 12) joint targets: the CoM by preview control, the pelvis under it, IK."""
    z = kin.dims.leg_length * (1 - p.depth)
    g = preview_gains(z, p.dt)
    cx, _ = track(g, gait.zmp[:, 0])
    cy, _ = track(g, gait.zmp[:, 1])
    postures = np.zeros((len(gait.time), 6))
    postures[:, 2] = z
    q = posture_ik(kin, pose_xyz_rpy(gait.left[0], [0, 0, 0]), pose_xyz_rpy(gait.right[0], [0, 0, 0]), postures[:1])[0]
    com = kin.com(q)  # the CoM in the pelvis frame at the starting pose
    postures[:, 0], postures[:, 1] = cx[:, 0] + p.com_x_bias - com[0], cy[:, 0] - com[1]
    Q = np.empty((len(gait.time), 12))
    for k in range(len(gait.time)):
        q = posture_ik(kin, pose_xyz_rpy(gait.left[k], [0, 0, 0]), pose_xyz_rpy(gait.right[k], [0, 0, 0]),
                       postures[k:k + 1], q)[0]
        Q[k] = q
    return Q
