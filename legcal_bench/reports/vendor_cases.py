"""`legcal-bench vendor-cases`: robots as vendors ship them, each against the A3-like robot.

Each case of `legcal_bench.robots.samples` (a URDF in a ROS package, an MJCF with
frames, roll-before-pitch ankles, a torso IMU through a waist, a drive joint, fixed gear
ratios, two-motor linkage ankles) runs through its leg map alone: a zero-noise kinematic
set (seed 0; the largest recovery error, in joint space and at the encoders; a linkage
ankle's offsets are its motors' already) and realistic weld sets (the seeds),
each calibrated by interfoot and scored. The bar (issue #59): zero-noise recovery
<= 1e-9 deg, and the weld sets' IMU-removed recovery (`vs_imu_vertical`, mean over the
seeds) within 1.5x of the A3-like robot's on the same seeds.

Each case is written as it finishes (`<out>/cases/`), so a stopped run resumes; the page
is `<out>/vendor_cases.md` and `.json`. Light at import.
"""

from __future__ import annotations

from pathlib import Path

CASES = ("ros_package", "framed", "roll_first", "torso_imu", "drive_joint", "fixed_ratio", "linkage_ankle")
REFERENCE = "a3"
# Ten seeds: the A3-like robot's own IMU-removed recovery ranges 0.0011-0.0045 deg over
# seeds 0-9, so a mean over three seeds (0.0022 at 0-2, 0.0031 at 6-8) moves by 1.4x
# with the seeds alone and cannot judge a 1.5x bar; at three seeds the linkage ankle read
# 1.92x, at ten 1.28x (`legcal-bench vendor-cases --seeds 0 1 2` and the default).
SEEDS = tuple(range(10))
RATIO_BAR = 1.5
ZERO_NOISE_BAR_DEG = 1e-9


def case_legmap(case: str, folder: Path) -> str:
    if case == REFERENCE:
        return REFERENCE
    from legcal_bench.robots.samples import SAMPLES

    return str(SAMPLES[case](folder / case))


def run_case(job: tuple[str, str, str, int]) -> dict:
    """(case, leg map, "kinematic" | "weld", seed): collected, calibrated, scored."""
    import numpy as np

    from legcal_bench.provenance import code_version, describe
    from legcal_bench.reports.realistic_set import calibrated_set
    from legcal_bench.robots.transmission import transmissions

    case, spec, mode, seed = job
    legmap, _, result, s = calibrated_set(spec, mode, seed, "vendor_cases",
                                          sensors="zero" if mode == "kinematic" else "realistic")
    rec = s["recovery"]
    row = {"case": case, "mode": mode, "seed": seed, "verdict": result.decision,
           "max_error_deg": rec["max_error_deg"], "rms_error_deg": rec["rms_error_deg"],
           "code": describe(code_version())}
    if "vs_imu_vertical" in rec:
        row["vs_imu_deg"] = rec["vs_imu_vertical"]["rms_error_deg"]
    drives = transmissions(legmap)
    if drives:  # the error at the encoders: the joint-space error over c1
        c1 = {n: t.c1 for n, t in drives.items()}
        err = [rec["per_joint_error_deg"][n] / c1.get(n, 1.0) for n in legmap.joint_names]
        row["max_motor_error_deg"] = float(np.abs(err).max())
    return row


def measure(out: str | Path, cases=CASES, seeds=SEEDS, workers: int = 2, progress: bool = True) -> dict:
    from legcal_bench.reports.realistic_set import kept_cases
    from legcal_bench.files.reports import write_report
    from legcal_bench.provenance import code_version, describe

    out = Path(out)
    folder = out / "robots"
    jobs = []
    for case in (REFERENCE, *cases):
        spec = case_legmap(case, folder)
        jobs += [(case, spec, "kinematic", 0)] + [(case, spec, "weld", s) for s in seeds]

    def path(job) -> Path:
        case, _, mode, seed = job
        return out / "cases" / f"{case}_{mode}_{seed}.json"

    rows = kept_cases(run_case, jobs, [path(j) for j in jobs], workers, "vendor-cases", progress)
    made_by = f"legcal-bench vendor-cases --cases {' '.join(cases)} --seeds {' '.join(map(str, seeds))} --out {out}"
    data = {"made_by": made_by, "code": code_version(), "rows": rows, "summary": summarize(rows)}
    write_report(out, markdown(data["summary"], made_by, describe(data["code"])), data, name="vendor_cases")
    return data


def summarize(rows: list[dict]) -> dict:
    import numpy as np

    weld = {}
    for r in rows:
        if r["mode"] == "weld":
            weld.setdefault(r["case"], []).append(r["vs_imu_deg"])
    ref = float(np.mean(weld[REFERENCE]))
    out = {}
    for case in dict.fromkeys(r["case"] for r in rows):
        k = next(r for r in rows if r["case"] == case and r["mode"] == "kinematic")
        zero = max(k["max_error_deg"], k.get("max_motor_error_deg", 0.0))
        vs = float(np.mean(weld[case]))
        out[case] = {"zero_noise_max_deg": zero, "zero_noise_met": zero <= ZERO_NOISE_BAR_DEG,
                     "weld_vs_imu_deg": vs, "vs_reference": vs / ref, "weld_met": vs / ref <= RATIO_BAR,
                     "verdicts": sorted({r["verdict"] for r in rows if r["case"] == case})}
    return out


def summary_lines(data: dict, out) -> list[str]:
    """What `legcal-bench vendor-cases` prints of a measurement."""
    out = [f"wrote {out}/vendor_cases.md, .json ({len(data['rows'])} sets)"]
    for case, s in data["summary"].items():
        out.append(f"  {case:<12} zero noise {s['zero_noise_max_deg']:.1e} deg, weld {s['vs_reference']:.2f}x the "
                   f"A3-like robot's ({', '.join(s['verdicts'])})")
    return out


def markdown(summary: dict, made_by: str, code: str) -> str:
    L = ["# Robots as vendors ship them, against the A3-like robot", "", f"Made by `{made_by}` at {code}.", "",
         "Each case runs through its leg map alone (`legcal_bench.robots.samples`). Zero noise: a kinematic set, "
         "seed 0, the largest recovery error (at the encoders too, for joints behind a transmission); the bar "
         f"{ZERO_NOISE_BAR_DEG:g} deg. Weld: realistic sets, the IMU-removed recovery (`vs_imu_vertical`) "
         f"mean over the seeds, against the A3-like robot's; the bar {RATIO_BAR:g}x.", "",
         "| case | zero noise, max (deg) | weld vs IMU (deg) | vs A3-like | bar | verdicts |",
         "|---|---:|---:|---:|---|---|"]
    for case, s in summary.items():
        met = s["zero_noise_met"] and s["weld_met"]
        L.append(f"| {case} | {s['zero_noise_max_deg']:.1e} | {s['weld_vs_imu_deg']:.5f} | {s['vs_reference']:.2f}x | "
                 f"{'met' if met else 'missed'} | {', '.join(s['verdicts'])} |")
    return "\n".join(L) + "\n"
