"""The closed-loop suite: every registered calibrator variant judged by what its
estimate does to a walking policy (issue #15), beside recovery in the leaderboard.

For each robot with a walking policy (`CLOSED_LOOP_ROBOTS`) and each offset pattern
(`CLOSED_LOOP_OFFSETS`), one closed-loop evaluation (`legcal_bench.evaluation.closed_loop`)
whose static session sets are calibrated by every variant, each variant then walking
corrected by its own estimate against the same nominal, uncorrected and oracle walks.
One result file per robot and pattern (`<root>/closed_loop/<robot>_<pattern>.json`: the
summary the leaderboard shows), kept if its key (the evaluation's config and
`RESULTS_VERSION`) matches; its per-trial rows beside it in `closed_loop/trials/` (raw
output, not committed).

The suite `closed-loop` runs the A3-like and A2-like robots with our own policies
(issue #14; `--policy a3` names policies/walkers/a3/policy.yaml); `closed-loop-full`
adds the G1 with its published policy through its leg map and spec.
"""

from __future__ import annotations

import json
from pathlib import Path

from legcal_bench.benchmark.plan import calibrator_variants
from legcal_bench.benchmark.suites import EXTERNAL_ROBOT
from legcal_bench.evaluation.closed_loop import ClosedLoopConfig, evaluate
from legcal_bench.files.examples import example
from legcal_bench.files.atomic import atomic_write_json
from legcal_bench.provenance import RESULTS_VERSION, code_version, stable_hash

# robot -> its walking policy (a shipped policy's name, or a spec path relative to the checkout)
CLOSED_LOOP_ROBOTS = {"a3": "a3", "a2": "a2", EXTERNAL_ROBOT: example("external_robot", "policy")}
CLOSED_LOOP_OFFSETS = ("paper@3", "random:3")
PRIMARY = ("interfoot", "sensor")  # the variant whose walks the report's "corrected" row shows
RESULTS_DIR = "closed_loop"
TRIALS_DIR = "trials"  # under RESULTS_DIR: each result file's per-trial rows, same name


def result_path(root: Path, robot: str, offsets: str) -> Path:
    from legcal_bench.robots import robot_label

    return root / RESULTS_DIR / f"{robot_label(robot)}_{offsets.replace(':', '').replace('@', '')}.json"


def trials_path(result: Path) -> Path:
    """Where the per-trial rows of a result file go."""
    return result.parent / TRIALS_DIR / result.name


def suite_configs(trials: int, robots=None) -> list[ClosedLoopConfig]:
    """One evaluation per robot and pattern, every calibrator variant on it."""
    variants = calibrator_variants()
    primary = next(((n, v, o) for n, v, o in variants if (n, v) == PRIMARY), variants[0])
    extra = tuple((f"{n}-{v}", n, tuple(sorted(o.items()))) for n, v, o in variants)
    out = []
    for robot, policy in CLOSED_LOOP_ROBOTS.items():
        if robots and robot not in robots:
            continue
        for offsets in CLOSED_LOOP_OFFSETS:
            out.append(ClosedLoopConfig(robot=robot, policy=policy, offsets=offsets, trials=trials,
                                        calibrator=primary[0], options=dict(primary[2]), variants=extra))
    return out


def key(cfg: ClosedLoopConfig) -> str:
    from dataclasses import asdict

    return stable_hash({"config": asdict(cfg), "results_version": RESULTS_VERSION})


def run_closed_loop_suite(root: str | Path, trials: int = 35, executor=None, robots=None,
                          progress: bool = True) -> list[Path]:
    """Run (or keep) every evaluation of the suite; returns the result files."""
    from legcal_bench.robots import resolve_robot

    root = Path(root)
    written = []
    for cfg in suite_configs(trials, robots):
        try:
            resolve_robot(cfg.robot)
        except Exception as e:  # the G1 outside a checkout with ../shared: skipped, said why
            print(f"closed-loop suite: skipping {cfg.robot}: {e}")
            continue
        path = result_path(root, cfg.robot, cfg.offsets)
        try:
            if json.loads(path.read_text()).get("key") == key(cfg):
                written.append(path)
                continue
        except (OSError, ValueError):
            pass
        summary, trial_rows = evaluate(cfg, executor, progress=progress)
        provenance = code_version()
        atomic_write_json(trials_path(path), {"key": key(cfg), "provenance": provenance,
                                              "trials": [{k: v for k, v in t.items()
                                                          if k not in ("nominal", "uncorrected", "corrected", "oracle")}
                                                         for t in trial_rows]})
        atomic_write_json(path, {"key": key(cfg), "provenance": provenance, "summary": summary})
        written.append(path)
    return written
