"""The model-gap suite (issue #17): the loop itself scored (`legcal-bench bench --suite
modelgap`).

Cases, each a session set (weld, `calibrated-imu`, the paper's injection) diagnosed by
`legcal_bench.evaluation.modelgap.diagnose`, its fit started from a calibrator's offsets
(default `interfoot`, its default `sensor` setting; any registered one with
`bench --calibrators`), on the training recordings only:
  clean         no effect: the false-alarm rate (an effect claimed, or "ambiguous"),
                and how far the data are from the declared noise at the true offsets;
  clean_kinematic  the same on the kinematic floor;
  library       each library effect at a magnitude drawn from the seed in a realistic
                range (`library_spec`), side and target alternating: detected,
                attributed to the right effect, offsets error before/after;
  near          each library effect at a small fraction of its draw (NEAR_SCALES): the
                near-threshold band, scored over the seeds whose offsets-only z is in NEAR_Z;
  multi         several small effects at once (MULTI_COUNT of them at MULTI_SCALE);
  outside       physical edits no library effect describes (`OUTSIDE`): "unexplained"
                (or a poor fit) with the edited leg located, never a confident wrong
                attribution; the channel is compared with a reference run of the same
                edit at REFERENCE_SCALE times the size (where noise cannot move it).

Resumable, case by case (`run`): each finished case (its session set collected and
diagnosed) is written atomically to its own file under the cases folder with its
provenance (the code version, the command, the case: robot, kind, effect, seed,
stances, calibrator) and a key, a hash of what its numbers depend on (`case_key`: the
case and the code, with any uncommitted change to it). A rerun keeps the cases whose
key matches and recomputes the others; the report is assembled from the files, so an
interrupted run loses only the cases in progress.
"""

from __future__ import annotations

import hashlib
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from legcal_bench.errors import ConfigError
from legcal_bench.evaluation.modelgap import ALPHA

RESULTS_NAME = "modelgap"  # its folder and files under the leaderboard root
CASES = ("clean", "library", "near", "multi", "outside")  # `bench --cases`: clean takes
# its kinematic floor along, outside its reference runs
LIBRARY = ("imu_tilt", "leg_length", "encoder_scale", "compliance", "hip_axis")
OUTSIDE = {
    "shank_bent": "link_offset:link={side}_shank,axis=y,mm={size}",
    "shank_twisted": "link_twist:link={side}_shank,deg={size}",
    "knee_axis_tilted": "joint_axis:joint={side}_knee,about=x,deg={size}",
}
OUTSIDE_SIZE = {"shank_bent": 3.0, "shank_twisted": 1.0, "knee_axis_tilted": 0.5}
REFERENCE_SCALE = 4.0
NEAR_SCALES = (0.05, 0.5)  # the near-threshold band: this fraction of a realistic draw (log-uniform)
NEAR_Z = (2.0, 10.0)  # ... scored over the seeds whose offsets-only post-fit z falls here
MULTI_COUNT, MULTI_SCALE = 3, 0.25  # several small effects at once: 3 library effects, each at a quarter of its draw
OUTSIDE_ROBOTS = ("a3",)  # the outside edits run on these of the suite's robots (time: ~35 s a diagnosis)
SIDES = ("left", "right")
DEFAULT_CALIBRATOR = ("interfoot", ())  # (name, options as key-value pairs): the offsets each diagnosis starts from
GAP_LABEL = {"cross_validation": "left-out stances", "heldout": "held-out"}


def library_spec(effect: str, seed: int, scale: float = 1.0) -> str:
    """A library effect at a magnitude drawn in its realistic range (seeded), times
    `scale` (compliance: its deflection, so the stiffness divided by `scale`)."""
    rng = np.random.default_rng([seed, 17])
    side = SIDES[seed % 2]
    sign = 1.0 if rng.random() < 0.5 else -1.0
    if effect == "imu_tilt":
        return f"imu_tilt:roll={scale * sign * rng.uniform(0.3, 0.7):.4f}"
    if effect == "leg_length":
        mm = scale * sign * rng.uniform(1.5, 3.0)
        return f"link_length:link={side}_{('shank', 'thigh')[(seed // 2) % 2]},mm={mm:.4f}"
    if effect == "encoder_scale":
        return f"encoder_scale:joint={side}_knee,scale={scale * sign * rng.uniform(0.003, 0.007):.6f}"
    if effect == "compliance":
        return f"compliance:joint={side}_knee,k={rng.uniform(0.7e4, 1.5e4) / scale:.0f}"
    if effect == "hip_axis":
        return f"hip_axis:joint={side}_hip_pitch,about=z,deg={scale * sign * rng.uniform(0.3, 0.7):.4f}"
    raise KeyError(effect)


def near_scale(seed: int) -> float:
    """The near-threshold band's size, a fraction of the realistic draw: log-uniform in
    NEAR_SCALES (seeded). The offsets-only z grows with the size squared; realistic draws
    give z ~ 15-460 on the A3-like robot (commit 49f9cd0's suite), so the band straddles
    z = 2-10 for every library effect; the score counts the seeds that land there."""
    lo, hi = NEAR_SCALES
    return float(np.exp(np.random.default_rng([seed, 71]).uniform(np.log(lo), np.log(hi))))


def multi_effects(seed: int) -> tuple[str, ...]:
    """Several small effects at once: MULTI_COUNT library effects (seeded choice)."""
    pick = np.random.default_rng([seed, 23]).choice(len(LIBRARY), MULTI_COUNT, replace=False)
    return tuple(LIBRARY[i] for i in sorted(pick))


def multi_specs(seed: int) -> tuple[str, ...]:
    """... each at MULTI_SCALE of its realistic draw."""
    return tuple(library_spec(e, seed, MULTI_SCALE) for e in multi_effects(seed))


def outside_spec(name: str, seed: int, scale: float = 1.0) -> tuple[str, str]:
    side = SIDES[seed % 2]
    return OUTSIDE[name].format(side=side, size=OUTSIDE_SIZE[name] * scale), side


# Held-out sessions recorded per session set: none. Since #35 nothing here reads them
# (the diagnosis, its calibrator and the chi-square at the truth read the training
# recordings only), and each segment's randomness is its own (`collect`'s seed per
# segment, held-out ones recorded last), so the training recordings are the same bytes
# with or without them; they were 1500 of the 4150 frames of a default set.
HELDOUT = 0
COLLECT: dict = {}  # CollectConfig overrides of every case `run` makes (a test's shorter sessions); in its key


def _collect(robot: str, specs: tuple[str, ...], seed: int, work: Path, mode: str = "weld", stances=None,
             collect_overrides: dict | None = None):
    from legcal_bench.data.recording import list_segments, load_session, load_truth
    from legcal_bench.protocol.collect import CollectConfig, collect
    from legcal_bench.robots import load_robot

    legmap = load_robot(robot)
    cfg = CollectConfig(**{"robot": robot, "mode": mode, "sensors": "calibrated-imu", "seed": seed, "heldout": HELDOUT,
                           "effects": tuple(specs), **({"stances": tuple(stances)} if stances else {}),
                           **(collect_overrides or {})})
    collect(cfg, work / "set", progress=False)
    return legmap, load_session(work / "set", robot=legmap), load_truth(list_segments(work / "set")[0])


def run_case(robot: str, kind: str, name: str | None, seed: int, stances=None,
             calibrator: tuple = DEFAULT_CALIBRATOR, collect: dict | None = None) -> dict:
    """One diagnosed session set; `kind` clean | library | near | multi | outside |
    reference; `stances` recorded (default: the paper's four); `calibrator` (name,
    options as key-value pairs) makes the offsets the diagnosis starts from; `collect`:
    CollectConfig overrides (shorter sessions)."""
    from legcal_bench.calibrators.base import calibrate_training
    from legcal_bench.calibrators.registry import get_calibrator
    from legcal_bench.estimation.problem.fit import fit_model
    from legcal_bench.evaluation.metrics import rms
    from legcal_bench.evaluation.modelgap import context, diagnose, evaluate, trace

    specs, side, scale = (), None, None
    if kind == "library":
        specs = (library_spec(name, seed),)
    elif kind == "near":
        scale = near_scale(seed)
        specs = (library_spec(name, seed, scale),)
    elif kind == "multi":
        specs = multi_specs(seed)
        name = "+".join(multi_effects(seed))
    elif kind in ("outside", "reference"):
        spec, side = outside_spec(name, seed, REFERENCE_SCALE if kind == "reference" else 1.0)
        specs = (spec,)
    cal_name, cal_options = calibrator
    cal = get_calibrator(cal_name, **dict(cal_options))
    with tempfile.TemporaryDirectory(prefix="legcal_modelgap_") as work:
        mode = "kinematic" if kind == "clean_kinematic" else "weld"
        legmap, recs, truth = _collect(robot, specs, seed, Path(work), mode, stances, collect)
        row = {"robot": legmap.name, "robot_spec": robot, "kind": kind, "name": name,
               "spec": " ".join(specs) or None, "seed": seed, "side": side, "scale": scale, "mode": mode}
        if kind == "reference":
            ctx = context(legmap, recs)
            ev = evaluate(ctx, fit_model(ctx.prep), ctx.prep.segments, keep_frames=True)
            row["localization"] = trace(ctx, ev)["localization"]
            return row
        names = legmap.joint_names
        start = calibrate_training(cal, legmap, recs).offsets_vector(names)
        ctx = context(legmap, recs)  # the diagnosis's prepared data, shared with the chi-square at the truth
        rep = diagnose(legmap, recs, start=start, prep=ctx.prep)
        if kind.startswith("clean"):
            row["at_truth"] = _chi2_at_truth(ctx, truth)
    injected = np.asarray(truth.offsets)
    if calibrator != DEFAULT_CALIBRATOR:
        row["calibrator"] = {"name": cal_name, "options": dict(cal_options),
                             "offsets_rms_deg": float(np.rad2deg(rms(start - injected)))}
    before = np.array([rep["offsets_only_rad"][n] for n in names])
    after = np.array([rep["offsets_rad"][n] for n in names])
    row.update(verdict=rep["verdict"], selected=rep["selected"], poor_fit=rep["poor_fit"],
               ambiguous=[a["effect"] for a in rep["ambiguous"]], summary=rep["summary"],
               chi2_per_dof=rep["detection"]["chi2_per_dof"], p_value=rep["detection"]["p_value"],
               z=rep["detection"]["z"], cross_validation=rep["detection"].get("cross_validation"),
               chi2_per_dof_after=rep["after"]["chi2_per_dof"],
               localization=rep["tracing"]["localization"],
               offsets_rms_deg={"before": float(np.rad2deg(rms(before - injected))),
                                "after": float(np.rad2deg(rms(after - injected)))},
               confounded=[c["effect"] for c in rep["confounded"]])
    return row


def _chi2_at_truth(ctx, truth) -> dict:
    """Whitened chi-square per degree of freedom with the offsets at the injected truth
    (no step), on the training stances (`ctx`, the diagnosis's `context`): what the data
    hold beyond the declared noise that no estimate causes."""
    from legcal_bench.estimation.problem.fit import offsets_fit
    from legcal_bench.evaluation.modelgap import evaluate

    segs = ctx.prep.segments
    ev = evaluate(ctx, offsets_fit(ctx.prep, np.asarray(truth.offsets)), segs)
    return {"training": float(ev.z @ ev.z) / (ev.n_rows - 6 * len({s.name for s in segs}))}


CASES_DIR = Path("runs/bench/modelgap")  # `run`'s cases folder unless given (relative: the working directory)
# Submission order (`run`): the long cases first, so that no worker is left with one at the
# end (seconds a case, A3-like at commit 8ea50e6: a library effect ~60, clean ~15).
COST = {"clean_kinematic": 1, "clean": 1, "reference": 1, "library": 4, "near": 4, "multi": 4, "outside": 4}


def case_path(cases_dir: str | Path, job: tuple) -> Path:
    """Where a case (a `jobs` tuple) is kept: <robot>/<kind>[_<effect>]/seed<NN>.json, the
    stances and a calibrator other than the default in the folder's name."""
    from legcal_bench.robots import robot_label

    robot, kind, name, seed, stances, calibrator = job
    group = kind + (f"_{name}" if name else "")
    if stances:
        group += "_st-" + "-".join(stances)
    if tuple(calibrator) != DEFAULT_CALIBRATOR:
        cal, options = calibrator
        group += f"_cal-{cal}" + ("-" + _short_hash(list(options)) if options else "")
    return Path(cases_dir) / robot_label(robot) / group / f"seed{seed:02d}.json"


def _short_hash(obj) -> str:
    from legcal_bench.provenance import stable_hash

    return stable_hash(obj)[:8]


def case_identity(job: tuple, collect: dict | None = None) -> dict:
    """A case as its file records it (JSON): robot, kind, effect, seed, stances, the
    collection's overrides, the calibrator and its settings."""
    from legcal_bench.calibrators.registry import get_calibrator
    from legcal_bench.robots import robot_label

    robot, kind, name, seed, stances, (cal, options) = job
    return {"robot": robot_label(robot), "kind": kind, "name": name, "seed": seed,
            "stances": list(stances) if stances else None, "heldout": HELDOUT,
            "collect": dict(sorted((collect or {}).items())),
            "calibrator": {"name": cal, "options": dict(options),
                           "settings": get_calibrator(cal, **dict(options)).settings()}}


def code_identity(code: dict) -> dict:
    """What of the code a case's numbers depend on: `code_version()`'s package, commit
    and results version and, with uncommitted changes to the code (`CODE_PATHS`), a hash
    of those changes (`git diff`), so that a case is kept only under the same code."""
    from legcal_bench.provenance import CODE_PATHS, _git

    out = {k: code.get(k) for k in ("package", "commit", "results_version")}
    if code.get("dirty"):
        diff = _git("diff", "HEAD", "--", *(f":(top){p}" for p in CODE_PATHS))
        out["changes"] = None if diff is None else hashlib.sha256(diff.encode()).hexdigest()[:16]
    return out


def case_key(job: tuple, code_id: dict, collect: dict | None = None) -> str:
    """The resume key of a case: a hash of the case (`case_identity`) and the code
    (`code_identity`)."""
    from legcal_bench.provenance import stable_hash

    return stable_hash({"case": case_identity(job, collect), "code": code_id})


def is_done(path: Path, key: str) -> bool:
    """True if `path` holds a whole case made under `key`."""
    try:
        c = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return False
    return isinstance(c, dict) and c.get("key") == key and isinstance(c.get("row"), dict)


def run_job(job: tuple, cases_dir: str, provenance: dict, collect: dict | None = None) -> str:
    """Run one case (`run_case`, with the collection's overrides `collect`) and write
    its file (`case_path`) atomically, with its key and provenance (`provenance`: the
    key, the code version and the command, read once when the run started); returns
    the file's path. A worker process's task."""
    from legcal_bench.benchmark.tasks import single_thread
    from legcal_bench.files.atomic import atomic_write_json

    single_thread()
    t0 = time.perf_counter()
    row = run_case(*job, collect=collect)
    path = case_path(cases_dir, job)
    atomic_write_json(path, {"key": provenance["key"], "case": case_identity(job, collect),
                             "provenance": {"code": provenance["code"], "command": provenance["command"]},
                             "wall_s": time.perf_counter() - t0, "row": row})
    return str(path)


def jobs(robots, seeds: int, clean_seeds: int, outside_robots, outside_seeds: int, near_seeds: int = 0,
         multi_seeds: int = 0, stances=None, cases=CASES, calibrator: tuple = DEFAULT_CALIBRATOR) -> list[tuple]:
    """(robot, kind, name, seed, stances, calibrator) of every case of the groups in `cases`."""
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        raise ConfigError(f"--cases: {', '.join(unknown)} unknown; the model-gap suite's cases are "
                          f"{', '.join(CASES)}")
    st = None if stances is None else tuple(stances)
    out = [(r, kind, None, s, st) for r in robots for kind in ("clean", "clean_kinematic")
           for s in range(clean_seeds)]
    out += [(r, "library", e, s, st) for r in robots for e in LIBRARY for s in range(seeds)]
    out += [(r, "near", e, 1000 + s, st) for r in robots for e in LIBRARY for s in range(near_seeds)]
    out += [(r, "multi", None, 2000 + s, st) for r in robots for s in range(multi_seeds)]
    out += [(r, "reference", o, s, st) for r in outside_robots for o in OUTSIDE for s in range(2)]
    out += [(r, "outside", o, s, st) for r in outside_robots for o in OUTSIDE for s in range(outside_seeds)]
    group = {"clean_kinematic": "clean", "reference": "outside"}
    return [(*j, calibrator) for j in out if group.get(j[1], j[1]) in cases]


def run(robots, seeds: int = 10, clean_seeds: int = 20, outside_robots=OUTSIDE_ROBOTS, outside_seeds: int = 10,
        near_seeds: int = 10, multi_seeds: int = 10, workers: int = 2, progress: bool = True,
        stances=None, cases=CASES, calibrator: tuple = DEFAULT_CALIBRATOR, out: str | Path | None = None,
        command: str | None = None) -> dict:
    """Every case (`jobs`) of the groups in `cases` diagnosed; `seeds` per library
    effect, the other counts as named; `stances` recorded in every case (default: the
    paper's four); `calibrator` (name, options as key-value pairs) makes the offsets each
    diagnosis starts from. Each case is a file under `out` (default CASES_DIR), written
    as it finishes (`run_job`, on `workers` processes; 1: in this process); a case whose
    file holds its current key is kept, not recomputed (`case_key`); the rows are read
    back from the files, in `jobs` order. `command` is recorded in each new case's
    provenance (default: this call's arguments). Returns {"rows", "summary", "cases":
    how many there are, were computed and were kept}."""
    from legcal_bench.provenance import code_version

    todo = jobs(robots, seeds, clean_seeds, [r for r in outside_robots if r in robots], outside_seeds, near_seeds,
                multi_seeds, stances, cases, calibrator)
    cases_dir = Path(CASES_DIR if out is None else out).resolve()
    if command is None:
        command = (f"legcal_bench.benchmark.modelgap.run(robots={list(robots)}, seeds={seeds}, "
                   f"clean_seeds={clean_seeds}, outside_robots={list(outside_robots)}, outside_seeds={outside_seeds}, "
                   f"near_seeds={near_seeds}, multi_seeds={multi_seeds}, stances={stances and list(stances)}, "
                   f"cases={list(cases)}, calibrator={calibrator})")
    code = code_version()  # read once: every case of a run records the code the run started with
    code_id = code_identity(code)
    paths = [case_path(cases_dir, j) for j in todo]
    collect = dict(COLLECT)
    keys = [case_key(j, code_id, collect) for j in todo]
    pending = [i for i, (p, k) in enumerate(zip(paths, keys)) if not is_done(p, k)]
    pending.sort(key=lambda i: -COST.get(todo[i][1], 1))  # stable: job order within a cost
    provs = {i: {"key": keys[i], "code": code, "command": command} for i in pending}
    _execute([(todo[i], str(cases_dir), provs[i], collect) for i in pending], workers, progress)
    rows = [json.loads(p.read_text())["row"] for p in paths]
    return {"rows": rows, "summary": summarize(rows),
            "cases": {"total": len(todo), "computed": len(pending), "kept": len(todo) - len(pending)}}


def _execute(tasks: list[tuple], workers: int, progress: bool) -> None:
    """`run_job` on every task, on `workers` worker processes (the runner's executor: one
    BLAS thread each, ended with their parent) or in this process (workers <= 1). On a
    case's error no new case starts, the running ones finish (and are written), and the
    error is raised; on Ctrl-C the running ones are ended at once (a case file is whole
    or absent)."""
    from tqdm import tqdm

    bar = tqdm(total=len(tasks), desc="modelgap", unit="set", disable=not progress)
    try:
        if workers <= 1 or len(tasks) <= 1:
            for t in tasks:
                run_job(*t)
                bar.update(1)
            return
        from concurrent.futures import FIRST_EXCEPTION, wait

        from legcal_bench.benchmark.runner import make_executor

        ex, _ = make_executor(None, min(workers, len(tasks)))
        futures = []
        try:
            futures = [ex.submit(run_job, *t) for t in tasks]
            left = set(futures)
            while left:
                done, left = wait(left, return_when=FIRST_EXCEPTION)
                for f in done:
                    f.result()  # raises the case's error here
                    bar.update(1)
        except BaseException as e:
            for f in futures:
                f.cancel()
            if not isinstance(e, Exception):  # Ctrl-C: end our workers, and the cases in progress
                for proc in list((getattr(ex, "_processes", None) or {}).values()):
                    proc.terminate()
            ex.shutdown(wait=True, cancel_futures=True)
            raise
        ex.shutdown(wait=True)
    finally:
        bar.close()


def summarize(rows: list[dict]) -> list[dict]:
    out = []
    robots = list(dict.fromkeys(r["robot"] for r in rows))
    for robot in robots:
        rr = [r for r in rows if r["robot"] == robot]
        clean = [r for r in rr if r["kind"] == "clean"]
        floor = float(np.mean([_recommended(r) for r in clean])) if clean else float("nan")
        for case in ("clean", "clean_kinematic"):
            clean_rows = [r for r in rr if r["kind"] == case]
            if clean_rows:
                out.append(_clean_summary(robot, case, clean_rows))
        for e in LIBRARY:
            rs = [r for r in rr if r["kind"] == "library" and r["name"] == e]
            if not rs:
                continue
            conf = any(e in r["confounded"] for r in rs)
            after = float(np.mean([_recommended(r) for r in rs]))
            out.append({"robot": robot, "case": e, "seeds": len(rs),
                        "detected": sum(r["verdict"] != "explained" for r in rs),
                        "correct": sum(r["selected"] == [e] for r in rs),
                        "wrong_confident": sum(bool(r["selected"]) and r["selected"] != [e] for r in rs),
                        "verdicts": _count(r["verdict"] for r in rs),
                        "offsets_rms_deg_before": float(np.mean([r["offsets_rms_deg"]["before"] for r in rs])),
                        "offsets_rms_deg_after": after, "floor_offsets_rms_deg": floor,
                        "after_over_floor": after / floor if floor == floor else None,
                        "partly_confounded": conf})
        for e in LIBRARY:
            rs = [r for r in rr if r["kind"] == "near" and r["name"] == e]
            if not rs:
                continue
            band = [r for r in rs if NEAR_Z[0] <= r["z"] <= NEAR_Z[1]]
            out.append({"robot": robot, "case": f"near: {e}", "seeds": len(rs), "in_band": len(band),
                        "scales": [min(r["scale"] for r in rs), max(r["scale"] for r in rs)],
                        "z_range": [min(r["z"] for r in rs), max(r["z"] for r in rs)],
                        "detected_in_band": sum(r["verdict"] != "explained" for r in band),
                        "correct_in_band": sum(r["selected"] == [e] for r in band),
                        "detected": sum(r["verdict"] != "explained" for r in rs),
                        "correct": sum(r["selected"] == [e] for r in rs),
                        "wrong_confident": sum(bool(r["selected"]) and r["selected"] != [e] for r in rs),
                        "verdicts": _count(r["verdict"] for r in rs)})
        multi = [r for r in rr if r["kind"] == "multi"]
        if multi:
            inj = [set(r["name"].split("+")) for r in multi]
            out.append({"robot": robot, "case": f"multi: {MULTI_COUNT} effects at {MULTI_SCALE:g} of their size",
                        "seeds": len(multi), "detected": sum(r["verdict"] != "explained" for r in multi),
                        "effects_injected": MULTI_COUNT * len(multi),
                        "effects_selected_right": sum(len(set(r["selected"]) & i) for r, i in zip(multi, inj)),
                        "wrong_confident": sum(bool(set(r["selected"]) - i) for r, i in zip(multi, inj)),
                        "verdicts": _count(r["verdict"] for r in multi),
                        "offsets_rms_deg_before": float(np.mean([r["offsets_rms_deg"]["before"] for r in multi])),
                        "offsets_rms_deg_after": float(np.mean([_recommended(r) for r in multi])),
                        "floor_offsets_rms_deg": floor})
        refs = {(r["name"], r["side"]): r["localization"] for r in rr if r["kind"] == "reference"}
        for o in OUTSIDE:
            rs = [r for r in rr if r["kind"] == "outside" and r["name"] == o]
            if not rs:
                continue
            leg = [r["localization"]["location"] == f"{r['side']} leg" for r in rs]
            chan = [refs.get((o, r["side"])) is not None
                    and r["localization"]["channel"] == refs[(o, r["side"])]["channel"] for r in rs]
            unexplained = [r["verdict"] == "unexplained" for r in rs]
            out.append({"robot": robot, "case": f"outside: {o}", "seeds": len(rs),
                        "unexplained": sum(unexplained),
                        "unexplained_leg_and_channel": sum(u and a and b for u, a, b in zip(unexplained, leg, chan)),
                        "leg_correct": sum(leg), "channel_as_reference": sum(chan),
                        "reference_channels": sorted({v["channel"] for (n, _), v in refs.items() if n == o}),
                        "wrong_confident": sum(bool(r["selected"]) for r in rs),
                        "verdicts": _count(r["verdict"] for r in rs)})
    return out


def _clean_summary(robot: str, case: str, clean: list[dict]) -> dict:
    truth_chi2 = {k: [r["at_truth"][k] for r in clean if k in r.get("at_truth", {})] for k in ("training", "heldout")}
    # The gap test: leave-one-stance-out since #35; rows made before read the held-out sessions.
    gap = "cross_validation" if any("cross_validation" in r for r in clean) else "heldout"
    return {"robot": robot, "case": case, "seeds": len(clean),
            "no_effect_claimed": sum(not r["selected"] and not r["ambiguous"] for r in clean),
            "detected": sum(r["verdict"] != "explained" for r in clean),
            "training_test_fired": sum(r["p_value"] < ALPHA / 2 for r in clean),
            f"{gap}_test_fired": sum((r.get(gap) or {}).get("p_value", 1.0) < ALPHA / 2 for r in clean),
            "chi2_per_dof_at_truth": {k: _mean_max(v) for k, v in truth_chi2.items() if v},
            "verdicts": _count(r["verdict"] for r in clean),
            "floor_offsets_rms_deg": float(np.mean([_recommended(r) for r in clean]))}


def _gap_fired(s: dict) -> str:
    """The gap test's label and count of a clean summary (`_clean_summary`)."""
    gap = "cross_validation" if "cross_validation_test_fired" in s else "heldout"
    return f"{GAP_LABEL[gap]} {s[gap + '_test_fired']}"


def _recommended(r: dict) -> float:
    """Offsets RMS error (deg) of what the diagnosis recommends: with the selected
    effects, else (nothing kept, a poor fit included) the offsets-only estimate."""
    return r["offsets_rms_deg"]["after"] if r["selected"] else r["offsets_rms_deg"]["before"]


def _cell(x, nd: int) -> str:
    """A table number, or "–" where there is none (no clean floor among the cases run)."""
    return "–" if x is None or x != x else f"{x:.{nd}f}"


def _mean_max(v) -> dict:
    return {"mean": float(np.mean(v)), "max": float(np.max(v))}


def _count(values) -> dict:
    out: dict = {}
    for v in values:
        out[v] = out.get(v, 0) + 1
    return out


def markdown(data: dict, made_by: str, code: str) -> str:
    starts = sorted({r["calibrator"]["name"] for r in data.get("rows", ()) if "calibrator" in r})
    who = f"`{'`, `'.join(starts)}` (offsets the diagnosis starts from)" if starts else "`interfoot` (`sensor`)"
    L = ["# Model-gap loop: detection, attribution, \"unexplained\"", "",
         f"Made by `{made_by}` ({code}). Weld (clean_kinematic: the kinematic floor), `calibrated-imu`, the paper's "
         f"injection; {who} "
         "then `legcal_bench.evaluation.modelgap.diagnose`. Library magnitudes drawn per seed in realistic ranges "
         "(`library_spec`); offsets: RMS error of the offsets (deg), offsets-only vs after the diagnosis.", "",
         "| robot | case | seeds | detected | correct / no effect claimed | wrong confident | offsets before | after "
         "| floor | after/floor | verdicts |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in data["summary"]:
        v = ", ".join(f"{k} {n}" for k, n in s["verdicts"].items())
        if s["case"].startswith("clean"):
            L.append(f"| {s['robot']} | {s['case']} | {s['seeds']} | {s['detected']} (training test {s['training_test_fired']}"
                     f", {_gap_fired(s)}) | {s['no_effect_claimed']}/{s['seeds']} | – | – | "
                     f"{s['floor_offsets_rms_deg']:.4f} | – | – | {v} |")
        elif s["case"].startswith("near"):
            L.append(f"| {s['robot']} | {s['case']} ({s['scales'][0]:.2f}–{s['scales'][1]:.2f} of the size; z "
                     f"{s['z_range'][0]:.1f}–{s['z_range'][1]:.1f}) | {s['seeds']} ({s['in_band']} with z in "
                     f"{NEAR_Z[0]:g}–{NEAR_Z[1]:g}) | {s['detected']}/{s['seeds']} (band {s['detected_in_band']}/"
                     f"{s['in_band']}) | {s['correct']}/{s['seeds']} (band {s['correct_in_band']}/{s['in_band']}) | "
                     f"{s['wrong_confident']} | – | – | – | – | {v} |")
        elif s["case"].startswith("multi"):
            L.append(f"| {s['robot']} | {s['case']} | {s['seeds']} | {s['detected']}/{s['seeds']} | "
                     f"{s['effects_selected_right']}/{s['effects_injected']} injected effects selected | "
                     f"{s['wrong_confident']} | {s['offsets_rms_deg_before']:.4f} | {s['offsets_rms_deg_after']:.4f} | "
                     f"{_cell(s['floor_offsets_rms_deg'], 4)} | "
                     f"{_cell(s['offsets_rms_deg_after'] / s['floor_offsets_rms_deg'], 2)} | {v} |")
        elif s["case"].startswith("outside"):
            L.append(f"| {s['robot']} | {s['case']} | {s['seeds']} | {s['unexplained']} unexplained | "
                     f"{s['unexplained_leg_and_channel']}/{s['seeds']} with leg and channel (leg {s['leg_correct']}, "
                     f"channel {s['channel_as_reference']}; reference {', '.join(s['reference_channels'])}) | "
                     f"{s['wrong_confident']} | – | – | – | – | {v} |")
        else:
            L.append(f"| {s['robot']} | {s['case']} | {s['seeds']} | {s['detected']}/{s['seeds']} | "
                     f"{s['correct']}/{s['seeds']} | {s['wrong_confident']} | {s['offsets_rms_deg_before']:.4f} | "
                     f"{s['offsets_rms_deg_after']:.4f} | {_cell(s['floor_offsets_rms_deg'], 4)} | "
                     f"{_cell(s['after_over_floor'], 2)} | {v} |")
    return "\n".join(L) + "\n"
