"""Projection of small symmetric blocks to positive semi-definite (contact Hessians).

Newton needs a positive semi-definite contribution from every contact to keep a descent
direction; the exact pair blocks are indefinite (the distance's curvature times a repulsive
force). Each block is projected by clamping its negative eigenvalues: a 12 x 12 LAPACK
eigendecomposition in general (~10 us), or, for a block made of a single distance term, in
the <= 5-dimensional space its Hessian lives in (the term's node coefficients times the three
axes, plus the directions of its free closest-point parameters) with a small Jacobi solver.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _project_psd(H):
    """Clamp the negative eigenvalues of the symmetric block H (in place)."""
    lam, V = np.linalg.eigh(H)
    if lam[0] >= 0.0:
        return
    n = H.shape[0]
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for k in range(n):
                if lam[k] > 0.0:
                    acc += V[i, k] * lam[k] * V[j, k]
            H[i, j] = acc


@njit(cache=True)
def _jacobi(A, k, V):
    """Cyclic Jacobi on the leading k x k block of symmetric A: eigenvalues on its diagonal,
    eigenvectors in V's columns (k <= 5 here: cheaper than a LAPACK call)."""
    for i in range(k):
        for j in range(k):
            V[i, j] = 1.0 if i == j else 0.0
    for sweep in range(60):
        off = 0.0
        tot = 0.0
        for i in range(k):
            tot += A[i, i] * A[i, i]
            for j in range(i + 1, k):
                off += A[i, j] * A[i, j]
        if off <= 1e-32 * tot or off == 0.0:
            return
        for p in range(k - 1):
            for q in range(p + 1, k):
                apq = A[p, q]
                if apq == 0.0:
                    continue
                theta = (A[q, q] - A[p, p]) / (2.0 * apq)
                t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
                c = 1.0 / np.sqrt(t * t + 1.0)
                sn = t * c
                for r in range(k):
                    arp = A[r, p]
                    arq = A[r, q]
                    A[r, p] = c * arp - sn * arq
                    A[r, q] = sn * arp + c * arq
                for r in range(k):
                    apr = A[p, r]
                    aqr = A[q, r]
                    A[p, r] = c * apr - sn * aqr
                    A[q, r] = sn * apr + c * aqr
                for r in range(k):
                    vrp = V[r, p]
                    vrq = V[r, q]
                    V[r, p] = c * vrp - sn * vrq
                    V[r, q] = sn * vrp + c * vrq


@njit(cache=True)
def _project_single(P, s, t, free_s, free_t, H, Bm, M, V):
    """PSD projection of a block made of one distance term (case s, t, free_s, free_t).

    Its Hessian lies in the span of c (x) e_i (c the term's node coefficients) and the
    directions of its free parameters: at most 5 dimensions, projected there exactly.
    """
    cc = (1.0 - s, s, -(1.0 - t), -t)
    cn = np.sqrt(cc[0] ** 2 + cc[1] ** 2 + cc[2] ** 2 + cc[3] ** 2)
    for i in range(12):
        for j in range(5):
            Bm[i, j] = 0.0
    for k in range(4):
        for i in range(3):
            Bm[3 * k + i, i] = cc[k] / cn
    kk = 3
    for which in range(2):
        if (which == 0 and not free_s) or (which == 1 and not free_t):
            continue
        for k in range(4):
            for i in range(3):
                D = cc[0] * P[0, i] + cc[1] * P[1, i] + cc[2] * P[2, i] + cc[3] * P[3, i]
                if which == 0:       # d/ds of the optimality: as in _stencil_d2's F_xs
                    dc = -1.0 if k == 0 else (1.0 if k == 1 else 0.0)
                    v = 2.0 * dc * D + 2.0 * cc[k] * (P[1, i] - P[0, i])
                else:
                    dc = 1.0 if k == 2 else (-1.0 if k == 3 else 0.0)
                    v = 2.0 * dc * D - 2.0 * cc[k] * (P[3, i] - P[2, i])
                Bm[3 * k + i, kk] = v
        n0 = 0.0
        for i in range(12):
            n0 += Bm[i, kk] ** 2
        for rep in range(2):                       # Gram-Schmidt, twice
            for j in range(kk):
                dot = 0.0
                for i in range(12):
                    dot += Bm[i, j] * Bm[i, kk]
                for i in range(12):
                    Bm[i, kk] -= dot * Bm[i, j]
        nn = 0.0
        for i in range(12):
            nn += Bm[i, kk] ** 2
        if nn > 1e-20 * n0 and nn > 0.0:
            for i in range(12):
                Bm[i, kk] /= np.sqrt(nn)
            kk += 1
        else:
            for i in range(12):
                Bm[i, kk] = 0.0
    # M = B^T H B (HB into V's place first: 12 x kk, then the product)
    HB = np.empty((12, 5))
    for i in range(12):
        for b in range(kk):
            acc = 0.0
            for j in range(12):
                acc += H[i, j] * Bm[j, b]
            HB[i, b] = acc
    for a in range(kk):
        for b in range(kk):
            acc = 0.0
            for i in range(12):
                acc += Bm[i, a] * HB[i, b]
            M[a, b] = acc
    _jacobi(M, kk, V)
    neg = False
    for a in range(kk):
        if M[a, a] < 0.0:
            neg = True
    if not neg:
        return
    # H = sum over positive eigenvalues of lam (B v)(B v)^T
    for i in range(12):
        for a in range(kk):
            acc = 0.0
            for b in range(kk):
                acc += Bm[i, b] * V[b, a]
            HB[i, a] = acc
    for i in range(12):
        for j in range(12):
            acc = 0.0
            for a in range(kk):
                if M[a, a] > 0.0:
                    acc += M[a, a] * HB[i, a] * HB[j, a]
            H[i, j] = acc
