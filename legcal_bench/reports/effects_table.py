"""The model-gap before/after table (issue #16): for each library effect at a realistic
size, on each robot, over seeds: the offsets-only fit and the fit with that effect
added, beside the clean-data floor.

Each case collects a session set (weld, `calibrated-imu`, the paper's injection; the
effect's side alternates with the seed, the leg-length effect's link too), calibrates it
(`interfoot`, `sensor` setting, `--with-effects <effect>`), and scores:
  offsets    RMS error of the offsets, one per leg joint (deg), offsets-only and with the effect;
  heldout    RMS foot-height difference (mm) on the held-out sessions at their true
             postures: the noise-free encoder readings (truth `q_enc_clean`) through the
             model as fitted (offsets-only: nominal kinematics; with the effect: its
             parameters too), along the true vertical; the floor is flat, so 0 is right;
  parameter  the effect's true parameter (from the ground truth) against the estimate:
             error over the posterior standard deviation;
  confounds  the largest principal-angle cosine to the offsets and the parameters held.
Clean cases (no effect, offsets-only) give the floor.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from legcal_bench.files.scratch import scratch_dir
from legcal_bench.protocol.stances import STANCES

EFFECTS = ("imu_tilt", "leg_length", "encoder_scale", "compliance", "hip_axis")
DEFAULT_STANCES = tuple(STANCES)  # the paper's four


def effect_spec(effect: str, seed: int) -> str:
    """The realistic-size `collect --effect` spec of a library effect for `seed`."""
    side = ("left", "right")[seed % 2]
    link = ("shank", "thigh")[(seed // 2) % 2]
    return {"imu_tilt": "imu_tilt:roll=0.5",
            "leg_length": f"link_length:link={side}_{link},mm=2",
            "encoder_scale": f"encoder_scale:joint={side}_knee,scale=0.005",
            "compliance": f"compliance:joint={side}_knee,k=1e4",
            "hip_axis": f"hip_axis:joint={side}_hip_pitch,about=z,deg=0.5"}[effect]


def true_parameters(reality_truth: list[dict]) -> dict[str, float]:
    """Library parameter name -> true value, from a truth file's reality effects."""
    out = {}
    for t in reality_truth:
        k = t["kind"]
        if k == "imu_tilt":
            out["imu_tilt.roll"], out["imu_tilt.pitch"] = t["roll_rad"], t["pitch_rad"]
        elif k == "link_length":
            out[f"leg_length.{t['link']}"] = t["length_m"]
        elif k == "encoder_scale":
            out[f"encoder_scale.{t['joint']}"] = t["scale"]
        elif k == "compliance":
            out[f"compliance.{t['joint']}"] = t["compliance_rad_per_nm"]
        elif k == "hip_axis":
            out[f"hip_axis.{t['joint'].split('_')[0]}_about_{t['about']}"] = t["angle_rad"]
    return out


def run_case(robot: str, effect: str | None, seed: int, stances: tuple[str, ...] = DEFAULT_STANCES) -> dict:
    """One session set (`stances` recorded) and its fits; `effect` None is a clean case."""
    from legcal_bench.calibrators.base import calibrate_training
    from legcal_bench.calibrators.registry import get_calibrator
    from legcal_bench.data.recording import list_segments, load_session, load_truth
    from legcal_bench.estimation.modelgap.effects import EffectModel, load_effects
    from legcal_bench.evaluation.metrics import rms
    from legcal_bench.evaluation.scoring import heldout_heights
    from legcal_bench.protocol.collect import CollectConfig, collect
    from legcal_bench.robots import load_robot
    from legcal_bench.robots.kinematics import LegKinematics

    legmap = load_robot(robot)
    spec = None if effect is None else effect_spec(effect, seed)
    with scratch_dir("effects") as work:
        cfg = CollectConfig(robot=robot, mode="weld", sensors="calibrated-imu", seed=seed, stances=tuple(stances),
                            effects=() if spec is None else (spec,))
        collect(cfg, Path(work) / "set", progress=False)
        recs = load_session(Path(work) / "set", robot=legmap)
        options = {"setting": "sensor"} if effect is None else {"setting": "sensor", "effects": effect}
        result = calibrate_training(get_calibrator("interfoot", **options), legmap, recs)
        names = legmap.joint_names
        paths = list_segments(Path(work) / "set")
        truth = load_truth(paths[0])
        injected = np.asarray(truth.offsets)
        after = np.array([result.offsets_rad[n] for n in names])
        eff = result.diagnostics.get("effects")
        before = after if eff is None else np.array([eff["offsets_only_rad"][n] for n in names])
        model = EffectModel(LegKinematics(legmap), load_effects([] if effect is None else [effect]))
        nj = legmap.n_joints  # the model's parameters: the offsets, then the effect's
        x_after = np.r_[after, [eff["parameters"][n]["value"] for n in model.names[nj:]]] if eff else after
        x_before = np.r_[before, np.zeros(model.n - nj)]
        heights = heldout_heights(legmap, paths, [] if effect is None else [effect],
                                  {"before": x_before, "after": x_after})
        std = result.diagnostics["posterior"]["std_rad"] if eff is None else eff["offsets_std_rad"]
        row = {"robot": legmap.name, "robot_spec": robot, "effect": effect, "spec": spec, "seed": seed,
               "offsets_rms_deg": {"before": float(np.rad2deg(rms(before - injected))),
                                   "after": float(np.rad2deg(rms(after - injected)))},
               "offsets_posterior_rms_std_deg": float(np.rad2deg(rms(np.array([std[n] for n in names])))),
               "heldout_true_mm": {k: heights[k] for k in ("before", "after")},
               "seconds": result.timing_s.get("total")}
        if eff is not None:
            true = true_parameters(truth.meta["reality"]["effects"])
            params = {}
            for n, p in eff["parameters"].items():
                tv = true.get(n, 0.0)
                params[n] = {"true": tv, "value": p["value"], "std": p["std"], "held": p["held"],
                             "z": None if p["held"] or not np.isfinite(p["std"]) or p["std"] == 0
                             else (p["value"] - tv) / p["std"]}
            c = eff["confounds"]["effects"][effect]
            row.update(parameters=params, max_cosine_to_offsets=c["max_cosine_to_offsets"],
                       confounded=c["confounded_with_offsets"], held=eff["confounds"]["held"],
                       mimics=c["mimics_offsets"] if c["confounded_with_offsets"] else "")
        return row


def _case(args):
    return run_case(*args)


def build(robots, effects=EFFECTS, seeds: int = 10, workers: int = 2, progress: bool = True,
          stances: tuple[str, ...] = DEFAULT_STANCES) -> dict:
    """Every case (clean ones included) on `workers` processes."""
    from legcal_bench.files.parallel import map_with_progress

    jobs = [(r, e, s, tuple(stances)) for r in robots for e in (None, *effects) for s in range(seeds)]
    rows = map_with_progress(_case, jobs, workers, "effects-table", progress)
    return {"rows": rows, "summary": summarize(rows), "stances": list(stances)}


def summarize(rows: list[dict]) -> list[dict]:
    out = []
    robots = list(dict.fromkeys(r["robot"] for r in rows))
    for robot in robots:
        clean = [r for r in rows if r["robot"] == robot and r["effect"] is None]
        floor = float(np.mean([r["offsets_rms_deg"]["after"] for r in clean])) if clean else np.nan
        floor_h = float(np.mean([r["heldout_true_mm"]["after"] for r in clean])) if clean else np.nan
        floor_std = float(np.mean([r["offsets_posterior_rms_std_deg"] for r in clean])) if clean else np.nan
        for effect in dict.fromkeys(r["effect"] for r in rows if r["robot"] == robot and r["effect"]):
            rs = [r for r in rows if r["robot"] == robot and r["effect"] == effect]
            zs = [abs(p["z"]) for r in rs for n, p in r["parameters"].items()
                  if p["z"] is not None and p["true"] != 0.0]
            within = [all(abs(p["z"]) <= 3 for p in r["parameters"].values() if p["z"] is not None
                          and p["true"] != 0.0) for r in rs]
            after = float(np.mean([r["offsets_rms_deg"]["after"] for r in rs]))
            out.append({
                "robot": robot, "effect": effect, "seeds": len(rs),
                "offsets_rms_deg_before": float(np.mean([r["offsets_rms_deg"]["before"] for r in rs])),
                "offsets_rms_deg_after": after, "floor_offsets_rms_deg": floor, "after_over_floor": after / floor,
                "seeds_within_1_5x_floor": int(sum(r["offsets_rms_deg"]["after"] <= 1.5 * floor for r in rs)),
                # What the data allow: the posteriors' RMS std with the effect over the clean fits'
                # (the information's own price for the effect's parameters, any unbiased estimator).
                "posterior_ratio": float(np.mean([r["offsets_posterior_rms_std_deg"] for r in rs])) / floor_std,
                "heldout_true_mm_before": float(np.mean([r["heldout_true_mm"]["before"] for r in rs])),
                "heldout_true_mm_after": float(np.mean([r["heldout_true_mm"]["after"] for r in rs])),
                "floor_heldout_true_mm": floor_h,
                "true_parameter_within_3_sigma": int(sum(within)),
                "median_abs_z": float(np.median(zs)) if zs else None,
                "max_cosine_to_offsets": float(np.mean([r["max_cosine_to_offsets"] for r in rs])),
                "held": sorted({h for r in rs for h in r["held"]}),
                "confounded_with": sorted({r["mimics"] for r in rs if r["mimics"]}),
            })
    return out


def markdown(data: dict, made_by: str, code: str) -> str:
    lines = ["# Model gap: offsets-only fit vs the fit with the effect added", "",
             f"Made by `{made_by}` ({code}). Weld mode, stances {' '.join(data.get('stances', DEFAULT_STANCES))}, "
             "`calibrated-imu` sensors, the paper's injection, "
             "`interfoot` with the `sensor` setting. Offsets: RMS error of the 12 offsets (deg), mean over seeds; "
             "floor: the same on clean data. Held-out: RMS foot-height difference (mm) at the held-out sessions' "
             "true postures, flat floor. z: (estimate - truth) / posterior std of the effect's true parameter. "
             "Posterior ratio: the offsets' posterior RMS std with the effect over the clean fits' (what the "
             "effect's parameters cost on these data, the ratio an efficient fit would show).", "",
             "| robot | effect | seeds | offsets before | after | floor | after/floor | posterior ratio | "
             "seeds ≤1.5×floor | held-out before | after | floor | truth within 3σ | median abs z | cos to offsets | "
             "held |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in data["summary"]:
        z = "–" if s["median_abs_z"] is None else f"{s['median_abs_z']:.1f}"
        lines.append(f"| {s['robot']} | {s['effect']} | {s['seeds']} | {s['offsets_rms_deg_before']:.4f} | "
                     f"{s['offsets_rms_deg_after']:.4f} | {s['floor_offsets_rms_deg']:.4f} | "
                     f"{s['after_over_floor']:.2f} | {s['posterior_ratio']:.2f} | "
                     f"{s['seeds_within_1_5x_floor']}/{s['seeds']} | "
                     f"{s['heldout_true_mm_before']:.3f} | {s['heldout_true_mm_after']:.3f} | "
                     f"{s['floor_heldout_true_mm']:.3f} | {s['true_parameter_within_3_sigma']}/{s['seeds']} | {z} | "
                     f"{s['max_cosine_to_offsets']:.4f} | {', '.join(s['held']) or '–'} |")
    conf = [(s["robot"], s["effect"], c) for s in data["summary"] for c in s["confounded_with"]]
    if conf:
        lines += ["", "Confounded with the offsets (computed; held at zero in the fit):"]
        lines += [f"- {r} {e}: {c}" for r, e, c in conf]
    return "\n".join(lines) + "\n"


def plot(data: dict, path: Path) -> Path:
    from legcal_bench.files.plots import pyplot, save_figure

    plt = pyplot()
    summ = data["summary"]
    robots = list(dict.fromkeys(s["robot"] for s in summ))
    fig, axes = plt.subplots(1, len(robots), figsize=(4.5 * len(robots), 3.6), squeeze=False)
    for ax, robot in zip(axes[0], robots):
        ss = [s for s in summ if s["robot"] == robot]
        x = np.arange(len(ss))
        ax.bar(x - 0.2, [s["offsets_rms_deg_before"] for s in ss], 0.4, label="offsets only")
        ax.bar(x + 0.2, [s["offsets_rms_deg_after"] for s in ss], 0.4, label="effect added")
        ax.axhline(ss[0]["floor_offsets_rms_deg"], color="k", lw=1, ls="--", label="clean floor")
        ax.set_yscale("log")
        ax.set_xticks(x, [s["effect"] for s in ss], rotation=30, fontsize=8)
        ax.set_title(robot, fontsize=9)
        ax.set_ylabel("offsets RMS error (deg)")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path)
