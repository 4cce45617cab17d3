"""Multi-right-hand-side (block of vectors) kernels: BSR products, AMG V-cycle, lockstep PCG.

Homogenisation solves one operator for 6 load cases. Reading each matrix once for all k
vectors (and its index arrays once) instead of k times is the gain; scipy's ``bsr @ (n, k)``
is no faster than k matrix-vector products and pyamg's smoothers take one vector, so the pieces
here are numba kernels over C-contiguous (n, k) blocks of vectors. Measured on one core
(1e6-DOF wavy octet, every level of its hierarchy): the k = 6 product of a 6x6-block matrix
takes 1.5-1.9x less time than 6 scipy BSR matvecs (it is then bound by scalar multiply-adds:
LLVM does not vectorise it); the block V-cycle also skips the two fine-level residuals that
pyamg's ``solve`` computes around each preconditioning cycle.

- :func:`bsr_gemm`: ``Y = alpha Z + s (A @ X)`` for a BSR matrix A (any rectangular block
  shape, so also pyamg's prolongation P and restriction R), one pass over A.
- :class:`BatchedVCycle`: the V-cycle of an existing :class:`~homtex.solvers.ScaledAMG`
  hierarchy applied to k vectors at once, with the Chebyshev polynomial smoother pyamg set up
  (same coefficients, same Horner order, same coarse LU), so it equals pyamg's one-vector
  preconditioner to round-off.
- :func:`block_pcg`: k independent preconditioned CG recurrences in lockstep (per-column
  alpha, beta); a converged column is frozen (zeroed direction) and stops changing.
- :func:`solve_many`: what :meth:`LinearSolver.solve <homtex.solvers.LinearSolver.solve>` does
  (true-residual check, restarts, :class:`SolveReport`, :class:`SolverError`), for k cases.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from ..errors import SolverError
from .solvers import SolveReport, _blas_single, convergence_error

_CHUNK = 256  # block rows per parallel task


# ----------------------------------------------------------------------------- kernels
@njit(cache=True, parallel=True)
def _bsr_gemm(indptr, indices, data, X, Z, alpha, s, Y):
    """Y = alpha * Z + s * (A @ X) for BSR A (nb block rows, blocks (R, C)); X (ncol, k).

    Any k (the slow general loop; k = 6 has its own kernels, k = 1 goes to scipy). Z may be the
    same array as Y (in-place update); X must not alias Y.
    """
    nb = indptr.size - 1
    R = data.shape[1]
    C = data.shape[2]
    k = X.shape[1]
    nchunk = (nb + _CHUNK - 1) // _CHUNK
    for ch in prange(nchunk):
        acc = np.empty(k)
        for br in range(ch * _CHUNK, min(nb, (ch + 1) * _CHUNK)):
            for a in range(R):
                acc[:] = 0.0
                for p in range(indptr[br], indptr[br + 1]):
                    j0 = indices[p] * C
                    for b in range(C):
                        d = data[p, a, b]
                        for c in range(k):
                            acc[c] += d * X[j0 + b, c]
                i = br * R + a
                for c in range(k):
                    Y[i, c] = alpha * Z[i, c] + s * acc[c] if alpha != 0.0 else s * acc[c]


@njit(cache=True, parallel=True)
def _bsr_gemm6(indptr, indices, data, X, Z, alpha, s, Y):
    """:func:`_bsr_gemm` for k = 6 and any block shape (e.g. the 6x3 prolongation of a
    3-vector near-null space): one pass over A, 6 scalar accumulators per row."""
    nb = indptr.size - 1
    R = data.shape[1]
    C = data.shape[2]
    for br in prange(nb):
        p0 = indptr[br]
        p1 = indptr[br + 1]
        for a in range(R):
            s0 = s1 = s2 = s3 = s4 = s5 = 0.0
            for p in range(p0, p1):
                j0 = indices[p] * C
                for b in range(C):
                    d = data[p, a, b]
                    xr = X[j0 + b]
                    s0 += d * xr[0]
                    s1 += d * xr[1]
                    s2 += d * xr[2]
                    s3 += d * xr[3]
                    s4 += d * xr[4]
                    s5 += d * xr[5]
            i = br * R + a
            yr = Y[i]
            if alpha != 0.0:
                zr = Z[i]
                yr[0] = alpha * zr[0] + s * s0
                yr[1] = alpha * zr[1] + s * s1
                yr[2] = alpha * zr[2] + s * s2
                yr[3] = alpha * zr[3] + s * s3
                yr[4] = alpha * zr[4] + s * s4
                yr[5] = alpha * zr[5] + s * s5
            else:
                yr[0] = s * s0
                yr[1] = s * s1
                yr[2] = s * s2
                yr[3] = s * s3
                yr[4] = s * s4
                yr[5] = s * s5


@njit(cache=True, parallel=True, fastmath={'contract'})
def _bsr_gemm66(indptr, indices, dataT, X, Z, alpha, s, Y):
    """:func:`_bsr_gemm` for 6x6 blocks and k = 6: the 36 sums of a block row in registers.

    ``dataT`` holds the blocks transposed, (nnzb, 6, 6) with dataT[p, b, a] = A-block[a, b].
    Unrolled by hand (written out by a generator): a (6, 6) accumulator array, runtime loop
    bounds or a runtime-k inner loop kept the sums in memory and ran no faster than 6 scipy
    matvecs; this form (fused multiply-add, contiguous block columns) reads A once at 2.2x
    the speed of 6 scipy BSR matvecs on one core (40k random block rows: 6.6 ms vs 14 ms).
    """
    nb = indptr.size - 1
    for br in prange(nb):
        s00 = s01 = s02 = s03 = s04 = s05 = s10 = s11 = s12 = s13 = s14 = s15 = s20 = s21 = s22 = s23 = s24 = s25 = s30 = s31 = s32 = s33 = s34 = s35 = s40 = s41 = s42 = s43 = s44 = s45 = s50 = s51 = s52 = s53 = s54 = s55 = 0.0
        for p in range(indptr[br], indptr[br + 1]):
            j = indices[p] * 6
            d = dataT[p]
            x0, x1, x2 = X[j + 0, 0], X[j + 0, 1], X[j + 0, 2]
            x3, x4, x5 = X[j + 0, 3], X[j + 0, 4], X[j + 0, 5]
            d0, d1, d2 = d[0, 0], d[0, 1], d[0, 2]
            d3, d4, d5 = d[0, 3], d[0, 4], d[0, 5]
            s00 += d0 * x0; s10 += d1 * x0; s20 += d2 * x0; s30 += d3 * x0; s40 += d4 * x0; s50 += d5 * x0
            s01 += d0 * x1; s11 += d1 * x1; s21 += d2 * x1; s31 += d3 * x1; s41 += d4 * x1; s51 += d5 * x1
            s02 += d0 * x2; s12 += d1 * x2; s22 += d2 * x2; s32 += d3 * x2; s42 += d4 * x2; s52 += d5 * x2
            s03 += d0 * x3; s13 += d1 * x3; s23 += d2 * x3; s33 += d3 * x3; s43 += d4 * x3; s53 += d5 * x3
            s04 += d0 * x4; s14 += d1 * x4; s24 += d2 * x4; s34 += d3 * x4; s44 += d4 * x4; s54 += d5 * x4
            s05 += d0 * x5; s15 += d1 * x5; s25 += d2 * x5; s35 += d3 * x5; s45 += d4 * x5; s55 += d5 * x5
            x0, x1, x2 = X[j + 1, 0], X[j + 1, 1], X[j + 1, 2]
            x3, x4, x5 = X[j + 1, 3], X[j + 1, 4], X[j + 1, 5]
            d0, d1, d2 = d[1, 0], d[1, 1], d[1, 2]
            d3, d4, d5 = d[1, 3], d[1, 4], d[1, 5]
            s00 += d0 * x0; s10 += d1 * x0; s20 += d2 * x0; s30 += d3 * x0; s40 += d4 * x0; s50 += d5 * x0
            s01 += d0 * x1; s11 += d1 * x1; s21 += d2 * x1; s31 += d3 * x1; s41 += d4 * x1; s51 += d5 * x1
            s02 += d0 * x2; s12 += d1 * x2; s22 += d2 * x2; s32 += d3 * x2; s42 += d4 * x2; s52 += d5 * x2
            s03 += d0 * x3; s13 += d1 * x3; s23 += d2 * x3; s33 += d3 * x3; s43 += d4 * x3; s53 += d5 * x3
            s04 += d0 * x4; s14 += d1 * x4; s24 += d2 * x4; s34 += d3 * x4; s44 += d4 * x4; s54 += d5 * x4
            s05 += d0 * x5; s15 += d1 * x5; s25 += d2 * x5; s35 += d3 * x5; s45 += d4 * x5; s55 += d5 * x5
            x0, x1, x2 = X[j + 2, 0], X[j + 2, 1], X[j + 2, 2]
            x3, x4, x5 = X[j + 2, 3], X[j + 2, 4], X[j + 2, 5]
            d0, d1, d2 = d[2, 0], d[2, 1], d[2, 2]
            d3, d4, d5 = d[2, 3], d[2, 4], d[2, 5]
            s00 += d0 * x0; s10 += d1 * x0; s20 += d2 * x0; s30 += d3 * x0; s40 += d4 * x0; s50 += d5 * x0
            s01 += d0 * x1; s11 += d1 * x1; s21 += d2 * x1; s31 += d3 * x1; s41 += d4 * x1; s51 += d5 * x1
            s02 += d0 * x2; s12 += d1 * x2; s22 += d2 * x2; s32 += d3 * x2; s42 += d4 * x2; s52 += d5 * x2
            s03 += d0 * x3; s13 += d1 * x3; s23 += d2 * x3; s33 += d3 * x3; s43 += d4 * x3; s53 += d5 * x3
            s04 += d0 * x4; s14 += d1 * x4; s24 += d2 * x4; s34 += d3 * x4; s44 += d4 * x4; s54 += d5 * x4
            s05 += d0 * x5; s15 += d1 * x5; s25 += d2 * x5; s35 += d3 * x5; s45 += d4 * x5; s55 += d5 * x5
            x0, x1, x2 = X[j + 3, 0], X[j + 3, 1], X[j + 3, 2]
            x3, x4, x5 = X[j + 3, 3], X[j + 3, 4], X[j + 3, 5]
            d0, d1, d2 = d[3, 0], d[3, 1], d[3, 2]
            d3, d4, d5 = d[3, 3], d[3, 4], d[3, 5]
            s00 += d0 * x0; s10 += d1 * x0; s20 += d2 * x0; s30 += d3 * x0; s40 += d4 * x0; s50 += d5 * x0
            s01 += d0 * x1; s11 += d1 * x1; s21 += d2 * x1; s31 += d3 * x1; s41 += d4 * x1; s51 += d5 * x1
            s02 += d0 * x2; s12 += d1 * x2; s22 += d2 * x2; s32 += d3 * x2; s42 += d4 * x2; s52 += d5 * x2
            s03 += d0 * x3; s13 += d1 * x3; s23 += d2 * x3; s33 += d3 * x3; s43 += d4 * x3; s53 += d5 * x3
            s04 += d0 * x4; s14 += d1 * x4; s24 += d2 * x4; s34 += d3 * x4; s44 += d4 * x4; s54 += d5 * x4
            s05 += d0 * x5; s15 += d1 * x5; s25 += d2 * x5; s35 += d3 * x5; s45 += d4 * x5; s55 += d5 * x5
            x0, x1, x2 = X[j + 4, 0], X[j + 4, 1], X[j + 4, 2]
            x3, x4, x5 = X[j + 4, 3], X[j + 4, 4], X[j + 4, 5]
            d0, d1, d2 = d[4, 0], d[4, 1], d[4, 2]
            d3, d4, d5 = d[4, 3], d[4, 4], d[4, 5]
            s00 += d0 * x0; s10 += d1 * x0; s20 += d2 * x0; s30 += d3 * x0; s40 += d4 * x0; s50 += d5 * x0
            s01 += d0 * x1; s11 += d1 * x1; s21 += d2 * x1; s31 += d3 * x1; s41 += d4 * x1; s51 += d5 * x1
            s02 += d0 * x2; s12 += d1 * x2; s22 += d2 * x2; s32 += d3 * x2; s42 += d4 * x2; s52 += d5 * x2
            s03 += d0 * x3; s13 += d1 * x3; s23 += d2 * x3; s33 += d3 * x3; s43 += d4 * x3; s53 += d5 * x3
            s04 += d0 * x4; s14 += d1 * x4; s24 += d2 * x4; s34 += d3 * x4; s44 += d4 * x4; s54 += d5 * x4
            s05 += d0 * x5; s15 += d1 * x5; s25 += d2 * x5; s35 += d3 * x5; s45 += d4 * x5; s55 += d5 * x5
            x0, x1, x2 = X[j + 5, 0], X[j + 5, 1], X[j + 5, 2]
            x3, x4, x5 = X[j + 5, 3], X[j + 5, 4], X[j + 5, 5]
            d0, d1, d2 = d[5, 0], d[5, 1], d[5, 2]
            d3, d4, d5 = d[5, 3], d[5, 4], d[5, 5]
            s00 += d0 * x0; s10 += d1 * x0; s20 += d2 * x0; s30 += d3 * x0; s40 += d4 * x0; s50 += d5 * x0
            s01 += d0 * x1; s11 += d1 * x1; s21 += d2 * x1; s31 += d3 * x1; s41 += d4 * x1; s51 += d5 * x1
            s02 += d0 * x2; s12 += d1 * x2; s22 += d2 * x2; s32 += d3 * x2; s42 += d4 * x2; s52 += d5 * x2
            s03 += d0 * x3; s13 += d1 * x3; s23 += d2 * x3; s33 += d3 * x3; s43 += d4 * x3; s53 += d5 * x3
            s04 += d0 * x4; s14 += d1 * x4; s24 += d2 * x4; s34 += d3 * x4; s44 += d4 * x4; s54 += d5 * x4
            s05 += d0 * x5; s15 += d1 * x5; s25 += d2 * x5; s35 += d3 * x5; s45 += d4 * x5; s55 += d5 * x5
        i = br * 6
        if alpha != 0.0:
            Y[i + 0, 0] = alpha * Z[i + 0, 0] + s * s00; Y[i + 0, 1] = alpha * Z[i + 0, 1] + s * s01; Y[i + 0, 2] = alpha * Z[i + 0, 2] + s * s02
            Y[i + 0, 3] = alpha * Z[i + 0, 3] + s * s03; Y[i + 0, 4] = alpha * Z[i + 0, 4] + s * s04; Y[i + 0, 5] = alpha * Z[i + 0, 5] + s * s05
            Y[i + 1, 0] = alpha * Z[i + 1, 0] + s * s10; Y[i + 1, 1] = alpha * Z[i + 1, 1] + s * s11; Y[i + 1, 2] = alpha * Z[i + 1, 2] + s * s12
            Y[i + 1, 3] = alpha * Z[i + 1, 3] + s * s13; Y[i + 1, 4] = alpha * Z[i + 1, 4] + s * s14; Y[i + 1, 5] = alpha * Z[i + 1, 5] + s * s15
            Y[i + 2, 0] = alpha * Z[i + 2, 0] + s * s20; Y[i + 2, 1] = alpha * Z[i + 2, 1] + s * s21; Y[i + 2, 2] = alpha * Z[i + 2, 2] + s * s22
            Y[i + 2, 3] = alpha * Z[i + 2, 3] + s * s23; Y[i + 2, 4] = alpha * Z[i + 2, 4] + s * s24; Y[i + 2, 5] = alpha * Z[i + 2, 5] + s * s25
            Y[i + 3, 0] = alpha * Z[i + 3, 0] + s * s30; Y[i + 3, 1] = alpha * Z[i + 3, 1] + s * s31; Y[i + 3, 2] = alpha * Z[i + 3, 2] + s * s32
            Y[i + 3, 3] = alpha * Z[i + 3, 3] + s * s33; Y[i + 3, 4] = alpha * Z[i + 3, 4] + s * s34; Y[i + 3, 5] = alpha * Z[i + 3, 5] + s * s35
            Y[i + 4, 0] = alpha * Z[i + 4, 0] + s * s40; Y[i + 4, 1] = alpha * Z[i + 4, 1] + s * s41; Y[i + 4, 2] = alpha * Z[i + 4, 2] + s * s42
            Y[i + 4, 3] = alpha * Z[i + 4, 3] + s * s43; Y[i + 4, 4] = alpha * Z[i + 4, 4] + s * s44; Y[i + 4, 5] = alpha * Z[i + 4, 5] + s * s45
            Y[i + 5, 0] = alpha * Z[i + 5, 0] + s * s50; Y[i + 5, 1] = alpha * Z[i + 5, 1] + s * s51; Y[i + 5, 2] = alpha * Z[i + 5, 2] + s * s52
            Y[i + 5, 3] = alpha * Z[i + 5, 3] + s * s53; Y[i + 5, 4] = alpha * Z[i + 5, 4] + s * s54; Y[i + 5, 5] = alpha * Z[i + 5, 5] + s * s55
        else:
            Y[i + 0, 0] = s * s00; Y[i + 0, 1] = s * s01; Y[i + 0, 2] = s * s02; Y[i + 0, 3] = s * s03; Y[i + 0, 4] = s * s04; Y[i + 0, 5] = s * s05
            Y[i + 1, 0] = s * s10; Y[i + 1, 1] = s * s11; Y[i + 1, 2] = s * s12; Y[i + 1, 3] = s * s13; Y[i + 1, 4] = s * s14; Y[i + 1, 5] = s * s15
            Y[i + 2, 0] = s * s20; Y[i + 2, 1] = s * s21; Y[i + 2, 2] = s * s22; Y[i + 2, 3] = s * s23; Y[i + 2, 4] = s * s24; Y[i + 2, 5] = s * s25
            Y[i + 3, 0] = s * s30; Y[i + 3, 1] = s * s31; Y[i + 3, 2] = s * s32; Y[i + 3, 3] = s * s33; Y[i + 3, 4] = s * s34; Y[i + 3, 5] = s * s35
            Y[i + 4, 0] = s * s40; Y[i + 4, 1] = s * s41; Y[i + 4, 2] = s * s42; Y[i + 4, 3] = s * s43; Y[i + 4, 4] = s * s44; Y[i + 4, 5] = s * s45
            Y[i + 5, 0] = s * s50; Y[i + 5, 1] = s * s51; Y[i + 5, 2] = s * s52; Y[i + 5, 3] = s * s53; Y[i + 5, 4] = s * s54; Y[i + 5, 5] = s * s55


@njit(cache=True, parallel=True)
def _coldot(X, Y):
    """Column-wise dot products sum_i X[i, c] Y[i, c]: (k,)."""
    n, k = X.shape
    nchunk = (n + 4 * _CHUNK - 1) // (4 * _CHUNK)
    part = np.zeros((nchunk, k))
    for ch in prange(nchunk):
        for i in range(ch * 4 * _CHUNK, min(n, (ch + 1) * 4 * _CHUNK)):
            for c in range(k):
                part[ch, c] += X[i, c] * Y[i, c]
    out = np.zeros(k)
    for ch in range(nchunk):
        for c in range(k):
            out[c] += part[ch, c]
    return out


@njit(cache=True, parallel=True)
def _cg_update(X, Rr, P, AP, alpha):
    """X += alpha P, R -= alpha AP (per column); returns the column norms^2 of the new R."""
    n, k = X.shape
    nchunk = (n + 4 * _CHUNK - 1) // (4 * _CHUNK)
    part = np.zeros((nchunk, k))
    for ch in prange(nchunk):
        for i in range(ch * 4 * _CHUNK, min(n, (ch + 1) * 4 * _CHUNK)):
            for c in range(k):
                X[i, c] += alpha[c] * P[i, c]
                r = Rr[i, c] - alpha[c] * AP[i, c]
                Rr[i, c] = r
                part[ch, c] += r * r
    out = np.zeros(k)
    for ch in range(nchunk):
        for c in range(k):
            out[c] += part[ch, c]
    return out


@njit(cache=True, parallel=True)
def _p_update(P, Zz, beta):
    """P = Z + beta P (per column)."""
    n, k = P.shape
    for i in prange(n):
        for c in range(k):
            P[i, c] = Zz[i, c] + beta[c] * P[i, c]


@njit(cache=True, parallel=True)
def _row_scale(s, X, Y):
    """Y = s[:, None] * X."""
    n, k = X.shape
    for i in prange(n):
        for c in range(k):
            Y[i, c] = s[i] * X[i, c]


def _as_bsr(M):
    """(indptr, indices, data) of M as BSR; CSR/other formats become 1x1 blocks."""
    if not isinstance(M, (sp.bsr_matrix, sp.bsr_array)):
        M = sp.bsr_matrix(sp.csr_matrix(M), blocksize=(1, 1))
    return (np.ascontiguousarray(M.indptr, dtype=np.int64),
            np.ascontiguousarray(M.indices, dtype=np.int64),
            np.ascontiguousarray(M.data, dtype=np.float64), M.shape)


class BlockOperator:
    """A sparse matrix prepared for products with (n, k) blocks of vectors.

    ``op.gemm(X, out, alpha=0, Z=None, s=1)`` writes ``alpha Z + s A X`` into ``out``;
    X and out are C-contiguous float64 arrays of shapes (ncols, k) and (nrows, k).
    """

    def __init__(self, M):
        self.matrix = M
        self.indptr, self.indices, self.data, self.shape = _as_bsr(M)
        # 6x6 blocks, stored transposed for the k = 6 kernel (contiguous block columns)
        self.dataT = (np.ascontiguousarray(self.data.transpose(0, 2, 1))
                      if self.data.shape[1:] == (6, 6) else None)

    def gemm(self, X, out, *, alpha: float = 0.0, Z=None, s: float = 1.0):
        k = X.shape[1]
        if k == 1:  # one vector: scipy's matvec is faster than the block kernels
            y = self.matrix @ X[:, 0]
            if alpha != 0.0:
                zc = (out if Z is None else Z)[:, 0]
                out[:, 0] = alpha * zc + s * y if s != 1.0 else alpha * zc + y
            else:
                out[:, 0] = s * y if s != 1.0 else y
            return out
        if k == 6 and self.dataT is not None:
            _bsr_gemm66(self.indptr, self.indices, self.dataT, X, out if Z is None else Z,
                        float(alpha), float(s), out)
        else:
            kern = _bsr_gemm6 if k == 6 else _bsr_gemm
            kern(self.indptr, self.indices, self.data, X, out if Z is None else Z,
                 float(alpha), float(s), out)
        return out

    def __matmul__(self, X):
        X = np.ascontiguousarray(X, dtype=float)
        one = X.ndim == 1
        X2 = X.reshape(len(X), -1)
        out = np.empty((self.shape[0], X2.shape[1]))
        self.gemm(X2, out)
        return out[:, 0] if one else out


def bsr_gemm(A, X: np.ndarray) -> np.ndarray:
    """A @ X for a sparse A (BSR read once) and X of shape (n,) or (n, k); returns (m,) or (m, k)."""
    return BlockOperator(A) @ X


# ----------------------------------------------------------------------------- V-cycle
def _chebyshev_coefficients(A, degree: int) -> np.ndarray:
    """pyamg's Chebyshev smoother coefficients for level matrix A (its cached rho)."""
    from pyamg.relaxation.chebyshev import chebyshev_polynomial_coefficients
    from pyamg.util.linalg import approximate_spectral_radius

    rho = approximate_spectral_radius(A)  # cached on A by pyamg's own smoother setup
    # pyamg's setup_chebyshev: bounds rho/30 and 1.1 rho, constant coefficient dropped
    return -chebyshev_polynomial_coefficients(rho / 30.0, rho * 1.1, degree)[:-1]


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
            from scipy.sparse.linalg import splu
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


# ----------------------------------------------------------------------------- block PCG
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
    import numba

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
    with _blas_single():
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
