"""Block-of-vectors kernels: BSR products and the small vector updates of lockstep PCG.

Homogenisation solves one operator for 6 load cases. Reading each matrix once for all k
vectors (and its index arrays once) instead of k times is the gain; scipy's ``bsr @ (n, k)``
is no faster than k matrix-vector products and pyamg's smoothers take one vector, so the pieces
here are numba kernels over C-contiguous (n, k) blocks of vectors. Measured on one core
(1e6-DOF wavy octet, every level of its hierarchy): the k = 6 product of a 6x6-block matrix
takes 1.5-1.9x less time than 6 scipy BSR matvecs (it is then bound by scalar multiply-adds:
LLVM does not vectorise it). The solvers built on them are in :mod:`homtex.linalg.multirhs`.

- :func:`bsr_gemm`: ``Y = alpha Z + s (A @ X)`` for a BSR matrix A (any rectangular block
  shape, so also pyamg's prolongation P and restriction R), one pass over A.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

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




# ----------------------------------------------------------------------------- block PCG


