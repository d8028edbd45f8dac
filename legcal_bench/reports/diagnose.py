"""`legcal-bench diagnose`'s report (issue #17): markdown, JSON and plots of a model-gap
diagnosis (`legcal_bench.evaluation.modelgap.diagnose`), with the truth's offsets error
before/after when the recordings carry it, and (`--walk`) the two estimates walked."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def json_ready(report: dict) -> dict:
    return {k: v for k, v in report.items() if not k.startswith("_")}


def truth_scores(report: dict, bags: Path, joint_names: list[str]) -> dict | None:
    """Offsets RMS error (deg) against the ground truth, if the session has one: before
    (offsets only), after (the recommended estimate) and per candidate."""
    from legcal_bench.data.recording import list_segments, load_truth, truth_path
    from legcal_bench.evaluation.metrics import rms

    first = list_segments(bags, allow_partial=True)[0]
    if not truth_path(first).is_file():  # a real robot's logs have no truth
        return None
    truth = load_truth(first)
    inj = np.asarray(truth.offsets)

    def err(offsets: dict) -> float:
        return float(np.rad2deg(rms(np.array([offsets[n] for n in joint_names]) - inj)))

    out = {"before": err(report["offsets_only_rad"]), "after": err(report["offsets_rad"]),
           "candidates": {c["name"]: err(c["offsets_rad"]) for c in report.get("candidates", [])}}
    out["effects_in_truth"] = [e.get("effect") for e in truth.meta.get("reality", {}).get("effects", [])]
    return out


def diagnosis_walks(report: dict, legmap, bags: Path, policy: str, trials: int, progress: bool = True) -> dict:
    """`diagnose --walk`: the policy walked with the true offsets (the session's ground
    truth; for real logs the diagnosis's final estimate, said so) corrected by the
    offsets-only estimate and by the estimate after the diagnosis
    (`legcal_bench.evaluation.closed_loop.estimate_walks`)."""
    from legcal_bench.data.recording import list_segments, load_truth, truth_path
    from legcal_bench.evaluation.closed_loop import estimate_walks

    names = legmap.joint_names
    before = np.array([report["offsets_only_rad"][n] for n in names])
    after = np.array([report["offsets_rad"][n] for n in names])
    first = list_segments(bags, allow_partial=True)[0]
    if truth_path(first).is_file():
        true_dq, source = np.asarray(load_truth(first).offsets, dtype=float), "the recordings' ground truth"
    else:
        true_dq, source = after, "the diagnosis's final estimate (no ground truth in the recordings)"
    out = estimate_walks(legmap, policy, true_dq, {"offsets_only": before, "after": after}, trials=trials,
                         progress=progress)
    out.update(policy=policy, true_offsets=source, same_estimate=bool(np.array_equal(before, after)))
    return out


def walks_line(w: dict) -> str:
    from legcal_bench.evaluation.metrics import format_mean_std

    return (f"walks ({w['trials']} seeds, {w['seconds']:.0f} s, pelvis RMS deviation from nominal, mm): uncorrected "
            f"{format_mean_std(w['uncorrected']['pelvis_rms_mm'], 1)}, offsets-only estimate "
            f"{format_mean_std(w['offsets_only']['pelvis_rms_mm'], 1)}, after the diagnosis "
            f"{format_mean_std(w['after']['pelvis_rms_mm'], 1)}; nominal spread "
            f"{format_mean_std(w['nominal_spread']['pelvis_rms_mm'], 1)}")


def _walks_table(w: dict) -> list[str]:
    from legcal_bench.evaluation.metrics import format_mean_std

    L = ["## Closed loop: the two estimates walked", "",
         f"Policy `{w['policy']}`, {w['trials']} seeds of {w['seconds']:.0f} s; the robot carries the true offsets "
         f"({w['true_offsets']}); the walking model is the nominal one, so this is the offsets' share of the answer. "
         "Deviation from the same seed's nominal walk; the nominal spread is a nominal walk with other noise.", "",
         "| walk | upright | pelvis RMS (mm) | foot-strike RMS (mm) | estimate RMS error (deg) |",
         "|---|---:|---:|---:|---:|"]
    for c, label in (("uncorrected", "uncorrected"), ("offsets_only", "corrected, offsets-only estimate"),
                     ("after", "corrected, after the diagnosis")):
        r = w[c]
        err = f"{r['estimate_rms_error_deg']:.4f}" if "estimate_rms_error_deg" in r else "–"
        L.append(f"| {label} | {w['upright'][c]}/{w['trials']} | {format_mean_std(r['pelvis_rms_mm'], 1)} | "
                 f"{format_mean_std(r['foot_strike_rms_mm'], 1)} | {err} |")
    s = w["nominal_spread"]
    L += [f"| nominal spread | {w['upright']['nominal']}/{w['trials']} | {format_mean_std(s['pelvis_rms_mm'], 1)} | "
          f"{format_mean_std(s['foot_strike_rms_mm'], 1)} | – |", ""]
    if w["same_estimate"]:
        L += ["(No effect was kept: both estimates are the same.)", ""]
    return L


def where_text(localization: dict) -> str:
    from legcal_bench.evaluation.modelgap import where_text as words

    return words(localization)


def family_text(generic: dict) -> str:
    from legcal_bench.evaluation.modelgap import family_text as words

    return words(generic)


def _generic_section(report: dict) -> list[str]:
    g = report.get("generic")
    if not g:
        return []
    L = ["## The generic geometric alternative", "",
         f"Both legs' full geometry (a twist at each hip's mounting and after each joint) and the IMU's mount, "
         f"reduced jointly by a pivoted QR to the {g['parameters']} of {g['of']} parameters these data identify "
         f"beyond the offsets: chi2/dof {g['chi2_per_dof']:.4f} (p = {g['p_value']:.2g}): "
         + ("it explains the data." if g["explains"] else "it does not explain the data either.")]
    if "bic_minus_selected" in g:
        L[-1] += (f" Its BIC minus the selected model's: {g['bic_minus_selected']:.0f} (an effect is claimed only "
                  f"when this is at least {report['rules']['ambiguous_bic']:g}).")
    if g["families"] is None:
        return L + ["", "(Families of geometry change not tested: the selection is claimed.)", ""]
    L += ["", "| family alone | parameters | delta chi2 vs the whole | dof | p | consistent |", "|---|---|---|---|---|---|"]
    for f, v in g["families"].items():
        ok = ("yes" if v["consistent"] else "no (as good as the whole, which does not fit either)"
              if v.get("as_good_as_the_whole") else "no")
        L.append(f"| {f} | {v['parameters']} | {v['delta_chi2']:.1f} | {v['dof']} | {v['p_value']:.2g} | {ok} |")
    return L + [""]


def _candidates_section(report: dict, truth: dict | None) -> list[str]:
    cands = report.get("candidates", [])
    if len(cands) < 2:
        return []
    cv = report["detection"].get("cross_validation", {})
    hh = (report.get("heldout_foot_height_mm") or {}).get("candidates", {})
    tc = (truth or {}).get("candidates", {})
    L = ["## The recommended estimate", "",
         "A claimed selection's own fit is the estimate. Otherwise it is chosen among these candidates by "
         "leave-one-stance-out cross-validation on the training stances (each stance predicted from the fit on the "
         "others; candidates within 10 of the lowest left-out chi2 are a tie, resolved to the fewest parameters); "
         "inadmissible fits are never chosen. The held-out figures score the choice, they never make it.",
         "", "| candidate | parameters | chi2 / dof | left-out chi2 / dof | held-out foot height (mm) | "
         "offsets error vs truth (deg) | status |", "|---|---|---|---|---|---|---|"]
    for c in cands:
        cvd = f"{c['cv_chi2'] / cv['dof']:.4f}" if c.get("cv_chi2") is not None and cv.get("dof") else "–"
        h = f"{hh[c['name']]:.4f}" if c["name"] in hh else "–"
        e = f"{tc[c['name']]:.4f}" if c["name"] in tc else "–"
        status = ("**recommended**" if c["recommended"] else "") + (
            f" set aside: {c['set_aside']}" if c.get("set_aside") else
            "" if c.get("claimed") or c["kind"] == "generic" else " not claimed")
        L.append(f"| {c['name']} | {c['k']} | {c['chi2'] / c['dof']:.4f} | {cvd} | {h} | {e} | {status.strip()} |")
    return L + [""]


def rules_text(report: dict) -> str:
    """The selection's decision rules in words (the report's JSON keeps them as numbers)."""
    r = report["rules"]
    per_parameter = float(np.log(r["n_rows"]))
    return (f"Decision rules: an effect is kept only if its chi2 drop exceeds k ln(n_rows) = k x {per_parameter:.1f} "
            f"(the BIC penalty, k its parameters, {r['n_rows']} rows), the fit with it predicts each stance left out "
            f"of the fit better (leave-one-stance-out cross-validation), and it moves some offset by more than "
            f"{r['move_sigmas']:g} noise-only standard deviations. Candidates within {r['ambiguous_bic']:g} of BIC "
            f"of each other are reported as ambiguous; at most {r['max_effects']} effects are kept; a fit that "
            "leaves the residual significant, with a leg or IMU location test significant on it, is a poor fit "
            f"(set aside). A fitted parameter outside its effect's declared bounds by more than "
            f"{r.get('admissible_sigmas', 3):g} standard deviations makes the fit inadmissible. A selection is claimed "
            f"only if its BIC beats the generic geometric alternative's (both legs and the IMU mount, reduced to "
            f"what the data identify) by {r['ambiguous_bic']:g}; within that, it is ambiguous. The residual is tested at a false-alarm rate of {report['alpha']:g} in all (each test at "
            f"{report['alpha'] / 2:g}).")


def markdown(report: dict, made_by: str, code: str, truth: dict | None, walks: dict | None = None) -> str:
    d, a = report["detection"], report["after"]
    L = [f"# Model-gap diagnosis: {report['verdict']}", "", f"Made by `{made_by}` ({code}).", "",
         f"**{report.get('verdict_line') or report['summary']}**", "", report["summary"], "",
         f"| | offsets only | {'after the selection' if report['steps'] else 'after'} |", "|---|---|---|",
         f"| chi2 / dof (training) | {d['chi2_per_dof']:.4f} (p = {d['p_value']:.2g}) | "
         f"{a['chi2_per_dof']:.4f} (p = {a['p_value']:.2g}) |"]
    if "cross_validation" in d:  # each training stance at the estimate from the others
        h, ha = d["cross_validation"], a["cross_validation"]
        L.append(f"| chi2 / dof (each stance left out) | {h['chi2_per_dof']:.4f} | {ha['chi2_per_dof']:.4f} |")
        L.append(f"| left out / training (the gap) | {h['ratio_to_training']:.4f} (p = {h['p_value']:.2g}) | "
                 f"{ha['ratio_to_training']:.4f} (p = {ha['p_value']:.2g}) |")
    start = report.get("start")
    if start:
        L.append(f"| fit started from | {start['calibrator']} | |")
    rec = f"recommended ({report.get('recommended', 'offsets only')}): "
    if truth:
        L.append(f"| offsets RMS error vs truth (deg) | {truth['before']:.4f} | {rec}{truth['after']:.4f} |")
    hh = report.get("heldout_foot_height_mm")
    if hh:
        L.append(f"| held-out foot height RMS ({hh['postures']} postures, mm) | {hh['before']:.4f} | "
                 f"{rec}{hh['after']:.4f} |")
    L += ["", rules_text(report), ""]
    nz = report.get("noise")
    if nz:
        meas = "–" if nz["tilt_measured_rad"] is None else f"{nz['tilt_measured_rad'] * 1e3:.3f}"
        L += [f"Judged against: encoder noise {np.rad2deg(nz['encoder_rad']):.4f} deg; IMU tilt noise "
              f"{nz['tilt_used_rad'] * 1e3:.3f} mrad per axis (declared {nz['tilt_declared_rad'] * 1e3:.3f}, "
              f"measured from the data {meas}: the larger is used).", ""]
    if report["parameters"]:
        for x in report.get("set_aside", []):
            L += [f"Set aside, not a result: the fit with {x['effects']}: {x['why']}; its parameters, for "
                  "reference:", ""]
        if report.get("ambiguous") and not report.get("set_aside"):
            L += [f"Not a result (ambiguous): the fit with {' + '.join(report['poor_fit'])}; its parameters, for "
                  "reference:", ""]
        L += ["| parameter | value | std | unit |", "|---|---|---|---|"]
        for n, p in report["parameters"].items():
            L.append(f"| {n} | {p['value']:.4g} | {p['std']:.2g} | {p['unit']}{' (held: confounded)' if p['held'] else ''} |")
        L.append("")
    for c in report["confounded"]:
        L.append(f"- confounded: {c['text']}")
    for n in report["notes"]:
        L.append(f"- {n}")
    L += ["", "## Selection steps", ""]
    for st in report["steps"]:
        head = ("Pairs, each on top of the offsets (the greedy path left a residual; a pair passes only if it also "
                "explains the data):" if st.get("pairs") else f"On top of {st['on_top_of'] or 'the offsets'}:")
        L += [head, "",
              "| effect | delta chi2 | BIC penalty | CV agrees | max offset move (sigma) | admissible |",
              "|---|---|---|---|---|---|"]
        for c in st["candidates"]:
            adm = "yes" if c.get("admissible", True) else "no: " + "; ".join(c["inadmissible"])
            L.append(f"| {c['effect']} | {c['delta_chi2']:.1f} | {c['bic_penalty']:.1f} | {c['passes_cv']} | "
                     f"{c['max_offset_move_sigmas']:.1f} | {adm} |")
        L.append("")
    L += _generic_section(report)
    L += _candidates_section(report, truth)
    t = report["tracing"]
    g = report.get("generic")
    if report["verdict"] == "explained":
        where = ("Localization: none: the offsets explain these data within the declared noise (the tables below "
                 "are the residual's shares, not a finding).")
    elif g and g["explains"] and not report["selected"]:
        where = f"Localization (by the generic fit's families): {family_text(g)}."
    else:
        where = f"Localization: {where_text(t['localization'])}; channel **{t['localization']['channel']}**."
    L += ["## Tracing (offsets-only residual)", "", where, "", "| channel | chi2 / expected |", "|---|---|"]
    L += [f"| {c} | {v['ratio']:.3f} |" for c, v in t["channels"].items()]
    L += ["", "| location | delta chi2 | dof |", "|---|---|---|"]
    L += [f"| {c} | {v['delta_chi2']:.1f} | {v['dof']} |" for c, v in t["locations"].items()]
    L += ["", "![trace](trace.png)", ""]
    if walks:
        L += _walks_table(walks)
    return "\n".join(L) + "\n"


def plot(report: dict, path: Path) -> Path:
    from legcal_bench.files.plots import pyplot, save_figure

    plt = pyplot()
    cands = [c for c in report.get("candidates", []) if c.get("cv_chi2") is not None]
    cv = report["detection"].get("cross_validation", {})
    fig, axes = plt.subplots(1, 5 if len(cands) > 1 and cv.get("dof") else 4, figsize=(22, 4.4))
    tr = [("offsets only", report["tracing"])]
    if report.get("tracing_after") and report.get("selected"):  # a set-aside fit is no result: not drawn
        tr.append((f"after: {' + '.join(report['selected'])}", report["tracing_after"]))
    top: list[str] = []  # the offsets-only fit's strongest signatures, shown for both fits
    for k, (label, t) in enumerate(tr):
        w = 0.4
        for ax, key, val in ((axes[0], "channels", "ratio"), (axes[1], "stances", "ratio")):
            names = list(t[key])
            ax.bar(np.arange(len(names)) + (k - 0.5) * w, [t[key][n][val] for n in names], w, label=label)
            ax.set_xticks(np.arange(len(names)), names, rotation=40, ha="right", rotation_mode="anchor", fontsize=7)
        names = list(t["locations"])
        excess = np.array([t["locations"][n]["excess"] for n in names])
        x = np.arange(len(names)) + (k - 0.5) * w
        bars = axes[2].bar(x, np.maximum(excess, LOG_FLOOR), w, label=label)
        for b, e in zip(bars, excess):  # at or below the log axis's floor: drawn hollow, said so
            if e <= LOG_FLOOR:
                b.set_fill(False)
                b.set_hatch("//")
                axes[2].text(b.get_x() + b.get_width() / 2, LOG_FLOOR * 1.15, f"<={LOG_FLOOR:g}", ha="center",
                             fontsize=6)
        axes[2].set_xticks(np.arange(len(names)), names, rotation=20, ha="right", rotation_mode="anchor",
                           fontsize=8)
        sig = {f"{fam}: {s['joint'].replace('_joint', '')}": s["excess"] for fam, ss in t["signatures"].items()
               for s in ss}
        top = top or sorted(sig, key=lambda n: -sig[n])[:8]
        sig = [(n, sig.get(n, 0.0)) for n in top]
        axes[3].barh(np.arange(len(sig)) + (k - 0.5) * w, [max(v, 0.0) for _, v in sig], w, label=label)
        axes[3].set_yticks(np.arange(len(sig)), [n for n, _ in sig], fontsize=7)
    axes[0].axhline(1, color="k", lw=0.8, ls="--")
    axes[1].axhline(1, color="k", lw=0.8, ls="--")
    axes[0].set_title("chi2 / expected by channel", fontsize=9)
    axes[1].set_title("chi2 / expected by stance", fontsize=9)
    axes[2].set_yscale("log")
    axes[2].set_title("where: excess chi2 explained (score test)", fontsize=9)
    axes[3].set_title("signatures: excess chi2 (score test)", fontsize=9)
    if len(axes) == 5:  # the recommendation: each candidate's left-out chi2 / dof
        ax = axes[4]
        vals = [c["cv_chi2"] / cv["dof"] for c in cands]
        colors = ["tab:green" if c["recommended"] else "0.6" if c.get("set_aside") else "tab:gray" for c in cands]
        ax.barh(np.arange(len(cands)), vals, color=colors, hatch=None)
        ax.set_yticks(np.arange(len(cands)), [c["name"] + (" (set aside)" if c.get("set_aside") else "")
                                              for c in cands], fontsize=7)
        ax.invert_yaxis()
        ax.axvline(1, color="k", lw=0.8, ls="--")
        ax.set_xlim(0, 1.2 * max(vals))  # from zero: a bar's length is its value
        for i, v in enumerate(vals):
            ax.text(v, i, f" {v:.3f}", va="center", fontsize=6)
        ax.set_title("left-out chi2 / dof (green: recommended)", fontsize=9)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=7, frameon=False)  # clear of the bars
    import textwrap

    # The short verdict line (the long account is the report's): never cut, wrapped to the width.
    title = textwrap.wrap(report.get("verdict_line") or report["summary"], 150)
    fig.suptitle("\n".join(title), fontsize=9)
    fig.tight_layout(rect=(0, 0.06, 1, 1 - 0.045 * len(title)))
    return save_figure(fig, path)


LOG_FLOOR = 0.1  # the location panel's log axis starts here; an excess at or below it is drawn hollow
