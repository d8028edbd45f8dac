"""`legcal-bench imu-mount`: a torso IMU declared through its waist, against its pelvis-IMU twin.

Two twins per robot, the same model and session settings, the IMU the only difference:
`pelvis` (the leg map's IMU on the pelvis) and `torso` (the IMU in the torso above the
waist joints, declared with `imu.through`), plus `undeclared` (the torso IMU with no
`through`: its verdict must be `do-not-apply`). Robots: the generated A3-like robot with
a 3-joint waist (`legcal_bench.robots.build.build_model(..., upper_body=True,
waist=3)`; its torso IMU mounted 2 and 3 deg off) and the whole-body example robot (the
`whole_body` role of examples/cases.yaml: its torso IMU site and the waist joints below
it). Each seed collects realistic weld sets, calibrates them with interfoot and
scores them: the IMU-removed recovery (`vs_imu_vertical`) of the torso twin against
the pelvis twin's (the issue's bar: within 1.5x, mean over the seeds), and the verdicts.

Each case is written as it finishes (`<out>/cases/`), so a stopped run resumes; the page
is `<out>/imu_mount.md` and `.json`. Light at import.
"""

from __future__ import annotations

import os
from pathlib import Path

from legcal_bench.files.examples import example, example_entry

WHOLE_BODY = example("whole_body")
WHOLE_BODY_LABEL = Path(WHOLE_BODY).name.removesuffix(".legmap.yaml")
WHOLE_BODY_WAIST = tuple(example_entry("whole_body")["torso_imu"]["through"])
ROBOTS = ("a3_waist", WHOLE_BODY_LABEL)
TWINS = ("pelvis", "torso", "undeclared")
SEEDS = (0, 1, 2, 3, 4)
RATIO_BAR = 1.5


def twin_legmaps(robot: str, folder: Path) -> dict[str, Path]:
    """The three twins' leg maps of `robot` (one of ROBOTS), written into `folder`."""
    import yaml

    from legcal_bench.robots.samples import imu_twins, torso_imu_twins

    folder.mkdir(parents=True, exist_ok=True)
    if robot == "a3_waist":
        return torso_imu_twins(folder)
    if robot != WHOLE_BODY_LABEL:
        raise ValueError(f"robot {robot!r}: one of {ROBOTS}")
    from legcal_bench.robots import resolve_robot

    src = Path(resolve_robot(WHOLE_BODY))
    doc = yaml.safe_load(src.read_text())
    doc["mjcf"] = os.path.relpath((src.parent / doc["mjcf"]).resolve(), folder.resolve())
    pelvis = folder / src.name
    pelvis.write_text(yaml.safe_dump(doc, sort_keys=False))
    return imu_twins(pelvis, example_entry("whole_body")["torso_imu"]["site"], WHOLE_BODY_WAIST)


def run_case(job: tuple[str, str, str, int]) -> dict:
    """(robot, twin, leg map path, seed): a realistic weld set collected, calibrated, scored."""
    from legcal_bench.provenance import code_version, describe
    from legcal_bench.reports.realistic_set import calibrated_set

    robot, twin, spec, seed = job
    legmap, summary, result, s = calibrated_set(spec, "weld", seed, "imu_mount")
    rec = s["recovery"]
    waist = [h for h in summary.held_joints if h["joint"] in WHOLE_BODY_WAIST]  # the twins' waist (one naming in both)
    return {"robot": robot, "twin": twin, "seed": seed, "verdict": result.decision,
            "reasons": [r["text"] for r in result.verdict["reasons"]],
            "rms_error_deg": rec["rms_error_deg"], "vs_imu_deg": rec["vs_imu_vertical"]["rms_error_deg"],
            "waist_hold_error_deg": max((h.get("error_deg", 0.0) for h in waist), default=0.0),
            "code": describe(code_version())}


def measure(out: str | Path, robots=ROBOTS, seeds=SEEDS, workers: int = 2, progress: bool = True) -> dict:
    from legcal_bench.reports.realistic_set import kept_cases
    from legcal_bench.files.reports import write_report
    from legcal_bench.provenance import code_version, describe

    out = Path(out)
    cases = out / "cases"
    jobs = []
    for robot in robots:
        legmaps = twin_legmaps(robot, out / "robots" / robot)
        jobs += [(robot, twin, str(legmaps[twin]), s) for twin in TWINS for s in seeds]

    def path(job) -> Path:
        robot, twin, _, seed = job
        return cases / f"{robot}_{twin}_{seed}.json"

    rows = kept_cases(run_case, jobs, [path(j) for j in jobs], workers, "imu-mount", progress)
    made_by = f"legcal-bench imu-mount --robots {' '.join(robots)} --seeds {' '.join(map(str, seeds))} --out {out}"
    data = {"made_by": made_by, "code": code_version(), "rows": rows, "summary": summarize(rows)}
    write_report(out, markdown(rows, data["summary"], made_by, describe(data["code"])), data, name="imu_mount")
    return data


def summarize(rows: list[dict]) -> dict:
    import numpy as np

    out = {}
    for robot in dict.fromkeys(r["robot"] for r in rows):
        mine = [r for r in rows if r["robot"] == robot]
        vs = {t: float(np.mean([r["vs_imu_deg"] for r in mine if r["twin"] == t])) for t in TWINS}
        ratio = vs["torso"] / vs["pelvis"]
        out[robot] = {"mean_vs_imu_deg": vs, "torso_over_pelvis": ratio, "met": ratio <= RATIO_BAR,
                      "verdicts": {t: sorted({r["verdict"] for r in mine if r["twin"] == t}) for t in TWINS},
                      "undeclared_all_do_not_apply": all(r["verdict"] == "do-not-apply" for r in mine
                                                         if r["twin"] == "undeclared")}
    return out


def summary_lines(data: dict, out) -> list[str]:
    """What `legcal-bench imu-mount` prints of a measurement."""
    out = [f"wrote {out}/imu_mount.md, .json ({len(data['rows'])} cases)"]
    for robot, s in data["summary"].items():
        out.append(f"  {robot}: torso / pelvis {s['torso_over_pelvis']:.2f}x (bar {RATIO_BAR:g}x: "
                   f"{'met' if s['met'] else 'missed'}); undeclared all do-not-apply: "
                   f"{s['undeclared_all_do_not_apply']}")
    return out


def markdown(rows: list[dict], summary: dict, made_by: str, code: str) -> str:
    L = ["# A torso IMU through its waist, against its pelvis-IMU twin", "",
         f"Made by `{made_by}` at {code}.", "",
         "Realistic weld sets, calibrated by interfoot. `vs IMU` is the recovery error with the IMU's vertical "
         "error's share removed (`score`'s `vs_imu_vertical`); the bar: the torso twin's mean within "
         f"{RATIO_BAR:g}x of the pelvis twin's, and every undeclared twin `do-not-apply`.", "",
         "| robot | pelvis vs IMU (deg) | torso vs IMU (deg) | torso / pelvis | bar | verdicts pelvis / torso / "
         "undeclared |", "|---|---:|---:|---:|---|---|"]
    for robot, s in summary.items():
        v = s["mean_vs_imu_deg"]
        L.append(f"| {robot} | {v['pelvis']:.5f} | {v['torso']:.5f} | {s['torso_over_pelvis']:.2f}x | "
                 f"{'met' if s['met'] and s['undeclared_all_do_not_apply'] else 'missed'} | "
                 + " / ".join(", ".join(s["verdicts"][t]) for t in TWINS) + " |")
    L += ["", "| robot | twin | seed | verdict | rms (deg) | vs IMU (deg) | waist hold error (deg) |",
          "|---|---|---:|---|---:|---:|---:|"]
    for r in rows:
        L.append(f"| {r['robot']} | {r['twin']} | {r['seed']} | {r['verdict']} | {r['rms_error_deg']:.4f} | "
                 f"{r['vs_imu_deg']:.5f} | {r['waist_hold_error_deg']:.4f} |")
    return "\n".join(L) + "\n"
