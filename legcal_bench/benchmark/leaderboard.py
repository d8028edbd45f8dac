"""`legcal-bench leaderboard`: tables and plots regenerated from the result rows alone.

Reads the leaderboard's rows (`leaderboard/results.rows.json`, `rows_path`) and every
cell JSON under `leaderboard/results/` (a cell replaces its row), writes the rows back
and `leaderboard/README.md` and `leaderboard/plots/*.png`. The cells are `bench`'s raw
output and its resume state, not committed; the rows keep of each cell the values the
tables and plots read (`ROW_FIELDS`), so the committed rows regenerate the committed
pages. Nothing but the results goes in (no clock, no machine facts), so the same rows
always give the same bytes.
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from legcal_bench.evaluation.metrics import format_mean_std, rms
from legcal_bench.files.atomic import atomic_write_text
from legcal_bench.files.plots import pyplot, save_figure
from legcal_bench.paper import HELDOUT_FOOT_HEIGHT_MM
from legcal_bench.provenance import describe


def _paper_heldout(robot: str) -> str | None:
    if robot not in HELDOUT_FOOT_HEIGHT_MM:
        return None
    before, after = HELDOUT_FOOT_HEIGHT_MM[robot]
    return f"{before:.2f} → {after:.2f} ({robot.upper()})"


# name -> (column header, how to read it from a cell, decimals); the table shows them in this order.
METRICS = {
    "heldout_true_after": ("held-out foot height, true postures (mm)",
                           lambda c: c["native"]["score"]["heldout"]["foot_height_rms_true_mm"]["after"], 4),
    "recovery_rms": ("recovery RMS (deg)", lambda c: c["injected"]["score"]["recovery"]["rms_error_deg"], 3),
    "recovery_vs_imu": ("vs IMU vertical (deg)", lambda c: c["injected"]["score"]["recovery"].get(
        "vs_imu_vertical", {}).get("rms_error_deg", float("nan")), 3),
    "recovery_max": ("recovery max (deg)", lambda c: c["injected"]["score"]["recovery"]["max_error_deg"], 3),
    "pitch_sum_error": ("pitch-sum err (deg)", lambda c: float(np.mean(np.abs(
        [c["injected"]["score"]["recovery"]["pitch_sum_error_deg"][k] for k in ("left", "right")]))), 4),
    "paired_delta_rms": ("paired Δ RMS (deg)", lambda c: c["paired_delta_rms_deg"], 3),
    "native_rms": ("native RMS (deg)", lambda c: c["native"]["score"]["recovery"]["rms_error_deg"], 3),
    "heldout_before": ("held-out foot height, sensors (mm) before",
                       lambda c: c["native"]["score"]["heldout"]["foot_height_rms_mm"]["before"], 3),
    "heldout_after": ("after", lambda c: c["native"]["score"]["heldout"]["foot_height_rms_mm"]["after"], 3),
    "sole_normal_after": ("sole normal after (deg)",
                          lambda c: c["native"]["score"]["heldout"]["sole_normal_rms_deg"]["after"], 3),
    "kappa_H_data": ("κ(H_data)", lambda c: c["injected"]["conditioning"].get("kappa_H_data", float("nan")), 0),
    "solve_s": ("solve (s)",
                lambda c: c["injected"]["timing_s"].get("solve", c["injected"]["timing_s"].get("total", 0.0)), 3),
}
BASELINE = "zero-default"  # the "beats zero" count: seeds whose true-posture held-out foot height is lower


def _beats_baseline(cells: list[dict], baseline: list[dict]) -> str:
    """How many seeds this variant's true-posture held-out foot height beats the
    baseline's on the same session sets, out of the seeds both have."""
    get = METRICS["heldout_true_after"][1]
    base = {c["cell"]["seed"]: get(c) for c in baseline}
    pairs = [(get(c), base[c["cell"]["seed"]]) for c in cells if c["cell"]["seed"] in base]
    return f"{sum(a < b for a, b in pairs)}/{len(pairs)}" if pairs else "–"


# The matched comparison's columns.
COMPARED = ("recovery_rms", "paired_delta_rms", "pitch_sum_error", "heldout_true_after")


# The leaderboard's rows: per results folder `<name>/`, `<name>.rows.json` beside it. Of
# each cell at scale 1 (the others are not shown), its identity, code version and these
# values (dotted paths into the cell; a kind "joints" is a per-joint dict kept as a list in
# the leg map's order, "hist" the held-out histogram with its zero tails cut, "solve" the
# solve time METRICS reads: the total where a cell has no solve stage).
ROWS_SUFFIX = ".rows.json"
ROWS_FORMAT = 1
ROW_KEYS = ("suite", "robot", "mode", "calibrator", "variant", "seed")
ROW_FIELDS = (
    ("native.score.heldout.foot_height_rms_true_mm.after", "value"),
    ("native.score.heldout.foot_height_rms_mm.before", "value"),
    ("native.score.heldout.foot_height_rms_mm.after", "value"),
    ("native.score.heldout.sole_normal_rms_deg.after", "value"),
    ("native.score.recovery.rms_error_deg", "value"),
    ("native.heldout_foot_height_hist", "hist"),
    ("injected.score.recovery.rms_error_deg", "value"),
    ("injected.score.recovery.vs_imu_vertical.rms_error_deg", "value"),
    ("injected.score.recovery.max_error_deg", "value"),
    ("injected.score.recovery.pitch_sum_error_deg.left", "value"),
    ("injected.score.recovery.pitch_sum_error_deg.right", "value"),
    ("injected.score.recovery.per_joint_error_deg", "joints"),
    ("injected.conditioning.kappa_H_data", "value"),
    ("injected.conditioning.eigenvalues_H_data", "value"),
    ("injected.timing_s.solve", "solve"),
    ("paired_delta_rms_deg", "value"),
    ("injected.verdict", "value"),
)


def rows_path(results: str | Path) -> Path:
    """The rows file of a results folder: `leaderboard/results` -> `leaderboard/results.rows.json`."""
    results = Path(results)
    return results.with_name(results.name + ROWS_SUFFIX)


def _identity(c: dict) -> tuple:
    cell = c["cell"]
    return (cell["suite"], c["robot"], cell["mode"], cell["calibrator"], cell["variant"], cell["seed"])


def _leaf(c, path: str):
    for k in path.split("."):
        if not isinstance(c, dict) or k not in c:
            return None
        c = c[k]
    return c


def _put(c: dict, path: str, value) -> None:
    *parents, last = path.split(".")
    for k in parents:
        c = c.setdefault(k, {})
    c[last] = value


def to_row(c: dict, provenances: list) -> list:
    """A cell as its row: identity, the index of its code version in `provenances`
    (appended if new), its error (None) and ROW_FIELDS' values (None where absent)."""
    p = c.get("provenance")
    if p not in provenances:
        provenances.append(p)
    row = [*_identity(c), provenances.index(p), c.get("error")]
    if "error" in c:
        return row
    for path, kind in ROW_FIELDS:
        v = _leaf(c, path)
        if kind == "solve":
            t = c["injected"]["timing_s"]
            v = t.get("solve", t.get("total", 0.0))
        elif v is not None and kind == "joints":
            v = [v[j] for j in c["joint_names"]]
        elif v is not None and kind == "hist":
            v = {k: counts if k == "edges_mm" else _cut(counts) for k, counts in v.items()}
        row.append(v)
    return row


def _cut(counts: list) -> list:
    """[index of the first nonzero bin, the bins from it to the last nonzero one]."""
    nz = [i for i, n in enumerate(counts) if n]
    return [nz[0], *counts[nz[0]:nz[-1] + 1]] if nz else [len(counts)]


def from_row(row: list, provenances: list, joint_names: dict) -> dict:
    """The cell a row was made from, as far as the leaderboard reads it."""
    suite, robot, mode, calibrator, variant, seed, p, error = row[:8]
    c: dict = {"cell": {"suite": suite, "mode": mode, "calibrator": calibrator, "variant": variant, "seed": seed},
               "robot": robot}
    if provenances[p] is not None:
        c["provenance"] = provenances[p]
    if error is not None:
        c["error"] = error
        return c
    c["joint_names"] = joint_names[robot]
    c["injected"] = {"conditioning": {}}  # read with .get: a cell without conditioning numbers has it empty
    for (path, kind), v in zip(ROW_FIELDS, row[8:]):
        if v is None:
            continue
        if kind == "joints":
            v = dict(zip(joint_names[robot], v))
        elif kind == "hist":
            n = v["edges_mm"][2]
            v = {k: b if k == "edges_mm" else [0] * b[0] + b[1:] + [0] * (n - b[0] - len(b) + 1) for k, b in v.items()}
        _put(c, path, v)
    return c


def read_rows(path: str | Path) -> list[dict]:
    """The cells of a rows file (`from_row`); none if it does not exist."""
    path = Path(path)
    if not path.is_file():
        return []
    d = json.loads(path.read_text())
    return [from_row(r, d["provenance"], d["joint_names"]) for r in d["rows"]]


def write_rows(path: str | Path, cells: list[dict]) -> None:
    """`cells` (at scale 1) as a rows file, in `_identity` order."""
    from legcal_bench.files.atomic import rows_json

    provenances: list = []
    cells = sorted(cells, key=_identity)
    rows = [to_row(c, provenances) for c in cells]
    names = {c["robot"]: c["joint_names"] for c in cells if "joint_names" in c}
    atomic_write_text(path, rows_json({"format": ROWS_FORMAT, "columns": [*ROW_KEYS, "provenance", "error",
                                                                          *(f for f, _ in ROW_FIELDS)],
                                       "provenance": provenances, "joint_names": names, "rows": rows}))


def read_cells(results: str | Path) -> list[dict]:
    """The cells at scale 1 of a results folder: its rows file's, each replaced by the
    cell file of the same identity under the folder if there is one, in `_identity` order."""
    results = Path(results)
    cells = {_identity(c): c for c in read_rows(rows_path(results))}
    for p in sorted(results.rglob("*.json")) if results.is_dir() else []:
        c = json.loads(p.read_text())
        if c["cell"].get("scale", 1.0) == 1.0:
            cells[_identity(c)] = c
    return [cells[k] for k in sorted(cells)]


def group(cells: list[dict]) -> tuple[dict, dict]:
    """(cells by (suite, robot, mode) and calibrator-variant, failed cells likewise)."""
    groups: dict = defaultdict(lambda: defaultdict(list))
    failed: dict = defaultdict(lambda: defaultdict(list))
    for c in cells:
        cell = c["cell"]
        key = (cell["suite"], c["robot"], cell["mode"])
        (failed if "error" in c else groups)[key][f"{cell['calibrator']}-{cell['variant']}"].append(c)
    for g in groups.values():
        for cs in g.values():
            cs.sort(key=lambda c: c["cell"]["seed"])
    return groups, failed


def load_results(results: Path) -> tuple[dict, dict]:
    """(cells by (suite, robot, mode) and calibrator-variant, failed cells likewise), of
    a results folder and its rows (`read_cells`)."""
    return group(read_cells(results))


def _fmt(vals: list[float], nd: int) -> str:
    v = np.asarray(vals, dtype=float)
    if np.all(np.isnan(v)):
        return "–"
    if nd == 0:
        return f"{np.nanmean(v):.3g}"
    m, s = np.nanmean(v), np.nanstd(v)
    return f"{m:.{nd}f} ± {s:.{nd}f}" if len(v) > 1 else f"{m:.{nd}f}"


def _verdicts(g: dict) -> list[str]:
    """Per variant whose injected sets did not all get `apply`: its verdicts in words (a
    do-not-apply cell is a failed calibration, scored as no correction)."""
    L = []
    for name in sorted(g):
        v = [c.get("injected", {}).get("verdict") for c in g[name]]
        if all(x in (None, "apply") for x in v):
            continue
        rej = [c["cell"]["seed"] for c, x in zip(g[name], v) if x == "do-not-apply"]
        L.append(f"\n{name}: verdicts {v.count('apply')} apply, {v.count('review')} review (scored as corrections), "
                 f"{len(rej)} do-not-apply" + (f" (seeds {', '.join(map(str, rej))}: failed calibrations, scored as "
                                               "no correction)" if rej else ""))
    return L


def _matched_comparison(groups: dict) -> list[str]:
    """Inter-foot vs Yamane on the same states, noise and split, seed by seed."""
    L = []
    for (suite, robot, mode), g in sorted(groups.items()):
        pairs = [(a, b) for a in sorted(g) if a.startswith("interfoot") for b in sorted(g) if b.startswith("yamane")]
        if not pairs:
            continue
        L += [f"**{robot}, {mode}, suite {suite}** (seeds won, paired by seed; lower is better):", "",
              "| inter-foot | Yamane | recovery RMS | paired Δ RMS | pitch-sum err | held-out height (true postures) |",
              "|---|---|---|---|---|---|"]
        for a, b in pairs:
            row = [a.split("-", 1)[1], b.split("-", 1)[1]]
            for metric in COMPARED:
                get = METRICS[metric][1]
                fa = np.array([get(c) for c in g[a]])
                fb = np.array([get(c) for c in g[b]])
                n = min(len(fa), len(fb))
                wins = int((fa[:n] < fb[:n]).sum())
                row.append(f"{wins}/{n} vs {n - wins}/{n} ({fa.mean():.3g} vs {fb.mean():.3g})")
            L.append("| " + " | ".join(row) + " |")
        L.append("")
    return L


def _plots(groups: dict, out: Path) -> dict:
    plt = pyplot()
    made = {}
    for (suite, robot, mode), g in sorted(groups.items()):
        tag = f"{suite}_{robot}_{mode}"
        names = sorted(g)
        # Held-out foot-height histograms (the paper's figure), pooled over seeds.
        fig, ax = plt.subplots(figsize=(7, 3.8))

        def pooled(cells, which):
            h = cells[0]["native"]["heldout_foot_height_hist"]
            edges = np.linspace(h["edges_mm"][0], h["edges_mm"][1], h["edges_mm"][2] + 1)
            counts = np.sum([c["native"]["heldout_foot_height_hist"][which] for c in cells], axis=0)
            pooled_rms = rms([c["native"]["score"]["heldout"]["foot_height_rms_mm"][which] for c in cells])
            return edges, counts, pooled_rms

        edges, counts, pooled_rms = pooled(g[names[0]], "before")
        ax.stairs(counts, edges, fill=True, alpha=0.3, color="gray", label=f"uncorrected (RMS {pooled_rms:.2f} mm)")
        for n in names:
            if n.startswith("zero"):
                continue
            edges, counts, pooled_rms = pooled(g[n], "after")
            ax.stairs(counts, edges, lw=1.4, label=f"{n} (RMS {pooled_rms:.2f} mm)")
        ax.set_xlabel("held-out foot-height residual p_Lz - p_Rz (mm), logged sensors")
        ax.set_ylabel("frames")
        ax.set_title(f"{robot}, {mode}: held-out flat-ground validation, native offsets")
        ax.legend(fontsize=7)
        fig.tight_layout()
        made[f"{tag}_heldout"] = _save(fig, out / f"{tag}_heldout.png")
        # Information spectra.
        fig, ax = plt.subplots(figsize=(6, 3.6))
        for n in names:
            eig = [c["injected"]["conditioning"].get("eigenvalues_H_data") for c in g[n]]
            if all(e is not None for e in eig):
                mean = np.mean(eig, axis=0)
                ax.semilogy(range(1, len(mean) + 1), mean, "o-", ms=3, label=n)
        ax.set_xlabel("eigenvalue index (ascending)")
        ax.set_ylabel("eigenvalue of H_data (method's own units)")
        ax.set_title(f"{robot}, {mode}: information spectra (mean over seeds)")
        ax.legend(fontsize=7)
        ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        made[f"{tag}_spectra"] = _save(fig, out / f"{tag}_spectra.png")
        # Recovery error per joint.
        joints = g[names[0]][0]["joint_names"]
        fig, ax = plt.subplots(figsize=(9, 3.8))
        shown = [n for n in names if not n.startswith("zero")]
        width = 0.8 / max(len(shown), 1)
        for i, n in enumerate(shown):
            errs = np.array([[c["injected"]["score"]["recovery"]["per_joint_error_deg"][j] for j in joints] for c in g[n]])
            ax.bar(np.arange(len(joints)) + (i - (len(shown) - 1) / 2) * width, errs.mean(0), width, yerr=errs.std(0),
                   label=n, capsize=1.5)
        ax.set_xticks(range(len(joints)), [j.replace("_joint", "").replace("_", " ") for j in joints], rotation=40,
                      ha="right", fontsize=7)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel("signed recovery error (deg)")
        ax.set_title(f"{robot}, {mode}: recovery error per joint (mean ± std over seeds)")
        ax.legend(fontsize=7)
        fig.tight_layout()
        made[f"{tag}_joints"] = _save(fig, out / f"{tag}_joints.png")
    return made


def _save(fig, path: Path) -> str:
    # tight_layout leaves a placeholder layout engine, for which savefig draws the figure
    # once more before drawing it into the PNG (a third of the save); the layout is done,
    # so without it the bytes are the same.
    fig.set_layout_engine(None)
    return save_figure(fig, path, dpi=100).name


def _provenance(g: dict) -> str:
    """Which code made a table's cells: one entry per distinct code version."""
    versions: dict[str, int] = defaultdict(int)
    for cells in g.values():
        for c in cells:
            p = c.get("provenance")
            versions[describe(p) if p else "code version not recorded (cells from before provenance)"] += 1
    return "; ".join(f"{v} ({n} cells)" for v, n in sorted(versions.items()))


DESIGNED = "designed"  # the designed protocols' leaderboard, under the main one (`bench --protocol --out`)


def _protocol_comparison(root: Path, default: dict | None = None) -> list[str]:
    """The designed protocols (`root/designed/results` and its rows) against the default
    stances (`root/results` and its rows; `default`: its cells, if loaded already),
    paired seed by seed per robot, weld floor: one row per variant."""
    designed = root / DESIGNED / "results"
    if not all(p.is_dir() or rows_path(p).is_file() for p in (designed, root / "results")):
        return []
    groups, failed = load_results(designed)
    if default is None:
        default = load_results(root / "results")[0]
    L = ["## Protocols: the four default stances against a designed protocol", "",
         f"The designed protocols (`legcal-bench design`, their own leaderboard in [{DESIGNED}/]({DESIGNED}/README.md)) "
         "against the default stances, on the seeds both ran (paired: same seed, factory offsets, injection and "
         "sensor noise; the stances and hence the held-out sessions differ, so held-out height is not compared). "
         "Each cell: default → designed mean, and the seeds in which the designed protocol is lower; a designed "
         "session set that failed the hold check is counted in the last column, and its reason is in the "
         "designed leaderboard.", "",
         "| robot | calibrator-variant | seeds | recovery RMS (deg) | designed lower | vs IMU vertical (deg) | "
         "designed lower | designed seeds failed |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for robot, mode in sorted({(rb, md) for (_, rb, md) in groups if md == "weld"}):
        rec = {r["variant"]: r for r in compare(groups, default, robot, mode, "recovery_rms")}
        imu = {r["variant"]: r for r in compare(groups, default, robot, mode, "recovery_vs_imu")}
        fails = {name: len(cs) for (_, rb, md), g in failed.items() if (rb, md) == (robot, mode)
                 for name, cs in g.items()}
        for name in sorted(set(rec) - {BASELINE}):
            r, v = rec[name], imu.get(name)
            n = len(r["seeds"])
            vs = "–" if v is None or not np.isfinite([v["a_mean"], v["b_mean"]]).all() else \
                f"{v['b_mean']:.4f} → {v['a_mean']:.4f} | {v['a_lower']}/{len(v['seeds'])}"
            L.append(f"| {robot} | {name} | {n} | {r['b_mean']:.3f} → {r['a_mean']:.3f} | {r['a_lower']}/{n} | "
                     + (vs if "|" in vs else f"{vs} | –") + f" | {fails.get(name, 0)} |")
    return L + [""]


def _closed_loop(root: Path) -> list[str]:
    """The closed-loop suite's results (`legcal_bench.benchmark.closed_loop`), one table
    per robot and offset pattern: each variant's corrected walk beside the references."""
    from legcal_bench.benchmark.closed_loop import RESULTS_DIR
    from legcal_bench.robots import robot_label

    files = sorted((root / RESULTS_DIR).glob("*.json"))
    if not files:
        return []
    L = ["## Closed loop: what each estimate does to a walking policy", "",
         "From `legcal-bench bench --suite closed-loop` (files in `closed_loop/`): per trial, a static session set "
         "with the trial's offsets (weld, `calibrated-imu`, stances I–IV) calibrated by every variant; the same "
         "policy then walks 20 s corrected by each estimate, against the same seed's nominal walk. Deviations are "
         "RMS (mm), mean ± std over the trials upright in both walks; 'of uncorrected' = the corrected foot-strike "
         "deviation over the uncorrected one (paper, real A3 at 3°: 2.2 %). The nominal seed-to-seed spread (a "
         "nominal walk with other noise) is the floor below which a correction cannot be told from perfect.", ""]
    for f in files:
        d = json.loads(f.read_text())
        s, cfg = d["summary"], d["summary"]["config"]
        c = s["conditions"]
        L += [f"### {robot_label(cfg['robot'])} — `{cfg['offsets']}` — policy "
              f"`{Path(cfg['policy']).name}` ({cfg['trials']} trials)", "",
              f"Produced by {describe(d['provenance'])}.", "",
              "| calibrator-variant | upright | recovery RMS (deg) | foot-strike dev (mm) | pelvis dev (mm) | "
              "of uncorrected |", "|---|---:|---:|---:|---:|---:|"]
        for name, v in sorted(s["variants"].items()):
            ratio = "–" if v["corrected_over_uncorrected"] is None else f"{100 * v['corrected_over_uncorrected']:.2f} %"
            L.append(f"| {name} | {v['upright']}/{v['trials']} | {format_mean_std(v['recovery_rms_deg'], 4)} | "
                     f"{format_mean_std(v['foot_strike_rms_mm'], 1)} | {format_mean_std(v['pelvis_rms_mm'], 1)} | {ratio} |")
        for name in ("uncorrected", "oracle"):
            r = c[name]
            L.append(f"| *{name}* | {r['upright']}/{r['trials']} | – | {format_mean_std(r['foot_strike_rms_mm'], 1)} | "
                     f"{format_mean_std(r['pelvis_rms_mm'], 1)} | – |")
        sp = s["nominal_spread"]
        L += [f"| *nominal seed-to-seed spread* | – | – | {format_mean_std(sp['foot_strike_rms_mm'], 1)} | "
              f"{format_mean_std(sp['pelvis_rms_mm'], 1)} | – |", ""]
        failed = s.get("static_failed") or {}
        if failed.get("count"):
            L += [f"{failed['count']} trial(s) (seeds {failed['seeds']}) have no calibration: the robot could not "
                  "hold the static session set with their offsets, so no variant walks them (they count in the "
                  "uncorrected and oracle rows).", ""]
    return L


def _modelgap(root: Path) -> list[str]:
    """The model-gap suite's table (`legcal_bench.benchmark.modelgap`). Its summary and
    its own page are views of its rows: rebuilt here from them (and rewritten, so a
    scoring change reaches both without rerunning the suite)."""
    from legcal_bench.benchmark.modelgap import RESULTS_NAME, markdown, summarize
    from legcal_bench.files.reports import write_report

    path = root / RESULTS_NAME / f"{RESULTS_NAME}.json"
    if not path.is_file():
        return []
    d = json.loads(path.read_text())
    d["summary"] = summarize(d["rows"])
    page = markdown(d, d["made_by"], describe(d["code"]))
    write_report(root / RESULTS_NAME, page, d, name=RESULTS_NAME)
    table = page.splitlines()[1:]  # without its title
    return ["## Model gap: the detect / trace / select loop scored", "",
            f"Its own page, with every case's verdict: [{RESULTS_NAME}/{RESULTS_NAME}.md]({RESULTS_NAME}/{RESULTS_NAME}.md).",
            *table, ""]


# Reports the leaderboard shows from their own results folders (`<root>/<folder>/<name>.json`,
# written by the report's command with --out <root>/<folder>): (folder, name, report
# module, section title).
REPORT_SECTIONS = (
    ("contact_floor", "contact_floor", "legcal_bench.reports.contact_floor", "Contact floor against weld floor"),
    ("contact_floor_robustness", "contact_floor", "legcal_bench.reports.contact_floor",
     "Contact floor: robustness to the floor's parameters"),
    ("contact_floor_realistic", "contact_floor", "legcal_bench.reports.contact_floor",
     "Contact floor against weld floor: realistic sensors"),
    ("contact_floor_stand_ins", "contact_floor", "legcal_bench.reports.contact_floor",
     "Contact floor against weld floor: the stand-ins and the whole-body G1"),
    ("contact_holds", "contact_holds", "legcal_bench.reports.contact_holds", "Holding stances on the contact floor"),
    ("contact_holds_stand_ins", "contact_holds", "legcal_bench.reports.contact_holds",
     "Holding stances on the contact floor: the stand-ins"),
)


def _report_sections(root: Path) -> list[str]:
    """Each of REPORT_SECTIONS whose results exist: its page rebuilt from its rows (so a
    formatting change reaches it without rerunning), and its tables here."""
    import importlib

    from legcal_bench.files.reports import report_data, report_page, write_report

    L = []
    for folder, name, module, title in REPORT_SECTIONS:
        path = report_data(root / folder, name)
        if not path.is_file():
            continue
        mod = importlib.import_module(module)
        d = json.loads(path.read_text())
        d["summary"] = mod.summarize(d["rows"])
        page = mod.markdown(d, d["made_by"], describe(d["code"]))
        write_report(root / folder, page, d, name=name)
        link = report_page(folder, name).as_posix()
        L += [f"## {title}", "", f"Its own page, with every set: [{link}]({link}).",
              *page.splitlines()[1:], ""]
    return L


def generate(root: str | Path = "leaderboard") -> str:
    root = Path(root)
    cells = read_cells(root / "results")
    if cells:
        write_rows(rows_path(root / "results"), cells)
    groups, failed = group(cells)
    plots = _plots(groups, root / "plots") if groups else {}
    L = ["# legcal-bench leaderboard", "",
         "Generated by `legcal-bench leaderboard` from the rows in `results.rows.json` alone (of each cell `legcal-bench "
         "bench` writes to `results/`, the values shown here; `results/` itself is not committed: `bench` writes it "
         "again, and its cells replace their rows); regenerating gives the same bytes. Mean ± std over seeds.", "",
         "Columns: the headline, **held-out foot height on the true postures** = RMS of p_Lz − p_Rz on three "
         "held-out sessions of the native set, from the true joint angles minus the native offsets, corrected by "
         "the method's estimate, in the true vertical (noise-free: it ranks methods); **beats zero** = seeds in "
         "which it is lower than with no correction at all (`zero-default`) on the same sessions; **recovery** on "
         "the injected session set (native factory offsets + the paper's injection), against the true total, and "
         "**vs IMU vertical** = the same with the share of the IMU's realized tilt removed (the part static "
         "level-ground data cannot separate from offsets; see `score`); **pitch-sum err** = mean |error| of s_L and "
         "s_R; **paired Δ** = estimate(injected) − estimate(native) − injection (the paper's real-robot metric); "
         "**native RMS** = error on the session set with only the factory residual (uniform ±1.2° per joint since "
         "results version 5, ±0.3° before); **held-out foot height, sensors** = the same row from the logged, "
         "noisy sensors (the paper's validation, motion-compensated since results version 4), which sits at the "
         "sensor floor once a method is decent; κ(H_data) in each method's own residual units.", ""]
    for (suite, robot, mode), g in sorted(groups.items()):
        seeds = sorted({c["cell"]["seed"] for cells in g.values() for c in cells})
        L += [f"## {robot} — {mode} — suite `{suite}` ({len(seeds)} seed{'s' if len(seeds) > 1 else ''})", ""]
        L += [f"Produced by {_provenance(g)}.", ""]
        heads = ["calibrator-variant", "beats zero (seeds)"] + [m[0] for m in METRICS.values()]
        L += ["| " + " | ".join(heads) + " |", "|---|" + "---:|" * (len(METRICS) + 1)]
        for name in sorted(g):
            L.append(f"| {name} | {_beats_baseline(g[name], g.get(BASELINE, []))} | "
                     + " | ".join(_fmt([get(c) for c in g[name]], nd) for _, get, nd in METRICS.values()) + " |")
        L += _verdicts(g)
        for name, cells in sorted(failed.get((suite, robot, mode), {}).items()):
            seeds_failed = ", ".join(str(c["cell"]["seed"]) for c in cells)
            L.append(f"\n{name} could not calibrate seed(s) {seeds_failed}: {cells[0]['error']}")
        if _paper_heldout(robot):
            L += ["", f"Paper, real robots, held-out foot height: {_paper_heldout(robot)} mm."]
        tag = f"{suite}_{robot}_{mode}"
        L += ["", f"![held-out](plots/{plots[tag + '_heldout']}) ![spectra](plots/{plots[tag + '_spectra']})",
              "", f"![per joint](plots/{plots[tag + '_joints']})", ""]
    L += _protocol_comparison(root, groups)
    L += _closed_loop(root)
    L += _modelgap(root)
    L += _report_sections(root)
    L += ["## Matched comparison: inter-foot vs Yamane", "",
          "Same simulated states, noise and held-out split for both methods (the paper's comparison section); "
          "each cell counts the seeds each method wins. The paper found no universal winner.", ""]
    L += _matched_comparison(groups) or ["(no suite with both methods yet)", ""]
    L += ["## Add your calibrator and get a row", "",
          "1. Write a `legcal_bench.calibrators.base.Calibrator` subclass (see `docs/calibrators.md`); optionally a "
          "classmethod `benchmark_variants()` returning {variant: options}.",
          "2. Register it in your package's `pyproject.toml` under `[project.entry-points.\"legcal_bench.calibrators\"]` "
          "and `pip install -e` it.",
          "3. `legcal-bench bench --suite standard` (only your new cells run; finished cells are kept), then "
          "`legcal-bench leaderboard`.", ""]
    text = "\n".join(L)
    atomic_write_text(root / "README.md", text)
    return text


def compare(a: str | Path | dict, b: str | Path | dict, robot: str, mode: str,
            metric: str = "recovery_rms") -> list[dict]:
    """Two result folders (e.g. a designed protocol's and the default's), or their cells
    as `load_results` groups them, paired seed by seed for one robot and floor: per
    calibrator variant, the seeds both have, each side's mean of `metric` (a `METRICS`
    key) over those seeds, and how often `a` is lower."""
    get = METRICS[metric][1]

    def cells(root):
        groups = root if isinstance(root, dict) else load_results(Path(root))[0]
        out: dict = {}
        for (suite, rb, md), g in groups.items():
            if rb == robot and md == mode:
                for name, cs in g.items():
                    out.setdefault(name, {}).update({c["cell"]["seed"]: c for c in cs})
        return out

    ca, cb = cells(a), cells(b)
    rows = []
    for name in sorted(set(ca) & set(cb)):
        seeds = sorted(set(ca[name]) & set(cb[name]))
        if not seeds:
            continue
        va, vb = [get(ca[name][k]) for k in seeds], [get(cb[name][k]) for k in seeds]
        rows.append({"variant": name, "seeds": seeds, "a_mean": float(np.mean(va)), "b_mean": float(np.mean(vb)),
                     "a_lower": int(sum(x < y for x, y in zip(va, vb)))})
    return rows
