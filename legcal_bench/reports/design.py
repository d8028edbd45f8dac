"""The stance-design figure: the information's eigenvalues and the predicted standard
deviation of each offset, default stances against the designed ones."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from legcal_bench.files.plots import pyplot, save_figure


def plot_design(result: dict, robot: str, path: str | Path) -> Path:
    """`result` from `legcal_bench.estimation.information.design.design`."""
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    names = list(result["default"]["std_deg"])
    x = np.arange(len(names))
    for k, (name, colour) in enumerate((("default", "tab:gray"), ("designed", "tab:blue"))):
        s = result[name]
        ax1.semilogy(range(1, 4), s["eigenvalues"], "o-", color=colour,
                     label=f"{name} (κ {s['kappa']:.3g})")
        ax2.bar(x + (k - 0.5) * 0.4, list(s["std_deg"].values()), 0.4, color=colour, label=name)
    ax1.set_xticks([1, 2, 3])
    ax1.set_xlabel("eigenvalue rank (smallest first)")
    ax1.set_ylabel("whitened information")
    ax1.set_title(f"{robot}: smallest eigenvalues ({result['frames']} frames)")
    ax1.legend(fontsize=8)
    ax2.set_xticks(x, [n.replace("_joint", "") for n in names], rotation=70, fontsize=7)
    ax2.set_ylabel("predicted std (deg)")
    ax2.set_title("per offset")
    ax2.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)
