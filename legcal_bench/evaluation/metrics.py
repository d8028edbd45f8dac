"""Summary statistics shared by every score and report."""

from __future__ import annotations

import numpy as np


def rms(x) -> float:
    """Root mean square of all entries (NaN for an empty array)."""
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")
