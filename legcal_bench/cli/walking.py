"""`legcal-bench walk`: a policy from its spec walking a robot, with offsets and an
optional correction; one walk or paired trials."""

from __future__ import annotations

import argparse
import json

from legcal_bench.cli.robots import robot_args


def _correction(path, legmap):
    if path is None:
        return None
    from legcal_bench.calibrators.base import CalibrationResult

    return CalibrationResult.load(path).offsets_vector(legmap.joint_names)


def cmd_walk(a: argparse.Namespace) -> int:
    import numpy as np

    from legcal_bench.envs.walking import WalkingEnv
    from legcal_bench.errors import ConfigError
    from legcal_bench.evaluation.walk import trial_offsets, walk, walk_trials
    from legcal_bench.policies.runner import PolicyRunner
    from legcal_bench.provenance import code_version, describe

    if a.seconds <= 0 or a.trials < 0:
        raise ConfigError(f"--seconds {a.seconds} / --trials {a.trials}: need seconds > 0 and trials >= 0")
    env = WalkingEnv(robot=a.robot, policy=a.policy, sensors=a.sensors, mjcf=a.mjcf,
                     render_mode="rgb_array" if a.strip else None, width=320, height=400)
    runner = PolicyRunner(env.policy_spec, env.legmap)
    correction = _correction(a.correction, env.legmap)
    code = describe(code_version())
    made_by = (f"legcal-bench walk --robot {a.robot} --policy {a.policy} --offsets {a.offsets} --seconds {a.seconds:g} "
               f"--sensors {a.sensors}" + (f" --trials {a.trials}" if a.trials else f" --seed {a.seed}")
               + (f" --correction {a.correction}" if a.correction else ""))
    if a.trials:
        out = walk_trials(env, runner, a.offsets, a.trials, a.seconds, correction, progress=not a.json)
        out.update(code=code, made_by=made_by, robot=env.legmap.name, policy=runner.spec.name)
        if a.out:
            from legcal_bench.files.atomic import atomic_write_json

            atomic_write_json(a.out, out)
        if a.json:
            print(json.dumps(out, indent=2, default=float))
            return 0
        print(f"{env.legmap.name}, policy {runner.spec.name}, {a.trials} trials x {a.seconds:g} s, offsets {a.offsets}, "
              f"sensors {a.sensors} ({code})")
        priv = f"; privileged observation terms: {', '.join(out['privileged'])}" if out["privileged"] else ""
        print(f"  upright: nominal {out['upright_nominal']}/{a.trials}, with offsets {out['upright']}/{a.trials}{priv}")
        for key in ("pelvis_rms_mm", "foot_strike_rms_mm"):
            if out[key]:
                print(f"  {key}: {out[key]['mean']:.0f} +- {out[key]['std']:.0f} (trials upright in both)")
        print(f"  wall per walk: {out['wall_s_per_walk']:.2f} s")
        if a.out:
            print(f"wrote {a.out}")
        return 0
    frames = []
    every = max(1, int(round(a.strip_every / env.dt)))

    def grab(e):
        if a.strip and int(round(e.unwrapped.sim.time / e.unwrapped.dt)) % every == 0:
            frames.append(e.render())

    dq = trial_offsets(a.offsets, env.legmap, a.seed)
    w = walk(env, runner, a.seconds, a.seed, {"offsets": dq, "correction": correction}, on_step=grab)
    s = {**w.summary(), "code": code, "made_by": made_by, "robot": env.legmap.name, "policy": runner.spec.name}
    if a.strip and frames:
        from legcal_bench.reports.walking import write_strip

        s["strip"] = str(write_strip(frames, a.strip, every * env.dt))
    if a.out:
        from legcal_bench.files.atomic import atomic_write_json

        atomic_write_json(a.out, {**s, "time": w.time.tolist(), "pelvis": w.pelvis.tolist(), "strikes": w.strikes})
    if a.json:
        print(json.dumps(s, indent=2, default=float))
        return 0
    state = "upright" if w.upright else f"FELL at {w.fallen_at:.2f} s"
    print(f"{env.legmap.name}, policy {runner.spec.name}, seed {a.seed}, offsets {a.offsets} "
          f"(max {np.degrees(np.abs(dq)).max():.2f} deg): {state}; walked {s['distance_m']:.2f} m in "
          f"{s['duration_s']:.1f} s, strikes L/R {s['strike_counts']['left']}/{s['strike_counts']['right']}, mean "
          f"torque {w.torque_mean:.1f} N m, power {w.power_mean:.0f} W; {w.wall_s:.2f} s wall ({code})")
    if "strip" in s:
        print(f"wrote {s['strip']}")
    return 0


def add_commands(sub) -> None:
    from legcal_bench.sim.offsets import PRESETS_HELP

    w = sub.add_parser("walk", help="a policy (from its spec) walking a robot, with encoder offsets and an optional "
                                    "correction: one walk, or paired trials against the nominal walk")
    robot_args(w)
    w.add_argument("--policy", required=True, help="policy spec YAML (see legcal_bench/policies/spec.py; e.g. "
                                                   "examples/unitree_g1.policy.yaml)")
    w.add_argument("--offsets", default="none", help=f"encoder offsets: {PRESETS_HELP}; also paper@<deg>; "
                                                     "random:<deg> draws one pattern per seed")
    w.add_argument("--correction", default=None, help="a calibration result JSON: its offsets are applied as the "
                                                      "robot applies them (q_enc + dq_hat)")
    w.add_argument("--seconds", type=float, default=20.0)
    w.add_argument("--seed", type=int, default=0, help="noise and initial-jitter seed (one walk)")
    w.add_argument("--trials", type=int, default=0, help="paired trials (seeds 0..N-1): nominal and with offsets")
    w.add_argument("--sensors", default="realistic", help="sensor preset: zero, realistic, calibrated-imu")
    w.add_argument("--strip", default=None, help="write an image strip of the walk (PNG)")
    w.add_argument("--strip-every", type=float, default=2.0, help="seconds between strip frames (default 2)")
    w.add_argument("--out", default=None, help="write the walk (or trials) as JSON")
    w.add_argument("--json", action="store_true")
    w.set_defaults(func=cmd_walk)
