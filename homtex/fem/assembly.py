"""Global stiffness assembly into 6x6 BSR with a pattern computed once.

The kernel is parallel over *nodes* (block rows): each node loops over its
incident element ends and adds that end's two 6x6 blocks (self, other) into its
own block row. No two threads write the same row, so there is no race and no
atomics; every element is visited once per end, computing only half of its
matrix each time.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from .beam import add_element_block, coefficients, local_stiffness


class Pattern:
    """Block sparsity of a frame's stiffness (reused while connectivity is fixed).

    Attributes
    ----------
    indptr, indices : BSR block-row pointer and block-column indices.
    node_ptr, inc_elem, inc_end : element ends incident to each node (CSR).
    slot_self, slot_other : data slot of block (node, node) and (node, other end) per incident entry.
    """

    def __init__(self, elements: np.ndarray, n_nodes: int):
        el = np.asarray(elements, dtype=np.int64)
        m = len(el)
        n = int(n_nodes)
        i, j = el[:, 0], el[:, 1]
        diag = np.arange(n, dtype=np.int64)
        rows = np.concatenate([diag, i, j])
        cols = np.concatenate([diag, j, i])
        key = np.unique(rows * n + cols)
        brow = key // n
        self.indices = np.ascontiguousarray((key % n).astype(np.int32))
        self.indptr = np.zeros(n + 1, dtype=np.int32)
        np.cumsum(np.bincount(brow, minlength=n), out=self.indptr[1:])
        self.n = n
        self.nnzb = len(key)
        # incidence: entries (element, end) grouped by node
        ends = np.concatenate([i, j])
        order = np.argsort(ends, kind="stable")
        self.inc_elem = np.ascontiguousarray((order % m).astype(np.int64))
        self.inc_end = np.ascontiguousarray((order // m).astype(np.int64))
        self.node_ptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.bincount(ends, minlength=n), out=self.node_ptr[1:])
        node = ends[order]
        other = np.where(self.inc_end == 0, j[self.inc_elem], i[self.inc_elem])
        self.slot_self = np.ascontiguousarray(np.searchsorted(key, node * n + node).astype(np.int64))
        self.slot_other = np.ascontiguousarray(np.searchsorted(key, node * n + other).astype(np.int64))

    def empty(self) -> sp.bsr_matrix:
        data = np.zeros((self.nnzb, 6, 6))
        return sp.bsr_matrix((data, self.indices, self.indptr), shape=(6 * self.n, 6 * self.n))


@njit(cache=True, parallel=True)
def assemble_kernel(node_ptr, inc_elem, inc_end, slot_self, slot_other,
                    R, L, EA, GJ, EIy, EIz, kGA, data):
    """data[nnzb, 6, 6] = global stiffness blocks (overwritten row by row)."""
    n = node_ptr.size - 1
    for a in prange(n):
        # zero this node's row blocks that elements touch, then accumulate
        for p in range(node_ptr[a], node_ptr[a + 1]):
            data[slot_self[p]] = 0.0
            data[slot_other[p]] = 0.0
        for p in range(node_ptr[a], node_ptr[a + 1]):
            e = inc_elem[p]
            s = inc_end[p]
            ax, tor, a_y, b_y, c_y, d_y, a_z, b_z, c_z, d_z = coefficients(
                L[e], EA[e], GJ[e], EIy[e], EIz[e], kGA[e])
            add_element_block(data[slot_self[p]], R[e], s, s, ax, tor, a_y, b_y, c_y, d_y,
                              a_z, b_z, c_z, d_z, 1.0)
            add_element_block(data[slot_other[p]], R[e], s, 1 - s, ax, tor, a_y, b_y, c_y, d_y,
                              a_z, b_z, c_z, d_z, 1.0)


def element_arrays(frame) -> tuple:
    """Per-element arrays the kernels take: (R (m, 3, 3), L, EA, GJ, EIy, EIz, kGA (m,)), mm, N, N mm^2."""
    f = frame
    return (f.R, f.length, f.E * f.A, f.G * f.J, f.E * f.Iy, f.E * f.Iz, f.k * f.G * f.A)


class Assembler:
    """Assembles a frame's stiffness; the pattern is built once and reused.

    >>> asm = Assembler(frame)
    >>> K = asm.stiffness()          # scipy.sparse.bsr_matrix, 6x6 blocks
    """

    def __init__(self, frame):
        self.frame = frame
        self.pattern = Pattern(frame.elements, frame.n_nodes)
        self._K = None

    def element_arrays(self):
        """(R, L, EA, GJ, EIy, EIz, kGA) of the frame (:func:`element_arrays`)."""
        return element_arrays(self.frame)

    def stiffness(self, element_arrays=None) -> sp.bsr_matrix:
        """Global stiffness (6n x 6n BSR). ``element_arrays`` overrides (R, L, EA, GJ, EIy, EIz, kGA)."""
        if self._K is None:
            self._K = self.pattern.empty()
        arrs = self.element_arrays() if element_arrays is None else element_arrays
        p = self.pattern
        assemble_kernel(p.node_ptr, p.inc_elem, p.inc_end, p.slot_self, p.slot_other,
                        *arrs, self._K.data)
        return self._K


def assemble_reference(frame) -> sp.csr_matrix:
    """Plain-numpy assembly (dense 12x12 elements, COO sum); slow, for tests only."""
    rows, cols, vals = [], [], []
    for e, (i, j) in enumerate(frame.elements):
        k = local_stiffness(frame.length[e], frame.E[e] * frame.A[e], frame.G[e] * frame.J[e],
                            frame.E[e] * frame.Iy[e], frame.E[e] * frame.Iz[e],
                            frame.k[e] * frame.G[e] * frame.A[e])
        T = np.kron(np.eye(4), frame.R[e])
        ke = T.T @ k @ T
        dofs = np.concatenate([6 * i + np.arange(6), 6 * j + np.arange(6)])
        rows.append(np.repeat(dofs, 12))
        cols.append(np.tile(dofs, 12))
        vals.append(ke.ravel())
    n = frame.ndof
    return sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n, n)).tocsr()
