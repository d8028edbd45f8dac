"""One calibration problem assembled from residual terms (the mink pattern).

A `Term` is a group of weighted residual rows over named parameter blocks; it
computes its error and its Jacobian with respect to each block it uses. A `Problem`
stacks its terms' rows in order, packs the blocks into one vector, hands residual and
Jacobian to scipy's least squares, and reports the information matrix of the shared
blocks from the data terms alone and regularized (priors added), with any per-frame
blocks eliminated (Schur complement).

Blocks are shared (one instance, e.g. the offsets) or per frame (one instance per
frame of the term set, e.g. Yamane's roll and pitch of each frame). Columns are the
shared blocks in order, then the per-frame blocks frame-major. Rows are the terms in
order; consecutive per-frame terms over the same frames are interleaved frame by frame
(frame 0 of each, then frame 1 of each, ...), which keeps each frame's rows together.
A problem with per-frame blocks has a sparse Jacobian; one without, a dense one.

A later effect (a model-gap parameter) adds a block and the terms (or Jacobian
columns) that depend on it; no calibrator needs to change.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix

from legcal_bench.errors import CalibrationError

LSMR_TOL = 1e-12  # inner (LSMR) tolerance of trust-region steps on sparse problems


@dataclass(frozen=True)
class Block:
    """A named parameter block: `size` values per instance, shared or one per frame."""

    name: str
    size: int
    per_frame: bool = False
    bound: float = np.inf  # |value| <= bound for every entry


class Term(ABC):
    """Weighted residual rows over named parameter blocks.

    `blocks` names the blocks the rows depend on. A per-frame term has `n_frames`
    (its rows come in `rows_per_frame` rows per frame, frame-major) and its Jacobian
    with respect to a per-frame block is given per frame, (n_frames, rows_per_frame,
    size); with respect to a shared block it is dense, (rows, size). `data` is False
    for priors and regularizers (they add curvature to H_reg, not information to
    H_data)."""

    name: str = ""
    blocks: tuple[str, ...] = ()
    data: bool = True
    n_frames: int | None = None
    rows_per_frame: int | None = None

    @abstractmethod
    def compute(self, x: dict[str, np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """(weighted residual rows, block name -> Jacobian) at the block values `x`
        (name -> array); error and Jacobian together, as they share most of the work."""

    def compute_error(self, x: dict[str, np.ndarray]) -> np.ndarray:
        return self.compute(x)[0]

    def compute_jacobian(self, x: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return self.compute(x)[1]


class Problem:
    """Terms over blocks, solved by scipy least squares."""

    def __init__(self, blocks: list[Block], terms: list[Term]):
        self.blocks = {b.name: b for b in blocks}
        if len(self.blocks) != len(blocks):
            raise CalibrationError("problem: block names must be distinct")
        self.terms = list(terms)
        frames = {t.n_frames for t in terms if t.n_frames is not None}
        if any(b.per_frame for b in blocks) and len(frames) != 1:
            raise CalibrationError("problem: per-frame blocks need every per-frame term over the same frames")
        self.n_frames = frames.pop() if len(frames) == 1 else 0
        self.shared = [b for b in blocks if not b.per_frame]
        self.per_frame = [b for b in blocks if b.per_frame]
        offset, self.cols = 0, {}
        for b in self.shared:
            self.cols[b.name] = offset
            offset += b.size
        self.n_shared = offset
        for b in self.per_frame:
            self.cols[b.name] = offset  # first column of frame 0; frame k adds k * frame_width
            offset += b.size
        self.frame_width = offset - self.n_shared
        self.n_params = self.n_shared + self.frame_width * self.n_frames
        self.sparse = bool(self.per_frame)
        for t in terms:
            unknown = set(t.blocks) - set(self.blocks)
            if unknown:
                raise CalibrationError(f"term {t.name!r} uses unknown blocks {sorted(unknown)}")
            if t.n_frames is None and any(self.blocks[b].per_frame for b in t.blocks):
                raise CalibrationError(f"term {t.name!r} uses a per-frame block: give it n_frames and rows_per_frame")
        self._groups = self._row_groups()
        self._cache: tuple | None = None
        self._patterns: dict = {}

    # ------------------------------------------------------------ layout
    def _row_groups(self) -> list[list[Term]]:
        """Consecutive per-frame terms form one interleaved group; others stand alone."""
        groups: list[list[Term]] = []
        for t in self.terms:
            if t.n_frames is not None and groups and groups[-1][0].n_frames is not None:
                groups[-1].append(t)
            else:
                groups.append([t])
        return groups

    def unpack(self, x: np.ndarray) -> dict[str, np.ndarray]:
        out = {b.name: x[self.cols[b.name]:self.cols[b.name] + b.size] for b in self.shared}
        if self.per_frame:
            frames = x[self.n_shared:].reshape(self.n_frames, self.frame_width)
            for b in self.per_frame:
                c = self.cols[b.name] - self.n_shared
                out[b.name] = frames[:, c:c + b.size]
        return out

    def pack(self, values: dict[str, np.ndarray]) -> np.ndarray:
        x = np.zeros(self.n_params)
        for b in self.shared:
            x[self.cols[b.name]:self.cols[b.name] + b.size] = values.get(b.name, 0.0)
        if self.per_frame:
            frames = x[self.n_shared:].reshape(self.n_frames, self.frame_width)
            for b in self.per_frame:
                c = self.cols[b.name] - self.n_shared
                frames[:, c:c + b.size] = values.get(b.name, 0.0)
        return x

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        ub = self.pack({b.name: np.full(b.size, b.bound) for b in self.blocks.values()})
        return -ub, ub

    # ------------------------------------------------------------ evaluation
    def dense(self, J: dict[str, np.ndarray], rows: int) -> np.ndarray:
        """A shared-only term's Jacobian blocks (name -> (rows, size)) as rows over every
        column."""
        Jd = np.zeros((rows, self.n_params))
        for name, Jb in J.items():
            c = self.cols[name]
            Jd[:, c:c + self.blocks[name].size] = Jb
        return Jd

    def _chunks(self, x: np.ndarray, data_only: bool) -> list[tuple]:
        """Row chunks in order: ("dense", r, J (rows, n_params)) for a shared-only term,
        ("frames", r, Bq (n, per, n_shared), Ba (n, per, frame_width)) for a group of
        per-frame terms, rows frame-major."""
        values = self.unpack(x)
        out = []
        for group in self._groups:
            group = [t for t in group if t.data or not data_only]
            if not group:
                continue
            computed = [t.compute(values) for t in group]
            if group[0].n_frames is None:
                (r, J), = computed
                out.append(("dense", r, self.dense(J, len(r))))
                continue
            n = group[0].n_frames
            widths = [t.rows_per_frame for t in group]
            per = sum(widths)
            r = np.concatenate([e.reshape(n, w) for (e, _), w in zip(computed, widths)], axis=1).ravel()
            Bq = np.zeros((n, per, self.n_shared))
            Ba = np.zeros((n, per, self.frame_width))
            # Which (rows, columns) each term fills: the sparse Jacobian stores only those.
            filled = np.zeros((per, self.n_shared + self.frame_width), dtype=bool)
            start = 0
            for (_, J), w in zip(computed, widths):
                for name, Jb in J.items():
                    b = self.blocks[name]
                    target, c = (Ba, self.cols[name] - self.n_shared) if b.per_frame else (Bq, self.cols[name])
                    target[:, start:start + w, c:c + b.size] = np.asarray(Jb).reshape(n, w, b.size)
                    filled[start:start + w, self.cols[name]:self.cols[name] + b.size] = True
                start += w
            out.append(("frames", r, Bq, Ba, filled))
        return out

    def evaluate(self, x: np.ndarray, data_only: bool = False):
        """(residual, Jacobian) at the packed vector `x`; the Jacobian is dense, or CSR
        when the problem has per-frame blocks. `data_only` keeps the data terms' rows."""
        chunks = self._chunks(x, data_only)
        r = np.concatenate([c[1] for c in chunks])
        if not self.sparse:
            return r, np.vstack([c[2] for c in chunks])
        data, ri, ci = [], [], []
        row0 = 0
        for c in chunks:
            if c[0] == "dense":  # shared columns only (checked when the problem is built)
                Jd = c[2][:, :self.n_shared]
                rr, cc = np.nonzero(np.ones_like(Jd, dtype=bool))
                data.append(Jd.ravel()), ri.append(rr + row0), ci.append(cc)
                row0 += len(Jd)
                continue
            _, _, Bq, Ba, filled = c
            n, per = Bq.shape[:2]
            fr, fc = np.nonzero(filled)  # (row in frame, column in [shared | this frame's block])
            shared = fc < self.n_shared
            rows = row0 + per * np.arange(n)[:, None] + fr[None, :]
            cols = np.where(shared, fc, fc + self.frame_width * np.arange(n)[:, None])
            vals = np.concatenate([Bq, Ba], axis=2)[:, fr, fc]
            data.append(vals.ravel()), ri.append(rows.ravel()), ci.append(cols.ravel())
            row0 += n * per
        return r, self._csr(np.concatenate(data), ri, ci, row0, data_only)

    def _csr(self, values: np.ndarray, ri: list, ci: list, n_rows: int, data_only: bool) -> csr_matrix:
        """CSR from entries in assembly order; the sparsity pattern is fixed for a problem,
        so its sort order and index arrays are computed once and reused."""
        key = (data_only, n_rows, len(values))
        if key not in self._patterns:
            rows, cols = np.concatenate(ri), np.concatenate(ci)
            order = np.lexsort((cols, rows))
            indptr = np.zeros(n_rows + 1, dtype=np.int64)
            np.add.at(indptr, rows + 1, 1)
            self._patterns[key] = (order, cols[order], np.cumsum(indptr))
        order, indices, indptr = self._patterns[key]
        return csr_matrix((values[order], indices, indptr), shape=(n_rows, self.n_params))

    # ------------------------------------------------------------ solving
    def functions(self):
        """(fun, jac) for scipy, evaluating each point once."""

        def both(x):
            if self._cache is None or not np.array_equal(self._cache[0], x):
                self._cache = (x.copy(), *self.evaluate(x))
            return self._cache[1], self._cache[2]

        return (lambda x: both(x)[0]), (lambda x: both(x)[1])

    def reset_cache(self) -> None:
        self._cache = None

    def cached_residual(self, x: np.ndarray) -> np.ndarray | None:
        """The residual at `x` if the last solve evaluated it there (else None)."""
        if self._cache is not None and np.array_equal(self._cache[0], x):
            return self._cache[1]
        return None

    def solve(self, x0: np.ndarray, method: str = "lm", tol: float = 1e-10, max_nfev: int = 100,
              jac: str = "analytic", on_jacobian=None, **kwargs):
        """scipy least squares from `x0`. `method="lm"` (MINPACK, unbounded) is re-run
        with the bounded trust-region method from its clipped answer if it leaves the
        bounds; `method="trf"` honours the bounds throughout (LSMR inner solves for
        sparse problems); `method="projected"` eliminates the per-frame blocks by variable
        projection (`_solve_projected`). `on_jacobian(x)` is called at each Jacobian
        evaluation."""
        self.reset_cache()
        fun, jac_fn = self.functions()
        lb, ub = self.bounds()
        if jac == "analytic":
            jac_arg = jac_fn if on_jacobian is None else (lambda x: (on_jacobian(x), jac_fn(x))[1])
        else:
            jac_arg = jac
        if method == "lm":
            sol = least_squares(fun, x0, jac=jac_arg, method="lm", x_scale=1.0, ftol=tol, xtol=tol, gtol=tol,
                                max_nfev=max_nfev, **kwargs)
            if np.any(sol.x < lb) or np.any(sol.x > ub):
                sol = least_squares(fun, np.clip(sol.x, lb, ub), jac=jac_arg, bounds=(lb, ub), method="trf",
                                    x_scale=1.0, ftol=tol, xtol=tol, gtol=tol, max_nfev=100, **kwargs)
            return sol
        if method == "projected":
            return self._solve_projected(x0, tol, max_nfev)
        # LSMR's default tolerances leave each trust-region step inexact, and trf then stops
        # ~1e-4 (relative) short of the optimum, at a point that moves with rounding; solved
        # to 1e-12 the answer is repeatable to ~1e-13 and comes in fewer evaluations.
        opts = dict(tr_solver="lsmr", tr_options={"atol": LSMR_TOL, "btol": LSMR_TOL}) if self.sparse else {}
        return least_squares(fun, x0, jac=jac_arg, bounds=(lb, ub), method="trf", x_scale=1.0, ftol=tol, xtol=tol,
                             gtol=tol, max_nfev=max_nfev, **{**opts, **kwargs})

    def _frame_blocks(self, x: np.ndarray):
        """Residual rows and Jacobian blocks at `x`, per frame where they have one:
        (dense rows r_d (m,), J_d (m, n_shared); frame rows r_f (n, p), Bq (n, p, n_shared),
        Ba (n, p, frame_width))."""
        chunks = self._chunks(x, data_only=False)
        dense = [c for c in chunks if c[0] == "dense"]
        frames = [c for c in chunks if c[0] == "frames"]
        n = self.n_frames
        r_f = np.concatenate([c[1].reshape(n, -1) for c in frames], axis=1)
        Bq = np.concatenate([c[2] for c in frames], axis=1)
        Ba = np.concatenate([c[3] for c in frames], axis=1)
        r_d = np.concatenate([c[1] for c in dense]) if dense else np.zeros(0)
        J_d = np.vstack([c[2][:, :self.n_shared] for c in dense]) if dense else np.zeros((0, self.n_shared))
        return r_d, J_d, r_f, Bq, Ba

    def _solve_projected(self, x0: np.ndarray, tol: float, max_nfev: int, inner_tol: float = 1e-13,
                         inner_max: int = 30):
        """Variable projection: for shared values s each frame's block a_k solves its own
        small least-squares problem (batched Gauss-Newton from the last solution); LM then
        minimizes the reduced residual r(s, a*(s)) over s alone, with the reduced Jacobian
        (I - B_k (B_k^T B_k)^-1 B_k^T) A_k per frame (Kaufman's). The optimum is the joint
        problem's; the solve is dense and small (n_shared unknowns). Bounds on the shared
        blocks are honoured by a bounded trust-region re-solve if LM leaves them."""
        from scipy.optimize import OptimizeResult

        if not self.per_frame:
            raise CalibrationError("projected solve: the problem has no per-frame block to eliminate")
        x = np.array(x0, dtype=float)
        state = {"x": x, "nfev": 0, "cache": None}

        def inner(s: np.ndarray):
            if state["cache"] is not None and np.array_equal(state["cache"][0], s):
                return state["cache"][1]
            xk = state["x"].copy()
            xk[:self.n_shared] = s
            frames = xk[self.n_shared:].reshape(self.n_frames, self.frame_width)
            for _ in range(inner_max):
                r_d, J_d, r_f, Bq, Ba = self._frame_blocks(xk)
                BaT = Ba.transpose(0, 2, 1)
                step = -np.linalg.solve(BaT @ Ba, BaT @ r_f[..., None])[..., 0]
                frames += step
                if np.abs(step).max() < inner_tol:
                    break
            r_d, J_d, r_f, Bq, Ba = self._frame_blocks(xk)
            BaT = Ba.transpose(0, 2, 1)
            G = np.linalg.solve(BaT @ Ba, BaT @ Bq)
            J_f = Bq - Ba @ G  # (n, p, n_shared): the per-frame blocks projected out
            r = np.concatenate([r_d, r_f.ravel()])
            J = np.vstack([J_d, J_f.reshape(-1, self.n_shared)])
            state["x"], state["nfev"] = xk, state["nfev"] + 1
            state["cache"] = (s.copy(), (r, J))
            return r, J

        lb, ub = (b[:self.n_shared] for b in self.bounds())
        fun, jac = (lambda s: inner(s)[0]), (lambda s: inner(s)[1])
        s0 = x[:self.n_shared]
        sol = least_squares(fun, s0, jac=jac, method="lm", x_scale=1.0, ftol=tol, xtol=tol, gtol=tol,
                            max_nfev=max_nfev)
        if np.any(sol.x < lb) or np.any(sol.x > ub):
            sol = least_squares(fun, np.clip(sol.x, lb, ub), jac=jac, bounds=(lb, ub), method="trf", x_scale=1.0,
                                ftol=tol, xtol=tol, gtol=tol, max_nfev=max_nfev)
        r, _ = inner(sol.x)
        return OptimizeResult(x=state["x"], cost=0.5 * float(r @ r), nfev=sol.nfev, status=sol.status,
                              success=sol.success, message=sol.message)

    # ------------------------------------------------------------ information
    def information(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(H_data, H_reg) on the shared blocks at `x`: J^T J of the data terms, and of
        all terms; per-frame blocks are eliminated frame by frame (Schur complement)."""
        H_data = self._shared_information(x, True)
        if all(t.data for t in self.terms):  # no priors: the two are one
            return H_data, H_data.copy()
        return H_data, self._shared_information(x, False)

    def shared_response(self, x: np.ndarray, dr: np.ndarray) -> np.ndarray:
        """(n_shared, k) how the optimum's shared blocks move, to first order, when the
        residual rows move by `dr` (rows, k) at the optimum `x`: the Gauss-Newton step
        -H^-1 g with the per-frame blocks re-optimised (eliminated frame by frame, as in
        `information`)."""
        k = dr.shape[1]
        H = np.zeros((self.n_shared, self.n_shared))
        g = np.zeros((self.n_shared, k))
        row0 = 0
        for c in self._chunks(x, data_only=False):
            if c[0] == "dense":
                Jq = c[2][:, :self.n_shared]
                H += Jq.T @ Jq
                g += Jq.T @ dr[row0:row0 + len(Jq)]
                row0 += len(Jq)
                continue
            _, _, Bq, Ba, _ = c
            n, per = Bq.shape[:2]
            d = dr[row0:row0 + n * per].reshape(n, per, k)
            row0 += n * per
            BqT, BaT = Bq.transpose(0, 2, 1), Ba.transpose(0, 2, 1)
            Hqa_Haa_inv = (BqT @ Ba) @ np.linalg.inv(BaT @ Ba)  # (n, q, a)
            H += _flat(Bq).T @ _flat(Bq) - _flat(Hqa_Haa_inv, 1).T @ _flat(BaT @ Bq)
            g += _flat(Bq).T @ _flat(d) - _flat(Hqa_Haa_inv, 1).T @ _flat(BaT @ d)
        return -np.linalg.solve(H, g)

    def _shared_information(self, x: np.ndarray, data_only: bool) -> np.ndarray:
        H = np.zeros((self.n_shared, self.n_shared))
        for c in self._chunks(x, data_only):
            if c[0] == "dense":
                Jq = c[2][:, :self.n_shared]
                H += Jq.T @ Jq
                continue
            _, _, Bq, Ba, _ = c
            BqT, BaT = Bq.transpose(0, 2, 1), Ba.transpose(0, 2, 1)
            Hqa_Haa_inv = (BqT @ Ba) @ np.linalg.inv(BaT @ Ba)  # (n, q, a)
            H += _flat(Bq).T @ _flat(Bq) - _flat(Hqa_Haa_inv, 1).T @ _flat(BaT @ Bq)
        return H


def _flat(A: np.ndarray, axis: int = 2) -> np.ndarray:
    """Per-frame blocks (n, r, c) stacked for one product over frames: sum_n A_n^T B_n =
    _flat(A).T @ _flat(B) with the rows stacked (axis 2, the default); axis 1 stacks the
    columns' transpose, sum_n A_n B_n = _flat(A, 1).T @ _flat(B)."""
    if axis == 2:
        return A.reshape(-1, A.shape[2])
    return A.transpose(0, 2, 1).reshape(-1, A.shape[1])
