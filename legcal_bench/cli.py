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
    info = {
        "name": legmap.name, "mjcf": str(legmap.mjcf), "hip_order": "->".join(r.replace("hip_", "") for r in legmap.hip_order),
        "dims_m": asdict(kin.dims), "knee_straight_deg": float(np.rad2deg(legmap.knee_straight_rad)),
        "held_joints_deg": {k: float(np.rad2deg(v)) for k, v in legmap.held_joints_rad.items()},
        "joints": [],
    }
    axes = kin.joint_axes()
    for i, (name, role) in enumerate(zip(legmap.joint_names, legmap.joint_roles)):
        info["joints"].append({
            "index": i, "name": name, "role": role, "axis_in_pelvis_at_zero": np.round(axes[i], 6).tolist(),
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


def _parse_options(pairs: list[str]) -> dict:
    out = {}
    for pair in pairs or []:
        if "=" not in pair:
            raise ValueError(f"--option {pair!r}: write key=value")
        k, v = pair.split("=", 1)
        try:
            out[k] = json.loads(v)
        except json.JSONDecodeError:
            out[k] = v
    return out


def cmd_calibrate(a: argparse.Namespace) -> int:
    from legcal_bench.calibration import get_calibrator
    from legcal_bench.recording import load_session
    from legcal_bench.robots import load_robot

    legmap = load_robot(a.robot, a.mjcf)
    recordings = load_session(a.bags, legmap.joint_names)
    options = _parse_options(a.option)
    if a.setting is not None:
        options["setting"] = a.setting
    if a.solver is not None:
        options["solver"] = a.solver
    result = get_calibrator(a.calibrator, **options).calibrate(legmap, recordings)
    result.settings["robot_spec"] = str(a.robot)
    result.save(a.out)
    if a.plots and result.conditioning.get("eigenvalues_H_data"):
        from legcal_bench.observability import plot_observability

        plot_observability(result.conditioning, legmap.joint_names, Path(a.plots) / "observability.png",
                           title=f"{legmap.name} {result.calibrator}")
    print(format_result(result, legmap.joint_names))
    print(f"wrote {a.out}")
    return 0


def format_result(result, names: list[str]) -> str:
    c = result.conditioning
    lines = [f"{result.calibrator} on {result.robot}: offsets (deg)"]
    for n in names:
        lines.append(f"  {n:<28} {np.rad2deg(result.offsets_rad[n]):+8.4f}")
    if result.pitch_sums_rad:
        ps = result.pitch_sums_rad
        lines.append("pitch sums (deg): " + ", ".join(f"{k} {np.rad2deg(v):+.4f}" for k, v in ps.items()))
    if c:
        lines.append(f"conditioning: kappa(J_data) {c['kappa_J_data']:.4g}, kappa(H_data) {c['kappa_H_data']:.4g}, "
                     f"kappa(H_reg) {c['kappa_H_reg']:.4g}")
    lines.append("time (s): " + ", ".join(f"{k} {v:.3f}" for k, v in result.timing_s.items()))
    lines += [f"WARNING: {w}" for w in result.warnings]
    return "\n".join(lines)


def cmd_score(a: argparse.Namespace) -> int:
    from legcal_bench.calibration import CalibrationResult
    from legcal_bench.robots import load_robot
    from legcal_bench.scoring import score

    result = CalibrationResult.load(a.result)
    legmap = load_robot(a.robot or result.settings.get("robot_spec", result.robot))
    s = score(a.bags, result, legmap)
    if not a.residuals:
        s.get("heldout", {}).pop("foot_height_residuals_mm", None)
    if a.json:
        print(json.dumps(s, indent=2))
        return 0
    if "recovery" in s:
        r = s["recovery"]
        print(f"recovery: RMS {r['rms_error_deg']:.4g} deg, max {r['max_error_deg']:.4g} deg; pitch-sum errors (deg) "
              + ", ".join(f"{k} {v:+.4g}" for k, v in r["pitch_sum_error_deg"].items()))
    if "heldout" in s:
        h = s["heldout"]
        print(f"held-out ({h['frames']} frames): foot height RMS {h['foot_height_rms_mm']['before']:.3f} -> "
              f"{h['foot_height_rms_mm']['after']:.3f} mm, sole normal RMS {h['sole_normal_rms_deg']['before']:.3f} -> "
              f"{h['sole_normal_rms_deg']['after']:.3f} deg")
        if "foot_height_rms_true_mm" in h:
            t = h["foot_height_rms_true_mm"]
            print(f"  on the true held-out postures (noise-free): foot height RMS {t['before']:.4f} -> {t['after']:.4f} mm")
    return 0


def cmd_reproduce(a: argparse.Namespace) -> int:
    from legcal_bench.reproduce import reproduce

    print(reproduce(a.out, progress=not a.quiet))
    return 0


def cmd_bench_speed(a: argparse.Namespace) -> int:
    from legcal_bench.bench_speed import run_bench_speed

    print(run_bench_speed(a.out, robot=a.robot, repeats=a.repeats, progress=not a.quiet))
    return 0


def cmd_bench(a: argparse.Namespace) -> int:
    import time

    from legcal_bench import bench
    from legcal_bench.leaderboard import generate

    if a.suite not in bench.SUITES:
        raise ValueError(f"--suite {a.suite!r}: use one of {list(bench.SUITES)}")
    cells = bench.plan(a.suite, robots=a.robots, modes=a.modes, seeds=a.seeds, calibrators=a.calibrators)
    out = Path(a.out)
    t0 = time.perf_counter()
    counts = bench.run(cells, a.data, out / "results", workers=a.workers, scheduler=a.scheduler, progress=not a.quiet)
    wall = time.perf_counter() - t0
    text = generate(out)
    tables = text[text.index("## "):text.index("## Matched comparison")] if "## " in text else text
    print("\n".join(line for line in tables.splitlines() if not line.startswith("![")).strip() + "\n")
    print(f"{counts['computed']} cells computed, {counts['skipped']} already done, {wall:.0f} s wall; "
          f"leaderboard: {out / 'README.md'}")
    return 0


def cmd_sweep(a: argparse.Namespace) -> int:
    from legcal_bench import bench

    cells = bench.plan("sweep", robots=a.robots, modes=[a.mode], seeds=a.seeds, scales=a.scales,
                       calibrators=a.calibrators,
                       collect_overrides=dict(stance_s=a.stance_seconds, heldout=a.heldout))
    out = Path(a.out)
    counts = bench.run(cells, Path(a.out) / "data", out / "results", workers=a.workers, scheduler=a.scheduler,
                       progress=not a.quiet)
    rows: dict = {}
    for c in cells:
        r = json.loads(c.path(out / "results").read_text())
        key = (bench.robot_label(c.robot), f"{c.calibrator}-{c.variant}", c.scale)
        rows.setdefault(key, []).append(r["injected"]["score"]["recovery"]["rms_error_deg"])
    print(f"{'robot':<12} {'calibrator-variant':<22} {'scale':>6} {'recovery RMS (deg), mean ± std':>32}")
    for (robot, name, scale), v in sorted(rows.items()):
        print(f"{robot:<12} {name:<22} {scale:>6g} {np.mean(v):>20.4f} ± {np.std(v):.4f}")
    print(f"{counts['computed']} cells computed, {counts['skipped']} already done; results in {out / 'results'}")
    return 0


def cmd_leaderboard(a: argparse.Namespace) -> int:
    from legcal_bench.leaderboard import generate

    generate(a.out)
    print(f"wrote {Path(a.out) / 'README.md'}")
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

    k = sub.add_parser("calibrate", help="estimate the offsets from a directory of recordings")
    _robot_args(k)
    k.add_argument("--bags", required=True, help="directory of recordings (legcal-bench collect --out, or your own)")
    k.add_argument("--calibrator", default="interfoot", help="registered calibrator name (default interfoot)")
    k.add_argument("--setting", default=None, help="interfoot: operating (default), matched, a3_operating, a2_operating")
    k.add_argument("--solver", default=None, help="interfoot: projected (default) or alternating (the paper's)")
    k.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="any calibrator option, e.g. --option lambda_q=0.1 (repeatable)")
    k.add_argument("--out", default="result.json", help="result JSON (default result.json)")
    k.add_argument("--plots", default=None, help="directory for the observability plot")
    k.set_defaults(func=cmd_calibrate)

    sc = sub.add_parser("score", help="score a result against the ground truth kept with simulated recordings")
    sc.add_argument("--bags", required=True)
    sc.add_argument("--result", required=True)
    sc.add_argument("--robot", default=None, help="robot (default: the one the result was calibrated for)")
    sc.add_argument("--json", action="store_true")
    sc.add_argument("--residuals", action="store_true", help="include per-frame held-out residuals in the JSON")
    sc.set_defaults(func=cmd_score)

    bn = sub.add_parser("bench", help="run a benchmark suite (collect, calibrate, score every cell) and the leaderboard")
    bn.add_argument("--suite", default="smoke", help="smoke (default), standard or full")
    bn.add_argument("--robots", nargs="+", default=None, help="override the suite's robots")
    bn.add_argument("--modes", nargs="+", default=None, help="override the suite's floor modes")
    bn.add_argument("--seeds", type=int, default=None, help="override the suite's number of seeds")
    bn.add_argument("--calibrators", nargs="+", default=None, help="only these registered calibrators")
    bn.add_argument("--workers", type=int, default=2, help="local worker processes (default 2)")
    bn.add_argument("--scheduler", default=None, help="Dask scheduler address (tcp://host:8786): run there instead")
    bn.add_argument("--data", default="runs/bench/data", help="where session sets are cached")
    bn.add_argument("--out", default="leaderboard", help="leaderboard root: results/ and README.md (default leaderboard)")
    bn.add_argument("--quiet", action="store_true")
    bn.set_defaults(func=cmd_bench)

    sw = sub.add_parser("sweep", help="seeds x robots x calibrators x offset scales, through local processes or Dask")
    sw.add_argument("--robots", nargs="+", default=["a2", "a3"])
    sw.add_argument("--calibrators", nargs="+", default=None)
    sw.add_argument("--mode", default="weld")
    sw.add_argument("--seeds", type=int, default=3)
    sw.add_argument("--scales", nargs="+", type=float, default=[0.5, 1.0, 2.0], help="multiples of the paper's injection")
    sw.add_argument("--stance-seconds", type=float, default=12.0)
    sw.add_argument("--heldout", type=int, default=3)
    sw.add_argument("--workers", type=int, default=2)
    sw.add_argument("--scheduler", default=None, help="Dask scheduler address")
    sw.add_argument("--out", default="runs/sweep")
    sw.add_argument("--quiet", action="store_true")
    sw.set_defaults(func=cmd_sweep)

    lb = sub.add_parser("leaderboard", help="regenerate leaderboard/README.md and plots from the result files")
    lb.add_argument("--out", default="leaderboard")
    lb.set_defaults(func=cmd_leaderboard)

    rp = sub.add_parser("reproduce", help="the paper's experiments side by side with its numbers (markdown report)")
    rp.add_argument("--out", default="reports/reproduction")
    rp.add_argument("--quiet", action="store_true")
    rp.set_defaults(func=cmd_reproduce)

    bs = sub.add_parser("bench-speed", help="time the inter-foot solve (analytic vs forward-difference Jacobians)")
    bs.add_argument("--robot", default="a3")
    bs.add_argument("--repeats", type=int, default=5)
    bs.add_argument("--out", default="reports/bench_speed")
    bs.add_argument("--quiet", action="store_true")
    bs.set_defaults(func=cmd_bench_speed)

    b = sub.add_parser("bench-env", help="measure foot drift per floor mode and collection speed; writes a report")
    b.add_argument("--robots", nargs="+", default=["a2", "a3", "pair_ryp", "pair_pry", "examples/unitree_g1.legmap.yaml"])
    b.add_argument("--modes", nargs="+", default=["kinematic", "weld", "contact"])
    b.add_argument("--seed", type=int, default=0)
    b.add_argument("--out", default="reports/bench_env", help="report directory (markdown + JSON)")
    b.add_argument("--quiet", action="store_true")
    b.set_defaults(func=cmd_bench_env)
    return p


def main(argv: list[str] | None = None) -> int:
    from legcal_bench.calibration import CalibrationError
    from legcal_bench.kinematics import IKError
    from legcal_bench.offsets import OffsetSpecError
    from legcal_bench.recording import RecordingError
    from legcal_bench.robots.legmap import LegMapError

    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (LegMapError, RecordingError, OffsetSpecError, IKError, CalibrationError, ValueError) as e:
        print(f"legcal-bench {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
