"""Linear solvers for frame stiffness systems, with reports and failure detection.

Methods
-------
``"amg"``    pyamg smoothed aggregation (6x6 blocks, rigid-body near-null space)
             as preconditioner for CG. Default.
``"direct"`` CHOLMOD when scikit-sparse is installed, else SuperLU with a
             fill-reducing ordering (small systems; the reference in tests).
``"cg"``     Jacobi-preconditioned CG; kept to show where it fails on slender
             frames (it stalls, and that is detected and raised).

Every solve returns a :class:`SolveReport`; a solve that misses its tolerance
raises :class:`~homtex.errors.SolverError` with its residual history.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..config import _blas_controller, option
from ..errors import InputError, SolverError
from ..validate import check_int, check_tol

try:  # optional, fast sparse Cholesky
    from sksparse.cholmod import cholesky as _cholmod  # type: ignore
except Exception:  # pragma: no cover - depends on the machine
    _cholmod = None


from .amg import SINGULAR, ScaledAMG, amg_hierarchy, singular_error  # noqa: F401  (re-exported: their home was here)

METHODS = ("amg", "direct", "cg")


@dataclass
class SolveReport:
    """What a solve did: method, timings (s), iterations, the true relative residual
    ||b - A x|| / ||b|| and the normwise backward error ||b - A x|| / (||A|| ||x|| + ||b||)
    (infinity norm of A, 2-norms of vectors)."""

    method: str
    ndof: int
    setup_seconds: float = 0.0
    solve_seconds: float = 0.0
    iterations: int = 0
    residual: float = np.nan
    backward_error: float = np.nan
    operator_complexity: float = 1.0
    history: list = field(default_factory=list, repr=False)
    reused_setup: bool = False

    def as_dict(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k != "history"}


@njit(cache=True, parallel=True)
def _apply_dirichlet(indptr, indices, data, mask, diag):
    """Zero rows/columns of constrained DOFs in BSR data; put ``diag`` on their diagonal."""
    nb = indptr.size - 1
    for br in prange(nb):
        for p in range(indptr[br], indptr[br + 1]):
            bc = indices[p]
            for i in range(6):
                ri = mask[6 * br + i]
                for j in range(6):
                    if ri or mask[6 * bc + j]:
                        data[p, i, j] = diag if (br == bc and i == j) else 0.0


def constrain(K: sp.bsr_matrix, mask: np.ndarray, diag: float | None = None) -> sp.bsr_matrix:
    """A copy of K with constrained rows and columns replaced by ``diag`` * identity."""
    A = K.copy()
    if diag is None:
        d = K.diagonal()
        free = d[~mask]
        diag = float(np.mean(free)) if free.size else 1.0
    if mask.any():
        _apply_dirichlet(A.indptr, A.indices, A.data, mask.astype(np.bool_), diag)
    return A


def blas_single_thread():
    """A context limiting BLAS to one thread: BLAS threads inside small dot products slow AMG setup
    and CG many times over. The controller is made once (making one per call, as
    ``threadpool_limits`` does, cost 0.37 ms, up to 45 % of a small contact solve; reusing it 0.01 ms)."""
    return _blas_controller().limit(limits=1, user_api="blas")


def pcg(A, b, M, *, x0=None, tol: float = 1e-10, maxiter: int = 1000):
    """Preconditioned conjugate gradients; returns (x, relative residual history).

    The recurrence residual ||r_k|| / ||b|| is recorded every iteration at no extra cost
    (for stall reports). A non-positive curvature p^T A p <= 0 means A is not positive
    definite on the Krylov space (an unstable structure or a bad constraint): it raises.
    Measured: pyamg.krylov.cg diverged on a slender tower (cond ~ 1e8) where this loop and
    scipy's cg converge in 26 iterations with the same preconditioner.
    """
    nb = float(np.linalg.norm(b))
    x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=float)
    r = b - A @ x if x0 is not None else b.copy()
    hist = [float(np.linalg.norm(r)) / nb]
    if hist[0] <= tol:
        return x, hist
    z = M @ r
    p = z.copy()
    rz = float(r @ z)
    for it in range(maxiter):
        Ap = A @ p
        pAp = float(p @ Ap)
        if not pAp > 0.0:
            raise SolverError(f"non-positive curvature p^T A p = {pAp:.3e} at CG iteration {it}: "
                              f"the operator is not positive definite (unstable structure?)",
                              history=hist)
        alpha = rz / pAp
        x += alpha * p
        r -= alpha * Ap
        hist.append(float(np.linalg.norm(r)) / nb)
        if hist[-1] <= tol:
            break
        z = M @ r
        rz_new = float(r @ z)
        p *= rz_new / rz
        p += z
        rz = rz_new
    return x, hist


class LinearSolver:
    """Solves A x = b for one operator, many right-hand sides, setup once.

    Parameters
    ----------
    A : sparse SPD matrix (BSR 6x6 preferred)
    method : "amg" | "direct" | "cg"
    B : (ndof, 6) near-null space for AMG (rigid-body modes)
    tol : relative residual ||b - A x|| / ||b|| to reach
    maxiter : CG iteration limit (default 1000 for amg, 5000 for cg)
    hierarchy : a :class:`ScaledAMG` to reuse (built for a nearby operator; CG runs on A)
    cycle : "numba" (the V-cycle applied directly with parallel numba kernels,
        :mod:`homtex.linalg.parallel_amg`), "pyamg", or "gpu" (:mod:`homtex.linalg.gpu`, CuPy)
        (default: option ``amg_cycle``)
    precision : "float64" or "float32" level matrices in the numba V-cycle (option ``amg_precision``)
    node_graph : node graph aggregated on the finest level (see :class:`ScaledAMG`)
    """

    def __init__(self, A, *, method: str = "amg", B=None, tol: float | None = None,
                 maxiter: int | None = None, hierarchy=None, cycle: str | None = None,
                 precision: str | None = None, node_graph=None):
        if method not in METHODS:
            raise InputError(f"solver must be one of {METHODS}, got {method!r}")
        self.A = A
        self.method = method
        self.tol = check_tol(option("tol", tol))
        self.maxiter = (1000 if method == "amg" else 5000) if maxiter is None else check_int(maxiter, "maxiter", ge=1)
        self.ndof = A.shape[0]
        # infinity norm of A: the scale of the backward error
        self.anorm = float(abs(sp.csr_matrix(A)).sum(axis=1).max()) if A.shape[0] else 0.0
        self.operator_complexity = 1.0
        self.reused = hierarchy is not None
        t0 = time.perf_counter()
        with blas_single_thread():
            if method == "amg":
                # a reused hierarchy (built for a nearby operator) is still a valid SPD
                # preconditioner; CG runs on the new A, so the answer stays exact
                self._cache = None
                if hierarchy is None and option("amg_reuse"):
                    from .reuse import CACHE

                    hierarchy, self.reused = CACHE.get(A, B, node_graph=node_graph)
                    self._cache = CACHE
                self.ml = hierarchy if hierarchy is not None else amg_hierarchy(A, B, node_graph=node_graph)
                self.M = self.ml.aspreconditioner(cycle="V")
                self.operator_complexity = float(self.ml.operator_complexity())
                self.cycle = option("amg_cycle", cycle)
                if self.cycle == "gpu":
                    from .gpu import DeviceAMG

                    self.device = DeviceAMG(self.ml, A, device="gpu",
                                            precision=option("amg_precision", precision))
                elif self.cycle == "numba":
                    from .parallel_amg import BSROperator, VCycle

                    self.vcycle = VCycle(self.ml, precision=option("amg_precision", precision))
                    self.Aop = BSROperator(A if isinstance(A, sp.bsr_matrix) else sp.csr_matrix(A))
            elif method == "cg":
                d = A.diagonal()
                inv = 1.0 / d
                self.M = sp.diags(inv)
            else:
                if _cholmod is not None:
                    try:
                        self.factor = _cholmod(sp.csc_matrix(A))
                    except Exception as err:  # CholmodNotPositiveDefiniteError and kin
                        raise SolverError(f"CHOLMOD factorisation failed ({err}): the matrix is singular "
                                          f"or not positive definite") from err
                    self.backend = "cholmod"
                else:
                    from scipy.sparse.linalg import splu
                    # SymmetricMode + no pivoting keeps the symmetric minimum-degree ordering
                    # (measured 100x faster than the default on a 17k-DOF lattice)
                    try:
                        self.factor = splu(sp.csc_matrix(A), permc_spec="MMD_AT_PLUS_A",
                                           diag_pivot_thresh=0.0, options={"SymmetricMode": True})
                    except RuntimeError as err:   # "Factor is exactly singular"
                        raise singular_error("direct (superlu)", err) from err
                    self.backend = "superlu"
        self.setup_seconds = time.perf_counter() - t0

    def solve(self, b, x0=None) -> tuple[np.ndarray, SolveReport]:
        """x with A x = b and its :class:`SolveReport`.

        The right-hand side is scaled to unit size first (the problem is linear), so loads of
        any magnitude that double precision holds solve alike (1e-300 N and 1e300 N). The
        solve is accepted when the true relative residual meets the tolerance, or else when
        the normwise backward error does (``tol`` for iterative solves, 1e-12 for the direct
        one): near condition 1e10 (slender yarns, stiff/soft contrasts) the relative residual
        cannot reach 1e-10 in double precision, while an answer with a backward error of
        round-off is the exact answer of a system within round-off of the given one. A
        non-finite right-hand side, solution or residual raises.
        """
        b = np.asarray(b, dtype=float)
        rep = SolveReport(method=self.method, ndof=self.ndof, setup_seconds=self.setup_seconds,
                          operator_complexity=self.operator_complexity, reused_setup=self.reused)
        if not np.all(np.isfinite(b)):
            raise SolverError("the right-hand side (loads) is not finite", report=rep)
        scale = float(np.abs(b).max()) if b.size else 0.0
        if scale == 0.0:
            rep.residual = rep.backward_error = 0.0
            return np.zeros_like(b), rep
        bs = b / scale
        nb = float(np.linalg.norm(bs))
        t0 = time.perf_counter()
        with blas_single_thread():
            if self.method == "direct":
                xs = self.factor(bs) if self.backend == "cholmod" else self.factor.solve(bs)
                rep.method = f"direct ({self.backend})"
            else:
                try:
                    xs = self._iterate(bs, None if x0 is None else np.asarray(x0, dtype=float) / scale, nb, rep)
                except RuntimeError as err:   # a factorisation inside the preconditioner (a foreign hierarchy)
                    if isinstance(err, SolverError):
                        raise
                    raise singular_error(self.method, err, coarse=self.method == "amg") from err
        rep.solve_seconds = time.perf_counter() - t0
        if getattr(self, "_cache", None) is not None:
            self._cache.record(self.A, rep.iterations, rep.solve_seconds)
        if not np.all(np.isfinite(xs)):
            raise SolverError(f"{rep.method} solve produced non-finite values "
                              f"(singular or indefinite matrix?)", history=rep.history, report=rep)
        r = bs - self.A @ xs
        nr = float(np.linalg.norm(r))
        rep.residual = nr / nb
        rep.backward_error = nr / (self.anorm * float(np.linalg.norm(xs)) + nb)
        if not (np.isfinite(rep.residual) and np.isfinite(rep.backward_error)):
            raise SolverError(f"{rep.method} solve: the residual is not finite", history=rep.history, report=rep)
        limit = self.tol * 10 if self.method != "direct" else max(self.tol, 1e-8)
        eta_limit = self.tol if self.method != "direct" else max(self.tol, 1e-12)
        if rep.residual > limit and rep.backward_error > eta_limit:
            raise convergence_error(rep, self.tol, rep.method)
        with np.errstate(over="ignore"):
            x = xs * scale
        if not np.all(np.isfinite(x)):
            raise SolverError(f"{rep.method} solve: the solution overflows double precision (loads of "
                              f"{scale:.3g} on this structure)", report=rep)
        return x, rep

    def _iterate(self, bs, x0, nb, rep):
        """Preconditioned CG on the scaled right-hand side, restarted from the current x (at most
        twice) while the true residual misses both criteria although the recurrence met them."""
        if getattr(self, "cycle", None) == "gpu":
            xp = self.device.xp

            def run(x_start, maxiter):
                x, h = self.device.pcg(xp.asarray(bs), x0=None if x_start is None else xp.asarray(x_start),
                                       tol=self.tol, maxiter=maxiter)
                return xp.asnumpy(x), h
        elif getattr(self, "cycle", None) == "numba":
            import numba

            from .parallel_amg import cg_threads
            from .parallel_amg import pcg as fast_pcg

            def run(x_start, maxiter):
                old = numba.get_num_threads()
                numba.set_num_threads(cg_threads(option("amg_threads")))
                try:
                    return fast_pcg(self.Aop, bs, self.vcycle, x0=x_start, tol=self.tol, maxiter=maxiter)
                finally:
                    numba.set_num_threads(old)
        else:
            def run(x_start, maxiter):
                return pcg(self.A, bs, self.M, x0=x_start, tol=self.tol, maxiter=maxiter)
        xs, hist = run(x0, self.maxiter)
        for _ in range(2):
            nr = float(np.linalg.norm(bs - self.A @ xs))
            eta = nr / (self.anorm * float(np.linalg.norm(xs)) + nb)
            if nr / nb <= self.tol or eta <= self.tol or len(hist) - 1 >= self.maxiter:
                break
            xs, more = run(xs, self.maxiter - len(hist) + 1)
            hist += more
        rep.history = hist
        rep.iterations = len(hist) - 1
        return xs

    def refine(self, b, x) -> tuple[np.ndarray, float]:
        """One step of iterative refinement with the direct factor: returns (x + dx, ||dx||/||x||).

        The relative correction estimates the forward error, which the residual check in
        :meth:`solve` cannot see on an ill-conditioned system (its backward error stays small).
        """
        if self.method != "direct":
            raise ValueError("refine() needs method='direct'")
        r = np.asarray(b, dtype=float) - self.A @ x
        with blas_single_thread():
            dx = self.factor(r) if self.backend == "cholmod" else self.factor.solve(r)
        return x + dx, float(np.linalg.norm(dx) / max(np.linalg.norm(x), 1e-300))


def convergence_error(rep: SolveReport, tol: float, label: str) -> SolverError:
    """The SolverError for a solve that missed ``tol``: residual, iterations and, from the
    residual history, whether it stalled, still falls, or is too ill-conditioned."""
    h = rep.history
    msg = (f"{label} did not converge: true relative residual {rep.residual:.3e} and backward error "
           f"{rep.backward_error:.3e} > tolerance {tol:.1e} after {rep.iterations} iterations")
    if h and h[-1] <= tol:
        msg += ("; the CG recurrence reached the tolerance but the true residual did not "
                "follow after restarts: the system is too ill-conditioned for this "
                "tolerance (loosen tol or use solver='direct')")
    elif len(h) > 50:
        drop = h[-51] / max(h[-1], 1e-300)
        msg += (f"; stalled: the last 50 iterations reduced the residual "
                f"by a factor of only {drop:.3g}" if drop < 10 else
                f"; the residual still falls (x{drop:.3g} per 50 iterations): raise maxiter")
    return SolverError(msg, history=h, report=rep)


def solve(A, b, *, method="amg", B=None, tol=None, maxiter=None):
    """One-shot solve: returns (x, report)."""
    return LinearSolver(A, method=method, B=B, tol=tol, maxiter=maxiter).solve(b)
