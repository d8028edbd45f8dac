"""Observability of the offsets: the information matrix and its eigenstructure.

H_data = J_data^T J_data (the information matrix of the weighted data rows) and
H_reg = H_data + lambda_q diag(W_q^2) + H_mech. Condition numbers are numerical
conditioning measures, not posterior uncertainties. Eigenvectors of the smallest
eigenvalues name the offset combinations the data determine worst (the pitch sums
that orientation does see are `legcal_bench.robots.kinematics.pitch_sums`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from legcal_bench.estimation.verdict import LIMITS, Finding
from legcal_bench.files.plots import pyplot, save_figure
from legcal_bench.robots.design import PITCH_ROLES

# Relative eigenvalue below which a combination counts as undetermined.
UNOBSERVABLE_RTOL = 1e-12


def _kappa_from_eigs(w: np.ndarray) -> float:
    w = np.maximum(w, 0.0)
    return float(w[-1] / w[0]) if w[0] > 0 else float("inf")


def describe_combination(v: np.ndarray, names: list[str], tol: float = 0.15) -> str:
    terms = [(c, n) for c, n in zip(v, names) if abs(c) >= tol]
    terms.sort(key=lambda t: -abs(t[0]))
    return " ".join(f"{'+' if c > 0 else '-'} {abs(c):.2f} {n}" for c, n in terms).lstrip("+ ")


def analyze(J_data: np.ndarray, H_prior: np.ndarray, names: list[str], roles: list[str],
            J_data_projected: np.ndarray | None = None) -> dict:
    """Conditioning report for a fit. `H_prior` = lambda_q diag(W_q^2) + H_mech."""
    s = np.linalg.svd(J_data, compute_uv=False)
    H_data = J_data.T @ J_data
    H_reg = H_data + H_prior
    w_d, V_d = np.linalg.eigh(H_data)
    w_r, V_r = np.linalg.eigh(H_reg)
    pitch = [i for i, r in enumerate(roles) if r in PITCH_ROLES]
    out = {
        "kappa_J_data": float(s[0] / s[-1]) if s[-1] > 0 else float("inf"),
        "kappa_H_data": _kappa_from_eigs(w_d),
        "kappa_H_reg": _kappa_from_eigs(w_r),
        "eigenvalues_H_data": w_d.tolist(),
        "eigenvalues_H_reg": w_r.tolist(),
        "weakest_H_data": [
            {"eigenvalue": float(w_d[i]), "vector": V_d[:, i].tolist(),
             "pitch_components": {names[j]: float(V_d[j, i]) for j in pitch},
             "combination": describe_combination(V_d[:, i], names)} for i in range(3)],
        "weakest_H_reg": [
            {"eigenvalue": float(w_r[i]), "vector": V_r[:, i].tolist(),
             "pitch_components": {names[j]: float(V_r[j, i]) for j in pitch},
             "combination": describe_combination(V_r[:, i], names)} for i in range(3)],
        "rows": int(J_data.shape[0]),
    }
    if J_data_projected is not None:
        sp = np.linalg.svd(J_data_projected, compute_uv=False)
        out["kappa_J_data_mean_recomputed"] = float(sp[0] / sp[-1]) if sp[-1] > 0 else float("inf")
        out["kappa_H_data_mean_recomputed"] = out["kappa_J_data_mean_recomputed"] ** 2
    scale = max(w_d[-1], 1e-300)
    out["unobservable_data"] = [describe_combination(V_d[:, i], names)
                                for i in range(len(w_d)) if w_d[i] < UNOBSERVABLE_RTOL * scale]
    out["unobservable_reg"] = [describe_combination(V_r[:, i], names)
                               for i in range(len(w_r)) if w_r[i] < UNOBSERVABLE_RTOL * max(w_r[-1], 1e-300)]
    return out


def observability_warnings(report: dict) -> list[str]:
    msgs = []
    if report["unobservable_data"]:
        combos = "; ".join(report["unobservable_data"])
        where = ("the regulariser and priors alone pick them" if not report["unobservable_reg"]
                 else "nothing determines them")
        msgs.append(Finding(f"the data do not determine {len(report['unobservable_data'])} offset combination(s) "
                    f"({where}): {combos}. Record more varied postures (several stances with hip roll and "
                    "yaw excitation) to observe them.", LIMITS))
    return msgs


def plot_observability(report: dict, names: list[str], path: str | Path, title: str = "") -> Path:
    """Eigenvalue spectra of H_data and H_reg, and the pitch components of the three
    weakest eigenvectors of H_data (the paper's Hessian figure)."""
    plt = pyplot()
    fig, (a, b) = plt.subplots(2, 1, figsize=(7, 6.5))
    a.semilogy(range(1, 13), np.maximum(report["eigenvalues_H_data"], 1e-300), "o-", label="H_data")
    a.semilogy(range(1, 13), report["eigenvalues_H_reg"], "s--", label="H_reg")
    a.set_xlabel("eigenvalue index (ascending)")
    a.set_ylabel("eigenvalue")
    a.set_title(f"{title}  κ(H_data) = {report['kappa_H_data']:.3g}, κ(H_reg) = {report['kappa_H_reg']:.3g}")
    a.legend()
    a.grid(True, which="both", alpha=0.3)
    pitch_names = list(report["weakest_H_data"][0]["pitch_components"])
    x = np.arange(len(pitch_names))
    for i, d in enumerate(report["weakest_H_data"]):
        b.bar(x + (i - 1) * 0.27, [d["pitch_components"][n] for n in pitch_names], 0.27,
              label=f"D{i + 1} (λ = {d['eigenvalue']:.3g})")
    b.set_xticks(x, [n.replace("_joint", "").replace("_", " ") for n in pitch_names], rotation=30, ha="right")
    b.set_ylabel("eigenvector component")
    b.set_title("pitch components of the three weakest eigenvectors of H_data")
    b.axhline(0, color="k", lw=0.5)
    b.legend()
    fig.tight_layout()
    return save_figure(fig, path, dpi=110)
