"""`legcal-bench bench-speed`: the hot paths timed, new code against an older commit.

One A3-like weld session set (realistic sensors, four stances) is collected; then the
speed probe (`speed_probe.py`) runs on the code at hand and on the baseline commit
(default: the last commit before the calibration core was rebuilt), that commit
installed into a temporary folder beside it (`git archive` + `pip install --no-deps
--target`), each in its own process on the same recordings, alternating
`--rounds` times. Reported: medians, the ratio old/new, the targets, and the largest
difference between the two versions' offsets (the same answer, faster). Writes
`report.md` and `report.json`.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from legcal_bench.errors import ConfigError
from legcal_bench.files.reports import write_report
from legcal_bench.provenance import code_version, describe

BASELINE = "a27a25a"  # the last commit before the calibration core (terms, batched kinematics)
PROBE = Path(__file__).with_name("speed_probe.py")
# case -> (label, target text, check(new median, old median))
TARGETS = {
    "interfoot_solve": ("inter-foot solve, 4 x 450 frames (default solver)", "<= 0.08 s and >= 2x faster",
                        lambda new, old: new <= 0.08 and old / new >= 2.0),
    "interfoot_end_to_end": ("inter-foot calibrate end to end (500 -> trim -> 450)", "<= 0.25 s",
                             lambda new, old: new <= 0.25),
    "interfoot_end_to_end_operating": ("inter-foot calibrate end to end, setting operating", "–", None),
    "interfoot_end_to_end_sensor": ("inter-foot calibrate end to end, setting sensor", "–", None),
    "interfoot_solve_2point": ("inter-foot solve, forward-difference Jacobian", "–", None),
    "interfoot_solve_alternating": ("inter-foot solve, the paper's alternation", "–", None),
    "yamane_solve_default": ("Yamane solve, 4 x 450 frames, default weights", "<= 0.25 s", lambda new, old: new <= 0.25),
    "yamane_solve_sensor": ("Yamane solve, 4 x 450 frames, sensor weights", "<= 0.25 s", lambda new, old: new <= 0.25),
    "collect_kinematic_frames_per_s": ("kinematic collection (frames/s)", ">= 5000", lambda new, old: new >= 5000),
    "collect_kinematic_x_real_time": ("kinematic collection (x real time)", "–", None),
    "collect_weld_frames_per_s": ("weld collection (frames/s)", "–", None),
    "collect_weld_x_real_time": ("weld collection (x real time)", ">= 50", lambda new, old: new >= 50),
}


def _repo_root() -> Path:
    out = subprocess.run(["git", "rev-parse", "--show-toplevel"], cwd=Path(__file__).parent, capture_output=True,
                         text=True, check=False)
    if out.returncode != 0:
        raise ConfigError("bench-speed --baseline: needs a git checkout of legcal-bench (give --baseline none to "
                          "time only the code at hand)")
    return Path(out.stdout.strip())


def install_baseline(rev: str, work: Path) -> Path:
    """Install commit `rev` (code only, no dependencies) into `work`; returns the folder
    to put on PYTHONPATH."""
    root = _repo_root()
    src, site = work / "src", work / "site"
    src.mkdir(parents=True)
    archive = subprocess.run(["git", "archive", "--format=tar", rev], cwd=root, capture_output=True, check=False)
    if archive.returncode != 0:
        raise ConfigError(f"bench-speed --baseline {rev!r}: not a commit of this repository "
                          f"({archive.stderr.decode().strip()})")
    subprocess.run(["tar", "-x", "-C", str(src)], input=archive.stdout, check=True)
    subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", "--no-deps",
                    "--no-build-isolation", "--target", str(site), str(src)], check=True, capture_output=True)
    return site


def run_probe(data: str, robot: str, repeats: int, pythonpath: Path | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)
    out = subprocess.run([sys.executable, str(PROBE), "--data", data, "--robot", robot, "--repeats", str(repeats)],
                         env=env, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"speed probe failed ({'baseline' if pythonpath else 'current'} code):\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def run_bench_speed(out: str | Path, robot: str = "a3", repeats: int = 5, rounds: int = 2, baseline: str = BASELINE,
                    progress: bool = True) -> str:
    from legcal_bench.protocol.collect import CollectConfig, collect

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        collect(CollectConfig(robot=robot, mode="weld", sensors="realistic"), tmp / "data", progress=progress)
        site = None if baseline == "none" else install_baseline(baseline, tmp / "baseline")
        runs: dict[str, list[dict]] = {"new": [], "old": []}
        for _ in range(rounds):
            if site is not None:
                runs["old"].append(run_probe(str(tmp / "data"), robot, repeats, site))
            runs["new"].append(run_probe(str(tmp / "data"), robot, repeats, None))
    rows = []
    for case, (label, target, check) in TARGETS.items():
        med = {side: statistics.median(v for r in rs for v in r["cases"][case]["values"]) if rs else None
               for side, rs in runs.items()}
        row = {"case": case, "label": label, "new": med["new"], "old": med["old"], "target": target}
        if med["old"] is not None:
            faster = med["old"] / med["new"] if runs["new"][0]["cases"][case]["unit"] == "s" else med["new"] / med["old"]
            row["speedup"] = faster
            if "offsets" in runs["new"][0]["cases"][case]:
                row["max_offset_difference_deg"] = float(np.rad2deg(np.max(np.abs(
                    np.subtract(runs["new"][0]["cases"][case]["offsets"], runs["old"][0]["cases"][case]["offsets"])))))
        row["met"] = None if check is None else bool(check(med["new"], med["old"] if med["old"] is not None else np.inf))
        rows.append(row)
    cmd = f"legcal-bench bench-speed --robot {robot} --repeats {repeats} --rounds {rounds} --baseline {baseline}"
    version = code_version()
    L = ["# Speed: the code at hand against the baseline commit", "",
         f"Generated by `{cmd}` on {platform.machine()}, Python {platform.python_version()}, one BLAS thread per "
         f"process; {describe(version)}; baseline `{baseline}`. Medians over {rounds} alternating rounds x {repeats} "
         "repeats (calibration) or x 1 (collection: the default session set, 4150 frames, settle included).", "",
         "| case | baseline | now | speed-up | target | met | offsets now vs baseline (max, deg) |",
         "|---|---:|---:|---:|---|---|---:|"]
    for r in rows:
        seconds = r["case"].startswith(("interfoot", "yamane"))

        def fmt(v):
            return "–" if v is None else (f"{v:.3f} s" if seconds else f"{v:.0f}")

        speedup = f"{r['speedup']:.1f}x" if "speedup" in r else "–"
        met = "–" if r["met"] is None else ("yes" if r["met"] else "NO")
        diff = r.get("max_offset_difference_deg")
        L.append(f"| {r['label']} | {fmt(r['old'])} | {fmt(r['new'])} | {speedup} | {r['target']} | {met} | "
                 f"{'–' if diff is None else f'{diff:.1e}'} |")
    return write_report(out, "\n".join(L) + "\n", {"command": cmd, "provenance": version, "baseline": baseline,
                                                     "rows": rows, "runs": runs})
