"""The engine's linear system with the lattice DOFs as a border (:class:`BorderedSystem`).

The free DOFs of the nodes (and plates) keep their :class:`~homtex.analysis.tangent.FreeSystem`
(pattern, LDL^T, inertia); the free lattice components (at most 9) border it:

    [K  B] [x]   [r]
    [B' C] [y] = [s],     S = C - B' K^-1 B,   y = S^-1 (s - B' K^-1 r),   x = K^-1 (r - B y),

with K^-1 B computed once per factorisation (one triangular solve per lattice column). The number
of negative eigenvalues of the whole matrix is that of K plus that of S (Haynsworth's inertia
additivity), so the stability of a state comes with the factor as before. B and C collect the
symmetric parts of the element tangents of the elements that cross the periodic boundary and the
contact and friction blocks on virtual nodes (:mod:`.lattice`), each column scaled by the image.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit

from .lattice import LatticeDriver

__all__ = ["BorderedSystem"]


@njit(cache=True)
def _scatter_rows(B, fidx, dof, vals):
    """B[fidx[dof[a, r]]] += vals[a, r] for every (a, r) whose DOF is free (fidx >= 0);
    B (nfi, q), fidx (N,), dof (na, R), vals (na, R, q)."""
    for a in range(dof.shape[0]):
        for r in range(dof.shape[1]):
            row = fidx[dof[a, r]]
            if row >= 0:
                for c in range(vals.shape[2]):
                    B[row, c] += vals[a, r, c]


class BorderedSystem:
    """The free system of the nodes bordered by the free lattice components.

    Parameters
    ----------
    inner : FreeSystem of the nodes and plates (lattice rows constrained in its mask).
    driver : the :class:`~homtex.contact.lattice.LatticeDriver`.
    free : (nf,) the solver's free DOFs (global indices, sorted: the lattice rows come last).
    elements : (m, 2) the frame's elements.
    """

    def __init__(self, inner, driver: LatticeDriver, free: np.ndarray, elements: np.ndarray):
        self.inner = inner
        self.lat = driver
        self.elements = elements
        nfi = inner.nf
        self.nfi = nfi
        fidx = np.full(int(max(free.max(initial=0), inner.mask.size - 1)) + 1, -1, dtype=np.int64)
        fidx[inner.free] = np.arange(nfi)
        self.fidx = fidx
        k = driver.k
        lat_dof = (6 * driver.rows[:, None] + np.arange(3)).ravel()        # (3k,) component order
        self.lf = np.flatnonzero(np.isin(lat_dof, free))                   # free lattice components
        self.nl = len(self.lf)
        self.nf = nfi + self.nl
        self.B = np.zeros((nfi, 3 * k))
        self.C = np.zeros((3 * k, 3 * k))
        self.cshift = np.zeros(self.nl)
        self.negative = None
        self._X = None
        self._S = None

    # ------------------------------------------------------------------ assembly
    def assemble(self, Ke: np.ndarray) -> None:
        """Nodes from the element tangents (m, 12, 12); the border from the crossing elements."""
        self.inner.assemble(Ke)
        self.B[...] = 0.0
        self.C[...] = 0.0
        self.cshift[...] = 0.0
        e = self.lat.img_el
        if len(e):
            K = 0.5 * (Ke[e] + np.transpose(Ke[e], (0, 2, 1)))
            W = self.lat.images[e].astype(float)                            # (me, k)
            el = self.elements[e]
            dof = np.concatenate([6 * el[:, :1] + np.arange(6), 6 * el[:, 1:] + np.arange(6)], axis=1)
            part = np.einsum("eac,ek->eakc", K[:, :, 6:9], W)              # (me, 12, k, 3)
            self._add_rows(dof, part)
            self.C += np.einsum("ek,eij,el->kilj", W, K[:, 6:9, 6:9], W).reshape(self.C.shape)

    def _add_rows(self, dof: np.ndarray, part: np.ndarray) -> None:
        # a kernel, not np.add.at: with thousands of contact pairs on virtual nodes the scatter
        # was a twentieth of a knit cell's Newton iteration
        _scatter_rows(self.B, self.fidx, np.ascontiguousarray(dof, dtype=np.int64),
                      np.ascontiguousarray(part).reshape(part.shape[0], part.shape[1], -1))

    def add_lattice_blocks(self, H: np.ndarray, nodes: np.ndarray) -> None:
        """Border of contact or friction blocks H (na, 3S, 3S) over contact positions (na, S)."""
        if not len(H):
            return
        W = self.lat.images_of(nodes)                                       # (na, S, k)
        sel = np.flatnonzero(np.any(W != 0, axis=(1, 2)))
        if not len(sel):
            return
        n, S, k = len(sel), nodes.shape[1], self.lat.k
        Hr = H[sel].reshape(n, S, 3, S, 3)
        W = W[sel].astype(float)
        real = self.lat.real(nodes[sel])
        # P[a, p, i, l, j] = sum_q Hr[a, p, i, q, j] W[a, q, l] and C[k, i, l, j] += sum_{a, p} W[a, p, k]
        # P[a, p, i, l, j]: a batched matmul and a tensordot (BLAS), not einsum's loops (thousands of
        # contact pairs in a knit cell made these a fifth of a Newton iteration)
        P = np.matmul(Hr.transpose(0, 1, 2, 4, 3).reshape(n, 9 * S, S), W)
        P = P.reshape(n, S, 3, 3, k).transpose(0, 1, 2, 4, 3)
        dof = (6 * real[:, :, None] + np.arange(3)).reshape(n, 3 * S)
        self._add_rows(dof, np.ascontiguousarray(P).reshape(n, 3 * S, k, 3))
        self.C += np.tensordot(W, P, axes=([0, 1], [0, 1])).reshape(self.C.shape)

    def block_slots(self, nodes, strict: bool = True):
        return self.inner.block_slots(nodes, strict=strict)

    def add_blocks(self, blocks, slots) -> None:
        self.inner.add_blocks(blocks, slots)

    def add_diagonal(self, d: np.ndarray) -> None:
        self.inner.add_diagonal(d[:self.nfi])
        self.cshift += d[self.nfi:]

    def diagonal(self) -> np.ndarray:
        return np.r_[self.inner.diagonal(), np.diag(self.C)[self.lf] + self.cshift]

    def symmetric(self):
        """The full symmetric matrix (both triangles) of the last assembly over the free DOFs, the
        lattice components last (as :meth:`solve` orders them; the critical mode of a buckling state)."""
        if not self.nl:
            return self.inner.symmetric()
        Bf = sp.csr_matrix(self.B[:, self.lf])
        return sp.bmat([[self.inner.symmetric(), Bf], [Bf.T, sp.csr_matrix(self._Cf())]], format="csc")

    def save(self):
        """The assembled values, to hand back to :meth:`load`."""
        return self.inner.A.data.copy(), self.cshift.copy()

    def load(self, saved) -> None:
        self.inner.A.data[:] = saved[0]
        self.cshift[...] = saved[1]

    # ------------------------------------------------------------------ factor and solve
    def _Cf(self) -> np.ndarray:
        return self.C[np.ix_(self.lf, self.lf)] + np.diag(self.cshift)

    def factor(self, inertia: bool = True) -> None:
        self.inner.factor(inertia=inertia)
        Bf = self.B[:, self.lf]
        self._X = np.column_stack([self.inner.solve(Bf[:, c]) for c in range(self.nl)]) if self.nl else \
            np.zeros((self.nfi, 0))
        S = self._Cf() - Bf.T @ self._X
        self._S = 0.5 * (S + S.T)
        self.negative = None
        if self.inner.negative is not None:
            self.negative = int(self.inner.negative) + int(np.count_nonzero(np.linalg.eigvalsh(self._S) < 0.0))

    def solve(self, b: np.ndarray) -> np.ndarray:
        b1, b2 = b[:self.nfi], b[self.nfi:]
        z = self.inner.solve(b1)
        if not self.nl:
            return z
        y = np.linalg.solve(self._S, b2 - self.B[:, self.lf].T @ z)
        return np.r_[z - self._X @ y, y]

    def matvec(self, v: np.ndarray) -> np.ndarray:
        v1, v2 = v[:self.nfi], v[self.nfi:]
        Bf = self.B[:, self.lf]
        return np.r_[self.inner.matvec(v1) + Bf @ v2, Bf.T @ v1 + self._Cf() @ v2]
