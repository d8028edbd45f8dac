"""Summary statistics shared by every score and report."""

from __future__ import annotations

import numpy as np


def mean_std(values) -> dict | None:
    """{"mean", "std", "n"} of the finite values among `values` (None skipped); None if
    there are none."""
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    return {"mean": float(v.mean()), "std": float(v.std()), "n": int(v.size)} if v.size else None


def format_mean_std(s: dict | None, nd: int = 0) -> str:
    """'mean ± std' of a `mean_std` result with `nd` decimals; '–' for none."""
    return "–" if not s else f"{s['mean']:.{nd}f} ± {s['std']:.{nd}f}"


def rms(x) -> float:
    """Root mean square of all entries (NaN for an empty array)."""
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")
