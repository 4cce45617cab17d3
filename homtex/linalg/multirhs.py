"""Solving one operator for many right-hand sides at once: block AMG V-cycle and lockstep PCG.

- :class:`BatchedVCycle`: the V-cycle of an existing :class:`~homtex.linalg.solvers.ScaledAMG`
  hierarchy applied to k vectors at once, with the Chebyshev polynomial smoother pyamg set up
  (same coefficients, same Horner order, same coarse LU), so it equals pyamg's one-vector
  preconditioner to round-off.
- :func:`block_pcg`: k independent preconditioned CG recurrences in lockstep (per-column
  alpha, beta); a converged column is frozen (zeroed direction) and stops changing.
- :func:`solve_many`: what :meth:`LinearSolver.solve <homtex.linalg.solvers.LinearSolver.solve>`
  does (true-residual check, restarts, :class:`SolveReport`, :class:`SolverError`), for k cases.

The block kernels (products, updates) are in :mod:`homtex.linalg.krylov`.
"""

from __future__ import annotations

import time

import numba
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..errors import SolverError
from .krylov import BlockOperator, _cg_update, _coldot, _p_update, _row_scale
from .parallel_amg import chebyshev_coefficients
from .solvers import SolveReport, blas_single_thread, convergence_error

__all__ = ["BatchedVCycle", "block_pcg", "solve_many"]


_chebyshev_coefficients = chebyshev_coefficients


class BatchedVCycle:
    """One AMG V-cycle of a :class:`~homtex.solvers.ScaledAMG` hierarchy for k vectors.

    ``M(Rres)`` with Rres (n, k) C-contiguous returns ``D^-1/2 V(D^-1/2 Rres)`` (n, k), the
    same preconditioner as ``ScaledAMG.aspreconditioner()`` column by column (to round-off):
    Chebyshev pre/post smoothing with pyamg's coefficients (Horner form, the first
    presmoothing step starting from x = 0 as pyamg does), restriction R, the coarse LU of
    pyamg's coarse solver, prolongation P.
    """

    def __init__(self, hierarchy, degree: int | None = None):
        ml = hierarchy.ml
        deg = degree if degree is not None else getattr(hierarchy, "degree", 3)
        self.scale = np.ascontiguousarray(hierarchy.scale, dtype=float)
        self.levels = []
        for i, lvl in enumerate(ml.levels):
            rec = {"A": BlockOperator(lvl.A), "n": lvl.A.shape[0]}
            if i < len(ml.levels) - 1:
                rec["P"] = BlockOperator(lvl.P)
                rec["R"] = BlockOperator(lvl.R)
                rec["coef"] = [float(c) for c in _chebyshev_coefficients(lvl.A, deg)]
            self.levels.append(rec)
        # pyamg's coarse solver factorises lazily on its first call: trigger it, reuse its LU
        Ac = ml.levels[-1].A
        cs = ml.coarse_solver
        if not hasattr(cs, "LU"):
            cs(Ac, np.zeros(Ac.shape[0]))
        if hasattr(cs, "LU"):
            self._lu, self._map = cs.LU, sp.csr_matrix(cs.LU_Map)
        else:  # pragma: no cover - other coarse solvers
            self._lu, self._map = splu(sp.csc_matrix(Ac)), sp.identity(Ac.shape[0], format="csr")
        self._mapT = sp.csr_matrix(self._map.T)
        self._buf = {}

    def _coarse(self, b):
        y = self._lu.solve(np.ascontiguousarray(self._mapT @ b))
        return np.ascontiguousarray(self._map @ y.reshape(y.shape[0], -1))

    def _buffers(self, lvl: int, w: int) -> dict:
        """Work arrays of level ``lvl`` for blocks of width w (kept: fresh 50 MB arrays at
        1e6 DOF cost page faults on every V-cycle)."""
        key = (lvl, w)
        if key not in self._buf:
            n = self.levels[lvl]["n"]
            nc = self.levels[lvl]["R"].shape[0]
            self._buf[key] = {"x": np.empty((n, w)), "r": np.empty((n, w)),
                              "h": np.empty((n, w)), "h2": np.empty((n, w)),
                              "cb": np.empty((nc, w))}
        return self._buf[key]

    def _smooth(self, L, W, x, b, zero: bool):
        """pyamg polynomial smoother: x += p(A) (b - A x) in Horner form; from x = 0 the
        residual is b (no product), as in pyamg."""
        A, coef = L["A"], L["coef"]
        if zero:
            res = b
        else:
            res = A.gemm(x, W["r"], alpha=1.0, Z=b, s=-1.0)
        h, h2 = W["h"], W["h2"]
        np.multiply(res, coef[0], out=h)
        for c in coef[1:]:
            A.gemm(h, h2, alpha=c, Z=res, s=1.0)
            h, h2 = h2, h
        if zero:
            np.copyto(x, h)
        else:
            x += h

    def _cycle(self, lvl: int, b):
        L = self.levels[lvl]
        if lvl == len(self.levels) - 1:
            return self._coarse(b)
        W = self._buffers(lvl, b.shape[1])
        x = W["x"]
        self._smooth(L, W, x, b, zero=True)
        res = L["A"].gemm(x, W["r"], alpha=1.0, Z=b, s=-1.0)
        cb = L["R"].gemm(res, W["cb"])
        cx = self._cycle(lvl + 1, cb)
        L["P"].gemm(cx, x, alpha=1.0, Z=x, s=1.0)
        self._smooth(L, W, x, b, zero=False)
        return x

    def __call__(self, Rres: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """The preconditioner applied to Rres, (n,) or (n, k); written into ``out`` if given
        (C-contiguous (n, k)); a new array otherwise."""
        Rres = np.ascontiguousarray(Rres, dtype=float)
        one = Rres.ndim == 1
        R2 = Rres.reshape(len(Rres), -1)
        key = ("in", R2.shape[1])
        if key not in self._buf:
            self._buf[key] = np.empty_like(R2)
        b = self._buf[key]
        _row_scale(self.scale, R2, b)
        x = self._cycle(0, b)
        if out is None:
            out = np.empty_like(R2)
        _row_scale(self.scale, x, out)
        return out[:, 0] if one else out


def block_pcg(A, B, M, *, X0=None, tol: float = 1e-10, maxiter: int = 1000, names=None):
    """k independent preconditioned CG recurrences in lockstep.

    Each column runs the recurrence of :func:`homtex.solvers.pcg` (own alpha and beta);
    the sparse products and the preconditioner see all k columns at once. A converged
    column is frozen (its residual and direction are zeroed, so alpha = 0 keeps its x).

    Parameters
    ----------
    A : BlockOperator (or sparse matrix) of the SPD operator, (n, n).
    B : (n, k) right-hand sides (columns); zero columns are returned as zero.
    M : callable (n, k) -> (n, k), the preconditioner applied column by column
        (e.g. :class:`BatchedVCycle`); it must map a zero column to zero.
    X0 : (n, k) initial guesses or None (zeros).
    tol, maxiter : per column, as :func:`homtex.solvers.pcg` (recurrence residual
        ||r|| / ||b|| <= tol).
    names : labels of the columns for error messages (default "column c").

    Returns
    -------
    X (n, k) and a list of k residual histories (relative recurrence residuals; empty for
    a zero column).

    Raises
    ------
    SolverError when p^T A p <= 0 in a column (the operator is not positive definite on
    its Krylov space), naming the column, with that column's history.
    """
    Aop = A if isinstance(A, BlockOperator) else BlockOperator(A)
    B = np.ascontiguousarray(B, dtype=float)
    n, k = B.shape
    names = names or [f"column {c}" for c in range(k)]
    nb = np.sqrt(_coldot(B, B))
    live = nb > 0
    nbs = np.where(live, nb, 1.0)
    if X0 is None:
        X = np.zeros((n, k))
        Rr = B.copy()
    else:
        X = np.array(X0, dtype=float, order="C")
        Rr = Aop.gemm(X, np.empty((n, k)), alpha=1.0, Z=B, s=-1.0)
    rel = np.sqrt(_coldot(Rr, Rr)) / nbs
    hists = [[float(rel[c])] if live[c] else [] for c in range(k)]
    on = live & (rel > tol)
    if not on.any():
        return X, hists
    Rr[:, ~on] = 0.0
    reuse = isinstance(M, BatchedVCycle)
    Z = M(Rr)
    P = Z.copy()
    rz = _coldot(Rr, Z)
    AP = np.empty_like(P)
    alpha = np.zeros(k)
    beta = np.zeros(k)
    for it in range(maxiter):
        Aop.gemm(P, AP)
        pAp = _coldot(P, AP)
        bad = np.flatnonzero(on & ~(pAp > 0.0))
        if bad.size:
            c = int(bad[0])
            raise SolverError(f"non-positive curvature p^T A p = {pAp[c]:.3e} at CG iteration "
                              f"{it} in {names[c]}: the operator is not positive definite "
                              f"(unstable structure?)", history=hists[c])
        alpha[:] = 0.0
        alpha[on] = rz[on] / pAp[on]
        rel = np.sqrt(_cg_update(X, Rr, P, AP, alpha)) / nbs
        for c in np.flatnonzero(on):
            hists[c].append(float(rel[c]))
        done = on & (rel <= tol)
        if done.any():
            on &= ~done
            if not on.any():
                break
            Rr[:, done] = 0.0
            P[:, done] = 0.0
        Z = M(Rr, out=Z) if reuse else M(Rr)
        rz_new = _coldot(Rr, Z)
        beta[:] = 0.0
        beta[on] = rz_new[on] / rz[on]
        _p_update(P, Z, beta)
        rz = rz_new
    return X, hists


def solve_many(lin, B: np.ndarray, *, names=None, vcycle: BatchedVCycle | None = None,
               threads: int | None = 1):
    """Solve ``lin.A X = B`` for k right-hand sides with lockstep block PCG (AMG only).

    Columns go in groups of 6 (the width of the fast kernel; a group of 2..5 is padded with
    zero columns, which cost matrix reads but no iterations of their own).

    Parameters
    ----------
    lin : :class:`~homtex.solvers.LinearSolver` with method "amg" (its hierarchy, tol and
        maxiter are used).
    B : (k, n) right-hand sides, one per row (the layout homogenize uses).
    names : k labels for error messages (default "case q").
    vcycle : a prepared :class:`BatchedVCycle` of ``lin.ml`` (built if None).
    threads : numba threads for the kernels during the solve (None: numba's setting).
        Default 1: on the shared 2-core machine, 2 threads made the block solve 2.9x
        slower (5.9 s vs 2.0 s for 6 cases at 98k DOF, load average 3): the V-cycle runs
        many short parallel loops, and each waits for a descheduled thread.

    Returns
    -------
    X (k, n) and k :class:`~homtex.solvers.SolveReport` (solve_seconds: each case's share
    of the block solve, the block time divided by k; iterations and true residual per case).

    Raises
    ------
    SolverError as ``LinearSolver.solve`` does, naming the case.
    """
    if lin.method != "amg":
        raise ValueError(f"solve_many needs an 'amg' LinearSolver, got {lin.method!r}")
    B = np.atleast_2d(np.asarray(B, dtype=float))
    k, n = B.shape
    names = names or [f"case {q}" for q in range(k)]
    t0 = time.perf_counter()
    X = np.zeros((k, n))
    hists = [[] for _ in range(k)]
    old_threads = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    rn = np.zeros(k)
    nb = np.zeros(k)
    try:
        _solve_groups(lin, B, names, vcycle, X, hists, rn, nb)
    finally:
        numba.set_num_threads(old_threads)
    elapsed = time.perf_counter() - t0
    if not np.all(np.isfinite(X)):
        raise SolverError("amg block solve produced non-finite values "
                          "(singular or indefinite matrix?)")
    reports = []
    for q in range(k):
        rep = SolveReport(method="amg", ndof=lin.ndof, setup_seconds=lin.setup_seconds,
                          operator_complexity=lin.operator_complexity, reused_setup=lin.reused,
                          solve_seconds=elapsed / k, history=hists[q],
                          iterations=max(len(hists[q]) - 1, 0),
                          residual=float(rn[q] / nb[q]) if nb[q] > 0 else 0.0)
        _judge(rep, lin.tol, names[q])
        reports.append(rep)
    return X, reports


def _solve_groups(lin, B, names, vcycle, X, hists, rn, nb):
    """Block PCG over groups of 6 columns of B (k, n); fills X, hists, rn, nb in place."""
    k, n = B.shape
    with blas_single_thread():
        V = vcycle if vcycle is not None else BatchedVCycle(lin.ml)
        Aop = BlockOperator(lin.A)
        for g0 in range(0, k, 6):
            cols = np.arange(g0, min(k, g0 + 6))
            w = 1 if cols.size == 1 else 6
            Bg = np.zeros((n, w))
            Bg[:, :cols.size] = B[cols].T
            gn = [names[q] for q in cols] + ["padding"] * (w - cols.size)
            Xg, hg = block_pcg(Aop, Bg, V, tol=lin.tol, maxiter=lin.maxiter, names=gn)
            # restart (at most twice) from the current x when the true residual missed the
            # tolerance: the recurrence residual drifts on ill-conditioned systems
            for _ in range(2):
                Rt = Aop.gemm(Xg, np.empty_like(Bg), alpha=1.0, Z=Bg, s=-1.0)
                true = np.sqrt(_coldot(Rt, Rt)) / np.maximum(np.sqrt(_coldot(Bg, Bg)), 1e-300)
                its = np.array([max(len(h) - 1, 0) for h in hg])
                redo = (true > lin.tol) & (its < lin.maxiter) & (np.arange(w) < cols.size)
                if not redo.any():
                    break
                Br = np.where(redo, 1.0, 0.0)[None, :] * Bg
                Xr, hr = block_pcg(Aop, Br, V, X0=Xg * redo[None, :], tol=lin.tol,
                                   maxiter=int(lin.maxiter - its[redo].min()), names=gn)
                for j in np.flatnonzero(redo):
                    Xg[:, j] = Xr[:, j]
                    hg[j] = hg[j] + hr[j]
            Rt = Aop.gemm(Xg, np.empty_like(Bg), alpha=1.0, Z=Bg, s=-1.0)
            rg = np.sqrt(_coldot(Rt, Rt))
            bg = np.sqrt(_coldot(Bg, Bg))
            for j, q in enumerate(cols):
                X[q] = Xg[:, j]
                hists[q] = hg[j]
                rn[q], nb[q] = rg[j], bg[j]


def _judge(rep: SolveReport, tol: float, name: str) -> None:
    """Raise SolverError when a column missed 10 tol (the rule of LinearSolver.solve)."""
    if rep.residual > tol * 10:
        raise convergence_error(rep, tol, f"amg for {name}")
