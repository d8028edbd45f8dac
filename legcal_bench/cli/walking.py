"""`legcal-bench walk` (a policy from its spec walking a robot, with offsets and an
optional correction; one walk or paired trials) and `walk-eval` (the closed-loop
evaluation of a calibrator)."""

from __future__ import annotations

import argparse
import json
from functools import partial

from legcal_bench import inputs
from legcal_bench.cli.parsing import pool_options
from legcal_bench.cli.robots import COUNT0, MAX_RUNS, RUN_COUNT, door, robot_args
from legcal_bench.evaluation.distill_config import DistillConfig
from legcal_bench.sim.names import PRESETS_HELP, SENSOR_PRESET_NAMES

SENSORS = partial(inputs.choice, options=SENSOR_PRESET_NAMES)
# A walk keeps every control step (the path, the strikes, a strip's frames) in memory: an
# hour is more than any evaluation walks; beyond, a typo, refused with the number.
MAX_WALK_S = 3600.0
WALK_SECONDS = partial(inputs.positive, high=MAX_WALK_S, fix="seconds of each walk")
TRIALS0 = partial(inputs.count, low=0, high=MAX_RUNS, fix="paired trials, 0 for one walk")
WALK_EVAL_OUT = "runs/walk-eval"
TRAIN_OUT = "runs/train-policy"  # + /<robot>


def _correction(path, legmap):
    """The offsets of the calibration result at `path`, which must be `legmap`'s robot's."""
    if path is None:
        return None
    from legcal_bench.calibrators.base import CalibrationResult

    result = CalibrationResult.load(path)
    result.check_robot(legmap, f"--correction {path}")
    return result.offsets_vector(legmap.joint_names)


def cmd_walk(a: argparse.Namespace) -> int:
    door(a, seconds=WALK_SECONDS, trials=TRIALS0, seed=inputs.seed, strip_every=inputs.positive, sensors=SENSORS,
         out=inputs.output_file, strip=inputs.output_file)
    import numpy as np

    from legcal_bench.envs.walking import WalkingEnv
    from legcal_bench.errors import ConfigError
    from legcal_bench.evaluation.walk import trial_offsets, walk, walk_trials
    from legcal_bench.policies.runner import PolicyRunner
    from legcal_bench.provenance import code_version, describe
    from legcal_bench.robots import load_robot

    if (a.policy is None) == (a.teacher is None):
        raise ConfigError("give --policy SPEC (a policy) or --teacher RECIPE (the model-based teacher), not both")
    legmap = load_robot(a.robot, a.mjcf)
    correction = _correction(a.correction, legmap)  # another robot's result fails here, before the walk
    trial_offsets(a.offsets, legmap, a.seed)  # and a bad offsets spec
    render = dict(render_mode="rgb_array" if a.strip else None, width=320, height=400)
    if a.teacher is not None:
        from legcal_bench.envs.walking import teacher_walking_config
        from legcal_bench.policies.zmp_walker import ZmpWalker, load_teacher_recipe

        recipe = load_teacher_recipe(a.teacher)
        runner = ZmpWalker(legmap, a.seconds, recipe.gait, recipe.feedback)
        env = WalkingEnv(robot=legmap, sensors=a.sensors, walking=teacher_walking_config(legmap, recipe, runner),
                         **render)
    else:
        env = WalkingEnv(robot=a.robot, policy=a.policy, sensors=a.sensors, mjcf=a.mjcf, **render)
        runner = PolicyRunner(env.policy_spec, env.legmap)
    code = describe(code_version())
    who = f"--policy {a.policy}" if a.policy is not None else f"--teacher {a.teacher}"
    made_by = (f"legcal-bench walk --robot {a.robot} {who} --offsets {a.offsets} --seconds {a.seconds:g} "
               f"--sensors {a.sensors}" + (f" --trials {a.trials}" if a.trials else f" --seed {a.seed}")
               + (f" --correction {a.correction}" if a.correction else ""))
    if a.trials:
        out = walk_trials(env, runner, a.offsets, a.trials, a.seconds, correction, progress=not a.json)
        out.update(code=code, made_by=made_by, robot=env.legmap.name, policy=runner.name)
        if a.out:
            from legcal_bench.files.atomic import atomic_write_json

            atomic_write_json(a.out, out)
        if a.json:
            print(json.dumps(out, indent=2, default=float))
            return 0
        print(f"{env.legmap.name}, policy {runner.name}, {a.trials} trials x {a.seconds:g} s, offsets {a.offsets}, "
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
    s = {**w.summary(), "code": code, "made_by": made_by, "robot": env.legmap.name, "policy": runner.name}
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
    print(f"{env.legmap.name}, policy {runner.name}, seed {a.seed}, offsets {a.offsets} "
          f"(max {np.degrees(np.abs(dq)).max():.2f} deg): {state}; walked {s['distance_m']:.2f} m in "
          f"{s['duration_s']:.1f} s, strikes L/R {s['strike_counts']['left']}/{s['strike_counts']['right']}, mean "
          f"torque {w.torque_mean:.1f} N m, power {w.power_mean:.0f} W; {w.wall_s:.2f} s wall ({code})")
    if w.privileged:
        print(f"  the policy read privileged observation terms from the simulator: {', '.join(w.privileged)}")
    if getattr(runner, "spec", None) is not None:
        print(f"  simulation settings from the spec: {runner.spec.settings}")
    if "strip" in s:
        print(f"wrote {s['strip']}")
    return 0


def cmd_walk_eval(a: argparse.Namespace) -> int:
    door(a, trials=RUN_COUNT, seconds=WALK_SECONDS, sweep=inputs.positive, workers=inputs.count,
         sensors=SENSORS, static_sensors=SENSORS, out=inputs.output_folder)
    from legcal_bench.benchmark.runner import check_scheduler
    from legcal_bench.calibrators.registry import get_calibrator, parse_options
    from legcal_bench.evaluation.closed_loop import TRIALS_DIR, ClosedLoopConfig, calibrator_options, evaluate, keep_trials
    from legcal_bench.evaluation.walk import trial_offsets
    from legcal_bench.provenance import code_version, describe
    from legcal_bench.reports.closed_loop import write
    from legcal_bench.sim.offsets import with_magnitude

    if a.scheduler:
        check_scheduler(a.scheduler)
    options = calibrator_options(a.calibrator)
    if a.setting:
        options["setting"] = a.setting
    options.update(parse_options(a.calibrator, a.option))
    offsets = [a.offsets] if not a.sweep else [with_magnitude(a.offsets, d) for d in a.sweep]
    from legcal_bench.benchmark.runner import executing
    from legcal_bench.policies.runner import PolicyRunner
    from legcal_bench.robots import load_robot

    get_calibrator(a.calibrator, **options)  # a bad option (--setting included) fails here, before any walk
    legmap = load_robot(a.robot, a.mjcf)
    PolicyRunner(a.policy, legmap)  # a bad spec or robot fails here, before any worker
    for off in offsets:
        trial_offsets(off, legmap, 0)  # and a bad offsets spec
    summaries, trials = [], []
    with executing(a.scheduler, a.workers) as executor:
        with keep_trials(a.out) as store:  # each trial written as it finishes; a rerun takes the finished ones
            for off in offsets:
                cfg = ClosedLoopConfig(robot=a.robot, policy=a.policy, offsets=off, trials=a.trials, seconds=a.seconds,
                                       calibrator=a.calibrator, options=options, static_sensors=a.static_sensors,
                                       walk_sensors=a.sensors, mjcf=a.mjcf)
                s, t = evaluate(cfg, executor, progress=not a.quiet)
                summaries.append(s)
                trials.append(t)
    made_by = (f"legcal-bench walk-eval --robot {a.robot}" + (f" --mjcf {a.mjcf}" if a.mjcf else "")
               + f" --policy {a.policy} --offsets {a.offsets} --trials {a.trials} "
               f"--seconds {a.seconds:g} --calibrator {a.calibrator}" + (f" --setting {a.setting}" if a.setting else "")
               + (" --sweep " + " ".join(f"{d:g}" for d in a.sweep) if a.sweep else "")
               + "".join(f" --option {kv}" for kv in a.option or [])
               + (f" --static-sensors {a.static_sensors}" if a.static_sensors != "calibrated-imu" else "")
               + (f" --sensors {a.sensors}" if a.sensors != "realistic" else ""))
    print(write(a.out, summaries, trials, describe(code_version()), made_by, computed=set(store.written)))
    total = sum(len(t) for t in trials)
    if store.reused:
        print(f"resumed: {len(store.reused)} of {total} trial(s) taken from {a.out}/{TRIALS_DIR} (finished by an "
              f"earlier run with the same settings), {len(store.written)} run now")
    for s in summaries:
        rej = s.get("rejected") or {}
        if rej.get("count"):
            print(f"offsets {s['config']['offsets']}: {rej['count']} of {s['config']['trials']} trial(s) failed "
                  f"calibration (verdict do-not-apply; seeds {rej['seeds']}): walked and scored as no correction; "
                  f"the first reason: {rej['first_reason']}")
        if s["calibrated"] == 0:
            print(f"offsets {s['config']['offsets']}: no trial was calibrated (the static session set failed in all "
                  f"{s['config']['trials']}; first reason: {s['static_failed']['first_reason']}); no corrected walk")
    static_s = [t["static_s"] for ts in trials for t in ts]
    walk_s = [t[c]["wall_s"] for ts in trials for t in ts for c in ("nominal", "uncorrected", "corrected", "oracle")
              if "wall_s" in t[c]]
    print(f"wall clock (timings.json): static collection + calibration {sum(static_s) / len(static_s):.2f} s a trial, "
          f"a walk {sum(walk_s) / len(walk_s):.2f} s")
    print(f"wrote the report in {a.out}")
    return 0


def cmd_train_policy(a: argparse.Namespace) -> int:
    from legcal_bench.errors import ConfigError

    door(a, seed=inputs.seed, offsets_deg=inputs.non_negative, iterations=RUN_COUNT, rollouts=RUN_COUNT,
         selection_walks=partial(COUNT0, high=MAX_RUNS), out=inputs.output_folder)
    from pathlib import Path

    from legcal_bench.evaluation.distill import DistillConfig, export, train  # the training module's (tests shorten it)
    from legcal_bench.files.atomic import atomic_write_json, atomic_write_text, replace_dir
    from legcal_bench.policies.zmp_walker import TEACHERS_DIR, load_teacher_recipe
    from legcal_bench.provenance import code_version, describe
    from legcal_bench.robots import BUILTIN, load_robot

    legmap = load_robot(a.robot, a.mjcf)
    teacher = a.teacher
    if teacher is None:
        if a.robot not in BUILTIN or not (TEACHERS_DIR / f"{a.robot}.yaml").is_file():
            raise ConfigError(f"--teacher: robot {a.robot!r} has no built-in teacher recipe; write one (see "
                              f"{TEACHERS_DIR}, format legcal-teacher/1) and pass --teacher FILE")
        teacher = TEACHERS_DIR / f"{a.robot}.yaml"
    recipe = load_teacher_recipe(teacher)
    cfg = DistillConfig(iterations=a.iterations, rollouts=a.rollouts, offsets_deg=a.offsets_deg, seed=a.seed,
                        eval_rollouts=a.selection_walks)
    name = a.name or f"legcal_{legmap.name}_walker"
    out = Path(a.out or Path(TRAIN_OUT) / legmap.name)  # the shipped policies change only when --out names them
    made_by = (f"legcal-bench train-policy --robot {a.robot} --teacher {teacher} --iterations {a.iterations} "
               f"--rollouts {a.rollouts} --offsets-deg {a.offsets_deg:g} --selection-walks {a.selection_walks} "
               f"--seed {a.seed}")
    code = describe(code_version())
    lines = []

    def log(rec):
        lines.append(json.dumps(rec, default=float))
        if a.quiet:
            return
        print(f"iteration {rec['iteration']}: beta {rec['beta']:.3f}, {rec['samples']} samples, rollout falls "
              f"{rec['rollout_falls']}, val loss {rec['val_loss']:.4f}, student upright {rec['eval_upright']}/"
              f"{rec['eval_total']} (mean {rec['eval_mean_upright_s']:.1f} s), {rec['elapsed_s']:.0f} s", flush=True)

    student, spec, history = train(legmap, recipe, cfg, name, log, progress=not a.quiet)

    def write(folder: Path) -> None:
        import shutil

        shutil.copyfile(teacher, folder / "teacher.yaml")
        notes = {"made_by": made_by, "code": code, "teacher": "teacher.yaml",
                 "selected_iteration": history["selected_iteration"],
                 "train_seconds": round(history["train_seconds"], 1)}
        export(student, spec, folder, notes)
        atomic_write_text(folder / "train.log", "\n".join(lines) + "\n")
        atomic_write_json(folder / "training.json", {**history, "made_by": made_by, "code": code,
                                                     "robot": legmap.name, "name": name})

    replace_dir(out, write, keep_if=lambda p: (p / "training.json").is_file())
    print(f"trained in {history['train_seconds']:.0f} s; selected iteration {history['selected_iteration']}; "
          f"wrote {out}/policy.yaml (TorchScript) and {out}/policy.onnx.yaml (ONNX)")
    return 0


def add_commands(sub) -> None:
    _walk_options(sub.add_parser(
        "walk", help="a policy (from its spec) walking a robot, with encoder offsets and an optional correction: one "
                     "walk, or paired trials against the nominal walk",
        description="Walk a policy (a spec YAML or one of our walkers' names) or the model-based teacher on the "
                    "walking env, with encoder offsets injected and, optionally, a calibration result's correction "
                    "applied as the robot applies it. One walk prints whether it stayed upright (or when it fell), "
                    "the distance, foot strikes, torque and power; --trials N walks N paired seeds, nominal and "
                    "with offsets, and prints upright counts and the pelvis and foot-strike deviations (mm). "
                    "Writes a file only when --out or --strip names one."))
    e = sub.add_parser("walk-eval", help="the closed-loop evaluation: per trial a static calibration with the same "
                                         "offsets, then nominal, uncorrected, corrected and oracle walks",
                       description="Evaluate a calibrator in the closed loop: per trial, collect a static session "
                                   "set with the trial's offsets, calibrate it, then walk the policy four times "
                                   "(nominal, with the offsets uncorrected, corrected by the estimate, corrected "
                                   "by the truth). Writes report.md, report.json, paths.png and timings.json into "
                                   "--out, each finished trial in its trials/ folder (a rerun into it resumes). "
                                   "To update the committed report, name it: --out reports/walk_eval.")
    robot_args(e)
    e.add_argument("--policy", required=True, help="policy spec YAML, or our policy's name (a3, a2)")
    e.add_argument("--offsets", default="paper@3", help="paper@<deg> (the paper's signs, every joint), random:<deg> "
                                                        "(a pattern per trial: trial s draws from seed 20000 + s), "
                                                        "random:<deg>@<seed> (the same, trial s from seed <seed> + s), "
                                                        "or one radian per leg joint, comma-separated (e.g. "
                                                        "-0.02,0.01,...)")
    e.add_argument("--sweep", type=float, nargs="+", default=None, metavar="DEG",
                   help="magnitudes (deg, > 0) to sweep, e.g. 1 2 3 (replacing <deg> of paper@ or random:; default: "
                        "no sweep, --offsets as given)")
    e.add_argument("--trials", type=int, default=35, help="trials per offsets magnitude, at least 1 (default 35)")
    e.add_argument("--seconds", type=float, default=20.0, help="seconds of each walk, > 0, at most 3600 (default 20)")
    e.add_argument("--calibrator", default="interfoot", help="registered calibrator of the static calibration "
                                                             "(default interfoot)")
    e.add_argument("--setting", default=None, help="the calibrator's setting (default: its sensor-matched variant "
                                                   "where it has one)")
    e.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="a calibrator option, typed by its constructor, e.g. --option lambda_q=0.1 (repeatable; "
                        "default: none, the calibrator's defaults)")
    e.add_argument("--static-sensors", default="calibrated-imu", help="sensors of the static session sets "
                                                                      "(default calibrated-imu; also realistic)")
    e.add_argument("--sensors", default="realistic", help=f"sensors while walking: {', '.join(SENSOR_PRESET_NAMES)} "
                                                          "(default realistic)")
    pool_options(e, note=" (1 runs here)")
    e.add_argument("--out", default=WALK_EVAL_OUT,
                   help=f"report folder (report.md, report.json, paths.png, timings.json) with each finished trial in "
                        f"trials/; rerun into it to resume an interrupted run (default {WALK_EVAL_OUT}; the committed "
                        f"report changes only when named: --out reports/walk_eval)")
    e.add_argument("--quiet", action="store_true", help="no progress bar (default: a progress bar)")
    e.set_defaults(func=cmd_walk_eval, resume="the finished trials are kept in --out's trials/; rerun the same "
                                             "command into it to resume")

    _train_policy_options(sub.add_parser(
        "train-policy", help="train our walking policy from scratch: the model-based teacher (ZMP preview gait + IMU "
                             "balance feedback) distilled into an MLP by behaviour cloning and DAgger, checkpoint "
                             "chosen by rollout success",
        description="Distil the robot's model-based teacher (a ZMP preview gait with IMU balance feedback, from its "
                    "recipe) into an MLP policy: behaviour cloning, then DAgger iterations on rollouts with random "
                    "offsets, floor friction and masses; the checkpoint is chosen by how many selection walks stay "
                    "upright. Writes policy.yaml (TorchScript), policy.onnx.yaml (ONNX), the teacher recipe, "
                    "train.log and training.json into --out. The shipped policies (policies/walkers/<robot>) change "
                    "only when --out names their folder."))


def _walk_options(w: argparse.ArgumentParser) -> None:
    robot_args(w)
    from legcal_bench.files.examples import example

    w.add_argument("--policy", default=None, help="policy spec YAML (see legcal_bench/policies/spec.py; e.g. "
                                                  f"{example('external_robot', 'policy')}), or our policy's name "
                                                  "(a3, a2); no default: give --policy or --teacher")
    w.add_argument("--teacher", default=None, help="instead of a policy: the model-based teacher from its recipe "
                                                   "(e.g. policies/teachers/a3.yaml; default: none, --policy)")
    w.add_argument("--offsets", default="none", help=f"encoder offsets: {PRESETS_HELP}; also paper@<deg>; "
                                                     "random:<deg> draws one pattern per seed; a list of radians "
                                                     "reads e.g. -0.02,0.01,...")
    w.add_argument("--correction", default=None, help="a calibration result JSON of this robot: its offsets are "
                                                      "applied as the robot applies them (q_enc + dq_hat; default: "
                                                      "none, uncorrected)")
    w.add_argument("--seconds", type=float, default=20.0, help="seconds to walk, > 0, at most 3600 (default 20)")
    w.add_argument("--seed", type=int, default=0, help="noise and initial-jitter seed (one walk): an integer in "
                                                       "[0, 2^32 - 1] (default 0)")
    w.add_argument("--trials", type=int, default=0, help="paired trials (seeds 0..N-1): nominal and with offsets "
                                                         "(default 0: one walk)")
    w.add_argument("--sensors", default="realistic", help=f"sensor preset: {', '.join(SENSOR_PRESET_NAMES)}")
    w.add_argument("--strip", default=None, help="write an image strip of the walk (PNG file; default: none "
                                                 "drawn)")
    w.add_argument("--strip-every", type=float, default=2.0, help="seconds between strip frames, > 0 (default 2)")
    w.add_argument("--out", default=None, help="write the walk (or trials) as JSON (a file; checked writable before "
                                               "the walk; default: none written)")
    w.add_argument("--json", action="store_true", help="print the summary as JSON (default: text)")
    w.set_defaults(func=cmd_walk)


def _train_policy_options(t: argparse.ArgumentParser) -> None:
    robot_args(t)
    t.add_argument("--teacher", default=None, help="teacher recipe YAML (format legcal-teacher/1; default: "
                                                   "policies/teachers/<robot>.yaml for a built-in robot)")
    t.add_argument("--iterations", type=int, default=DistillConfig.iterations,
                   help="DAgger iterations, at least 1 (the first is behaviour cloning)")
    t.add_argument("--rollouts", type=int, default=DistillConfig.rollouts,
                   help=f"{DistillConfig.seconds:g} s rollouts per iteration, at least 1")
    t.add_argument("--offsets-deg", type=float, default=DistillConfig.offsets_deg,
                   help="training offsets, deg: uniform +- this per joint, >= 0")
    t.add_argument("--selection-walks", type=int, default=DistillConfig.eval_rollouts,
                   help="random offset patterns (besides none and paper@3) the pure student walks after each "
                        f"iteration to choose the checkpoint (default {DistillConfig.eval_rollouts})")
    t.add_argument("--seed", type=int, default=0, help="training seed: an integer in [0, 2^32 - 1] (default 0)")
    t.add_argument("--name", default=None, help="the policy's name in its spec (default: legcal_<robot>_walker)")
    t.add_argument("--out", default=None,
                   help=f"output folder, replaced only if it holds an earlier training result (default "
                        f"{TRAIN_OUT}/<robot>; the shipped policy changes only when named: --out "
                        f"policies/walkers/<robot>)")
    t.add_argument("--quiet", action="store_true", help="no progress output (default: a line per iteration)")
    t.set_defaults(func=cmd_train_policy)
