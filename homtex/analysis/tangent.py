"""The tangent stiffness on the free DOFs: a pattern built once, a factorisation reused.

:class:`FreeSystem` assembles the element tangents (m, 12, 12) of
:func:`homtex.fem.corotational.corotational_tangent` straight into a CSC matrix of the free DOFs
(upper triangle of the symmetric part, slots precomputed per element entry, one numba pass) and
factors it with qdldl (LDL^T: the fill-reducing ordering and the elimination tree are computed
once, each Newton iteration is a numeric ``update``). By Sylvester's law of inertia the number of
negative entries of D is the number of negative eigenvalues of the tangent: the stability of the
state comes with the factor.

Why these choices (measured on the 2-core EPYC of the project, 72 x 72 beam net, 29 400 free
DOFs): qdldl numeric update 0.32 s, SuperLU with its MMD ordering 0.27-0.36 s per factorisation but
no reuse of the ordering and no inertia; CHOLMOD (scikit-sparse, reference BLAS) 0.25 s but
positive definite only. The symmetric part suffices for Newton: the skew part of the consistent
tangent is -1/2 [m]x on each node's rotation block, m the node's internal moment, which is the
residual where no moment is applied (quadratic convergence kept); ``method="lu"`` factors the full
nonsymmetric tangent with SuperLU where moments are applied about fixed axes.

LDL^T without pivoting may lose accuracy on indefinite matrices: every solve is checked against
the assembled matrix, refined, and redone with pivoting (SuperLU) when that does not help.

The factorisation and the solves go through the tangent-solver interface of
:mod:`homtex.linalg.tangent_solver` (analyse once, factor, solve, report): ``tangent_solver=``
names the method of the symmetric tangent (default ``"ldl"``, qdldl as described above).
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import SolverError
from ..fem.corotational_system import add_blocks, scatter_free, sym_upper_matvec
from ..linalg.solvers import blas_single_thread
from ..linalg.tangent_solver import SymmetricUpper, make_tangent_solver, splu_or_raise

log = logging.getLogger(__name__)

# BLAS on one thread for small dense eigenproblems and factors (threads only wait on a shared
# machine: a 3D roll-up took 5 s instead of 0.2 s with them)
one_blas_thread = blas_single_thread


METHODS = ("ldl", "lu")


def _coupling_entries(couplings, fidx):
    """(rows, cols) of the free-DOF entries of the translational 3 x 3 blocks between node pairs
    ``couplings`` (p, 2) (both orders and both diagonal blocks)."""
    cp = np.asarray(couplings, dtype=np.int64).reshape(-1, 2)
    ar = np.arange(3)
    ga = (6 * cp[:, :1] + ar)                                   # (p, 3)
    gb = (6 * cp[:, 1:] + ar)
    g = np.concatenate([ga, gb], axis=1)                        # (p, 6)
    fg = fidx[g]
    r = np.broadcast_to(fg[:, :, None], (len(cp), 6, 6)).ravel()
    c = np.broadcast_to(fg[:, None, :], (len(cp), 6, 6)).ravel()
    return r, c


def _slots(frame, fidx, upper: bool, couplings=None):
    """CSC pattern (indptr, indices) of the free-DOF matrix, the slot of every element entry and
    the sorted entry keys (column * nf + row) of the pattern."""
    el = frame.elements
    ar = np.arange(6)
    g = np.concatenate([6 * el[:, :1] + ar, 6 * el[:, 1:] + ar], axis=1)       # (m, 12)
    fg = fidx[g]
    r = np.broadcast_to(fg[:, :, None], (len(el), 12, 12))
    c = np.broadcast_to(fg[:, None, :], (len(el), 12, 12))
    keep = (r >= 0) & (c >= 0)
    if upper:
        keep &= r <= c
    nf = int(fidx.max()) + 1 if fidx.size and fidx.max() >= 0 else 0
    key = c[keep].astype(np.int64) * nf + r[keep]
    diag = np.arange(nf, dtype=np.int64) * (nf + 1)           # every diagonal entry is stored
    extra = np.zeros(0, dtype=np.int64)
    if couplings is not None and len(couplings):
        cr, cc = _coupling_entries(couplings, fidx)
        ok = (cr >= 0) & (cc >= 0) & ((cr <= cc) if upper else True)
        extra = cc[ok].astype(np.int64) * nf + cr[ok]
    ukey = np.unique(np.concatenate([key, diag, extra]))
    cols = ukey // nf
    indices = (ukey % nf).astype(np.int32)
    indptr = np.zeros(nf + 1, dtype=np.int32)
    np.cumsum(np.bincount(cols, minlength=nf), out=indptr[1:])
    emap = np.full((len(el), 12, 12), -1, dtype=np.int32)
    emap[keep] = np.searchsorted(ukey, key).astype(np.int32)
    return indptr, indices, emap, ukey


class FreeSystem:
    """Tangent on the free DOFs of a frame, assembled into a fixed pattern and factored.

    Parameters
    ----------
    frame : the Frame. mask : (6N,) bool, constrained DOFs; N >= n: nodes beyond the frame's
        (rigid plates of a contact solve, say) carry no elements and couple only through
        ``couplings``.
    method : "ldl" (qdldl on the symmetric part; default) or "lu" (SuperLU on the full tangent).
    tangent_solver : the :mod:`homtex.linalg.tangent_solver` method of the symmetric tangent:
        "ldl", "cholmod", "amg" or "auto" (default: option ``tangent_solver``, "ldl"; with method
        "lu" it only gives the inertia), or a
        :class:`~homtex.linalg.tangent_solver.TangentSolver` instance (not shared between systems).
    couplings : (p, 2) node pairs whose translational 3 x 3 blocks belong to the pattern too
        (contact between yarns, or a yarn and a plate): :meth:`block_slots` maps blocks over
        such nodes to slots and :meth:`add_blocks` adds them after :meth:`assemble` (ldl only).

    Attributes
    ----------
    free : (nf,) global indices of the free DOFs. A : (nf, nf) CSC upper triangle of the
    symmetric part (``data`` refilled by :meth:`assemble`). negative : number of negative pivots
    of the last LDL^T (None when only an LU factor exists).
    """

    def __init__(self, frame, mask: np.ndarray, method: str = "ldl", *, couplings=None, tangent_solver=None):
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}")
        self.method = method
        self._frame = frame
        self.mask = np.asarray(mask, dtype=bool)
        self.free = np.flatnonzero(~self.mask)
        nf = len(self.free)
        self.nf = nf
        fidx = np.full(self.mask.size, -1, dtype=np.int64)
        fidx[self.free] = np.arange(nf)
        if couplings is not None and len(couplings) and method != "ldl":
            raise ValueError("couplings need method 'ldl'")
        self._fidx = fidx
        indptr, indices, self.emap, self._ukey = _slots(frame, fidx, upper=True, couplings=couplings)
        self._slot_cache: dict = {}             # (shape, hash) -> (nodes, slots) of recent block_slots calls
        self.A = sp.csc_matrix((np.zeros(len(indices)), indices, indptr), shape=(nf, nf))
        self.full_map = None
        if self.method == "lu":
            fp, fi, self.full_map, _ = _slots(frame, fidx, upper=False)
            self.F = sp.csc_matrix((np.zeros(len(fi)), fi, fp), shape=(nf, nf))
        self._view = SymmetricUpper(self.A)
        self._sym = None
        # with method "lu" the symmetric solver only counts negative eigenvalues: LDL^T
        self.solver = _tangent_solver("ldl" if method == "lu" else tangent_solver, frame, self.mask, nf)
        self.solver.analyse(self.A, self._view)
        self._lu = make_tangent_solver("lu") if self.method == "lu" else None
        self.negative = None

    @property
    def refinements(self) -> int:
        """Extra solves of iterative refinement so far."""
        return self.solver.report.refinements

    @property
    def fallbacks(self) -> int:
        """Solves redone with a pivoting LU so far."""
        return self.solver.report.fallbacks

    @property
    def report(self):
        """The :class:`~homtex.linalg.tangent_solver.TangentReport` of the symmetric tangent's solver."""
        return self.solver.report

    # -- assembly
    def assemble(self, Ke: np.ndarray) -> None:
        """Fill the free-DOF matrices from element tangents Ke (m, 12, 12)."""
        scatter_free(Ke, self.emap, self.A.data)
        if self.full_map is not None:
            _scatter_full(Ke, self.full_map, self.F.data)
        self._stale()

    def block_slots(self, nodes, strict: bool = True) -> np.ndarray:
        """(na, 3S, 3S) int32 slots of the translational blocks over ``nodes`` (na, S) in the
        upper triangle (-1: a constrained DOF or a lower-triangle entry). A block outside the
        pattern (its node pairs were not among the ``couplings``): SolverError, or with
        ``strict=False`` None."""
        nd = np.asarray(nodes, dtype=np.int64)
        memo = (nd.shape, hash(nd.tobytes()))
        hit = self._slot_cache.get(memo)
        if hit is not None and np.array_equal(hit[0], nd):
            return hit[1]           # a Newton iteration's contact set is mostly the previous one's
        na, S = nd.shape
        dof = (6 * nd[:, :, None] + np.arange(3)).reshape(na, 3 * S)
        fg = self._fidx[dof]
        r = np.broadcast_to(fg[:, :, None], (na, 3 * S, 3 * S))
        c = np.broadcast_to(fg[:, None, :], (na, 3 * S, 3 * S))
        keep = (r >= 0) & (c >= 0) & (r <= c)
        key = c[keep].astype(np.int64) * max(self.nf, 1) + r[keep]
        pos = np.searchsorted(self._ukey, key)
        pos = np.minimum(pos, len(self._ukey) - 1)
        if key.size and not np.array_equal(self._ukey[pos], key):
            if not strict:
                return None
            raise SolverError("a contact block lies outside the tangent's pattern (couplings missing)")
        out = np.full((na, 3 * S, 3 * S), -1, dtype=np.int32)
        out[keep] = pos.astype(np.int32)
        out.flags.writeable = False             # shared with the next call for the same nodes
        if len(self._slot_cache) >= 8:          # pairs, plates, friction, terms: a few live sets
            self._slot_cache.clear()
        self._slot_cache[memo] = (nd.copy(), out)
        return out

    def add_blocks(self, blocks: np.ndarray, slots: np.ndarray) -> None:
        """Add symmetric blocks (na, B, B) at ``slots`` (na, B, B) from :meth:`block_slots`."""
        if len(blocks):
            add_blocks(np.ascontiguousarray(blocks, dtype=float), np.ascontiguousarray(slots), self.A.data)
        self._stale()

    def add_diagonal(self, d: np.ndarray) -> None:
        """Add d (nf,) to the diagonal of the free matrix."""
        self.A.data[self.A.indptr[1:] - 1] += d
        self._stale()

    def diagonal(self) -> np.ndarray:
        """(nf,) the diagonal of the free matrix (last assembly)."""
        return self.A.data[self.A.indptr[1:] - 1].copy()

    def shift_diagonal(self, sigma: float, base: np.ndarray | None = None) -> np.ndarray:
        """Set the diagonal of the free matrix to base (1 + sigma) (base: the assembled diagonal,
        returned when not given) to make it positive definite; refactor afterwards."""
        slots = self.A.indptr[1:] - 1          # rows are sorted: the diagonal ends each column
        if base is None:
            base = self.A.data[slots].copy()
        self.A.data[slots] = base + sigma * np.abs(base)
        self._stale()
        return base

    def _stale(self) -> None:
        """The values changed: drop the cached full matrix."""
        self._sym = None
        self._view.invalidate()

    def symmetric(self) -> sp.csc_matrix:
        """The full symmetric matrix (both triangles) of the last assembly."""
        if self._sym is None:
            self._sym = self._view.full()
        return self._sym

    # -- factorisation
    def factor(self, inertia: bool = True) -> None:
        """Factor the last assembled matrix (numeric only after the first call)."""
        self.negative = None
        if self.method == "lu":
            self._lu.factor(self.F, inertia=False)
            if inertia:
                self.solver.factor(self.A, inertia=True)
                self.negative = self.solver.negative
            return
        self.solver.factor(self.A, inertia=inertia)
        self.negative = self.solver.negative

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x with (free tangent) x = b, checked against the assembled matrix and refined; (nf,)."""
        if self.method == "lu":
            return self._lu.solve(b)
        return self.solver.solve(b)

    def full(self, Ke: np.ndarray) -> sp.csc_matrix:
        """The full (nonsymmetric) free-DOF tangent assembled from Ke (m, 12, 12)."""
        if self.full_map is None:
            fidx = np.full(self.mask.size, -1, dtype=np.int64)
            fidx[self.free] = np.arange(self.nf)
            fp, fi, self.full_map, _ = _slots(self._frame, fidx, upper=False)
            self.F = sp.csc_matrix((np.zeros(len(fi)), fi, fp), shape=(self.nf, self.nf))
        _scatter_full(Ke, self.full_map, self.F.data)
        return self.F

    def matvec(self, x: np.ndarray) -> np.ndarray:
        """Symmetric free-DOF matrix (last assembly) times x (nf,)."""
        out = np.empty(self.nf)
        A = self.A
        sym_upper_matvec(A.indptr, A.indices, A.data, np.ascontiguousarray(x, dtype=float), out)
        return out


_splu = splu_or_raise


def _tangent_solver(spec, frame, mask, nf):
    """The TangentSolver of a FreeSystem from a name (None: option ``tangent_solver``) or an instance."""
    from ..config import option

    if spec is not None and not isinstance(spec, str):
        return spec
    name = option("tangent_solver", spec)
    if name in ("amg", "auto"):
        from ..linalg.tangent_backends import AMGTangent, auto_tangent_solver

        N = mask.size // 6
        nodes = np.empty((N, 3))
        nodes[:frame.n_nodes] = frame.nodes
        nodes[frame.n_nodes:] = frame.nodes.mean(axis=0)
        if name == "auto":
            return auto_tangent_solver(nf, nodes, mask)
        return AMGTangent(nodes, mask, tol=min(option("tol"), 1e-10))
    if name in ("cholmod", "pardiso"):
        from ..linalg import tangent_backends  # noqa: F401  (registers them)
    return make_tangent_solver(name)


def _scatter_full(Ke, fmap, data):
    data[:] = 0.0
    ok = fmap >= 0
    np.add.at(data, fmap[ok], Ke[ok])


def real_negative_eigenvalues(K: sp.spmatrix, k: int = 8) -> int:
    """Number of real negative eigenvalues of a nonsymmetric matrix (divergence modes) in the
    metric of its diagonal: eigenvalues mu of K v = mu D v, D = |diag K| (the same as those of
    D^-1/2 K D^-1/2, so translations and rotations are commensurate and a slender rod's complex
    pair is not mistaken for two real ones), all of them for small matrices (dense), else the k
    nearest zero (shift-invert). Real: |Im mu| <= 1e-8 |mu|; negative: Re mu below -1e-14."""
    n = K.shape[0]
    d = np.abs(K.diagonal())
    d = np.where(d > 0, d, max(float(d.max(initial=1.0)), 1.0))
    sc = sp.diags(1.0 / np.sqrt(d))
    Ks = sp.csc_matrix(sc @ K @ sc)
    if n <= 600:
        with one_blas_thread():
            ev = np.linalg.eigvals(Ks.toarray())
    else:
        try:
            ev = spla.eigs(Ks, k=min(k, n - 2), sigma=0.0, which="LM", return_eigenvectors=False)
        except RuntimeError:
            ev = spla.eigs(Ks, k=min(k, n - 2), sigma=-1e-10, which="LM", return_eigenvectors=False)
    real = np.abs(ev.imag) <= 1e-8 * np.abs(ev) + 1e-15
    return int(np.count_nonzero(real & (ev.real < -1e-14)))
