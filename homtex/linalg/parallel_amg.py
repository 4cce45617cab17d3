"""The AMG-CG phase on every core: a directly applied V-cycle and PCG from numba kernels.

- :func:`sa_levels`: smoothed-aggregation setup of the scaled operator (pyamg's strength,
  aggregation and tentative prolongator; the Jacobi prolongation smoother and the Chebyshev
  bounds from :func:`spectral_radius`, a short Lanczos run on the numba products, instead of
  pyamg's restarted Arnoldi, which took 33 of the 40 s of a 4e5-DOF setup here). Returns a pyamg
  ``MultilevelSolver`` (with ``A.rho`` set on every level), so pyamg's own cycle and
  :class:`~homtex.linalg.multirhs.BatchedVCycle` work on it unchanged.
- :class:`VCycle`: the V-cycle of a :class:`~homtex.linalg.solvers.ScaledAMG` hierarchy for one
  vector, applied directly (no residual products of pyamg's ``aspreconditioner``): Chebyshev
  smoothing in Horner form with the residual fused into the product, restriction, coarse LU,
  prolongation; level matrices in float64 or float32 (``precision``; sums in float64).
- :func:`pcg`: preconditioned CG with the products and updates fused (p^T A p with A p, the
  residual norm with the update, r^T z with the diagonal scaling of the V-cycle).

Every kernel runs on numba's threads where the level is large enough
(:data:`homtex.linalg.kernels.PARALLEL_MIN_ROWS`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import SolverError
from . import kernels as K

__all__ = ["BSROperator", "VCycle", "cg_threads", "pcg", "sa_levels", "spectral_radius"]


def cg_threads(requested=None) -> int:
    """numba threads for a CG phase: ``requested`` if given, else numba's setting, cut to 1 when
    the 1-minute load average says the other cores are busy (load > cores - 0.5).

    Measured on the shared 2-core EPYC at load 4.7-6.2 (other engineers' jobs on both cores), a
    9.3e4-DOF octet block to 1e-8: 1 thread 1.04 s CPU / 4.1 s wall, 2 threads 3.5 s CPU / 7.9 s
    wall (threads wait at every kernel's barrier for a descheduled partner; OpenMP spins)."""
    import os

    import numba

    if requested is not None:
        return max(1, min(int(requested), numba.config.NUMBA_NUM_THREADS))
    n = numba.get_num_threads()
    if n > 1:
        try:
            load = os.getloadavg()[0]
        except OSError:  # pragma: no cover - no load average on this platform
            return n
        if load > (os.cpu_count() or n) - 0.5:
            return 1
    return n


def chebyshev_coefficients(A, degree: int) -> np.ndarray:
    """pyamg's Chebyshev smoother coefficients for level matrix A (its cached rho): bounds rho/30
    and 1.1 rho, the constant coefficient dropped (pyamg's setup_chebyshev)."""
    from pyamg.relaxation.chebyshev import chebyshev_polynomial_coefficients
    from pyamg.util.linalg import approximate_spectral_radius

    rho = approximate_spectral_radius(A)  # cached on A by pyamg's own smoother setup (A.rho)
    return -chebyshev_polynomial_coefficients(rho / 30.0, rho * 1.1, degree)[:-1]


class BSROperator:
    """A BSR matrix prepared for the one-vector kernels: ``op.apply(x, y, alpha=0, z=None, s=1)``
    writes y = alpha z + s A x (float64 vectors); ``op.dot_apply(x, y)`` writes y = A x and returns
    x . y (6x6 blocks). ``precision`` "float32" stores the values in single precision."""

    def __init__(self, M, precision: str = "float64", parallel: bool = True):
        if not isinstance(M, (sp.bsr_matrix, sp.bsr_array)):
            M = sp.bsr_matrix(sp.csr_matrix(M), blocksize=(1, 1))
        M.sort_indices()
        self.shape = M.shape
        self.indptr = np.ascontiguousarray(M.indptr, dtype=np.int64)
        self.indices = np.ascontiguousarray(M.indices, dtype=np.int64)
        self.data = np.ascontiguousarray(M.data, dtype=np.float32 if precision == "float32" else np.float64)
        self.blocks66 = self.data.shape[1:] == (6, 6)
        self.nbytes = self.data.nbytes + self.indices.nbytes + self.indptr.nbytes
        n = self.shape[0]
        self._k = K.pick("bsr66" if self.blocks66 else "bsr", n, parallel)
        self._kd = K.pick("bsr66_dot", n, parallel) if self.blocks66 else None

    def apply(self, x, y, alpha: float = 0.0, z=None, s: float = 1.0):
        self._k(self.indptr, self.indices, self.data, x, y if z is None else z, float(alpha), float(s), y)
        return y

    def dot_apply(self, x, y) -> float:
        if self._kd is None:
            self.apply(x, y)
            return float(x @ y)
        return self._kd(self.indptr, self.indices, self.data, x, y)

    def __matmul__(self, x):
        y = np.empty(self.shape[0])
        return self.apply(np.ascontiguousarray(x, dtype=float), y)


def spectral_radius(A, steps: int = 20, seed: int = 0, parallel: bool = True) -> float:
    """Largest eigenvalue of a symmetric positive (semi-)definite matrix by ``steps`` Lanczos
    steps (no reorthogonalisation; the largest Ritz value converges first), times 1.01 to cover
    what is left (a lower bound otherwise). Products: :class:`BSROperator` (numba threads)."""
    op = A if isinstance(A, BSROperator) else BSROperator(A, parallel=parallel)
    n = op.shape[0]
    if n <= 40:
        M = (A if not isinstance(A, BSROperator) else None)
        if M is not None:
            return float(np.linalg.eigvalsh(M.toarray()).max())
    rng = np.random.default_rng(seed)
    v = rng.random(n) - 0.5
    v /= np.linalg.norm(v)
    v_old = np.zeros(n)
    w = np.empty(n)
    alphas, betas = [], []
    beta = 0.0
    for _ in range(min(steps, n)):
        a = op.dot_apply(v, w)
        alphas.append(a)
        w -= a * v
        w -= beta * v_old
        beta = float(np.linalg.norm(w))
        if beta <= 1e-14 * abs(a):
            break
        betas.append(beta)
        v_old, v = v, w / beta
        w = np.empty(n)
    m = len(alphas)
    T = np.diag(alphas) + np.diag(betas[:m - 1], 1) + np.diag(betas[:m - 1], -1)
    return 1.01 * float(np.linalg.eigvalsh(T).max())


def sa_levels(As, B, *, max_coarse: int = 3000, max_levels: int = 10, omega: float = 4.0 / 3.0,
              degree: int = 3, parallel: bool = True, strength0=None):
    """Smoothed-aggregation hierarchy of the scaled SPD operator ``As`` (unit diagonal, BSR 6x6)
    with near-null space ``B`` (n, 6): pyamg's symmetric strength (theta 0), standard
    aggregation and tentative prolongator; one Jacobi step P = (I - omega/rho D^-1 A) T with rho
    from :func:`spectral_radius`; Galerkin A_c = P^T A P; Chebyshev pre/post smoothers of
    ``degree`` (bounds rho/30, 1.1 rho as pyamg); coarse grid at most ``max_coarse`` unknowns,
    solved by SuperLU. ``strength0``: a node graph (nb, nb) sparse, used instead of the strength of
    the finest level (contact systems: the beam elements only, so no aggregate spans two yarns
    and each yarn keeps its own rigid-body modes on the coarse grid). Returns a pyamg
    ``MultilevelSolver``."""
    from pyamg.aggregation.aggregate import standard_aggregation
    from pyamg.aggregation.tentative import fit_candidates
    from pyamg.multilevel import MultilevelSolver
    from pyamg.relaxation.smoothing import change_smoothers
    from pyamg.strength import symmetric_strength_of_connection

    levels = []
    A = As
    A.symmetry = "symmetric"
    Bc = np.asarray(B, dtype=float)
    while True:
        lvl = MultilevelSolver.Level()
        lvl.A, lvl.B = A, Bc
        levels.append(lvl)
        bs = A.blocksize[0] if isinstance(A, (sp.bsr_matrix, sp.bsr_array)) else 1
        op = BSROperator(A, parallel=parallel)
        d = A.diagonal()
        dinv_sqrt = 1.0 / np.sqrt(np.where(d > 0, d, 1.0))
        # rho of D^-1 A equals that of D^-1/2 A D^-1/2 (similar matrices): the latter is symmetric
        if A.shape[0] // bs <= max(1, max_coarse // bs) or len(levels) >= max_levels:
            A.rho = spectral_radius(op, parallel=parallel)
            break
        Ds = sp.diags(dinv_sqrt)
        rho_dinv = spectral_radius(BSROperator(sp.bsr_matrix(Ds @ A @ Ds, blocksize=A.blocksize),
                                               parallel=parallel), parallel=parallel)
        A.rho = spectral_radius(op, parallel=parallel) if np.ptp(d) > 1e-12 * d.max() else rho_dinv
        if strength0 is not None and len(levels) == 1:
            C = sp.csr_matrix(strength0, dtype=float)
            C.data[:] = 1.0
        else:
            C = symmetric_strength_of_connection(A, theta=0.0)
        AggOp, _ = standard_aggregation(C)
        T, Bc = fit_candidates(AggOp, Bc)
        Dinv = sp.diags(1.0 / np.where(d > 0, d, 1.0))
        P = T - (omega / rho_dinv) * (Dinv @ (A @ T))
        P = sp.bsr_matrix(P, blocksize=T.blocksize)
        R = sp.bsr_matrix(P.T, blocksize=(T.blocksize[1], T.blocksize[0]))
        lvl.P, lvl.R = P, R
        Ac = sp.bsr_matrix(R @ (A @ P), blocksize=(T.blocksize[1], T.blocksize[1]))
        Ac.sort_indices()
        Ac.symmetry = "symmetric"
        A = Ac
    ml = MultilevelSolver(levels, coarse_solver="splu")
    cheb = ("chebyshev", {"degree": degree})
    change_smoothers(ml, cheb, cheb)
    return ml


class VCycle:
    """One V-cycle of a :class:`~homtex.linalg.solvers.ScaledAMG` hierarchy for one vector:
    ``M.apply(r, z)`` writes z = D^-1/2 V(D^-1/2 r) and returns r . z. The same preconditioner as
    ``ScaledAMG.aspreconditioner()`` (pyamg's coefficients and Horner order, its coarse LU) to
    round-off, or, with ``precision="float32"``, the level matrices rounded to single precision
    (still SPD; CG stays in float64 on the unscaled operator, so the answer keeps its accuracy)."""

    def __init__(self, hierarchy, precision: str = "float64", parallel: bool = True):
        ml = hierarchy.ml
        deg = getattr(hierarchy, "degree", 3)
        self.scale = np.ascontiguousarray(hierarchy.scale, dtype=float)
        self.n = self.scale.size
        self.parallel = parallel
        self.levels = []
        for i, lvl in enumerate(ml.levels):
            n = lvl.A.shape[0]
            rec = {"n": n}
            if i < len(ml.levels) - 1:
                rec["A"] = BSROperator(lvl.A, precision, parallel)
                rec["P"] = BSROperator(lvl.P, precision, parallel)
                rec["R"] = BSROperator(lvl.R, precision, parallel)
                rec["coef"] = [float(c) for c in chebyshev_coefficients(lvl.A, deg)]
                nc = lvl.R.shape[0]
                rec.update(x=np.empty(n), r=np.empty(n), h=np.empty(n), h2=np.empty(n), cb=np.empty(nc))
            self.levels.append(rec)
        cs = ml.coarse_solver
        Ac = ml.levels[-1].A
        if not hasattr(cs, "LU"):
            cs(Ac, np.zeros(Ac.shape[0]))
        if hasattr(cs, "LU"):
            self._lu, self._map = cs.LU, sp.csr_matrix(cs.LU_Map)
        else:  # pragma: no cover - other coarse solvers
            self._lu, self._map = sp.linalg.splu(sp.csc_matrix(Ac)), sp.identity(Ac.shape[0], format="csr")
        self._mapT = sp.csr_matrix(self._map.T)
        self._b0 = np.empty(self.n)
        self._scale_dot = K.pick("scale_dot", self.n, parallel)
        self._scale = K.pick("scale", self.n, parallel)
        self.nbytes = sum(L[k].nbytes for L in self.levels[:-1] for k in ("A", "P", "R"))

    def _coarse(self, b):
        return self._map @ self._lu.solve(self._mapT @ b)

    def _smooth(self, L, x, b, zero: bool):
        A, coef, h, h2 = L["A"], L["coef"], L["h"], L["h2"]
        if zero:
            res = b
        else:
            res = A.apply(x, L["r"], alpha=1.0, z=b, s=-1.0)
        np.multiply(res, coef[0], out=h)
        for c in coef[1:]:
            A.apply(h, h2, alpha=c, z=res, s=1.0)
            h, h2 = h2, h
        if zero:
            x[:] = h
        else:
            K.pick("axpy", x.size, self.parallel)(1.0, h, x)

    def _cycle(self, i: int, b):
        if i == len(self.levels) - 1:
            return self._coarse(b)
        L = self.levels[i]
        x = L["x"]
        self._smooth(L, x, b, zero=True)
        res = L["A"].apply(x, L["r"], alpha=1.0, z=b, s=-1.0)
        cb = L["R"].apply(res, L["cb"])
        cx = np.ascontiguousarray(self._cycle(i + 1, cb))
        L["P"].apply(cx, x, alpha=1.0, z=x, s=1.0)
        self._smooth(L, x, b, zero=False)
        return x

    def apply(self, r: np.ndarray, z: np.ndarray) -> float:
        """z = M r (both (n,) float64); returns r . z."""
        self._scale(self.scale, r, self._b0)
        x = self._cycle(0, self._b0)
        return self._scale_dot(self.scale, x, z, r)

    def __call__(self, r):
        z = np.empty(self.n)
        self.apply(np.ascontiguousarray(r, dtype=float), z)
        return z


def pcg(A: BSROperator, b, M: VCycle, *, x0=None, tol: float = 1e-10, maxiter: int = 1000):
    """Preconditioned CG, the recurrence of :func:`homtex.linalg.solvers.pcg` (relative recurrence
    residual history; p^T A p <= 0 raises SolverError) on fused numba kernels; (x, history)."""
    n = b.size
    par = M.parallel
    dot = K.pick("dot", n, par)
    upd = K.pick("cg_update", n, par)
    xpby = K.pick("xpby", n, par)
    b = np.ascontiguousarray(b, dtype=float)
    nb = float(np.sqrt(dot(b, b)))
    if x0 is None:
        x = np.zeros(n)
        r = b.copy()
    else:
        x = np.array(x0, dtype=float)
        r = A.apply(x, np.empty(n), alpha=1.0, z=b, s=-1.0)
    hist = [float(np.sqrt(dot(r, r))) / nb]
    if hist[0] <= tol:
        return x, hist
    z = np.empty(n)
    rz = M.apply(r, z)
    p = z.copy()
    ap = np.empty(n)
    for it in range(maxiter):
        pap = A.dot_apply(p, ap)
        if not pap > 0.0:
            raise SolverError(f"non-positive curvature p^T A p = {pap:.3e} at CG iteration {it}: "
                              f"the operator is not positive definite (unstable structure?)", history=hist)
        alpha = rz / pap
        hist.append(float(np.sqrt(upd(x, r, p, ap, alpha))) / nb)
        if hist[-1] <= tol:
            break
        rz_new = M.apply(r, z)
        xpby(z, rz_new / rz, p)
        rz = rz_new
    return x, hist
