"""`legcal-bench` command line. Degrees appear only here, at the edge."""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import asdict
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np


def _robot_args(p: argparse.ArgumentParser, default: str | None = "a3") -> None:
    p.add_argument("--robot", default=default,
                   help="built-in robot name (a2, a3, pair_ryp, pair_pry) or the path of a leg-map YAML "
                        f"(default: {default})")
    p.add_argument("--mjcf", default=None, help="use this MJCF instead of the one the leg map names")


def cmd_collect(a: argparse.Namespace) -> int:
    from legcal_bench.collect import CollectConfig, collect, format_summary

    cfg = CollectConfig(
        robot=a.robot, mjcf=a.mjcf, sim_robot=a.sim_model, mode=a.mode, stances=tuple(a.stances),
        offsets=a.offsets, sensors=a.sensors, seed=a.seed, heldout=a.heldout, rate_hz=a.rate,
        stance_s=a.stance_seconds, heldout_s=a.heldout_seconds, standing_s=a.standing_seconds,
        knee_straight_error_rad=float(np.deg2rad(a.knee_error_deg)))
    summary = collect(cfg, a.out, progress=not a.quiet)
    if a.json:
        print(json.dumps(asdict(summary), indent=2))
    else:
        print(format_summary(summary))
    return 0


def cmd_info(a: argparse.Namespace) -> int:
    from legcal_bench.robots import BUILTIN, load_robot

    if a.robot is None:
        print("built-in robots (or pass --robot path/to/robot.legmap.yaml):")
        for e in BUILTIN.values():
            print(f"  {e.name:<10} {e.description}  [{', '.join(e.tags)}]")
        return 0
    from legcal_bench.kinematics import LegKinematics

    legmap = load_robot(a.robot, a.mjcf)
    kin = LegKinematics(legmap)
    m, d = kin.model, kin.data
    import pinocchio as pin

    pin.framesForwardKinematics(m, d, kin.q_full(np.zeros(12)))
    R_B = d.oMf[kin.pelvis_frame].rotation
    info = {
        "name": legmap.name, "mjcf": str(legmap.mjcf), "hip_order": "->".join(r.replace("hip_", "") for r in legmap.hip_order),
        "dims_m": asdict(kin.dims), "knee_straight_deg": float(np.rad2deg(legmap.knee_straight_rad)),
        "held_joints_deg": {k: float(np.rad2deg(v)) for k, v in legmap.held_joints_rad.items()},
        "joints": [],
    }
    for i, (name, role) in enumerate(zip(legmap.joint_names, legmap.joint_roles)):
        jid = m.getJointId(name)
        axis_B = R_B.T @ d.oMi[jid].rotation @ _joint_axis(m, jid)
        info["joints"].append({
            "index": i, "name": name, "role": role, "axis_in_pelvis_at_zero": np.round(axis_B, 6).tolist(),
            "limits_deg": np.round(np.rad2deg([kin.q_lower[i], kin.q_upper[i]]), 3).tolist()})
    if a.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"{info['name']}: {info['mjcf']}")
    print(f"  hip order {info['hip_order']}; leg length {kin.dims.leg_length:.3f} m, "
          f"feet at y = ±{kin.dims.foot_y:.3f} m; sole {kin.dims.sole_length:.3f} x {kin.dims.sole_width:.3f} m")
    print(f"  {'#':>2} {'joint':<28} {'role':<12} {'axis (pelvis frame, q=0)':<26} limits (deg)")
    for j in info["joints"]:
        ax = " ".join(f"{v:+.3f}" for v in j["axis_in_pelvis_at_zero"])
        print(f"  {j['index']:>2} {j['name']:<28} {j['role']:<12} {ax:<26} "
              f"{j['limits_deg'][0]:+.1f} .. {j['limits_deg'][1]:+.1f}")
    if info["held_joints_deg"]:
        print("  held joints (deg): " + ", ".join(f"{k} {v:+.2f}" for k, v in info["held_joints_deg"].items()))
    return 0


def _joint_axis(model, jid: int) -> np.ndarray:
    """Axis of a revolute joint in its own frame (Pinocchio stores it per joint type)."""
    j = model.joints[jid]
    short = j.shortname()
    if short.endswith("RX"):
        return np.array([1.0, 0, 0])
    if short.endswith("RY"):
        return np.array([0, 1.0, 0])
    if short.endswith("RZ"):
        return np.array([0, 0, 1.0])
    return np.asarray(j.extract().axis, dtype=float)


def cmd_render(a: argparse.Namespace) -> int:
    from PIL import Image

    from legcal_bench.envs.static_double_support import StaticDoubleSupportEnv
    from legcal_bench.io_utils import atomic_write

    env = StaticDoubleSupportEnv(robot=a.robot, mjcf=a.mjcf, mode=a.mode, offsets="none", sensors="zero",
                                 render_mode="rgb_array")
    _, info = env.reset(seed=a.seed, options={"stance": a.stance})
    env.step(info["posture"])
    img = env.render()
    env.close()
    out = Path(a.out)
    atomic_write(out, lambda f: Image.fromarray(img).save(f, format="PNG"), mode="wb")
    print(f"wrote {out} ({img.shape[1]}x{img.shape[0]}, {env.legmap.name}, stance {a.stance}, {a.mode})")
    return 0


def cmd_bench_env(a: argparse.Namespace) -> int:
    from legcal_bench.bench_env import run_bench_env

    report = run_bench_env(a.robots, a.modes, a.out, seed=a.seed, progress=not a.quiet)
    print(report)
    return 0


def build_parser() -> argparse.ArgumentParser:
    from legcal_bench.offsets import PRESETS_HELP
    from legcal_bench.sensors import SENSOR_PRESETS

    p = argparse.ArgumentParser(prog="legcal-bench", description="Humanoid leg joint-offset calibration benchmark")
    sub = p.add_subparsers(dest="command", required=True)

    c = sub.add_parser("collect", help="simulate static double-support recordings with known offsets")
    _robot_args(c)
    c.add_argument("--sim-model", default=None,
                   help="simulate this robot (name or leg map) instead; recordings still name --robot, "
                        "the nominal model calibrators use")
    c.add_argument("--mode", default="weld", choices=("kinematic", "weld", "contact"), help="floor model (default weld)")
    c.add_argument("--stances", nargs="+", default=["I", "II", "III", "IV"], help="stances to record (default I II III IV)")
    c.add_argument("--offsets", default="paper", help=f"injected offsets: {PRESETS_HELP} (default paper)")
    c.add_argument("--sensors", default="realistic", choices=sorted(SENSOR_PRESETS), help="sensor model (default realistic)")
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--heldout", type=int, default=3, help="held-out sessions (default 3)")
    c.add_argument("--rate", type=float, default=50.0, help="logging rate, Hz (default 50)")
    c.add_argument("--stance-seconds", type=float, default=12.0)
    c.add_argument("--heldout-seconds", type=float, default=10.0)
    c.add_argument("--standing-seconds", type=float, default=5.0, help="straight-leg phase (0: none)")
    c.add_argument("--knee-error-deg", type=float, default=0.3,
                   help="true knee minus mechanical straight angle while standing (default 0.3)")
    c.add_argument("--out", default="runs/collect", help="output directory (default runs/collect)")
    c.add_argument("--json", action="store_true", help="print the summary as JSON")
    c.add_argument("--quiet", action="store_true", help="no progress bar")
    c.set_defaults(func=cmd_collect)

    i = sub.add_parser("info", help="list robots, or show one robot's joint order, axes and limits")
    _robot_args(i, default=None)
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=cmd_info)

    r = sub.add_parser("render", help="PNG of a robot in a stance (offscreen)")
    _robot_args(r)
    r.add_argument("--stance", default="I", help="I, II, III, IV or standing (default I)")
    r.add_argument("--mode", default="kinematic", choices=("kinematic", "weld", "contact"))
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--out", default="robot.png")
    r.set_defaults(func=cmd_render)

    b = sub.add_parser("bench-env", help="measure foot drift per floor mode and collection speed; writes a report")
    b.add_argument("--robots", nargs="+", default=["a2", "a3", "pair_ryp", "pair_pry", "examples/unitree_g1.legmap.yaml"])
    b.add_argument("--modes", nargs="+", default=["kinematic", "weld", "contact"])
    b.add_argument("--seed", type=int, default=0)
    b.add_argument("--out", default="reports/bench_env", help="report directory (markdown + JSON)")
    b.add_argument("--quiet", action="store_true")
    b.set_defaults(func=cmd_bench_env)
    return p


def main(argv: list[str] | None = None) -> int:
    from legcal_bench.kinematics import IKError
    from legcal_bench.offsets import OffsetSpecError
    from legcal_bench.recording import RecordingError
    from legcal_bench.robots.legmap import LegMapError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (LegMapError, RecordingError, OffsetSpecError, IKError, ValueError) as e:
        print(f"legcal-bench {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
