"""`legcal-bench bench-speed`: where users wait, timed, the code at hand against an
older commit in one run.

The baseline commit (default `BASELINE`, the last commit before issue #36) is checked
out into a temporary folder beside the code at hand (a local clone, `install_baseline`);
each group's probe script, always the one of the code at hand and using only interfaces
both versions have, runs in its own process once per version with the version on
PYTHONPATH, the two alternating (old first, then new first) for `rounds` rounds, on the
same inputs:

  calibration  `speed_probe.py --only calibration`: calibrators in-process on one A3-like
               weld session set (realistic sensors, 4 stances; collected once, by the code
               at hand, in the format both read), `timing_s` and each of its stages;
  collection   `speed_probe.py --only collection`: the default session set collected
               (kinematic and weld floors), frames per second;
  startup      `startup_probe.py`: `--help`, `calibrate --help` and an argument error in
               fresh interpreters (wall);
  closed_loop  `closed_loop_probe.py`: the 35-trial closed-loop evaluation (wall);
  modelgap     `modelgap_probe.py`: `bench --suite modelgap --cases clean library --seeds
               2`, seconds per session set;
  modelgap_outside  the same probe on `--cases outside --seeds 1 --robots a3` (the
               geometric edits outside the library and their reference runs);
  tests        `tests_probe.py`: the test command (`python -m pytest` with each version's
               own tests and settings) in its source tree, wall, counts and the slowest 20.

Reported: per case the medians, the ratio old/new (speed-up; for rates new/old), the
target and whether it is met (a case one version does not have: "not in the baseline"); per calibration stage the same; for the calibrators the
largest difference between the two versions' offsets (the same answer, faster). Writes
`report.md` and `report.json`, and prints the markdown. Each probe run is kept in
`partial.json` beside them as it finishes: a run stopped part-way (interrupted, a probe
failed) resumes there when the same command is given again on the same commit.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import subprocess
import sys
from pathlib import Path

from legcal_bench.errors import ConfigError
from legcal_bench.files.atomic import atomic_write_text
from legcal_bench.files.scratch import scratch_dir

# The command's parser reads GROUPS and BASELINE from here at every start-up: what only a
# run needs (provenance reads package metadata) is imported by the run.

BASELINE = "4bd338d"  # the commit issue #36 measured (the last before #35; #35 left these paths as fast as it found them)
HERE = Path(__file__).parent
GROUPS = {  # group -> (probe script, its extra arguments beyond --repeats, default repeats per round)
    "calibration": ("speed_probe.py", ["--only", "calibration"], 5),
    "collection": ("speed_probe.py", ["--only", "collection"], 1),
    "startup": ("startup_probe.py", [], 5),
    "closed_loop": ("closed_loop_probe.py", [], 1),
    "modelgap": ("modelgap_probe.py", [], 1),
    "modelgap_outside": ("modelgap_probe.py", ["--key", "modelgap_outside", "--cases", "outside", "--seeds", "1",
                                               "--robots", "a3"], 1),
    "tests": ("tests_probe.py", [], 1),
}
DEFAULT_GROUPS = ("calibration", "collection", "startup")  # the quick ones (a few minutes); the rest take long
ENVIRONMENT = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "MUJOCO_GL": "egl"}


def _at_most(limit: float):
    return f"<= {limit:g}", lambda new: new <= limit


def _at_least(limit: float):
    return f">= {limit:g}", lambda new: new >= limit


# case -> (label, (target text, check(new median)) or None)
TARGETS = {
    "interfoot_end_to_end_sensor": ("inter-foot calibrate end to end, setting sensor (the default), s", _at_most(0.15)),
    "interfoot_end_to_end": ("inter-foot calibrate end to end, the default setting (operating before #35), s", None),
    "interfoot_door": ("inter-foot through `calibrate_training`, the framework's door (wall; the motion resolved "
                       "from #39), s", None),
    "interfoot_end_to_end_operating": ("inter-foot calibrate end to end, setting operating, s", None),
    "interfoot_solve": ("inter-foot solve, sensor, 4 x 450 frames, s", None),
    "interfoot_solve_2point": ("inter-foot solve, sensor, forward-difference Jacobian, s", None),
    "interfoot_solve_alternating": ("inter-foot solve, sensor, the paper's alternation, s", None),
    "yamane_end_to_end": ("Yamane calibrate end to end, default weights, s", _at_most(0.25)),
    "yamane_end_to_end_sensor": ("Yamane calibrate end to end, sensor weights, s", _at_most(0.25)),
    "yamane_solve_default": ("Yamane solve, 4 x 450 frames, default weights, s", None),
    "yamane_solve_sensor": ("Yamane solve, 4 x 450 frames, sensor weights, s", None),
    "collect_kinematic_frames_per_s": ("kinematic collection, frames/s", _at_least(5000)),
    "collect_kinematic_x_real_time": ("kinematic collection, x real time", None),
    "collect_weld_frames_per_s": ("weld collection, frames/s", None),
    "collect_weld_x_real_time": ("weld collection, x real time", None),
    "collect_contact_frames_per_s": ("contact collection (the standing controller's default), frames/s", None),
    "collect_contact_x_real_time": ("contact collection, x real time", None),
    "help": ("`legcal-bench --help`, s", _at_most(0.5)),
    "calibrate_help": ("`legcal-bench calibrate --help`, s", _at_most(0.5)),
    "calibrate_bad_flag": ("`legcal-bench calibrate --no-such-flag` (argument error), s", _at_most(0.5)),
    "walk_eval_a3": ("35-trial closed loop (`walk-eval`, A3-like), s", _at_most(45.0)),
    "walk_eval_a3_cpu": ("35-trial closed loop, CPU s (workers included)", None),
    "collect_weld": ("`legcal-bench collect --mode weld` (default set), s", None),
    "collect_weld_cpu": ("`legcal-bench collect --mode weld`, CPU s", None),
    "modelgap_per_set": ("model-gap suite, s per session set", _at_most(4.0)),
    "modelgap_total": ("model-gap suite `--cases clean library --seeds 2`, s", None),
    "modelgap_outside_per_set": ("model-gap suite outside the library, s per session set", None),
    "modelgap_outside_total": ("model-gap suite `--cases outside --seeds 1 --robots a3`, s", None),
    "test_suite": ("test command (`python -m pytest`), s", _at_most(300.0)),
}
RATES = ("frames_per_s", "x_real_time")  # cases where more is faster


def _repo_root() -> Path:
    out = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=HERE, capture_output=True, text=True,
                         check=False)
    if out.returncode != 0:
        raise ConfigError("bench-speed --baseline: needs a git checkout of legcal-bench (give --baseline none to "
                          "time only the code at hand)")
    return Path(out.stdout.strip())


def install_baseline(rev: str, work: Path) -> Path:
    """A local clone of this repository at commit `rev` in `work/src` (a real checkout,
    so its tests run as they did: git, its own source tree), importable by putting it
    on PYTHONPATH; returns the clone.

    A package the clone's pyproject maps from another folder (`legcal_bench.calibrators`
    from `calibrators/`, ...) is linked into its package folder, untracked and excluded
    from its status: imported from the clone, `legcal_bench.calibrators` is then the
    baseline's, not the editable install's of the code at hand."""
    import tomllib

    root = _repo_root()
    src = work / "src"
    work.mkdir(parents=True, exist_ok=True)
    clone = subprocess.run(["git", "clone", "--quiet", "--shared", "--no-checkout", str(root), str(src)],
                           capture_output=True, text=True, check=False)
    checkout = clone if clone.returncode else subprocess.run(
        ["git", "-C", str(src), "checkout", "--quiet", "--detach", rev], capture_output=True, text=True, check=False)
    if checkout.returncode != 0:
        raise ConfigError(f"bench-speed --baseline {rev!r}: not a commit of this repository "
                          f"({checkout.stderr.strip()}); give a commit of `git log`, or none")
    shared = root.parent / "shared"
    if shared.is_dir():  # the examples' ../shared (the G1's model), as beside the checkout: its tests run too
        (work / "shared").symlink_to(shared)
    pyproject = src / "pyproject.toml"
    config = tomllib.loads(pyproject.read_text()) if pyproject.is_file() else {}
    mapped = config.get("tool", {}).get("setuptools", {}).get("package-dir", {})
    links = [_metadata(src)]
    for package, folder in mapped.items():
        parent, _, name = package.rpartition(".")
        link = src / parent.replace(".", "/") / name
        if parent and not link.exists() and (src / folder).is_dir():
            link.symlink_to(os.path.relpath(src / folder, link.parent), target_is_directory=True)
            links.append(link.relative_to(src).as_posix())
    with open(src / ".git" / "info" / "exclude", "a") as f:
        f.write("".join(f"/{p}\n" for p in links))
    return src


def _metadata(src: Path) -> str:
    """The clone's own package metadata, written by its build back end (PEP 517's
    `prepare_metadata_for_build_wheel`: the dist-info an install would have) beside its
    packages: its entry points (calibrators, effects) are then found before the code at
    hand's, whose names a baseline may not have. Returns the dist-info folder's name."""
    out = subprocess.run([sys.executable, "-c", "from setuptools import build_meta; "
                          "print(build_meta.prepare_metadata_for_build_wheel('.'))"],
                         cwd=src, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise ConfigError(f"bench-speed --baseline: the baseline's package metadata could not be built:\n"
                          f"{out.stderr[-2000:]}")
    return out.stdout.strip().splitlines()[-1]


def run_probe(group: str, repeats: int, pythonpath: Path | None, data: str, robot: str, src: Path) -> dict:
    """One run of `group`'s probe on one version (`pythonpath`: the baseline's clone;
    None: the code at hand). Both versions cache their bytecode (PYTHONDONTWRITEBYTECODE
    dropped): otherwise the clone, with no cache yet, compiles every module every time."""
    script, extra, _ = GROUPS[group]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONDONTWRITEBYTECODE")}
    env.update(ENVIRONMENT)
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)
    args = [sys.executable, str(HERE / script), "--repeats", str(repeats), *extra]
    if script == "speed_probe.py":
        args += ["--data", data, "--robot", robot]
    if script == "tests_probe.py":
        args += ["--src", str(src)]
    out = subprocess.run(args, env=env, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"{script} failed ({'baseline' if pythonpath else 'current'} code):\n{out.stderr[-4000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _median(runs: list[dict], case: str, stage: str | None = None) -> float | None:
    values = [v for r in runs if case in r["cases"]
              for v in (r["cases"][case]["values"] if stage is None else
                        r["cases"][case].get("stages", {}).get(stage, []))]
    return statistics.median(values) if values else None


def _ratio(case: str, new: float | None, old: float | None) -> float | None:
    if new is None or old is None or min(new, old) < 1e-3:  # a stage that did not run (or one not timed)
        return None
    return new / old if case.endswith(RATES) else old / new


def summarize(runs: dict[str, dict[str, list[dict]]]) -> tuple[list[dict], list[dict]]:
    """(a row per case, a row per calibration stage) from every group's runs."""
    import numpy as np

    rows, stages = [], []
    for group, by_side in runs.items():
        names = list(dict.fromkeys(c for r in by_side["new"] for c in r["cases"]))
        for case in names:
            new, old = _median(by_side["new"], case), _median(by_side["old"], case)
            label, target = TARGETS.get(case, (case, None))
            row = {"group": group, "case": case, "label": label, "new": new, "old": old,
                   "speedup": _ratio(case, new, old), "target": None if target is None else target[0],
                   "met": None if target is None or new is None else bool(target[1](new))}
            first = {side: next((r["cases"][case] for r in rs if case in r["cases"]), None)
                     for side, rs in by_side.items()}
            if first["new"] and first["old"] and "offsets" in first["new"] and "offsets" in first["old"]:
                row["max_offset_difference_deg"] = float(np.rad2deg(np.max(np.abs(
                    np.subtract(first["new"]["offsets"], first["old"]["offsets"])))))
            rows.append(row)
            for stage in (first["new"] or {}).get("stages", {}):
                s_new, s_old = _median(by_side["new"], case, stage), _median(by_side["old"], case, stage)
                stages.append({"case": case, "stage": stage, "new": s_new, "old": s_old,
                               "speedup": _ratio(case, s_new, s_old)})
    return rows, stages


PARTIAL_NAME = "partial.json"  # the probe runs finished so far, until the report is written


class Partial:
    """The probe runs of an unfinished `bench-speed`, kept in `path` after each one: a run
    stopped (interrupted, or a probe failed) resumes where it was when started again
    with the same command on the same code (`key`); another command or commit starts
    afresh."""

    def __init__(self, path: Path, key: dict, groups):
        self.path, self.key = path, key
        self.runs: dict[str, dict[str, list[dict]]] = {}
        self.done: list[str] = []
        if path.is_file():
            kept = json.loads(path.read_text())
            if kept.get("key") == key:
                self.runs, self.done = kept["runs"], kept["done"]
        for g in groups:
            self.runs.setdefault(g, {"new": [], "old": []})

    def has(self, round_: int, group: str, side: str) -> bool:
        return f"{round_}/{group}/{side}" in self.done

    def add(self, round_: int, group: str, side: str, result: dict) -> None:
        self.runs[group][side].append(result)
        self.done.append(f"{round_}/{group}/{side}")
        atomic_write_text(self.path, json.dumps({"key": self.key, "done": self.done, "runs": self.runs}))


def run_bench_speed(out: str | Path, robot: str = "a3", repeats: int | None = None, rounds: int = 2,
                    baseline: str = BASELINE, groups=DEFAULT_GROUPS, progress: bool = True) -> str:
    from legcal_bench.files.reports import write_report
    from legcal_bench.data.recording import list_segments, load_recording
    from legcal_bench.protocol.collect import CollectConfig, collect
    from legcal_bench.provenance import code_version, describe

    unknown = [g for g in groups if g not in GROUPS]
    if unknown:
        raise ConfigError(f"bench-speed --groups {' '.join(unknown)}: unknown; use any of {', '.join(GROUPS)}")
    missing = [g for g in groups if not (HERE / GROUPS[g][0]).is_file()]
    if missing:
        raise ConfigError(f"bench-speed --groups {' '.join(missing)}: this checkout has no probe for it "
                          f"({', '.join(GROUPS[g][0] for g in missing)} in {HERE}); leave it out")
    root = Path(__file__).resolve().parents[2]
    cmd = (f"legcal-bench bench-speed --groups {' '.join(groups)} --robot {robot} --rounds {rounds} "
           f"--baseline {baseline}" + (f" --repeats {repeats}" if repeats else ""))
    version = code_version()
    partial = Partial(Path(out) / PARTIAL_NAME, {"command": cmd, "commit": version["commit"],
                                                 "dirty": version["dirty"]}, groups)
    runs = partial.runs
    if partial.done and progress:
        print(f"bench-speed: resuming: {len(partial.done)} probe runs kept in {partial.path}", file=sys.stderr)
    with scratch_dir("benchspeed") as tmp:
        tmp = Path(tmp)
        data = tmp / "data"
        if "calibration" in groups:
            collect(CollectConfig(robot=robot, mode="weld", sensors="realistic"), data, progress=False)
            for path in list_segments(data):  # the format both read (a baseline before #39 reads version 1)
                load_recording(path).save(path, version=1)
        clone = None if baseline == "none" else install_baseline(baseline, tmp / "baseline")
        for k in range(rounds):
            for group in groups:
                n = repeats or GROUPS[group][2]
                sides = [("old", clone, clone), ("new", None, root)]  # (side, PYTHONPATH, source tree)
                for side, path, tree in (sides if k % 2 == 0 else sides[::-1]):
                    if (side == "old" and path is None) or partial.has(k, group, side):
                        continue
                    if progress:
                        print(f"bench-speed: round {k + 1}/{rounds}, {group}, {side} code", file=sys.stderr, flush=True)
                    partial.add(k, group, side, run_probe(group, n, path, str(data), robot, tree))
    meta = {"command": cmd, "provenance": version, "baseline": baseline, "rounds": rounds,
            "repeats": {g: repeats or GROUPS[g][2] for g in groups},
            "machine": f"{platform.machine()} ({os.cpu_count()} cores), Python {platform.python_version()}"}
    written = render(out, runs, meta)
    partial.path.unlink(missing_ok=True)
    return written


def rerender(out: str | Path) -> str:
    """Write `out`'s report again from the probe runs its report.json keeps, with the
    labels and targets of the code at hand (the runs' provenance and settings kept)."""
    from legcal_bench.files.reports import report_data

    path = report_data(out)
    if not path.is_file():
        raise ConfigError(f"bench-speed --rerender: {path} does not exist; run bench-speed --out {out} first")
    d = json.loads(path.read_text())
    meta = {k: d.get(k) for k in ("command", "provenance", "baseline", "rounds", "repeats", "machine")}
    words = d["command"].split()  # a report written before these were kept: from its command
    if meta["rounds"] is None and "--rounds" in words:
        meta["rounds"] = int(words[words.index("--rounds") + 1])
    if meta["repeats"] is None:
        meta["repeats"] = {g: GROUPS[g][2] for g in d["runs"] if g in GROUPS}
    return render(out, d["runs"], meta)


def render(out: str | Path, runs: dict, meta: dict) -> str:
    """report.md and report.json of probe `runs` (group -> side -> results) with `meta`
    (command, provenance, baseline, rounds, repeats per group, machine)."""
    from legcal_bench.files.reports import write_report
    from legcal_bench.provenance import describe

    rows, stages = summarize(runs)
    repeats = meta.get("repeats") or {}
    machine = meta.get("machine") or f"{platform.machine()} ({os.cpu_count()} cores), Python {platform.python_version()}"
    L = ["# Speed: the code at hand against the baseline commit", "",
         f"Generated by `{meta['command']}` on {machine}, "
         f"one BLAS thread per process; {describe(meta['provenance'])}; baseline `{meta['baseline']}`. Medians over "
         f"{meta.get('rounds') or '?'} rounds, "
         "the two versions alternating (old first, then new first), each probe in its own process; repeats per "
         f"round: {', '.join(f'{g} {n}' for g, n in repeats.items()) or 'as the groups default'}. Speed-up is "
         "old/new for times, new/old for rates; seconds on these shared machines move by about 30 %, the ratio is "
         "the evidence.", "",
         "| case | baseline | now | speed-up | target | met | offsets now vs baseline (max, deg) |",
         "|---|---:|---:|---:|---|---|---:|"]

    def fmt(v):
        return "–" if v is None else (f"{v:.0f}" if v >= 100 else f"{v:.3f}")

    for r in rows:
        speedup = ("not in the baseline" if r["old"] is None and meta.get("baseline") != "none" else
                   "–" if r["speedup"] is None else f"{r['speedup']:.2f}x")
        met = "–" if r["met"] is None else ("yes" if r["met"] else "NO")
        diff = r.get("max_offset_difference_deg")
        L.append(f"| {r['label']} | {fmt(r['old'])} | {fmt(r['new'])} | {speedup} | {r['target'] or '–'} | {met} | "
                 f"{'–' if diff is None else f'{diff:.1e}'} |")
    if stages:
        L += ["", "Calibration stages (`timing_s`, seconds; a stage the baseline did not time shows –):", "",
              "| case | stage | baseline | now | speed-up |", "|---|---|---:|---:|---:|"]
        for s in stages:
            speedup = "–" if s["speedup"] is None else f"{s['speedup']:.2f}x"
            L.append(f"| {s['case']} | {s['stage']} | {fmt(s['old'])} | {fmt(s['new'])} | {speedup} |")
    for side in ("old", "new"):
        suite = [r for r in runs.get("tests", {}).get(side, [])]
        for r in suite:
            for run in r.get("runs", []):
                L += ["", f"Test command, {'baseline' if side == 'old' else 'now'}: {run['summary']} "
                      f"(wall {run['wall_s']:.0f} s, exit code {run['returncode']}); the slowest 20:", "",
                      "| s | phase | test |", "|---:|---|---|"]
                L += [f"| {d['seconds']:.1f} | {d['phase']} | `{d['test']}` |" for d in run["slowest"]]
    return write_report(out, "\n".join(L) + "\n", {**meta, "rows": rows, "stages": stages, "runs": runs})


# The README's speed line: written from a committed report by `bench-speed --out R
# --readme README.md`, between these markers (the first names the report); a
# test holds the README to the report it names.
SPEED_LINE_CASES = (("interfoot_end_to_end_sensor", "calibrate (inter-foot, default setting)"),
                    ("yamane_end_to_end", "Yamane"), ("help", "`legcal-bench --help`"))
SPEED_LINE_START, SPEED_LINE_END = "<!-- speed line from ", "<!-- end of the speed line -->"


def speed_line(report: dict) -> str:
    """One line of where users wait, from a bench-speed report (its report.json): each
    case's median now, against the baseline, with the command and commit behind it."""
    rows = {r["case"]: r for r in report["rows"]}
    parts = []
    for case, label in SPEED_LINE_CASES:
        r = rows.get(case)
        if r is None or r["new"] is None:
            continue
        vs = "" if r["speedup"] is None else f" ({r['speedup']:.2f}x {report['baseline']}'s speed)"
        parts.append(f"{label} {r['new']:.2f} s{vs}")
    commit = (report.get("provenance") or {}).get("commit", "?")[:7]
    return (f"Speed, warm and in-process but for start-up: {'; '.join(parts)}. From `{report['command']}` at "
            f"{commit} on {report.get('machine') or 'this machine'}.")


def write_speed_line(readme: str | Path, out: str | Path) -> str:
    """Put `out`'s report's `speed_line` into `readme` between the markers (added at the
    end if it has none); returns the line."""
    from legcal_bench.files.reports import report_data

    path = report_data(out)
    if not path.is_file():
        raise ConfigError(f"bench-speed --readme: {path} does not exist; run bench-speed --out {out} first")
    line = speed_line(json.loads(path.read_text()))
    readme = Path(readme)
    text = readme.read_text()
    block = f"{SPEED_LINE_START}{Path(out).as_posix()} -->\n{line}\n{SPEED_LINE_END}"
    start, end = text.find(SPEED_LINE_START), text.find(SPEED_LINE_END)
    if start >= 0 and end > start:
        text = text[:start] + block + text[end + len(SPEED_LINE_END):]
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    atomic_write_text(readme, text)
    return line
