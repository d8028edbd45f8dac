"""Linear tests on whitened residuals (issue #17): how much of a residual a set of
columns explains, to first order about the current estimate.

With z the whitened residual (rows) and N the nuisance columns already fitted (the
offsets, the segment means), a candidate's columns C explain

    delta_chi2 = |P_[N C] z|^2 - |P_N z|^2

(Rao's score test: chi-square with rank(C after N) degrees of freedom when C is not in
the data). `chi2_after` is the residual left by a Gauss-Newton step over columns A.
Ranks are numerical, relative to the largest singular value (`RANK_RTOL`).
"""

from __future__ import annotations

import numpy as np

RANK_RTOL = 1e-8


def basis(A: np.ndarray) -> np.ndarray:
    """Orthonormal basis of span(A) (columns), rank by `RANK_RTOL`."""
    if A.shape[1] == 0:
        return A
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    return U[:, s > RANK_RTOL * s[0]] if s.size and s[0] > 0 else U[:, :0]


def chi2_after(z: np.ndarray, A: np.ndarray) -> float:
    """|z - A d|^2 at the least-squares step d."""
    Q = basis(A)
    return float(z @ z - np.sum((Q.T @ z) ** 2))


def score(z: np.ndarray, N: np.ndarray, C: np.ndarray) -> tuple[float, int]:
    """(delta_chi2, degrees of freedom) of columns C beyond the nuisance columns N."""
    Qn = basis(N)
    Cp = C - Qn @ (Qn.T @ C)
    zp = z - Qn @ (Qn.T @ z)
    Qc = basis(Cp) if np.abs(Cp).max(initial=0.0) > RANK_RTOL * max(np.abs(C).max(initial=0.0), 1e-300) \
        else Cp[:, :0]
    return float(np.sum((Qc.T @ zp) ** 2)), int(Qc.shape[1])
