"""How often a robot holds its stances on the contact floor with real-robot-scale offsets
(issue #38): factory offsets (uniform within +-1.2 deg per joint, the benchmark's native
draw) plus an injection uniform within +-3 deg, realistic sensors, the default protocol
without held-out sessions, with and without the standing controller.

A set holds when the collector's hold check passes every segment (`legcal_bench.sim.hold`):
every sole within 1 deg and 2 mm of its settled pose (no fall, no slip, no edge), and
the pelvis within 5 % of the leg's length of where the offsets' strain puts it. A set
that fails is counted with the check's reason (sole or pelvis)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from legcal_bench.files.scratch import scratch_dir

CASES = ("cop", "none")  # the standing controller (`CollectConfig.standing`)
FACTORY_DEG = 1.2
INJECTED_DEG = 3.0


def default_robots() -> list[str]:
    """The built-ins, the G1 and every generated robot (`legcal_bench.robots.design`)."""
    from legcal_bench.benchmark.suites import EXTERNAL_ROBOT
    from legcal_bench.robots.design import GENERATED, STAND_INS, VARIATIONS

    return ["a3", "a2", "pair_pry", "pair_ryp", EXTERNAL_ROBOT] + [d.name for d in (*VARIATIONS, *GENERATED,
                                                                                   *STAND_INS)]


def offsets_for(legmap, seed: int) -> tuple[float, ...]:
    """Factory (+-FACTORY_DEG) plus injected (+-INJECTED_DEG) offsets, uniform per joint (rad)."""
    rng = np.random.default_rng([seed, 38])
    n = legmap.n_joints
    return tuple((rng.uniform(-1, 1, n) * np.deg2rad(FACTORY_DEG) + rng.uniform(-1, 1, n) * np.deg2rad(INJECTED_DEG))
                 .tolist())


def run_case(robot: str, case: str, seed: int) -> dict:
    from legcal_bench.errors import HoldError
    from legcal_bench.protocol.collect import CollectConfig, collect
    from legcal_bench.robots import load_robot

    legmap = load_robot(robot)
    row = {"robot": legmap.name, "robot_spec": robot, "case": case, "seed": seed}
    with scratch_dir("holds") as work:
        try:
            summary = collect(CollectConfig(robot=robot, mode="contact", standing=case, seed=seed, heldout=0,
                                            offsets=offsets_for(legmap, seed)), Path(work) / "set", progress=False)
        except HoldError as e:  # the hold check's report says what failed; other refusals count as the pelvis's
            sole = e.report is not None and e.report.soles_failed
            return {**row, "held": False, "why": "sole" if sole else "pelvis", "message": str(e)}
    def largest(v):  # per-sole lists and scalars alike
        return max(v) if isinstance(v, list) else v

    worst = {k: max(largest(g.hold.get(k, 0.0)) for g in summary.segments)
             for k in ("sole_move_mm", "sole_tilt_deg", "pelvis_beyond_strain_mm")}
    return {**row, "held": True, **worst}


def _case(args):
    return run_case(*args)


def build(robots, cases=CASES, seeds: int = 50, workers: int = 2, progress: bool = True) -> dict:
    """`robots`: built-in names, leg-map paths, or the names of the generated robots
    (`legcal_bench.robots.design.GENERATED_DESIGNS`: written for the run)."""
    from legcal_bench.reports.robot_cases import map_robot_cases

    rows = map_robot_cases(_case, robots, cases, seeds, workers, "contact-holds", progress)
    return {"rows": rows, "summary": summarize(rows)}


def summarize(rows: list[dict]) -> list[dict]:
    out = []
    for robot in dict.fromkeys(r["robot"] for r in rows):
        for case in dict.fromkeys(r["case"] for r in rows if r["robot"] == robot):
            rs = [r for r in rows if r["robot"] == robot and r["case"] == case]
            held = [r for r in rs if r["held"]]
            out.append({"robot": robot, "case": case, "sets": len(rs), "held": len(held),
                        "sole_failures": sum(1 for r in rs if not r["held"] and r["why"] == "sole"),
                        "pelvis_failures": sum(1 for r in rs if not r["held"] and r["why"] == "pelvis"),
                        "worst_sole_tilt_deg": max((r["sole_tilt_deg"] for r in held), default=None),
                        "worst_sole_move_mm": max((r["sole_move_mm"] for r in held), default=None)})
    return out


def markdown(data: dict, made_by: str, code: str) -> str:
    lines = ["# Holding stances on the contact floor", "",
             f"Made by `{made_by}` ({code}). Contact floor, realistic sensors, the default protocol without held-out "
             f"sessions; offsets per seed: factory (uniform within ±{FACTORY_DEG:g}°) plus injected (uniform within "
             f"±{INJECTED_DEG:g}°) per joint. Case: the standing controller (`collect --standing`). Held: every "
             "segment passed the hold check (soles within 1° and 2 mm of their settled pose, the pelvis within 5 % of "
             "the leg of its strained pose). Worst: over the sets that held.", "",
             "| robot | standing | sets | held | failed: sole | failed: pelvis | worst sole tilt (deg) | "
             "worst sole move (mm) |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for s in data["summary"]:
        tilt = "–" if s["worst_sole_tilt_deg"] is None else f"{s['worst_sole_tilt_deg']:.3f}"
        move = "–" if s["worst_sole_move_mm"] is None else f"{s['worst_sole_move_mm']:.3f}"
        lines.append(f"| {s['robot']} | {s['case']} | {s['sets']} | {s['held']} | {s['sole_failures']} | "
                     f"{s['pelvis_failures']} | {tilt} | {move} |")
    failed = [r for r in data["rows"] if not r["held"]]
    if failed:
        lines += ["", "Failures:", ""] + [f"- {r['robot']} {r['case']} seed {r['seed']}: {r['message']}"
                                          for r in failed]
    return "\n".join(lines) + "\n"
