"""The closed-loop evaluation: what a calibration does to a walking policy (issue #15).

Per trial (seed s), paired: the offsets of the trial (`trial_offsets`: `paper@D` the
same in every trial, `random:D` a pattern per trial drawn from seed 20000 + s,
`random:D@S` the same from seed S + s) are put on the robot, and

  1. a static session set of the same robot with the same offsets and fresh noise is
     collected (weld floor, `calibrated-imu` sensors, stances I-IV, no held-out
     sessions by default) and calibrated by the method under test; its estimate is
     frozen before any walking;
  2. four 20 s walks with the same seed (sensor noise, initial jitter):
       nominal      no offsets
       uncorrected  the offsets, no correction
       corrected    the offsets, corrected by the estimate (q_enc + dq_hat)
       oracle       the offsets, corrected by the true offsets

Metrics per condition against the same seed's nominal walk (`deviation`): pelvis-
trajectory and foot-strike RMS deviation (mm; trials where either walk fell are
excluded and counted), upright, time to fall, mean torque and power. The oracle walk
has the same seed and the same true joint targets as the nominal one; with some
policies it repeats the nominal walk up to floating-point rounding, with others the
rounding grows into centimetres (the summary's `oracle_distance`: its mean and max
distance from nominal, which the report's wording follows). The other yardstick is the
nominal seed-to-seed spread: a nominal walk with other sensor noise and initial jitter
(`SPREAD_SEED_OFFSET`) against the trial's nominal walk. The leg-odometry check
(`legcal_bench.evaluation.odometry`) runs on each nominal walk with the trial's offsets
added to the logged encoders afterwards, before and after the trial's correction. Trials run through
any `concurrent.futures.Executor` (local processes, or Dask's), each trial's static estimate, walks
and odometry a task of its own (the same numbers as one trial a task, `run_trial`).

Resume (`TrialStore`, `keep_trials`; `walk-eval --out DIR`): each trial's row is written
as it finishes, atomically, to `DIR/trials/s<seed>_<key>.json`, `<key>` a stable hash
(`trial_key`) of everything that makes the row: the robot's leg map and MJCF (their
contents), the policy's spec and model file (contents), the offsets spec and the
trial's drawn offsets, the seed, seconds, calibrator with its options and settings (and
the variants'), static and walking sensors, the seed bases, `RESULTS_VERSION` and
`ROW_VERSION`. A rerun takes the rows whose key matches and runs only the rest; rows of
other settings in the same folder have other keys and are never read. The git commit is
recorded in each file, not keyed (as the benchmark's cells, `legcal_bench.provenance`).
"""

from __future__ import annotations

import contextvars
import hashlib
import json
import threading
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from legcal_bench.evaluation.metrics import mean_std, rms
from legcal_bench.evaluation.walk import deviation, trial_offsets, walk
from legcal_bench.files.scratch import scratch_dir

CONDITIONS = ("nominal", "uncorrected", "corrected", "oracle")
STATIC_SEED_BASE = 30_000  # the static session set of trial s is collected with seed STATIC_SEED_BASE + s
PATH_STEP = 5  # pelvis paths kept for the plot: every 5th control step
SPREAD_SEED_OFFSET = 100_000  # the spread walk of trial s uses seed s + SPREAD_SEED_OFFSET
ODOMETRY_KEYS = ("vertical_mm", "forward_mm", "lateral_mm", "total_mm", "final_vertical_drift_mm")
ROW_VERSION = 1  # a trial row's layout (its file's key): bump when rows change without a RESULTS_VERSION bump
TRIALS_DIR = "trials"  # finished trials under a run's folder (`TrialStore`)
TIMING_KEYS = ("static_s", "wall_s", "walk_s")  # wall-clock fields: a trial's, a walk's, the summary's


@dataclass(frozen=True)
class ClosedLoopConfig:
    robot: str
    policy: str  # spec path
    offsets: str = "paper@3"
    trials: int = 35
    seconds: float = 20.0
    calibrator: str = "interfoot"
    options: dict = field(default_factory=dict)  # the calibrator's; `calibrator_options` picks the default
    static_mode: str = "weld"
    static_sensors: str = "calibrated-imu"
    walk_sensors: str = "realistic"
    heldout: int = 0
    first_seed: int = 0
    mjcf: str | None = None
    # More methods on the same static sets and walks: (label, calibrator, options as
    # sorted items), each with its own corrected walk (the closed-loop suite).
    variants: tuple = ()


def calibrator_options(name: str) -> dict:
    """The calibrator's sensor-matched variant where it has one (`benchmark_variants`),
    else its defaults."""
    from legcal_bench.calibrators.registry import available_calibrators

    cls = available_calibrators().get(name)
    return dict(cls.benchmark_variants().get("sensor", {})) if cls is not None else {}


def run_trial(cfg: ClosedLoopConfig, seed: int) -> dict:
    """One trial: the static calibration, then the four walks (and the spread walk, the
    variants' corrected walks, the leg odometry), here, one after the other. `evaluate`
    runs the same parts as separate tasks."""
    static = static_estimate(cfg, seed)
    walks = {c: trial_walk(cfg, seed, c, static["dq_hat"]) for c in (*WALKS, "spread") if c != "corrected"
             or not static["failed"]}
    walks.update({("variant", label): trial_walk(cfg, seed, "corrected", static["others"][label])
                  for label, _, _ in cfg.variants if not static["failed"]})
    return assemble_trial(cfg, seed, static, walks, trial_odometry_of(cfg, seed, walks["nominal"], static))


WALKS = CONDITIONS  # a trial's walks besides the spread walk, in the order its row lists them
_WALKERS = threading.local()  # per thread (a Dask worker runs tasks in threads): its walker, reused across trials


def _walker(cfg: ClosedLoopConfig):
    """(legmap, walking env, policy runner) of `cfg`, built once per thread and reused
    by every walk (each `walk` resets the env and runner with its own seed), rebuilt if
    the policy's or the robot's files changed."""
    from legcal_bench.envs.walking import WalkingEnv
    from legcal_bench.policies.runner import PolicyRunner

    key = (cfg.robot, cfg.mjcf, cfg.policy, cfg.walk_sensors)
    hit = getattr(_WALKERS, "cached", None)  # (key, file stamps, legmap, env, runner)
    if hit is not None and hit[0] == key and hit[1] == _stamp(hit[2], hit[4]):
        return hit[2:]
    legmap = _robot(cfg)[0]
    env = WalkingEnv(robot=legmap, policy=cfg.policy, sensors=cfg.walk_sensors)
    runner = PolicyRunner(env.policy_spec, legmap)
    _WALKERS.cached = (key, _stamp(legmap, runner), legmap, env, runner)
    return legmap, env, runner


def _robot(cfg: ClosedLoopConfig):
    """(legmap, its leg kinematics) of `cfg`, loaded once per thread for the static
    estimates, walks and odometry of every trial, reloaded if the robot's files changed."""
    from legcal_bench.robots import load_robot
    from legcal_bench.robots.kinematics import LegKinematics

    key = (cfg.robot, cfg.mjcf)
    hit = getattr(_WALKERS, "robot", None)  # (key, file stamps, legmap, kinematics)
    if hit is not None and hit[0] == key and hit[1] == _stamp(hit[2]):
        return hit[2:]
    legmap = load_robot(cfg.robot, cfg.mjcf)
    _WALKERS.robot = (key, _stamp(legmap), legmap, LegKinematics(legmap))
    return _WALKERS.robot[2:]


def _stamp(legmap, runner=None) -> tuple:
    """Modification times of the files a cached walker (or leg map) was built from."""
    spec = runner.spec if runner is not None else None
    files = (legmap.source, legmap.mjcf) + ((spec.path, spec.model_file) if spec is not None else ())
    return tuple(Path(f).stat().st_mtime_ns if f is not None and Path(f).exists() else None for f in files)


def static_estimate(cfg: ClosedLoopConfig, seed: int) -> dict:
    """Step 1 of trial `seed`: its static session set collected and calibrated by the
    method under test (and each variant); the estimate is frozen before any walking."""
    from legcal_bench.calibrators.base import calibrate_training
    from legcal_bench.calibrators.registry import get_calibrator
    from legcal_bench.data.recording import load_session
    from legcal_bench.errors import HoldError
    from legcal_bench.protocol.collect import CollectConfig, collect

    legmap = _robot(cfg)[0]
    dq = trial_offsets(cfg.offsets, legmap, seed)
    t0 = time.perf_counter()
    failed, result, others, verdicts = None, None, {}, {}  # failed: a static session set the robot could not hold
    try:
        with scratch_dir("closedloop") as tmp:
            collect(CollectConfig(robot=cfg.robot, mjcf=cfg.mjcf, mode=cfg.static_mode, offsets=tuple(dq.tolist()),
                                  sensors=cfg.static_sensors, seed=STATIC_SEED_BASE + seed, heldout=cfg.heldout),
                    tmp, progress=False)
            recs = load_session(tmp, robot=legmap)
            result = calibrate_training(get_calibrator(cfg.calibrator, **cfg.options), legmap, recs)
            for label, name, opts in cfg.variants:
                r = calibrate_training(get_calibrator(name, **dict(opts)), legmap, recs)
                others[label], verdicts[label] = applied(r, legmap), r.decision
    except HoldError as e:
        failed = str(e)
    return {"dq": dq, "dq_hat": None if failed else applied(result, legmap), "others": others,
            "estimate": None if failed else result.offsets_vector(legmap.joint_names),
            "verdict": None if failed else result.decision, "variant_verdicts": verdicts,
            "verdict_reason": None if failed or not result.verdict["reasons"] else result.verdict["reasons"][0]["text"],
            "failed": failed, "warnings": [] if failed else result.warnings, "static_s": time.perf_counter() - t0}


def applied(result, legmap) -> np.ndarray:
    """The correction a trial applies: the estimate, or none (zeros) when its verdict is
    do-not-apply (a failed calibration, scored as no correction)."""
    from legcal_bench.estimation.verdict import DO_NOT_APPLY

    dq_hat = result.offsets_vector(legmap.joint_names)
    return np.zeros_like(dq_hat) if result.decision == DO_NOT_APPLY else dq_hat


def trial_walk(cfg: ClosedLoopConfig, seed: int, condition: str, estimate: np.ndarray | None = None):
    """One walk of trial `seed`: `condition` one of `CONDITIONS` or "spread" (a nominal
    walk with other noise and jitter); `estimate` the correction of a corrected walk.
    Only the nominal walk keeps its logs (the odometry reads them)."""
    legmap, env, runner = _walker(cfg)
    dq = trial_offsets(cfg.offsets, legmap, seed)
    none = np.zeros(legmap.n_joints)
    offsets, correction = {"nominal": (none, None), "uncorrected": (dq, None), "corrected": (dq, estimate),
                           "oracle": (dq, dq), "spread": (none, None)}[condition]
    return walk(env, runner, cfg.seconds, seed + (SPREAD_SEED_OFFSET if condition == "spread" else 0),
                {"offsets": offsets, "correction": correction}, log=condition == "nominal")


def trial_odometry_of(cfg: ClosedLoopConfig, seed: int, nominal, static: dict) -> dict | None:
    """`trial_odometry` of trial `seed`'s nominal walk (None if its static set failed)."""
    if static["failed"]:
        return None
    legmap, kin = _robot(cfg)
    return trial_odometry(legmap, nominal, static["dq"], static["dq_hat"], kin)


def assemble_trial(cfg: ClosedLoopConfig, seed: int, static: dict, walks: dict, odometry: dict | None) -> dict:
    """The trial's row from its parts: `walks` condition -> Walk (and ("variant", label)
    -> the variant's corrected walk)."""
    failed, dq, dq_hat = static["failed"], static["dq"], static["dq_hat"]
    estimate = static.get("estimate", dq_hat)
    # recovery_rms_deg: of the correction applied (none for a do-not-apply verdict); the
    # method's own estimate stays in estimate_rad.
    out = {"seed": seed, "offsets_rad": dq.tolist(), "estimate_rad": None if failed else estimate.tolist(),
           "calibration_verdict": static.get("verdict"), "calibration_verdict_reason": static.get("verdict_reason"),
           "recovery_rms_deg": None if failed else float(np.degrees(rms(dq_hat - dq))), "static_s": static["static_s"],
           "static_failed": failed, "calibration_warnings": static["warnings"], "privileged": walks["nominal"].privileged}
    nominal = walks["nominal"]
    for c in WALKS:
        if c not in walks:
            continue
        w = walks[c]
        row = {"upright": w.upright, "fallen_at": w.fallen_at, "torque_mean": w.torque_mean,
               "power_mean": w.power_mean, "wall_s": w.wall_s,
               "path": w.pelvis[::PATH_STEP, :2].round(4).tolist()}
        if c != "nominal" and w.upright and nominal.upright:
            row.update(deviation(w, nominal))
        out[c] = row
    if failed:
        out["corrected"] = {"skipped": failed}
    out["variants"] = {}
    for label, _, _ in cfg.variants:
        if failed:
            out["variants"][label] = {"skipped": failed}
            continue
        est, w = static["others"][label], walks[("variant", label)]
        row = {"upright": w.upright, "fallen_at": w.fallen_at, "recovery_rms_deg": float(np.degrees(rms(est - dq))),
               "calibration_verdict": static.get("variant_verdicts", {}).get(label)}
        if w.upright and nominal.upright:
            row.update(deviation(w, nominal))
        out["variants"][label] = row
    spread = walks["spread"]
    out["spread"] = deviation(spread, nominal) if spread.upright and nominal.upright else {}
    out["spread"]["upright"] = spread.upright
    out["odometry"] = odometry
    return out


def trial_odometry(legmap, nominal, dq: np.ndarray, dq_hat: np.ndarray, kin=None) -> dict:
    """Leg odometry of the nominal walk with the trial's offsets added to its logged
    encoders afterwards (q_enc - dq), before and after the correction (+ dq_hat), and
    without offsets; and the vertical drift per degree of symmetric hip-pitch offset.
    `kin`: the leg map's `LegKinematics`, if already built."""
    from legcal_bench.evaluation.odometry import (centre_of_pressure, imu_orientation, leg_odometry, odometry_errors,
                                                  pitch_sensitivity, pose_matrices, sole_from_ft)
    from legcal_bench.robots.kinematics import LegKinematics

    kin = LegKinematics(legmap) if kin is None else kin
    truth = pose_matrices(nominal.pelvis)
    dt = float(nominal.time[1] - nominal.time[0])
    R_WB = imu_orientation(nominal.gravity, nominal.ang_vel, dt, truth[0, :3, :3])
    q, loads, p0 = nominal.q_enc, nominal.loads, truth[0, :3, 3]
    frames = sole_from_ft(legmap)
    cop = centre_of_pressure(nominal.ft, frames) if nominal.ft is not None and frames is not None else None
    out = {name: odometry_errors(leg_odometry(kin, qq, loads, R_WB, p0, cop), truth)
           for name, qq in (("no_offsets", q), ("before", q - dq), ("after", q - dq + dq_hat))}
    out["pitch"] = pitch_sensitivity(kin, q, loads, R_WB, truth, cop)
    out["contact_point"] = "centre of pressure" if cop is not None else "sole origin"
    return out


def summarize(cfg: ClosedLoopConfig, trials: list[dict]) -> dict:
    """Mean +- std over trials per condition, and the ratios the paper reports."""
    conds = {}
    for c in CONDITIONS:
        rows = [t[c] for t in trials if "skipped" not in t[c]]
        conds[c] = {"upright": sum(r["upright"] for r in rows), "trials": len(rows),
                    "time_to_fall_s": mean_std([r["fallen_at"] for r in rows if r["fallen_at"] is not None]),
                    "torque_mean": mean_std([r["torque_mean"] for r in rows]),
                    "power_mean": mean_std([r["power_mean"] for r in rows])}
        if c != "nominal":
            for k in ("foot_strike_rms_mm", "pelvis_rms_mm"):
                conds[c][k] = mean_std([r.get(k) for r in rows])
    ratios = {}
    for k in ("foot_strike_rms_mm", "pelvis_rms_mm"):
        u, cor, ora = (conds[c][k]["mean"] if conds[c][k] else None for c in ("uncorrected", "corrected", "oracle"))
        ratios[k] = {"corrected_over_uncorrected": _ratio(cor, u), "corrected_over_oracle": _ratio(cor, ora)}
    spread = {k: mean_std([t["spread"].get(k) for t in trials]) for k in ("foot_strike_rms_mm", "pelvis_rms_mm")}
    oracle = {k: mean_max([t["oracle"].get(k) for t in trials]) for k in ("foot_strike_rms_mm", "pelvis_rms_mm")}
    variants = {}
    for label in (trials[0]["variants"] if trials else {}):
        rows = [t["variants"][label] for t in trials if "skipped" not in t["variants"][label]]
        v = {"upright": sum(r["upright"] for r in rows), "trials": len(rows),
             "recovery_rms_deg": mean_std([r["recovery_rms_deg"] for r in rows]),
             **{k: mean_std([r.get(k) for r in rows]) for k in ("foot_strike_rms_mm", "pelvis_rms_mm")}}
        unc = conds["uncorrected"]["foot_strike_rms_mm"]
        v["corrected_over_uncorrected"] = (v["foot_strike_rms_mm"]["mean"] / unc["mean"]
                                           if v["foot_strike_rms_mm"] and unc else None)
        variants[label] = v
    odo = [t["odometry"] for t in trials if t["odometry"] is not None]
    odometry = {name: {k: mean_std([o[name][k] for o in odo]) for k in ODOMETRY_KEYS}
                for name in ("no_offsets", "before", "after")}
    odometry["pitch_m_per_deg"] = mean_std([o["pitch"]["m_per_deg"] for o in odo])
    odometry["distance_m"] = mean_std([o["pitch"]["distance_m"] for o in odo])
    odometry["contact_point"] = odo[0]["contact_point"] if odo else None
    failed = [t for t in trials if t.get("static_failed")]
    rejected = [t for t in trials if t.get("calibration_verdict") == "do-not-apply"]
    return {"config": asdict(cfg), "conditions": conds, "ratios": ratios, "nominal_spread": spread,
            "oracle_distance": oracle, "calibrated": sum(t["estimate_rad"] is not None for t in trials),
            "odometry": odometry, "variants": variants,
            "recovery_rms_deg": mean_std([t["recovery_rms_deg"] for t in trials if t["recovery_rms_deg"] is not None]),
            "static_failed": {"count": len(failed), "seeds": [t["seed"] for t in failed],
                              "first_reason": failed[0]["static_failed"] if failed else None},
            # Trials whose calibration's verdict was do-not-apply: failed calibrations, walked and
            # scored as no correction; review trials are corrections, counted.
            "verdicts": {v: sum(t.get("calibration_verdict") == v for t in trials)
                         for v in ("apply", "review", "do-not-apply")},
            "rejected": {"count": len(rejected), "seeds": [t["seed"] for t in rejected],
                         "first_reason": rejected[0]["calibration_verdict_reason"] if rejected else None},
            "static_s": mean_std([t["static_s"] for t in trials]),
            "walk_s": mean_std([t[c]["wall_s"] for t in trials for c in CONDITIONS if "wall_s" in t[c]]),
            "privileged": trials[0]["privileged"] if trials else []}


def _ratio(a: float | None, b: float | None) -> float | None:
    """a / b, or None where either is missing or b is not a positive number."""
    if a is None or b is None or not (np.isfinite(a) and np.isfinite(b)) or b <= 0:
        return None
    return float(a / b)


def mean_max(values) -> dict | None:
    """{"mean", "max", "n"} of the finite values among `values` (None skipped); None if none."""
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    return {"mean": float(v.mean()), "max": float(v.max()), "n": int(v.size)} if v.size else None


def evaluate(cfg: ClosedLoopConfig, executor=None, progress: bool = True,
             store: TrialStore | None = None) -> tuple[dict, list[dict]]:
    """All trials (through `executor` if given, else here), summarized. Through an
    executor each trial's parts are tasks of their own (`trial_tasks`), so the workers
    stay busy to the end; the numbers are those of `run_trial`. With a `store` (given,
    or the one `keep_trials` set), each trial is written there as it finishes and the
    trials it already holds for `cfg` are taken, not run again; the rows are then the
    store's (as read back from JSON), finished in this run or an earlier one alike."""
    from tqdm import tqdm

    store = store if store is not None else _STORE.get()
    seeds = range(cfg.first_seed, cfg.first_seed + cfg.trials)
    trials = [row for row in (store.load(cfg, s) for s in seeds) if row is not None] if store is not None else []
    todo = [s for s in seeds if s not in {t["seed"] for t in trials}]

    def finished(row: dict) -> dict:
        return store.save(cfg, row) if store is not None else row

    desc = f"walk-eval {offsets_label(cfg.offsets)} {cfg.calibrator}"
    if executor is None:
        bar = tqdm(total=len(todo), desc=desc, unit="trial", disable=not progress)
        for s in todo:
            trials.append(finished(run_trial(cfg, s)))
            bar.update(1)
    else:
        bar = tqdm(total=len(todo) * tasks_per_trial(cfg), desc=desc, unit="task", disable=not progress)
        trials += [finished(row) for row in trial_tasks(cfg, todo, executor, bar)]
    bar.close()
    trials.sort(key=lambda t: t["seed"])
    return summarize(cfg, trials), trials


def offsets_label(spec: str, width: int = 24) -> str:
    """`spec` as a short label (a progress bar's, a plot's): as given if short, else
    "N explicit offsets" (comma-separated radians) or its start."""
    s = str(spec).strip()
    if len(s) <= width:
        return s
    if "," in s:
        return f"{len(s.split(','))} explicit offsets"
    return s[:width - 3] + "..."


def _file_hash(path) -> str | None:
    """sha256 (16 hex digits) of a file's bytes; None for no file."""
    if path is None or not Path(path).is_file():
        return None
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def trial_identity(cfg: ClosedLoopConfig) -> dict:
    """What determines every trial of `cfg` but its seed: the robot's and policy's files
    by content (not where they lie), the offsets spec, seconds, calibrator (name, options,
    settings) and variants, the static set's and walks' settings and seed bases, and the
    code's `RESULTS_VERSION` and `ROW_VERSION`. `cfg.trials` and `cfg.first_seed` are not
    in it: a longer run takes a shorter one's trials."""
    from legcal_bench.calibrators.registry import get_calibrator
    from legcal_bench.policies.spec import load_policy_spec
    from legcal_bench.provenance import RESULTS_VERSION
    from legcal_bench.robots import load_robot, robot_label

    legmap, spec = load_robot(cfg.robot, cfg.mjcf), load_policy_spec(cfg.policy)
    return {"row_version": ROW_VERSION, "results_version": RESULTS_VERSION,
            "robot": {"name": robot_label(cfg.robot), "legmap": _file_hash(legmap.source),
                      "mjcf": _file_hash(legmap.mjcf)},
            "policy": {"spec": _file_hash(spec.path), "model": _file_hash(spec.model_file)},
            "offsets": cfg.offsets, "seconds": cfg.seconds,
            "calibrator": {"name": cfg.calibrator, "options": cfg.options,
                           "settings": get_calibrator(cfg.calibrator, **cfg.options).settings()},
            "variants": [{"label": label, "name": name, "options": dict(opts),
                          "settings": get_calibrator(name, **dict(opts)).settings()}
                         for label, name, opts in cfg.variants],
            "static": {"mode": cfg.static_mode, "sensors": cfg.static_sensors, "heldout": cfg.heldout,
                       "seed_base": STATIC_SEED_BASE},
            "walks": {"sensors": cfg.walk_sensors, "spread_seed_offset": SPREAD_SEED_OFFSET, "path_step": PATH_STEP}}


def trial_key(identity: dict, seed: int, offsets_rad) -> str:
    """The resume key of one trial: its settings' `trial_identity`, its seed and the
    offsets drawn for it (`trial_offsets`)."""
    from legcal_bench.provenance import stable_hash

    return stable_hash({"identity": identity, "seed": int(seed), "offsets_rad": [float(x) for x in offsets_rad]})


class TrialStore:
    """Finished trials in `<folder>/trials/s<seed>_<key>.json` (`trial_key`), each written
    atomically as it finishes; `load` returns a trial only if its file's key is the one
    `cfg` and the seed give now. `reused` and `written` list the (offsets, seed) taken
    from files and written in this process."""

    FORMAT = "legcal-walk-eval-trial/1"

    def __init__(self, folder: str | Path):
        self.dir = Path(folder) / TRIALS_DIR
        self.reused: list[tuple[str, int]] = []
        self.written: list[tuple[str, int]] = []
        self._identities: dict[str, tuple] = {}  # config hash -> (identity, leg map, {seed: key})

    def _of(self, cfg: ClosedLoopConfig) -> tuple:
        from legcal_bench.provenance import stable_hash
        from legcal_bench.robots import load_robot

        k = stable_hash(asdict(cfg))
        if k not in self._identities:
            self._identities[k] = (trial_identity(cfg), load_robot(cfg.robot, cfg.mjcf), {})
        return self._identities[k]

    def identity(self, cfg: ClosedLoopConfig) -> dict:
        return self._of(cfg)[0]

    def key(self, cfg: ClosedLoopConfig, seed: int) -> str:
        identity, legmap, keys = self._of(cfg)
        if seed not in keys:
            keys[seed] = trial_key(identity, seed, trial_offsets(cfg.offsets, legmap, seed))
        return keys[seed]

    def path(self, cfg: ClosedLoopConfig, seed: int) -> Path:
        return self.dir / f"s{int(seed):04d}_{self.key(cfg, seed)}.json"

    def load(self, cfg: ClosedLoopConfig, seed: int) -> dict | None:
        path = self.path(cfg, seed)
        try:
            doc = json.loads(path.read_text())
        except (OSError, ValueError):
            return None
        if doc.get("format") != self.FORMAT or doc.get("key") != self.key(cfg, seed) or doc.get("seed") != seed:
            return None
        self.reused.append((cfg.offsets, seed))
        return doc["trial"]

    def save(self, cfg: ClosedLoopConfig, row: dict) -> dict:
        """Write `row` (trial `row["seed"]` of `cfg`); returns it as read back from the
        file's JSON, the form a later run's `load` gives."""
        from legcal_bench.files.atomic import atomic_write_text
        from legcal_bench.provenance import code_version

        seed = row["seed"]
        doc = {"format": self.FORMAT, "key": self.key(cfg, seed), "seed": seed, "identity": self.identity(cfg),
               "provenance": code_version(), "trial": row}
        text = json.dumps(doc, indent=2, sort_keys=True) + "\n"
        atomic_write_text(self.path(cfg, seed), text)
        self.written.append((cfg.offsets, seed))
        return json.loads(text)["trial"]


_STORE: contextvars.ContextVar[TrialStore | None] = contextvars.ContextVar("closed_loop_trial_store", default=None)


@contextmanager
def keep_trials(folder: str | Path):
    """Within the block, `evaluate` keeps its trials in a `TrialStore` of `folder` (and
    resumes from it) without being passed one; yields the store."""
    store = TrialStore(folder)
    token = _STORE.set(store)
    try:
        yield store
    finally:
        _STORE.reset(token)


def tasks_per_trial(cfg: ClosedLoopConfig) -> int:
    """Tasks of a trial through an executor: its static estimate, five walks (nominal,
    uncorrected, corrected, oracle, spread), one per variant, its odometry."""
    return 7 + len(cfg.variants)


def trial_tasks(cfg: ClosedLoopConfig, seeds, executor, bar=None):
    """Yield each trial's row as its last part finishes. Tasks: every static estimate
    first (the corrected walks wait for them), then the walks that need no estimate
    (nominal, uncorrected, oracle, spread); as an estimate arrives, its corrected walks;
    once a trial's estimate and nominal walk are in, its odometry. `bar` (tqdm) counts
    the tasks done (a failed static set's trial has fewer)."""
    from concurrent.futures import FIRST_COMPLETED, wait

    futures, parts = {}, {s: {} for s in seeds}

    def submit(key, fn, *args):
        futures[executor.submit(fn, cfg, *args)] = key

    for s in seeds:
        submit((s, "static"), static_estimate, s)
    for s in seeds:
        for c in ("nominal", "uncorrected", "oracle", "spread"):
            submit((s, c), trial_walk, s, c)
    while futures:
        done, _ = wait(futures, return_when=FIRST_COMPLETED)
        for f in done:
            s, part = futures.pop(f)
            got = parts[s]
            got[part] = f.result()
            static = got.get("static")
            if bar is not None:
                bar.update(1)
                if part == "static" and static["failed"]:
                    bar.total -= 2 + len(cfg.variants)  # no corrected walks, no odometry
                    bar.refresh()
            if part == "static" and not static["failed"]:
                submit((s, "corrected"), trial_walk, s, "corrected", static["dq_hat"])
                for label, _, _ in cfg.variants:
                    submit((s, ("variant", label)), trial_walk, s, "corrected", static["others"][label])
            if part in ("static", "nominal") and static is not None and "nominal" in got:
                if static["failed"]:
                    got["odometry"] = None
                else:
                    submit((s, "odometry"), trial_odometry_of, s, got["nominal"], static)
            # parts: one per task, and the odometry's None where a failed static set has none
            want = tasks_per_trial(cfg) - (1 + len(cfg.variants) if static is not None and static["failed"] else 0)
            if len(got) == want:
                walks = {k: v for k, v in got.items() if k not in ("static", "odometry")}
                yield assemble_trial(cfg, s, got.pop("static"), walks, got.pop("odometry"))
                del parts[s]


def estimate_walks(robot, policy: str, true_dq: np.ndarray, estimates: dict, trials: int = 5,
                   seconds: float = 20.0, sensors: str = "realistic", progress: bool = True) -> dict:
    """What the choice between estimates does to a walk: per seed, the nominal walk (no
    offsets), the walk with `true_dq` uncorrected, and one walk per estimate (label ->
    one radian per leg joint) with `true_dq` on the robot corrected by it, the same seed driving noise
    and jitter; deviations from the seed's nominal walk (mm), mean +- std over the trials
    where both stayed upright, and the nominal seed-to-seed spread (the noise floor).
    The walking model is the nominal one: the walk isolates the offsets' share of the
    answer, not the effect itself."""
    from tqdm import tqdm

    from legcal_bench.envs.walking import WalkingEnv
    from legcal_bench.policies.runner import PolicyRunner

    env = WalkingEnv(robot=robot, policy=policy, sensors=sensors)
    runner = PolicyRunner(env.policy_spec, robot)
    conds = {"uncorrected": None, **estimates}
    rows = {c: [] for c in conds}
    spread, upright = [], {c: 0 for c in ("nominal", *conds)}
    for seed in tqdm(range(trials), desc="walks", unit="trial", disable=not progress):
        none = np.zeros(env.legmap.n_joints)
        nominal = walk(env, runner, seconds, seed, {"offsets": none, "correction": None})
        upright["nominal"] += nominal.upright
        s = walk(env, runner, seconds, seed + SPREAD_SEED_OFFSET, {"offsets": none, "correction": None})
        if s.upright and nominal.upright:
            spread.append(deviation(s, nominal))
        for c, est in conds.items():
            w = walk(env, runner, seconds, seed, {"offsets": true_dq, "correction": None if est is None else est})
            upright[c] += w.upright
            if w.upright and nominal.upright:
                rows[c].append(deviation(w, nominal))
    keys = ("pelvis_rms_mm", "foot_strike_rms_mm")
    out = {"trials": trials, "seconds": seconds, "upright": upright,
           "nominal_spread": {k: mean_std([d[k] for d in spread]) for k in keys}}
    for c, rs in rows.items():
        out[c] = {k: mean_std([d[k] for d in rs]) for k in keys}
        out[c]["paired"] = len(rs)
        if c in estimates:
            out[c]["estimate_rms_error_deg"] = float(np.degrees(rms(np.asarray(estimates[c]) - true_dq)))
    return out
