"""Linear tests on whitened residuals (issue #17): how much of a residual a set of
columns explains, to first order about the current estimate.

With z the whitened residual (rows) and N the nuisance columns already fitted (the
offsets, the segment means), a candidate's columns C explain

    delta_chi2 = |P_[N C] z|^2 - |P_N z|^2

(Rao's score test: chi-square with rank(C after N) degrees of freedom when C is not in
the data). `chi2_after` is the residual left by a Gauss-Newton step over columns A.
Ranks are numerical, relative to the largest singular value (`RANK_RTOL`). A candidate
can also be given a `resolution`: how well its columns are known relative to their own
size. Columns evaluated at measured angles and tilts are known only to about the
sensors' per-frame noise (rad), and combinations that are exactly collinear on noise-free
data (a twist of one leg's chain and that leg's offsets and lengths) come apart by that
much on real data, in directions made of the noise itself, which the residual shares;
`score` does not test a direction of C whose residue beyond N is below `resolution`
times C's largest singular value.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import qr_multiply

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


def score(z: np.ndarray, N: np.ndarray, C: np.ndarray, resolution: float = 0.0) -> tuple[float, int]:
    """(delta_chi2, degrees of freedom) of columns C beyond the nuisance columns N, over
    the directions of C whose residue beyond N exceeds `resolution` (relative to C's
    largest singular value; `RANK_RTOL` at least)."""
    return score_beyond(z, basis(N), C, resolution)


def score_beyond(z: np.ndarray, Qn: np.ndarray, C: np.ndarray, resolution: float = 0.0) -> tuple[float, int]:
    """`score` with the nuisance columns given by their orthonormal basis Qn (`basis`):
    many candidates tested against one nuisance share its factorization.

    The residue's singular directions come from its Householder QR, with z carried
    through the reflectors (`qr_multiply`: Q is never formed), and the SVD of the small
    triangle R: the SVD of the residue itself, computed in about 0.4x the time (the tall
    U of a direct SVD is the cost). C's largest singular value, which scales the rank
    floor, from its Gram matrix (relative error ~1e-16, far below the floor's 1e-8)."""
    if C.shape[1] == 0 or not np.abs(C).max(initial=0.0) > 0:
        return 0.0, 0
    Cp = C - Qn @ (Qn.T @ C)
    zp = z - Qn @ (Qn.T @ z)
    qz, R = qr_multiply(Cp, zp[None, :], mode="right", overwrite_a=True)
    Ur, s, _ = np.linalg.svd(R)
    floor = max(resolution, RANK_RTOL) * np.sqrt(max(float(np.linalg.eigvalsh(C.T @ C)[-1]), 0.0))
    keep = s > floor
    return float(np.sum((Ur[:, keep].T @ qz[0]) ** 2)), int(keep.sum())


def identifiable(N: np.ndarray, C: np.ndarray, rtol: float = RANK_RTOL) -> np.ndarray:
    """Indices of the columns of C that are identifiable beyond the nuisance columns N,
    jointly (FIGAROH's base parameters): a QR with column pivoting of C, each column
    scaled to unit norm and N projected out, keeps a pivot column while its residue
    beyond N and the pivots before it exceeds `rtol` of its own norm. The others are
    combinations of the kept ones and N, or too close to one to be fitted: held at zero,
    they are absorbed by the kept ones."""
    from scipy.linalg import qr

    if C.shape[1] == 0:
        return np.zeros(0, dtype=int)
    norms = np.linalg.norm(C, axis=0)
    live = np.flatnonzero(norms > 0)
    Cs = C[:, live] / norms[live]
    Qn = basis(N)
    Cp = Cs - Qn @ (Qn.T @ Cs)
    _, R, piv = qr(Cp, mode="economic", pivoting=True)
    k = int(np.sum(np.abs(np.diag(R)) > max(rtol, RANK_RTOL)))
    return np.sort(live[piv[:k]])


def forward_selection(z: np.ndarray, N: np.ndarray, C: np.ndarray, penalty: float, rtol: float = RANK_RTOL,
                      max_columns: int = 12, prefer: np.ndarray | None = None, margin: float = 0.0) -> list[int]:
    """Columns of C added one at a time, each the one that lowers |z|^2 the most beyond
    N and the columns chosen before it, while the drop exceeds `penalty` (per column: the
    BIC's ln(n_rows)); a column whose residue beyond them is below `rtol` of its own
    norm is never chosen (`identifiable`'s sense). To first order about
    the point z and the columns were taken at: the sparsest set of columns that explains
    what the whole set would, found greedily. `prefer` (bool per column) breaks ties: a
    preferred column whose drop is within `margin` of the largest is chosen over it (the
    tie itself is `substitutes`' to report)."""
    chosen: list[int] = []
    floor = max(rtol, RANK_RTOL) * np.linalg.norm(C, axis=0)
    while len(chosen) < max_columns:
        r, Cp, res, ok = _beyond(z, N, C, chosen, chosen, floor)
        if not ok.any():
            break
        gain = np.where(ok, (Cp.T @ r) ** 2 / np.where(ok, res, 1.0) ** 2, -np.inf)
        j = int(np.argmax(gain))
        if gain[j] <= penalty:
            break
        if prefer is not None and not prefer[j]:
            near = np.flatnonzero(prefer & (gain >= gain[j] - margin))
            if near.size:
                j = int(near[np.argmax(gain[near])])
        chosen.append(j)
    return chosen


def _beyond(z, N, C, kept, excluded, floor):
    """z and C beyond N and C's `kept` columns: (residual, columns' residues, their norms,
    which may be chosen: residue above `floor` (per column), not `excluded`)."""
    Q = basis(np.concatenate([N, C[:, kept]], axis=1))
    r = z - Q @ (Q.T @ z)
    Cp = C - Q @ (Q.T @ C)
    res = np.linalg.norm(Cp, axis=0)
    ok = res > floor
    ok[excluded] = False
    return r, Cp, res, ok


def substitutes(z: np.ndarray, N: np.ndarray, C: np.ndarray, chosen: list[int], margin: float,
                rtol: float = RANK_RTOL) -> list[dict]:
    """The columns of C that can stand in for one of the `chosen` (the others kept) at a
    residual within `margin` of theirs: the sparse description is then not unique. Each:
    {"column", "instead_of", "delta_chi2" (its residual minus the chosen set's, >= 0 when
    the chosen set is the better), "nuisance_shift" (N's coefficients with it minus with
    the chosen set, to first order)}. To first order about the point z and C were taken at."""
    out: list[dict] = []
    if not chosen:
        return out
    floor = max(rtol, RANK_RTOL) * np.linalg.norm(C, axis=0)

    def coefficients(cols) -> tuple[np.ndarray, float]:
        A = np.concatenate([N, C[:, cols]], axis=1)
        x, *_ = np.linalg.lstsq(A, z, rcond=None)
        return x[:N.shape[1]], float(np.sum((z - A @ x) ** 2))

    own, chi2_own = coefficients(chosen)
    for i, c in enumerate(chosen):
        rest = [k for k in chosen if k != c]
        r, Cp, res, ok = _beyond(z, N, C, rest, chosen, floor)
        chi2 = np.where(ok, r @ r - (Cp.T @ r) ** 2 / np.where(ok, res, 1.0) ** 2, np.inf)
        for j in np.flatnonzero(chi2 < chi2_own + margin):
            alt, chi2_alt = coefficients([*rest, int(j)])
            out.append({"column": int(j), "instead_of": int(c), "delta_chi2": chi2_alt - chi2_own,
                        "nuisance_shift": alt - own})
    return out
