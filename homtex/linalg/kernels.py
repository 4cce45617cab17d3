"""numba kernels of the one-vector AMG-CG phase: BSR products, fused vector updates, reductions.

Each kernel comes twice, compiled with ``parallel=True`` (block rows or vector chunks over
numba's threads) and serially; :func:`pick` chooses by size: a parallel launch costs a few
microseconds, more than a coarse level's whole product (measured threshold in
``PARALLEL_MIN_ROWS``). The products store their matrices in float64 or float32 (the values;
sums are always in float64), so a float32 hierarchy halves the bytes a V-cycle reads.

Shapes: ``indptr`` (nb + 1,), ``indices`` (nnzb,), ``data`` (nnzb, R, C) of a BSR matrix with
nb block rows; vectors are float64, C-contiguous, of length nb * R (output) or ncols (input).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

#: rows (unknowns) below which the serial kernels run (a parallel launch costs more)
PARALLEL_MIN_ROWS = 20_000

_CH = 4096   # vector chunk per parallel task in reductions


def _make_bsr66(parallel: bool):
    rng = prange if parallel else range

    @njit(cache=True, parallel=parallel, fastmath={"contract"})
    def bsr66(indptr, indices, data, x, z, alpha, s, y):
        """y = alpha z + s A x for BSR A with 6x6 blocks (alpha = 0: y = s A x; z may be y)."""
        nb = indptr.size - 1
        for br in rng(nb):
            a0 = a1 = a2 = a3 = a4 = a5 = 0.0
            for p in range(indptr[br], indptr[br + 1]):
                j = indices[p] * 6
                x0 = x[j]
                x1 = x[j + 1]
                x2 = x[j + 2]
                x3 = x[j + 3]
                x4 = x[j + 4]
                x5 = x[j + 5]
                d = data[p]
                a0 += d[0, 0] * x0 + d[0, 1] * x1 + d[0, 2] * x2 + d[0, 3] * x3 + d[0, 4] * x4 + d[0, 5] * x5
                a1 += d[1, 0] * x0 + d[1, 1] * x1 + d[1, 2] * x2 + d[1, 3] * x3 + d[1, 4] * x4 + d[1, 5] * x5
                a2 += d[2, 0] * x0 + d[2, 1] * x1 + d[2, 2] * x2 + d[2, 3] * x3 + d[2, 4] * x4 + d[2, 5] * x5
                a3 += d[3, 0] * x0 + d[3, 1] * x1 + d[3, 2] * x2 + d[3, 3] * x3 + d[3, 4] * x4 + d[3, 5] * x5
                a4 += d[4, 0] * x0 + d[4, 1] * x1 + d[4, 2] * x2 + d[4, 3] * x3 + d[4, 4] * x4 + d[4, 5] * x5
                a5 += d[5, 0] * x0 + d[5, 1] * x1 + d[5, 2] * x2 + d[5, 3] * x3 + d[5, 4] * x4 + d[5, 5] * x5
            i = br * 6
            if alpha != 0.0:
                y[i] = alpha * z[i] + s * a0
                y[i + 1] = alpha * z[i + 1] + s * a1
                y[i + 2] = alpha * z[i + 2] + s * a2
                y[i + 3] = alpha * z[i + 3] + s * a3
                y[i + 4] = alpha * z[i + 4] + s * a4
                y[i + 5] = alpha * z[i + 5] + s * a5
            else:
                y[i] = s * a0
                y[i + 1] = s * a1
                y[i + 2] = s * a2
                y[i + 3] = s * a3
                y[i + 4] = s * a4
                y[i + 5] = s * a5

    return bsr66


def _make_bsr(parallel: bool):
    rng = prange if parallel else range

    @njit(cache=True, parallel=parallel, fastmath={"contract"})
    def bsr(indptr, indices, data, x, z, alpha, s, y):
        """y = alpha z + s A x for BSR A with any (R, C) blocks (restriction, prolongation)."""
        nb = indptr.size - 1
        R = data.shape[1]
        C = data.shape[2]
        for br in rng(nb):
            for a in range(R):
                acc = 0.0
                for p in range(indptr[br], indptr[br + 1]):
                    j0 = indices[p] * C
                    for b in range(C):
                        acc += data[p, a, b] * x[j0 + b]
                i = br * R + a
                if alpha != 0.0:
                    y[i] = alpha * z[i] + s * acc
                else:
                    y[i] = s * acc

    return bsr


def _make_bsr66_dot(parallel: bool):
    rng = prange if parallel else range

    @njit(cache=True, parallel=parallel, fastmath={"contract"})
    def bsr66_dot(indptr, indices, data, x, y):
        """y = A x (6x6 blocks); returns x . y (the CG curvature p^T A p in the same pass)."""
        nb = indptr.size - 1
        tot = 0.0
        for br in rng(nb):
            a0 = a1 = a2 = a3 = a4 = a5 = 0.0
            for p in range(indptr[br], indptr[br + 1]):
                j = indices[p] * 6
                x0 = x[j]
                x1 = x[j + 1]
                x2 = x[j + 2]
                x3 = x[j + 3]
                x4 = x[j + 4]
                x5 = x[j + 5]
                d = data[p]
                a0 += d[0, 0] * x0 + d[0, 1] * x1 + d[0, 2] * x2 + d[0, 3] * x3 + d[0, 4] * x4 + d[0, 5] * x5
                a1 += d[1, 0] * x0 + d[1, 1] * x1 + d[1, 2] * x2 + d[1, 3] * x3 + d[1, 4] * x4 + d[1, 5] * x5
                a2 += d[2, 0] * x0 + d[2, 1] * x1 + d[2, 2] * x2 + d[2, 3] * x3 + d[2, 4] * x4 + d[2, 5] * x5
                a3 += d[3, 0] * x0 + d[3, 1] * x1 + d[3, 2] * x2 + d[3, 3] * x3 + d[3, 4] * x4 + d[3, 5] * x5
                a4 += d[4, 0] * x0 + d[4, 1] * x1 + d[4, 2] * x2 + d[4, 3] * x3 + d[4, 4] * x4 + d[4, 5] * x5
                a5 += d[5, 0] * x0 + d[5, 1] * x1 + d[5, 2] * x2 + d[5, 3] * x3 + d[5, 4] * x4 + d[5, 5] * x5
            i = br * 6
            y[i] = a0
            y[i + 1] = a1
            y[i + 2] = a2
            y[i + 3] = a3
            y[i + 4] = a4
            y[i + 5] = a5
            tot += a0 * x[i] + a1 * x[i + 1] + a2 * x[i + 2] + a3 * x[i + 3] + a4 * x[i + 4] + a5 * x[i + 5]
        return tot

    return bsr66_dot


def _make_vec(parallel: bool):
    rng = prange if parallel else range

    @njit(cache=True, parallel=parallel)
    def dot(x, y):
        """x . y."""
        n = x.size
        nch = (n + _CH - 1) // _CH
        tot = 0.0
        for c in rng(nch):
            acc = 0.0
            for i in range(c * _CH, min(n, (c + 1) * _CH)):
                acc += x[i] * y[i]
            tot += acc
        return tot

    @njit(cache=True, parallel=parallel)
    def cg_update(x, r, p, ap, alpha):
        """x += alpha p; r -= alpha ap; returns ||r||^2 (one pass)."""
        n = x.size
        nch = (n + _CH - 1) // _CH
        tot = 0.0
        for c in rng(nch):
            acc = 0.0
            for i in range(c * _CH, min(n, (c + 1) * _CH)):
                x[i] += alpha * p[i]
                ri = r[i] - alpha * ap[i]
                r[i] = ri
                acc += ri * ri
            tot += acc
        return tot

    @njit(cache=True, parallel=parallel)
    def xpby(z, beta, p):
        """p = z + beta p."""
        for i in rng(p.size):
            p[i] = z[i] + beta * p[i]

    @njit(cache=True, parallel=parallel)
    def scale_dot(s, x, y, r):
        """y = s * x (elementwise); returns r . y."""
        n = x.size
        nch = (n + _CH - 1) // _CH
        tot = 0.0
        for c in rng(nch):
            acc = 0.0
            for i in range(c * _CH, min(n, (c + 1) * _CH)):
                v = s[i] * x[i]
                y[i] = v
                acc += r[i] * v
            tot += acc
        return tot

    @njit(cache=True, parallel=parallel)
    def scale(s, x, y):
        """y = s * x (elementwise)."""
        for i in rng(x.size):
            y[i] = s[i] * x[i]

    @njit(cache=True, parallel=parallel)
    def axpy(a, x, y):
        """y += a x."""
        for i in rng(x.size):
            y[i] += a * x[i]

    @njit(cache=True, parallel=parallel)
    def triad(a, b, s, c):
        """a = b + s c (the STREAM triad)."""
        for i in rng(a.size):
            a[i] = b[i] + s * c[i]

    return dot, cg_update, xpby, scale_dot, scale, axpy, triad


bsr66_par, bsr66_ser = _make_bsr66(True), _make_bsr66(False)
bsr_par, bsr_ser = _make_bsr(True), _make_bsr(False)
bsr66_dot_par, bsr66_dot_ser = _make_bsr66_dot(True), _make_bsr66_dot(False)
(dot_par, cg_update_par, xpby_par, scale_dot_par, scale_par, axpy_par, triad_par) = _make_vec(True)
(dot_ser, cg_update_ser, xpby_ser, scale_dot_ser, scale_ser, axpy_ser, triad_ser) = _make_vec(False)

_TABLE = {
    "bsr66": (bsr66_par, bsr66_ser), "bsr": (bsr_par, bsr_ser), "bsr66_dot": (bsr66_dot_par, bsr66_dot_ser),
    "dot": (dot_par, dot_ser), "cg_update": (cg_update_par, cg_update_ser), "xpby": (xpby_par, xpby_ser),
    "scale_dot": (scale_dot_par, scale_dot_ser), "scale": (scale_par, scale_ser), "axpy": (axpy_par, axpy_ser),
    "triad": (triad_par, triad_ser),
}


def pick(name: str, n: int, parallel: bool = True):
    """The parallel kernel ``name`` for n >= PARALLEL_MIN_ROWS unknowns (and ``parallel``), else the serial one."""
    par, ser = _TABLE[name]
    return par if (parallel and n >= PARALLEL_MIN_ROWS) else ser


def stream_triad(n: int = 20_000_000, repeats: int = 5, parallel: bool = True) -> float:
    """STREAM-like triad a = b + s c on n float64: best bandwidth over ``repeats``, GB/s (3 x 8 n
    bytes moved per pass; write-allocate traffic not counted, as STREAM reports). Threads: numba's
    current setting."""
    import time

    a = np.zeros(n)
    b = np.ones(n)
    c = np.full(n, 2.0)
    k = triad_par if parallel else triad_ser
    k(a, b, 0.5, c)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        k(a, b, 0.5, c)
        best = min(best, time.perf_counter() - t0)
    return 24.0 * n / best / 1e9
