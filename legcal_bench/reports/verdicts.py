"""`legcal-bench verdicts`: the results' verdicts measured (`legcal_bench.estimation.verdict`).

Clean realistic session sets of each robot on the weld and the contact floor, each
calibrated by the inter-foot calibrator: there every `do-not-apply` is a false refusal
and every `review` a doubt the data did not earn. Beside them the torso-IMU case: the
whole-body example robot (the `whole_body` role of examples/cases.yaml) with its leg
map's IMU moved to the model's torso IMU site, above the waist joints the leg map does not declare
(`imu.through`): on a real robot the waist's offsets move that IMU's vertical, unknown to
the calibration, and its verdict must be `do-not-apply` (the IMU-mount finding,
`legcal_bench.estimation.checks.imu_mount`; the simulated waist is held, so its offsets
happen to be right here).

Each case is written as it finishes (`<out>/cases/`), so a stopped run resumes; the page
is `<out>/verdicts.md` and `.json`. Light at import (the command line's parser reads its
defaults).
"""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

from legcal_bench.benchmark.suites import EXTERNAL_ROBOT
from legcal_bench.files.examples import example, example_entry

WHOLE_BODY = example("whole_body")  # a whole-body humanoid with a torso IMU (examples/cases.yaml)
ROBOTS = ("a2", "a3", "pair_ryp", "pair_pry", EXTERNAL_ROBOT, WHOLE_BODY)
MODES = ("weld", "contact")
SEEDS = tuple(range(10))
TORSO_IMU = "torso_imu"  # the case's robot label
TORSO_SITE = example_entry("whole_body")["torso_imu"]["site"]
TORSO_SEEDS = (0, 1, 2)
APPLY_SHARE = 0.95  # the bar: clean sets get `apply` in at least this share, `do-not-apply` in none


def torso_imu_legmap(folder: Path) -> Path:
    """The whole-body example's leg map with its IMU on the torso's site and no waist
    joint among its held joints, written into `folder` (its model path relative to it):
    what a team writes when its IMU sits in the torso and it declares no waist."""
    import yaml

    from legcal_bench.robots import resolve_robot

    src = Path(resolve_robot(WHOLE_BODY))
    doc = yaml.safe_load(src.read_text())
    doc["name"] = f"{doc['name']}_torso_imu"
    doc["imu"] = {"site": TORSO_SITE}
    # Its waist undeclared (no imu.through) and given no hold angle: held at the model's keyframe (#59).
    waist = set(example_entry("whole_body")["torso_imu"]["through"])
    doc["held_joints_rad"] = {k: v for k, v in (doc.get("held_joints_rad") or {}).items() if k not in waist}
    folder.mkdir(parents=True, exist_ok=True)
    # The model's path from the new leg map's folder (a checkout's reports/verdicts/ reaches
    # ../shared the same way on every machine).
    doc["mjcf"] = os.path.relpath((src.parent / doc["mjcf"]).resolve(), folder.resolve())
    out = folder / f"{doc['name']}.legmap.yaml"
    out.write_text("# made by legcal-bench verdicts: the whole-body example with its IMU in the torso\n"
                   + yaml.safe_dump(doc, sort_keys=False))
    return out


def run_case(job: tuple[str, str, str, int]) -> dict:
    """One case: (label, robot spec, mode, seed) collected, calibrated and scored."""
    from legcal_bench.errors import HoldError
    from legcal_bench.provenance import code_version, describe
    from legcal_bench.reports.realistic_set import calibrated_set
    from legcal_bench.robots import robot_label

    label, robot, mode, seed = job
    try:
        legmap, _, result, s = calibrated_set(robot, mode, seed, "verdicts")
    except HoldError as e:  # a set the robot cannot hold has no result to judge: said, not a crash
        return {"label": label, "robot": robot_label(robot), "mode": mode, "seed": seed, "verdict": None,
                "not_collected": str(e).split(". Likely cause")[0], "code": describe(code_version())}
    held = s.get("heldout", {}).get("foot_height_rms_true_mm", {})
    return {"label": label, "robot": legmap.name, "mode": mode, "seed": seed, "verdict": result.decision,
            "reasons": result.verdict["reasons"], "recovery_rms_deg": s["recovery"]["rms_error_deg"],
            "heldout_true_mm": held, "code": describe(code_version())}


def measure(out: str | Path, robots=ROBOTS, modes=MODES, seeds=SEEDS, workers: int = 2,
            progress: bool = True) -> dict:
    from legcal_bench.reports.realistic_set import kept_cases
    from legcal_bench.files.reports import write_report
    from legcal_bench.provenance import code_version, describe
    from legcal_bench.robots import robot_label

    out = Path(out)
    cases = out / "cases"
    jobs = [(str(r), str(r), m, s) for r in robots for m in modes for s in seeds]
    if TORSO_IMU not in [str(r) for r in robots]:
        legmap = torso_imu_legmap(out)
        jobs += [(TORSO_IMU, str(legmap), "weld", s) for s in TORSO_SEEDS]

    def path(job) -> Path:
        label, _, mode, seed = job
        return cases / f"{robot_label(label)}_{mode}_{seed}.json"

    rows = kept_cases(run_case, jobs, [path(j) for j in jobs], workers, "verdicts", progress)
    made_by = (f"legcal-bench verdicts --robots {' '.join(map(str, robots))} --modes {' '.join(modes)} --seeds "
               f"{' '.join(map(str, seeds))} --out {out}")
    data = {"made_by": made_by, "code": code_version(), "rows": rows}
    write_report(out, markdown(rows, made_by, describe(data["code"])), data, name="verdicts")
    return data


def markdown(rows: list[dict], made_by: str, code: str) -> str:
    clean = [r for r in rows if r["label"] != TORSO_IMU]
    torso = [r for r in rows if r["label"] == TORSO_IMU]
    L = ["# Verdicts on clean sets and on the torso-IMU case", "",
         f"Made by `{made_by}` at {code}.", "",
         "Each case: a realistic-sensor session set (the default protocol and offsets), calibrated by `interfoot` "
         "(its default, sensor-weighted setting). On a clean set every `do-not-apply` is a false refusal and "
         f"every `review` a doubt the data did not earn; the bar: `apply` in at least {APPLY_SHARE:.0%} of the "
         "clean sets of each floor and `do-not-apply` in none.", "",
         "Cases are kept as they finish and a rerun computes only the missing ones; they were computed at: "
         + "; ".join(f"{k} ({n} cases)" for k, n in Counter(r.get("code", "a commit not recorded (cases written "
                                                                "before rows named theirs)") for r in rows).items())
         + ".", "",
         "| robot | floor | sets | apply | review | do-not-apply | recovery RMS (deg, mean) |",
         "|---|---|---:|---:|---:|---:|---:|"]
    groups: dict = {}
    for r in clean:
        groups.setdefault((r["robot"], r["mode"]), []).append(r)
    for (robot, mode), g in groups.items():
        n = Counter(r["verdict"] for r in g)
        judged = [r for r in g if r["verdict"] is not None]
        if not judged:
            L.append(f"| {robot} | {mode} | 0 of {len(g)} collected | – | – | – | – |")
            continue
        rec = sum(r["recovery_rms_deg"] for r in judged) / len(judged)
        L.append(f"| {robot} | {mode} | {len(judged)} | {n['apply']} | {n['review']} | {n['do-not-apply']} | "
                 f"{rec:.3f} |")
    lost = [r for r in clean if r["verdict"] is None]
    if lost:
        L += ["", f"Not collected ({len(lost)} sets: the robot did not hold the posture, so there is no result to "
                  f"judge): {', '.join(sorted({r['robot'] + ' ' + r['mode'] for r in lost}))}; the first reason: "
                  f"{lost[0]['not_collected']}."]
    clean = [r for r in clean if r["verdict"] is not None]
    for mode in sorted({r["mode"] for r in clean}):
        g = [r for r in clean if r["mode"] == mode]
        n = Counter(r["verdict"] for r in g)
        ok = n["apply"] >= APPLY_SHARE * len(g) and not n["do-not-apply"]
        L += ["", f"**{mode}**: {n['apply']} of {len(g)} apply ({n['apply'] / len(g):.1%}), {n['review']} review, "
                  f"{n['do-not-apply']} do-not-apply: {'meets' if ok else 'misses'} the bar."]
    reasons = Counter((r["mode"], x["meaning"], _kind(x["text"])) for r in clean for x in r["reasons"]
                      if x["meaning"] in ("doubts", "invalidates"))
    if reasons:
        L += ["", "What put clean sets in doubt or refused them (count of sets, by the warning's opening words):", ""]
        L += [f"- {mode}, {meaning}: {kind}: {k}" for (mode, meaning, kind), k in reasons.most_common()]
    if torso:
        n = Counter(r["verdict"] for r in torso)
        L += ["", "## The torso-IMU case", "",
              f"The whole-body example with its leg map's IMU on `{TORSO_SITE}` (above the undeclared waist), weld floor, "
              f"seeds {', '.join(str(r['seed']) for r in torso)}: {n['do-not-apply']} of {len(torso)} do-not-apply "
              f"({'met' if n['do-not-apply'] == len(torso) else 'missed'}).", "",
              "| seed | verdict | recovery RMS (deg) | first reason |", "|---:|---|---:|---|"]
        for r in torso:
            first = r["reasons"][0]["text"] if r["reasons"] else "–"
            L.append(f"| {r['seed']} | {r['verdict']} | {r['recovery_rms_deg']:.3f} | {first[:200]} |")
    return "\n".join(L) + "\n"


def _kind(text: str) -> str:
    """A warning's kind: its words after the recording's name, to the first colon."""
    head = text.removeprefix("stance ").split(": ", 1)
    body = head[1] if len(head) > 1 and " " not in head[0] else text
    return body.split(":")[0][:80]
