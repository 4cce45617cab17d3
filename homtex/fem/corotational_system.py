"""Node-level kernels of the co-rotational Newton loop: gathering element end forces at the nodes,
assembling element tangents into a block pattern or the free-DOF CSC pattern, element-by-element
products, and the multiplicative update of the nodal rotations.

Parallel kernels are over nodes (each node writes only its own rows: no races); every parallel
kernel has a serial twin for small frames (a parallel launch cost 8 ms per call on the shared
2-core machine, more than the work of a 32-element frame).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .corotational import expmap, logmap


@njit(cache=True, inline="always")
def _gather_node(a, node_ptr, inc_elem, inc_end, fe, out):
    for k in range(6):
        out[a, k] = 0.0
    for p in range(node_ptr[a], node_ptr[a + 1]):
        e = inc_elem[p]
        s = inc_end[p]
        for k in range(6):
            out[a, k] += fe[e, s, k]


@njit(cache=True, parallel=True)
def gather_ends(node_ptr, inc_elem, inc_end, fe, out):
    """out (n, 6) = sum over the element ends at each node of fe (m, 2, 6) (no races: one node per thread)."""
    for a in prange(node_ptr.size - 1):
        _gather_node(a, node_ptr, inc_elem, inc_end, fe, out)


@njit(cache=True)
def gather_ends_serial(node_ptr, inc_elem, inc_end, fe, out):
    """:func:`gather_ends` on one thread."""
    for a in range(node_ptr.size - 1):
        _gather_node(a, node_ptr, inc_elem, inc_end, fe, out)


@njit(cache=True, parallel=True)
def scatter_bsr(node_ptr, inc_elem, inc_end, slot_self, slot_other, Ke, data, symmetric):
    """data[nnzb, 6, 6] = element tangents Ke (m, 12, 12) assembled into a BSR pattern (node rows,
    no races); ``symmetric``: the symmetric part 1/2 (Ke + Ke^T) instead."""
    n = node_ptr.size - 1
    for a in prange(n):
        for p in range(node_ptr[a], node_ptr[a + 1]):
            data[slot_self[p]] = 0.0
            data[slot_other[p]] = 0.0
        for p in range(node_ptr[a], node_ptr[a + 1]):
            e = inc_elem[p]
            s = inc_end[p]
            o = 1 - s
            for r in range(6):
                for c in range(6):
                    if symmetric:
                        data[slot_self[p], r, c] += 0.5 * (Ke[e, 6 * s + r, 6 * s + c] + Ke[e, 6 * s + c, 6 * s + r])
                        data[slot_other[p], r, c] += 0.5 * (Ke[e, 6 * s + r, 6 * o + c] + Ke[e, 6 * o + c, 6 * s + r])
                    else:
                        data[slot_self[p], r, c] += Ke[e, 6 * s + r, 6 * s + c]
                        data[slot_other[p], r, c] += Ke[e, 6 * s + r, 6 * o + c]


@njit(cache=True, parallel=True)
def add_geometric(node_ptr, inc_elem, inc_end, slot_self, slot_other, Rr, lcur, N, data):
    """data[nnzb, 6, 6] += axial-force geometric stiffness N / l (I - r1 r1^T) on translations
    (the turn of the chord under a fixed axial force; the approximate tangent)."""
    n = node_ptr.size - 1
    for a in prange(n):
        for p in range(node_ptr[a], node_ptr[a + 1]):
            e = inc_elem[p]
            g = N[e] / lcur[e]
            for r in range(3):
                for c in range(3):
                    v = g * ((1.0 if r == c else 0.0) - Rr[e, 0, r] * Rr[e, 0, c])
                    data[slot_self[p], r, c] += v
                    data[slot_other[p], r, c] -= v


@njit(cache=True)
def rotate_nodes(Q, dtheta):
    """Q[i] <- exp(dtheta[i]) Q[i] in place (spatial spin update), (n, 3, 3) and (n, 3)."""
    for i in range(Q.shape[0]):
        Q[i] = expmap(dtheta[i]) @ Q[i]


@njit(cache=True)
def log_nodes(Q, out):
    """out (n, 3) = rotation vectors log(Q[i]) of (n, 3, 3) rotation matrices (per-node work is too
    small for threads to pay)."""
    for i in range(Q.shape[0]):
        out[i] = logmap(Q[i])


# the free-DOF system (see homtex.analysis.tangent.FreeSystem)
@njit(cache=True)
def scatter_free(Ke, emap, data):
    """data (nnz,) = upper triangle of the symmetric part of the assembled tangent on the free DOFs.

    emap : (m, 12, 12) int32 slot of element entry (a, b) in ``data`` (-1: constrained or lower).
    """
    data[:] = 0.0
    m = Ke.shape[0]
    for e in range(m):
        for a in range(12):
            for b in range(12):
                k = emap[e, a, b]
                if k >= 0:
                    data[k] += 0.5 * (Ke[e, a, b] + Ke[e, b, a])


@njit(cache=True, inline="always")
def _matvec_node(a, node_ptr, inc_elem, inc_end, elements, Ke, du, out):
    for k in range(6):
        out[a, k] = 0.0
    for p in range(node_ptr[a], node_ptr[a + 1]):
        e = inc_elem[p]
        s = inc_end[p]
        i = elements[e, 0]
        j = elements[e, 1]
        for r in range(6):
            acc = 0.0
            for c in range(6):
                acc += Ke[e, 6 * s + r, c] * du[i, c] + Ke[e, 6 * s + r, 6 + c] * du[j, c]
            out[a, r] += acc


@njit(cache=True, parallel=True)
def element_matvec(node_ptr, inc_elem, inc_end, elements, Ke, du, out):
    """out (n, 6) = K du for the assembled element tangents Ke (m, 12, 12) and du (n, 6)."""
    for a in prange(node_ptr.size - 1):
        _matvec_node(a, node_ptr, inc_elem, inc_end, elements, Ke, du, out)


@njit(cache=True)
def element_matvec_serial(node_ptr, inc_elem, inc_end, elements, Ke, du, out):
    """:func:`element_matvec` on one thread."""
    for a in range(node_ptr.size - 1):
        _matvec_node(a, node_ptr, inc_elem, inc_end, elements, Ke, du, out)


@njit(cache=True)
def apply_increment(ut, Q, du):
    """ut (n, 3) += du[:, :3]; Q[i] <- exp(du[i, 3:]) Q[i] (spatial spins), in place."""
    Rm = np.empty((3, 3))
    tmp = np.empty((3, 3))
    for i in range(ut.shape[0]):
        for a in range(3):
            ut[i, a] += du[i, a]
        x, y, z = du[i, 3], du[i, 4], du[i, 5]
        if x == 0.0 and y == 0.0 and z == 0.0:
            continue
        th2 = x * x + y * y + z * z
        if th2 < 1e-16:
            a_ = 1.0 - th2 / 6.0
            b_ = 0.5 - th2 / 24.0
        else:
            th = np.sqrt(th2)
            a_ = np.sin(th) / th
            b_ = (1.0 - np.cos(th)) / th2
        # exp = I + a K + b K^2, K^2 = w w^T - |w|^2 I
        Rm[0, 0] = 1.0 + b_ * (x * x - th2)
        Rm[1, 1] = 1.0 + b_ * (y * y - th2)
        Rm[2, 2] = 1.0 + b_ * (z * z - th2)
        Rm[0, 1] = -a_ * z + b_ * x * y
        Rm[1, 0] = a_ * z + b_ * x * y
        Rm[0, 2] = a_ * y + b_ * x * z
        Rm[2, 0] = -a_ * y + b_ * x * z
        Rm[1, 2] = -a_ * x + b_ * y * z
        Rm[2, 1] = a_ * x + b_ * y * z
        for r in range(3):
            for c in range(3):
                tmp[r, c] = Rm[r, 0] * Q[i, 0, c] + Rm[r, 1] * Q[i, 1, c] + Rm[r, 2] * Q[i, 2, c]
        for r in range(3):
            for c in range(3):
                Q[i, r, c] = tmp[r, c]


@njit(cache=True)
def spin_between(Q1, Q0, out):
    """out (n, 3) = log(Q1[i] Q0[i]^T): the spatial rotation vector taking Q0 to Q1 (rad)."""
    for i in range(Q1.shape[0]):
        out[i] = logmap(Q1[i] @ Q0[i].T)


@njit(cache=True)
def sym_upper_matvec(indptr, indices, data, x, out):
    """out = S x for the symmetric S whose upper triangle is the CSC (indptr, indices, data)."""
    out[:] = 0.0
    for j in range(indptr.size - 1):
        xj = x[j]
        acc = 0.0
        for k in range(indptr[j], indptr[j + 1]):
            i = indices[k]
            v = data[k]
            acc += v * x[i]
            if i != j:
                out[i] += v * xj
        out[j] += acc


@njit(cache=True)
def add_blocks(H, slots, data):
    """data[slots[r, i, j]] += H[r, i, j] where slots >= 0: symmetric blocks (na, B, B) added to
    the upper triangle of a CSC matrix (contact Hessians on the free-DOF tangent)."""
    for r in range(H.shape[0]):
        for i in range(H.shape[1]):
            for j in range(H.shape[2]):
                k = slots[r, i, j]
                if k >= 0:
                    data[k] += H[r, i, j]
