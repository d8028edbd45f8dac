"""Figures: one headless matplotlib set-up and one atomic, deterministic PNG save."""

from __future__ import annotations

from pathlib import Path

from legcal_bench.files.atomic import atomic_write


def pyplot():
    """matplotlib.pyplot on the headless Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: str | Path, dpi: int = 100) -> Path:
    """Write `fig` as a PNG atomically (no software stamp, so the same figure gives the
    same bytes) and close it."""
    path = Path(path)
    atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=dpi, metadata={"Software": None}), mode="wb")
    pyplot().close(fig)
    return path
