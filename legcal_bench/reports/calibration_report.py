"""The calibration report for a robot engineer (issue #39 item 5): one folder with a
markdown page, the same page as HTML, the JSON its numbers come from, and its figures.

Sections: the summary (offsets with their posterior standard deviations, the sign
convention), the import's timeline (imported sessions), the segments used, each
recording's inter-foot spread before and after the offsets, the posterior standard
deviations and the combinations the data determine worst (named in the paper's
vocabulary), every warning with its fix, and the commands that reproduce it all.

The numbers are the result's own (`CalibrationResult`: `diagnostics["posterior"]`,
`conditioning`, `pitch_sums_rad`, `settings`, `warnings`) and the session's
(`session.json`, its `"import"` key for a log imported with `legcal-bench import`);
the one thing computed here is the spread of the inter-foot transform per recording,
from forward kinematics with the raw encoder angles and with the offsets added.
"""

from __future__ import annotations

import html
import json
import shlex
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from legcal_bench.calibrators.base import CalibrationResult
from legcal_bench.data.recording import MANIFEST, Recording, load_session
from legcal_bench.errors import ConfigError
from legcal_bench.estimation.verdict import headline
from legcal_bench.evaluation.metrics import rms
from legcal_bench.files.atomic import atomic_write_text, replace_dir
from legcal_bench.files.plots import pyplot, save_figure
from legcal_bench.files.reports import report_page, write_report
from legcal_bench.geometry.lie import Log, frechet_mean, inverse
from legcal_bench.provenance import code_version, describe
from legcal_bench.robots import load_robot
from legcal_bench.robots.design import PITCH_ROLES
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots.legmap import LegMap

SECTIONS = ("Summary", "Timeline", "Segments used", "Per-stance residuals before/after",
            "Posterior standard deviations and undetermined combinations", "Warnings and their fixes",
            "Commands to reproduce")
TIMELINE_PNG = "timeline.png"  # the import's, copied in
RESIDUALS_PNG = "residuals.png"
STD_PNG = "posterior_std.png"
WEAKEST_PNG = "weakest_combinations.png"
FIGURES = (TIMELINE_PNG, RESIDUALS_PNG, STD_PNG, WEAKEST_PNG)
CONVENTION = "q = q_enc + offset"
# A combination counts as moving a pitch sum when a unit step along it moves the sum by this much.
PITCH_SUM_SHARE = 0.5


def _short(name: str) -> str:
    return name.removesuffix("_joint")


def _deg(x: float) -> float:
    return float(np.rad2deg(x))


# ----------------------------------------------------------------------------- numbers

@dataclass
class Spread:
    """The spread of one recording's inter-foot transform about its mean (constant in
    static double support): translation RMS (mm) and rotation RMS (deg), with the raw
    encoder angles and with the offsets added."""

    name: str
    kind: str
    stance: str
    frames: int
    translation_mm_before: float
    translation_mm_after: float
    rotation_deg_before: float
    rotation_deg_after: float


def interfoot_spread(kin: LegKinematics, Q: np.ndarray) -> tuple[float, float]:
    """(translation RMS in m, rotation RMS in rad) of C = T_left^-1 T_right over the rows
    of Q about its mean: translations about their mean, rotations about the intrinsic
    (Frechet) mean's."""
    T_left, T_right = kin.sole_poses_batch(kin.joint_angles(Q))
    C = inverse(T_left) @ T_right
    p = C[:, :3, 3]
    translation = rms(np.linalg.norm(p - p.mean(axis=0), axis=1))
    rotation = rms(np.linalg.norm(Log(inverse(frechet_mean(C, tol=1e-12)) @ C)[:, 3:], axis=1))
    return translation, rotation


def spreads(kin: LegKinematics, recordings: list[Recording], dq: np.ndarray) -> list[Spread]:
    out = []
    for r in recordings:
        (tb, rb), (ta, ra) = interfoot_spread(kin, r.q_enc), interfoot_spread(kin, r.q_enc + dq)
        out.append(Spread(r.name, r.kind, r.stance, r.n_frames, 1e3 * tb, 1e3 * ta, _deg(rb), _deg(ra)))
    return out


def _leg_halves(v: np.ndarray, legmap: LegMap, signs: np.ndarray) -> str:
    """Which legs a combination moves: one leg, both alike, or the legs opposite."""
    h = legmap.n_joints // 2
    left, right = v[:h] * signs[:h], v[h:] * signs[h:]
    nl, nr = float(left @ left), float(right @ right)
    if nl < 0.1 * (nl + nr):
        return "right leg"
    if nr < 0.1 * (nl + nr):
        return "left leg"
    c = float(left @ right) / np.sqrt(nl * nr)
    return "both legs alike" if c > 0.7 else "the legs opposite" if c < -0.7 else "both legs"


def name_combination(v: np.ndarray, legmap: LegMap, kin: LegKinematics) -> str:
    """A weak combination of offsets named in the paper's vocabulary: the common pitch sum
    (the body pitching over both feet: seen through gravity only, so fixed by the IMU),
    the pitch-sum difference, the pitch-axis coupling inside the legs (Proposition 1:
    pitch sums unchanged), or a roll/yaw combination."""
    v = np.asarray(v, dtype=float)
    roles = legmap.joint_roles
    pitch = np.array([r in PITCH_ROLES for r in roles])
    psigns = kin.pitch_signs()
    h = legmap.n_joints // 2
    s_left, s_right = float(psigns[:h] @ v[:h]), float(psigns[h:] @ v[h:])
    common, diff = s_left + s_right, s_right - s_left
    legs = _leg_halves(v, legmap, kin.physical_signs())
    share = float(np.sum(v[pitch] ** 2))
    if share < 0.5:
        return (f"roll/yaw combination ({legs}): lateral; determined by hip roll and yaw excitation "
                "(the wide squat, stance IV, and sway)")
    if max(abs(common), abs(diff)) > PITCH_SUM_SHARE:
        if abs(common) >= abs(diff):
            return (f"common pitch sum s_L + s_R ({legs}): the body pitches over both feet alike, which the "
                    "inter-foot transform cannot see; the IMU (gravity, the flat-ground rows) fixes it; "
                    "without the IMU it is unobservable")
        return (f"pitch-sum difference s_R - s_L ({legs}): seen by the inter-foot rotation about the pelvis "
                "y axis")
    ph = np.abs(v) * pitch
    by_role = {r: float(np.sum(ph[[i for i, x in enumerate(roles) if x == r]] ** 2)) for r in PITCH_ROLES}
    weakest = min(by_role, key=by_role.get)
    pair = {"hip_pitch": "knee–ankle-pitch (the paper's v1 ∝ e_kn − e_ap)",
            "ankle_pitch": "hip-pitch–knee (the paper's v2 ∝ e_hp − e_kn)",
            "knee": "hip-pitch–ankle-pitch"}[weakest] if by_role[weakest] < 0.15 * share else \
        "hip-pitch / knee / ankle-pitch"
    return (f"pitch-axis coupling, {pair} ({legs}; pitch sums unchanged): the paper's near-nullspace of parallel "
            "pitch axes (Proposition 1), set by the lever arms, hip roll/yaw excitation and the knee prior "
            "(straight-leg standing)")


def undetermined(result: CalibrationResult, legmap: LegMap, kin: LegKinematics,
                 recordings: list[Recording]) -> dict:
    """What the result says the data determine worst, with names: the posterior's
    undetermined combinations, the information matrix's three weakest eigenvectors,
    exact null spaces, and the pitch sums (their std and how far the IMU's declared tilt
    bound moves them)."""
    c, d = result.conditioning, result.diagnostics
    post = d.get("posterior") if isinstance(d.get("posterior"), dict) else {}
    eig = c.get("eigenvalues_H_data") or []
    top = max(float(max(eig)), 1e-300) if eig else None
    weakest = []
    for w in c.get("weakest_H_data", []):
        v = np.asarray(w["vector"], dtype=float)
        weakest.append({"eigenvalue": float(w["eigenvalue"]),
                        "relative": float(w["eigenvalue"]) / top if top else None,
                        "combination": w["combination"], "name": name_combination(v, legmap, kin),
                        "vector": v.tolist()})
    out = {
        "posterior_undetermined": [{**u, "name": name_combination(np.asarray(u["vector"]), legmap, kin)}
                                   for u in post.get("undetermined", [])],
        "weakest_H_data": weakest,
        "unobservable_data": c.get("unobservable_data", []),
        "unobservable_reg": c.get("unobservable_reg", []),
        "pitch_sums_deg": {k: _deg(v) for k, v in result.pitch_sums_rad.items()},
        "pitch_sum_std_deg": {k: _deg(v) for k, v in post.get("pitch_sum_std_rad", {}).items()},
        "posterior_note": post.get("note") or (None if post.get("std_rad") else
                                               f"the result holds none (calibrator {result.calibrator} does not "
                                               "report a posterior)"),
    }
    response = d.get("imu_tilt_response")
    if response is not None and recordings:
        from legcal_bench.robots.kinematics import pitch_sums

        bound = recordings[0].sensor_model.tilt_bound
        R = np.asarray(response, dtype=float)
        signs = kin.pitch_signs()
        out["imu_tilt"] = {"bound_mrad": 1e3 * bound, "moves_pitch_sums_deg": {
            axis: {k: _deg(abs(v)) for k, v in pitch_sums(R[:, a] * bound, signs).items()}
            for axis, a in (("roll", 0), ("pitch", 1))},
            "moves_offsets_deg": {n: _deg(np.abs(R[i, :2]).max() * bound) for i, n in enumerate(legmap.joint_names)}}
    return out


# ----------------------------------------------------------------------------- commands

def _cmd(words: list[tuple[str, ...]]) -> str:
    """A shell command, one option per line."""
    return " \\\n    ".join(" ".join(shlex.quote(str(w)) for w in group) for group in words)


def _num(x: float) -> str:
    return f"{float(x):.10g}"


def _option_text(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple)):
        return " ".join(str(x) for x in v)
    return _num(v) if isinstance(v, float) else str(v)


def calibrate_words(result: CalibrationResult) -> tuple[list[tuple[str, ...]], str]:
    """The calibrate command's calibrator options (`--setting`, `--solver`,
    `--with-effects`, `--option k=v`) for every setting that differs from the
    calibrator's defaults; and a note on settings no option reproduces."""
    from legcal_bench.calibrators.registry import calibrator_class, get_calibrator, option_specs

    words: list[tuple[str, ...]] = [("--calibrator", result.calibrator)]
    settings = {k: v for k, v in result.settings.items() if k != "robot_spec"}
    try:
        specs = option_specs(calibrator_class(result.calibrator))
        default = get_calibrator(result.calibrator).settings()
    except Exception as e:  # noqa: BLE001 - a calibrator not installed here: its settings, as recorded
        return words, f"calibrator {result.calibrator!r} is not available here ({e}); its settings: {settings}"
    default = json.loads(json.dumps(default))  # as the result file holds them (tuples as lists)
    changed = {}
    for k, v in settings.items():
        if isinstance(v, dict) and isinstance(default.get(k), dict):
            changed.update({sk: sv for sk, sv in v.items() if default[k].get(sk) != sv})
        elif default.get(k) != v:
            changed[k] = v
    lost = []
    for k, v in changed.items():
        if specs is not None and k not in specs:
            lost.append(f"{k}={v!r}")
        elif k in ("setting", "solver"):
            words.append((f"--{k}", str(v)))
        elif k == "effects":
            if v:
                words.append(("--with-effects", *v))
        else:
            words.append(("--option", f"{k}={_option_text(v)}"))
    note = f"settings no option sets (derived, or from another version): {', '.join(lost)}" if lost else ""
    return words, note


def commands(result: CalibrationResult, manifest: dict, session_dir: Path, result_path: Path, out_dir: Path,
             robot: str) -> list[tuple[str, str]]:
    """(what, command) pairs reproducing the session (imported: `import`; simulated:
    `collect`), the calibration, the export and this report."""
    session, result_file = str(session_dir.resolve()), str(result_path.resolve())
    out = []
    imp = manifest.get("import")
    if imp:
        words = [("legcal-bench", "import"), ("--robot", robot), ("--log", *imp.get("logs", [])),
                 ("--map", imp.get("mapping", "MAPPING.yaml")), ("--out", session)]
        held = [s["name"] for s in imp.get("segments", []) if s.get("kind") == "heldout"]
        if held:
            words.append(("--heldout", *held))
        if imp.get("ranges"):
            words.append(("--ranges", *(f"{_num(a)}:{_num(b)}" for a, b in imp["ranges"])))
        out.append(("import the log (the session folder)", _cmd(words)))
    elif isinstance(manifest.get("config"), dict):
        out.append(("simulate the session", _collect_cmd(manifest["config"], session)))
    words, note = calibrate_words(result)
    out.append(("calibrate" + (f" ({note})" if note else ""),
                _cmd([("legcal-bench", "calibrate"), ("--robot", robot), ("--bags", session), *words,
                      ("--out", result_file)])))
    folder = result_path.resolve().parent
    out.append(("export the offsets (YAML in the joint names, ROS 2 parameters)",
                _cmd([("legcal-bench", "export"), ("--result", result_file), ("--out", str(folder / "offsets.yaml")),
                      ("--ros2-params", str(folder / "offsets.ros2.yaml"))])))
    out.append(("this report", _cmd([("legcal-bench", "report"), ("--robot", robot), ("--bags", session),
                                     ("--result", result_file), ("--out", str(out_dir.resolve()))])))
    return out


def _collect_cmd(cfg: dict, session: str) -> str:
    """`legcal-bench collect` from a simulated session's config (its main fields; the
    rest as recorded in session.json)."""
    words = [("legcal-bench", "collect"), ("--robot", cfg.get("robot", "a3")), ("--mode", cfg.get("mode", "weld")),
             ("--sensors", cfg.get("sensors", "realistic")), ("--seed", str(cfg.get("seed", 0))),
             ("--stances", *cfg.get("stances", ["I", "II", "III", "IV"])), ("--heldout", str(cfg.get("heldout", 3)))]
    if isinstance(cfg.get("offsets"), str):
        words.append(("--offsets", cfg["offsets"]))
    for key, opt in (("stance_s", "--stance-seconds"), ("heldout_s", "--heldout-seconds"),
                     ("standing_s", "--standing-seconds"), ("rate_hz", "--rate"), ("period_scale", "--period-scale")):
        if key in cfg:
            words.append((opt, _num(cfg[key])))
    if "knee_straight_error_rad" in cfg:
        words.append(("--knee-error-deg", _num(np.rad2deg(cfg["knee_straight_error_rad"]))))
    for key, opt in (("protocol", "--protocol"), ("contact_floor", "--floor")):
        if cfg.get(key):
            words.append((opt, str(cfg[key])))
    if cfg.get("standing", "auto") != "auto":
        words.append(("--standing", cfg["standing"]))
    for e in cfg.get("effects") or []:
        words.append(("--effect", e))
    sim = cfg.get("sim_model") or cfg.get("sim_robot")
    if sim:
        words.append(("--sim-model", sim))
    words.append(("--out", session))
    return _cmd(words)


# ----------------------------------------------------------------------------- figures

def plot_residuals(rows: list[Spread], path: Path, title: str) -> Path:
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(max(8.0, 1.3 * len(rows) + 4), 4.6))
    x = np.arange(len(rows))
    labels = [r.name + ("\n(held-out)" if r.kind == "heldout" else "\n(standing)" if r.kind == "standing" else "")
              for r in rows]
    for ax, key, unit in ((axes[0], "translation_mm", "mm"), (axes[1], "rotation_deg", "deg")):
        before = np.array([getattr(r, f"{key}_before") for r in rows])
        after = np.array([getattr(r, f"{key}_after") for r in rows])
        b1 = ax.bar(x - 0.2, before, 0.4, color="#d62728", label="raw encoders (offsets zero)")
        b2 = ax.bar(x + 0.2, after, 0.4, color="#2ca02c", label=f"calibrated ({CONVENTION})")
        for r, bar_b, bar_a in zip(rows, b1, b2):
            if r.kind == "heldout":
                bar_b.set_hatch("//")
                bar_a.set_hatch("//")
        for bars, vals in ((b1, before), (b2, after)):
            for bar, v in zip(bars, vals):
                ax.annotate(f"{v:.3g}", (bar.get_x() + bar.get_width() / 2, v), ha="center", va="bottom",
                            fontsize=7, rotation=90, xytext=(0, 2), textcoords="offset points")
        ax.set_yscale("log")
        lo, hi = max(min(before.min(), after.min()), 1e-6), max(before.max(), after.max())
        ax.set_ylim(lo / 3, hi * 6)
        ax.set_xticks(x, labels, fontsize=8)
        ax.set_ylabel(f"RMS about the recording's mean ({unit})")
        ax.set_title(f"inter-foot {'translation' if unit == 'mm' else 'rotation'} spread ({unit}, log scale)",
                     fontsize=10)
        ax.grid(True, axis="y", which="both", alpha=0.3)
    axes[0].legend(fontsize=8, loc="upper left")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


def plot_std(result: CalibrationResult, legmap: LegMap, path: Path, title: str) -> Path | None:
    post = result.diagnostics.get("posterior") or {}
    std = post.get("std_rad")
    if not std:
        return None
    names = [n for n in legmap.joint_names if n in std]
    sums = post.get("pitch_sum_std_rad", {})
    labels = [_short(n) for n in names] + [{"left": "pitch sum s_L", "right": "pitch sum s_R",
                                            "right_minus_left": "s_R - s_L"}.get(k, k) for k in sums]
    vals = np.rad2deg([std[n] for n in names] + list(sums.values()))
    colors = ["#1f77b4"] * len(names) + ["#ff7f0e"] * len(sums)
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 0.32 * len(vals) + 1.6))
    y = np.arange(len(vals))[::-1]
    finite = np.where(np.isfinite(vals), vals, 0.0)
    ax.barh(y, finite, color=colors)
    for yi, v in zip(y, vals):
        ax.annotate("unbounded" if not np.isfinite(v) else f"{v:.3g}°", (0 if not np.isfinite(v) else v, yi),
                    va="center", fontsize=7, xytext=(3, 0), textcoords="offset points")
    ax.set_yticks(y, labels, fontsize=8)
    ax.set_xlim(0, max(float(finite.max()), 1e-9) * 1.25)
    ax.set_xlabel("posterior standard deviation, 1 sigma (deg)")
    ax.set_title(title, fontsize=10)
    ax.grid(True, axis="x", alpha=0.3)
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in ("#1f77b4", "#ff7f0e")]
    ax.legend(handles, ["joint offset", "pitch sums"], fontsize=8, loc="lower right")
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


def plot_weakest(result: CalibrationResult, legmap: LegMap, path: Path, title: str) -> Path | None:
    c = result.conditioning
    eig, weakest = c.get("eigenvalues_H_data"), c.get("weakest_H_data")
    if not eig or not weakest:
        return None
    plt = pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.6), gridspec_kw={"width_ratios": [1, 2]})
    w = np.sort(np.asarray(eig, dtype=float))
    rel = np.maximum(w / max(w[-1], 1e-300), 1e-18)
    a.semilogy(np.arange(1, len(w) + 1), rel, "o-")
    for i, d in enumerate(weakest):
        a.annotate(f"D{i + 1}", (i + 1, rel[i]), fontsize=8, xytext=(5, -2), textcoords="offset points")
    a.set_xlabel("eigenvalue index (ascending)")
    a.set_ylabel("eigenvalue / largest")
    a.set_title(f"spectrum of the information matrix H_data\n(condition number {c.get('kappa_H_data', float('nan')):.3g})",
                fontsize=10)
    a.grid(True, which="both", alpha=0.3)
    names = legmap.joint_names
    x = np.arange(len(names))
    width = 0.8 / len(weakest)
    for i, d in enumerate(weakest):
        b.bar(x + (i - (len(weakest) - 1) / 2) * width, d["vector"], width,
              label=f"D{i + 1} (eigenvalue / largest {d['eigenvalue'] / max(w[-1], 1e-300):.2g})")
    b.set_xticks(x, [_short(n).replace("_", " ") for n in names], rotation=35, ha="right", fontsize=8)
    b.axhline(0, color="k", lw=0.5)
    b.set_ylabel("eigenvector component (unit vector)")
    b.set_title("the three weakest combinations of offsets", fontsize=10, pad=24)
    b.legend(fontsize=8, ncol=len(weakest), loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    b.grid(True, axis="y", alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)


# ----------------------------------------------------------------------------- markdown

def _table(header: list[str], rows: list[list]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    out += ["| " + " | ".join(str(c).replace("|", "\\|") for c in r) + " |" for r in rows]
    return out + [""]


def _summary(result: CalibrationResult, legmap: LegMap, session_dir: Path, manifest: dict, result_path: Path,
             rows: list[Spread], und: dict) -> list[str]:
    post = result.diagnostics.get("posterior") or {}
    std = post.get("std_rad", {})
    source = ("a robot log imported with `legcal-bench import`" if manifest.get("import")
              else f"a simulated session (`legcal-bench collect`, mode {manifest.get('mode', '?')})"
              if manifest.get("config") else "recordings")
    setting = result.diagnostics.get("setting") or result.settings.get("setting")
    lines = [f"**{headline(result.verdict).replace('verdict: ', 'Verdict: ', 1)}**: apply the offsets only on "
             "`apply`; on `review` look at the warnings that doubt them, on `do-not-apply` fix what the warnings "
             "that invalidate them name and calibrate again (each warning's meaning: Warnings and their fixes).", "",
             f"- robot: **{legmap.name}** (hip order {' → '.join(r.replace('hip_', '') for r in legmap.hip_order)})",
             f"- calibrator: **{result.calibrator}**" + (f", setting {setting}" if setting else "")
             + (f", {result.diagnostics['frames_used']} frames used" if "frames_used" in result.diagnostics else ""),
             f"- session: `{session_dir.resolve()}` ({source})",
             f"- result: `{result_path.resolve()}`",
             f"- sign convention: **{CONVENTION}**: add each offset to the encoder reading to get the joint angle "
             "(an encoder that reads too low by 1° has offset +1°)",
             f"- made by {describe(code_version())}", ""]
    stance = [r for r in rows if r.kind == "stance"]
    if stance:
        b = rms([r.translation_mm_before for r in stance])
        a = rms([r.translation_mm_after for r in stance])
        lines += [f"Over the {len(stance)} stances, the inter-foot translation spread goes from {b:.3g} mm (raw "
                  f"encoders) to {a:.3g} mm (calibrated) RMS.", ""]
    tilt = (und.get("imu_tilt") or {}).get("moves_offsets_deg")
    table = []
    for n in legmap.joint_names:
        s = std.get(n)
        table.append([f"`{n}`", f"{_deg(result.offsets_rad[n]):+.4f}",
                      "–" if s is None else "unbounded" if not np.isfinite(s) else f"{_deg(s):.4f}"]
                     + ([f"{tilt[n]:.3f}"] if tilt else []))
    lines += ["Offsets (degrees; ± std is the posterior standard deviation, 1 sigma, from the declared sensor noise"
              + ("; the last column is how far a fixed tilt of the IMU about the pelvis x or y axis, within its "
                 "declared bound, moves each offset: a systematic error no static level-ground data can separate "
                 "(see the pitch sums below)" if tilt else "")
              + "):", ""]
    lines += _table(["joint", "offset (deg)", "± std (deg)"] + (["± IMU tilt bound (deg)"] if tilt else []), table)
    if result.pitch_sums_rad:
        ps = post.get("pitch_sum_std_rad", {})
        lines += ["Pitch sums (hip pitch + knee + ankle pitch, in the pelvis frame's pitch sense):", ""]
        lines += _table(["pitch sum", "value (deg)", "± std (deg)"], [
            [k, f"{_deg(v):+.4f}", f"{_deg(ps[k]):.4f}" if k in ps else "–"] for k, v in result.pitch_sums_rad.items()])
    if post.get("note"):
        lines += [f"Posterior: {post['note']}.", ""]
    return lines


def _timeline(imp: dict | None, recordings: list[Recording], has_png: bool) -> list[str]:
    if not imp:
        return ["Simulated session (no log was imported): no timeline. Its segments:", ""] + _table(
            ["recording", "kind", "stance", "duration (s)", "frames"],
            [[r.name, r.kind, r.stance, f"{r.time[-1] - r.time[0]:.2f}", r.n_frames] for r in recordings])
    lines = [f"The log: {', '.join(f'`{p}`' for p in imp.get('logs', []))}, read through "
             f"`{imp.get('mapping')}`; {imp.get('duration_s', 0):.1f} s, {imp.get('frames')} frames on one clock "
             f"(the `{imp.get('clock')}` stream, stamps from {imp.get('time_source')}; gaps longer than "
             f"{imp.get('gap_tolerance_s')} s split a segment). Sensor model "
             f"{'declared' if imp.get('sensor_declared') else 'not declared (conservative bounds)'}; motion "
             f"{imp.get('declared_motion') or 'not declared (measured)'}."
             + (f" Time ranges given: {imp['ranges']}." if imp.get("ranges") else ""), ""]
    if has_png:
        lines += [f"![timeline: the traces the segments were found from, and what was taken]({TIMELINE_PNG})", ""]
    lines += ["Streams:", ""]
    lines += _table(["stream", "from", "samples", "rate (Hz)", "jitter (ms)", "duplicates", "dropped intervals"],
                    [[k, f"`{s.get('from', '')}`", s.get("samples"), f"{s.get('rate_hz', 0):.1f}",
                      f"{s.get('jitter_ms', 0):.2f}", s.get("duplicates", 0), s.get("dropped_count", 0)]
                     for k, s in imp.get("streams", {}).items()])
    gaps = imp.get("gaps") or []
    lines += (["Gaps (longer than the tolerance):", ""] + _table(
        ["stream", "from (s)", "to (s)", "length (s)"],
        [[g.get("stream"), f"{g.get('t0', 0):.2f}", f"{g.get('t1', 0):.2f}", f"{g.get('seconds', 0):.3f}"]
         for g in gaps]) if gaps else ["Gaps: none longer than the tolerance.", ""])
    lines += ["Intervals (seconds from the log's start): the segments taken, and why the rest was not:", ""]
    lines += _table(["from (s)", "to (s)", "taken", "segment / reason"],
                    [[f"{iv['t0']:.2f}", f"{iv['t1']:.2f}", "**taken**" if iv["taken"] else "–",
                      f"**{iv['segment']}** ({iv['kind']})" if iv["taken"] else iv["reason"]]
                     for iv in imp.get("intervals", [])])
    return lines


def _segments(imp: dict | None, recordings: list[Recording], result: CalibrationResult) -> list[str]:
    fit = result.diagnostics.get("segments", {})
    knee = result.diagnostics.get("knee_prior_rad") is not None
    found = {s["name"]: s for s in (imp or {}).get("segments", [])}
    rows = []
    for r in recordings:
        s = found.get(r.name, {})
        use = ("held out (scores only)" if r.kind == "heldout" else f"{fit[r.name]} frames in the fit" if r.name in fit
               else ("knee prior" if knee else "not used (no knee prior in this setting)") if r.kind == "standing"
               else "not in the fit (dropped)")
        span = f"{s['t0']:.2f}–{s['t1']:.2f}" if s else "–"
        motion = (f"{s['posture_range_m'] * 1e3:.1f} mm / {np.rad2deg(s['posture_range_rad']):.1f}°"
                  if "posture_range_m" in s else "–")
        rows.append([r.name, r.kind, r.stance, span, f"{r.time[-1] - r.time[0]:.2f}", r.n_frames, motion, use])
    return _table(["recording", "kind", "stance", "log time (s)", "duration (s)", "frames", "pelvis moves",
                   "used"], rows)


def _residuals(rows: list[Spread], has_png: bool) -> list[str]:
    lines = ["The spread of the inter-foot transform C = T_left⁻¹ T_right (forward kinematics, the right sole in "
             "the left sole's frame) about its mean over each recording: in static double support it is constant, "
             "so its spread is the offsets' signature plus noise. Before: raw encoder angles (offsets zero); "
             f"after: {CONVENTION}. Standing recordings barely move the posture, so their spread is the noise "
             "floor either way; held-out recordings were not given to the calibrator.", ""]
    lines += _table(["recording", "kind", "stance", "frames", "translation before (mm)", "after (mm)",
                     "rotation before (deg)", "after (deg)"],
                    [[r.name, "held-out" if r.kind == "heldout" else r.kind, r.stance, r.frames,
                      f"{r.translation_mm_before:.3f}", f"{r.translation_mm_after:.3f}",
                      f"{r.rotation_deg_before:.4f}", f"{r.rotation_deg_after:.4f}"] for r in rows])
    if has_png:
        lines += [f"![inter-foot spread per recording before and after]({RESIDUALS_PNG})", ""]
    return lines


def _posterior(result: CalibrationResult, und: dict, has_std: bool, has_weak: bool) -> list[str]:
    from legcal_bench.estimation.information.uncertainty import STD_LIMIT_RAD

    gls = result.diagnostics.get("generalized_least_squares") or {}
    lines = ["Standard deviations from the result's posterior (`diagnostics.posterior`): the data-only information "
             "matrix with every residual row divided by its declared noise level"
             + (" (the generalized least squares' whitened rows)" if gls.get("used") else "")
             + ", inverted to first order (frames taken as independent). They say what the noise leaves; a model "
             "error (an IMU tilt, a floor that is not flat) adds to them.", ""]
    if und.get("posterior_note"):
        lines += [f"No posterior: {und['posterior_note']}.", ""]
    if has_std:
        lines += [f"![posterior standard deviation per joint]({STD_PNG})", ""]
    limit = np.rad2deg(STD_LIMIT_RAD)
    lines += [f"**Not determined by the data** (posterior std above {limit:g}°, 1 sigma):", ""]
    if und["posterior_undetermined"]:
        lines += _table(["combination", "std (deg)", "what it is", "fix"],
                        [[u["combination"], "unbounded" if not np.isfinite(u["std_rad"]) else
                          f"{_deg(u['std_rad']):.3f}", u["name"], u["fix"]] for u in und["posterior_undetermined"]])
    elif und["posterior_note"]:
        lines += ["not known: the result holds no posterior (above)" + ("; the weakest combinations below still "
                  "rank what the data determine worst" if und["weakest_H_data"] else "") + ".", ""]
    else:
        lines += [f"none: every combination of offsets is known to better than {limit:g}° (1 sigma), as far as "
                  "the declared noise says.", ""]
    if und["unobservable_data"]:
        lines += ["**Exactly undetermined by the data** (the regulariser and priors alone pick them): "
                  + "; ".join(f"`{c}`" for c in und["unobservable_data"]), ""]
    if und["weakest_H_data"]:
        lines += ["**Weakest combinations**: the eigenvectors of the information matrix H_data (`conditioning."
                  "weakest_H_data`) with the smallest eigenvalues, named in the paper's vocabulary:", ""]
        lines += _table(["", "eigenvalue / largest", "combination (unit vector)", "what it is"],
                        [[f"D{i + 1}", f"{w['relative']:.3g}", w["combination"], w["name"]]
                         for i, w in enumerate(und["weakest_H_data"])])
        if has_weak:
            lines += [f"![eigenvalue spectrum and the three weakest combinations]({WEAKEST_PNG})", ""]
    lines += ["**The pitch sums** (hip pitch + knee + ankle pitch per leg; the paper reports them apart): their "
              "common part s_L + s_R pitches the body over both feet, which the inter-foot transform cannot see: "
              "the IMU's gravity direction (the flat-ground rows) fixes it; without the IMU it is unobservable. "
              "Their difference s_R − s_L is seen by the inter-foot rotation.", ""]
    rows = [[k, f"{v:+.4f}", f"{und['pitch_sum_std_deg'][k]:.4f}" if k in und["pitch_sum_std_deg"] else "–"]
            for k, v in und["pitch_sums_deg"].items()]
    tilt = und.get("imu_tilt")
    header = ["pitch sum", "value (deg)", "± std (deg)"]
    if tilt:
        header += ["± from the IMU tilt bound (deg)"]
        for r in rows:
            r.append(f"{max(tilt['moves_pitch_sums_deg'][a][r[0]] for a in ('roll', 'pitch')):.3f}")
    lines += _table(header, rows)
    if tilt:
        lines += [f"The IMU's declared tilt bound (mounting plus accelerometer bias over g) is ±{tilt['bound_mrad']:.2f} "
                  "mrad: a fixed tilt that size moves the pitch sums by the last column, which no static "
                  "level-ground data can tell from offsets (a systematic error, not in the std).", ""]
    return lines


def _warnings(result: CalibrationResult, imp: dict | None) -> list[str]:
    groups = [("From the import", (imp or {}).get("warnings", []) if imp else None),
              ("From the calibration", [f"*{r['meaning']}*: {r['text']}" for r in result.verdict["reasons"]])]
    lines = ["Each warning as its source wrote it, with what to do about it; a calibration warning is marked by "
             "what it means for the offsets (harmless; limits: the combinations it names are known less well; "
             "doubts: look before applying; invalidates: do not apply).", ""]
    for title, ws in groups:
        if ws is None:
            continue
        lines += [f"**{title}** ({len(ws)}):", ""]
        lines += [f"{i}. {w}" for i, w in enumerate(ws, 1)] if ws else ["none."]
        lines += [""]
    return lines


def _commands(cmds: list[tuple[str, str]]) -> list[str]:
    lines = ["Paths as on this machine; the session folder is replaced only if it holds an earlier session.", ""]
    for what, cmd in cmds:
        lines += [f"{what}:", "", "```bash", cmd, "```", ""]
    return lines


CSS = """body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1100px;margin:2em auto;
padding:0 1em;line-height:1.45;color:#222}
h1{border-bottom:2px solid #ddd;padding-bottom:.2em}h2{border-bottom:1px solid #eee;margin-top:1.8em}
table{border-collapse:collapse;margin:.6em 0;font-size:.9em}th,td{border:1px solid #ccc;padding:.25em .6em;
text-align:left}th{background:#f4f4f4}tr:nth-child(even) td{background:#fafafa}
code{background:#f4f4f4;padding:0 .2em;border-radius:3px;font-size:.92em}
pre{background:#f4f4f4;padding:.8em;overflow-x:auto;border-radius:4px}pre code{padding:0}
img{max-width:100%;border:1px solid #eee}"""


def to_html(text: str, title: str) -> str:
    import markdown

    body = markdown.markdown(text, extensions=["tables", "fenced_code"])
    return (f"<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{html.escape(title)}"
            f"</title>\n<style>\n{CSS}\n</style>\n</head>\n<body>\n{body}\n</body>\n</html>\n")


def _is_report_dir(path: Path) -> bool:
    """An earlier calibration report (which `write_calibration_report` may replace)."""
    return (report_page(path).is_file() and report_page(path).with_suffix(".html").is_file()
            and all(p.is_file() and p.suffix in (".md", ".html", ".json", ".png") for p in path.iterdir()))


def write_calibration_report(session_dir: str | Path, result_path: str | Path, out_dir: str | Path,
                             robot: str | None = None) -> Path:
    """Write the report for the session `session_dir` calibrated into `result_path`
    into the folder `out_dir` (written whole; an earlier report there is replaced):
    report.md, report.html, report.json and the figures. Returns the markdown's path."""
    session_dir, result_path, out_dir = Path(session_dir), Path(result_path), Path(out_dir)
    result = CalibrationResult.load(result_path)
    spec = robot or result.settings.get("robot_spec") or result.robot
    legmap = load_robot(spec)
    if legmap.name != result.robot:
        raise ConfigError(f"--robot {spec}: the result was calibrated for {result.robot!r}, not {legmap.name!r}; "
                          "give the robot it was calibrated for")
    recordings = load_session(session_dir, robot=legmap, allow_partial=True)
    result.check_session(recordings, f"--bags {session_dir}")
    manifest_path = session_dir / MANIFEST
    manifest = json.loads(manifest_path.read_text()) if manifest_path.is_file() else {}
    imp = manifest.get("import") if isinstance(manifest.get("import"), dict) else None
    kin = LegKinematics(legmap)
    dq = result.offsets_vector(legmap.joint_names)
    rows = spreads(kin, recordings, dq)
    und = undetermined(result, legmap, kin, recordings)
    cmds = commands(result, manifest, session_dir, result_path, out_dir, str(spec))
    timeline_png = session_dir / TIMELINE_PNG
    title = f"Calibration report: {legmap.name}, {result.calibrator}"

    def write(folder: Path) -> None:
        has_timeline = bool(imp) and timeline_png.is_file()
        if has_timeline:
            shutil.copyfile(timeline_png, folder / TIMELINE_PNG)
        plot_residuals(rows, folder / RESIDUALS_PNG, f"{legmap.name}: inter-foot spread per recording, before and "
                                                    "after the offsets")
        has_std = plot_std(result, legmap, folder / STD_PNG,
                           f"{legmap.name}: posterior standard deviations (1 sigma)") is not None
        has_weak = plot_weakest(result, legmap, folder / WEAKEST_PNG,
                                f"{legmap.name}: what the data determine worst") is not None
        parts = [f"# {title}", ""]
        sections = {
            "Summary": _summary(result, legmap, session_dir, manifest, result_path, rows, und),
            "Timeline": _timeline(imp, recordings, has_timeline),
            "Segments used": _segments(imp, recordings, result),
            "Per-stance residuals before/after": _residuals(rows, True),
            "Posterior standard deviations and undetermined combinations": _posterior(result, und, has_std, has_weak),
            "Warnings and their fixes": _warnings(result, imp),
            "Commands to reproduce": _commands(cmds),
        }
        for name in SECTIONS:
            parts += [f"## {name}", "", *sections[name]]
        text = "\n".join(parts).rstrip() + "\n"
        data = {"robot": legmap.name, "calibrator": result.calibrator, "convention": CONVENTION,
                "session": str(session_dir.resolve()), "result": str(result_path.resolve()),
                "offsets_deg": {n: _deg(result.offsets_rad[n]) for n in legmap.joint_names},
                "posterior_std_deg": {n: _deg(v) for n, v in
                                      ((result.diagnostics.get("posterior") or {}).get("std_rad") or {}).items()},
                "spreads": [asdict(r) for r in rows], "undetermined": und,
                "verdict": result.verdict,
                "warnings": {"import": (imp or {}).get("warnings", []), "calibration": result.warnings},
                "commands": [{"what": w, "command": c} for w, c in cmds], "code": code_version()}
        write_report(folder, text, json.loads(json.dumps(data, default=float)))
        atomic_write_text(report_page(folder).with_suffix(".html"), to_html(text, title))

    replace_dir(out_dir, write, keep_if=_is_report_dir)
    return report_page(out_dir)
