"""One interface for the tangent solves of the nonlinear solvers: analyse, factor, solve, report.

The co-rotational Newton of :mod:`homtex.analysis` and the large-motion contact engine solve
with a symmetric tangent whose sparsity pattern is fixed for many iterations (it grows only when
new contact pairs join). Everything they need from a linear solver is here:

1. ``analyse(A)`` once per pattern (orderings, elimination trees, symbolic factors, hierarchies),
2. ``factor(A, inertia=...)`` per numeric tangent (an LDL^T, a Cholesky, or a preconditioner for
   a positive-definite PTC-shifted tangent), with the inertia where the method gives it:
   ``negative`` (number of negative eigenvalues; None: not known) and ``positive_definite``,
3. ``solve(b)`` accurate to the assembled matrix (checked, refined, or redone with pivoting),
4. ``report`` (:class:`TangentReport`: method, counts and seconds of each phase).

``A`` is the free-DOF matrix as :class:`~homtex.analysis.tangent.FreeSystem` stores it: the
upper triangle of the symmetric tangent, CSC, (nf, nf), every diagonal entry stored and last in
its column. A method that needs the full matrix or products with it gets them from a
:class:`SymmetricUpper` view (made once per pattern).

Implementations: :class:`QdldlTangent` (``"ldl"``: qdldl LDL^T, non-supernodal, one thread; the
inertia from the signs of D; iterative refinement; SuperLU with pivoting when LDL^T without
pivoting fails on an indefinite matrix) and :class:`SuperLUTangent` (``"lu"``: SuperLU of a full,
possibly nonsymmetric matrix). :func:`make_tangent_solver` builds one by name; the registry
:data:`TANGENT_SOLVERS` takes further methods.
"""

from __future__ import annotations

import abc
import logging
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import SolverError

try:
    import qdldl as _qdldl
except Exception:  # pragma: no cover - qdldl is a declared dependency
    _qdldl = None

log = logging.getLogger(__name__)

__all__ = ["TANGENT_SOLVERS", "QdldlTangent", "SuperLUTangent", "SymmetricUpper", "TangentReport",
           "TangentSolver", "make_tangent_solver", "register_tangent_solver", "splu_or_raise"]


@dataclass
class TangentReport:
    """What a tangent solver did since it was made (seconds are wall time).

    method : name of the method (and backend). nf : unknowns. analyses, factorizations, solves :
    counts. analyse_seconds, factor_seconds, solve_seconds : time in each phase. refinements :
    extra solves of iterative refinement. fallbacks : solves redone with a pivoting LU.
    iterations : Krylov iterations of iterative methods (0 for direct ones). negative : negative
    eigenvalues of the last factored matrix (None: not known). positive_definite : of the last
    factored matrix (None: not known).
    """

    method: str
    nf: int = 0
    analyses: int = 0
    factorizations: int = 0
    solves: int = 0
    analyse_seconds: float = 0.0
    factor_seconds: float = 0.0
    solve_seconds: float = 0.0
    refinements: int = 0
    fallbacks: int = 0
    iterations: int = 0
    negative: int | None = None
    positive_definite: bool | None = None

    def as_dict(self) -> dict:
        return dict(self.__dict__)


class SymmetricUpper:
    """The full symmetric matrix behind an upper-triangle CSC ``A`` (values read when asked).

    ``matvec(x)``: (A + A^T - diag A) x in one numba pass over the upper triangle; ``full()``:
    the full CSC matrix (cached until ``invalidate()``, which :meth:`TangentSolver.factor` calls).
    """

    def __init__(self, A: sp.csc_matrix):
        self.A = A
        self._full = None

    def invalidate(self) -> None:
        self._full = None

    def full(self) -> sp.csc_matrix:
        if self._full is None:
            U = self.A
            self._full = (U + U.T - sp.diags(U.diagonal())).tocsc()
        return self._full

    def matvec(self, x: np.ndarray) -> np.ndarray:
        from ..fem.corotational_system import sym_upper_matvec

        A = self.A
        out = np.empty(A.shape[0])
        sym_upper_matvec(A.indptr, A.indices, A.data, np.ascontiguousarray(x, dtype=float), out)
        return out


class TangentSolver(abc.ABC):
    """Base of the tangent solvers (see the module docstring for the protocol).

    Subclasses implement :meth:`_analyse`, :meth:`_factor` and :meth:`_solve`; the public methods
    here time them, count them and keep the report. ``A`` must keep its pattern between
    :meth:`analyse` and later :meth:`factor` calls (numeric values may change in place).
    """

    name = "base"
    #: whether ``factor(inertia=True)`` gives the number of negative eigenvalues
    gives_inertia = False

    def __init__(self):
        self.report = TangentReport(method=self.name)
        self.view: SymmetricUpper | None = None
        self._pattern = None

    # -- public protocol
    @property
    def negative(self) -> int | None:
        return self.report.negative

    @property
    def positive_definite(self) -> bool | None:
        return self.report.positive_definite

    def analyse(self, A: sp.csc_matrix, view: SymmetricUpper | None = None) -> None:
        """Analyse the pattern of ``A`` (nf, nf) once; ``view`` its :class:`SymmetricUpper` (made if
        None: pass the one that holds ``A`` to share the cached full matrix)."""
        t0 = time.perf_counter()
        self.view = view if view is not None else SymmetricUpper(A)
        self.report.nf = A.shape[0]
        self._pattern = (A.indptr, A.indices)
        self._analyse(A)
        self.report.analyses += 1
        self.report.analyse_seconds += time.perf_counter() - t0

    def factor(self, A: sp.csc_matrix, *, inertia: bool = True) -> None:
        """Factor (or precondition) the current values of ``A``; sets ``negative`` and
        ``positive_definite`` where known (``inertia=False`` may skip counting)."""
        if self.view is None or self.view.A is not A or self._pattern is None or \
                self._pattern[0] is not A.indptr or self._pattern[1] is not A.indices:
            self.analyse(A)
        self.view.invalidate()
        t0 = time.perf_counter()
        self.report.negative = None
        self.report.positive_definite = None
        self._factor(A, inertia)
        self.report.factorizations += 1
        self.report.factor_seconds += time.perf_counter() - t0

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x with (symmetric tangent) x = b, (nf,), accurate to the assembled matrix."""
        t0 = time.perf_counter()
        x = self._solve(np.asarray(b, dtype=float))
        self.report.solves += 1
        self.report.solve_seconds += time.perf_counter() - t0
        return x

    # -- to implement
    def _refined(self, solve, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """x = solve(b), refined against the assembled matrix (x += solve(b - A x)) up to
        ``self.max_refine`` times until ||b - A x|| <= ``self.refine_tol`` ||b||; returns (x, b - A x)."""
        x = solve(b)
        nb = float(np.linalg.norm(b))
        if nb == 0.0:
            return x, np.zeros_like(b)
        mv = self.view.matvec
        r = b - mv(x)
        for _ in range(self.max_refine):
            if float(np.linalg.norm(r)) <= self.refine_tol * nb:
                break
            self.report.refinements += 1
            x = x + solve(r)
            r = b - mv(x)
        return x, r

    def _analyse(self, A) -> None:  # noqa: B027 - an optional hook, not abstract
        """Analyse the sparsity pattern once (default: nothing to analyse)."""

    @abc.abstractmethod
    def _factor(self, A, inertia: bool) -> None:
        """Factor A (inertia: count its negative eigenvalues into the report)."""

    @abc.abstractmethod
    def _solve(self, b) -> np.ndarray:
        """x with A x = b from the current factorisation."""


def splu_or_raise(A):
    """SuperLU of A (CSC); a singular matrix raises SolverError."""
    try:
        return spla.splu(sp.csc_matrix(A))
    except RuntimeError as err:     # "Factor is exactly singular"
        raise SolverError(f"the tangent stiffness is singular ({err})") from err


class QdldlTangent(TangentSolver):
    """qdldl LDL^T of the symmetric tangent (the default; the inertia comes with it).

    The fill-reducing ordering and the elimination tree are computed by the first factorisation,
    every later one is a numeric ``update``. By Sylvester's law of inertia the number of negative
    entries of D is the number of negative eigenvalues. An exactly zero pivot (a singular tangent
    hit on the nose) perturbs the diagonal by 1e-13 max|diag| and factors again; if that fails too
    the symmetric matrix is factored by SuperLU (no inertia). LDL^T without pivoting may lose
    accuracy on indefinite matrices: every solve is checked against the assembled matrix, refined
    (at most 3 times, to 1e-9), and redone with SuperLU with pivoting when the residual stays
    above 1e-6.
    """

    name = "ldl"
    gives_inertia = True

    def __init__(self, *, refine_tol: float = 1e-9, fallback_tol: float = 1e-6, max_refine: int = 3):
        if _qdldl is None:
            raise ImportError("the large-rotation solver needs qdldl (LDL^T with reused symbolic analysis and the "
                              "inertia of the tangent): pip install qdldl")
        super().__init__()
        self.refine_tol, self.fallback_tol, self.max_refine = refine_tol, fallback_tol, max_refine
        self._qd = None
        self._lu = None

    def _analyse(self, A) -> None:
        self._qd = None         # qdldl's symbolic analysis happens in its first factorisation
        self._lu = None

    def _factor(self, A, inertia: bool) -> None:
        self._lu = None
        try:
            if self._qd is None:
                self._qd = _qdldl.Solver(A, upper=True)
            else:
                self._qd.update(A, upper=True)
        except RuntimeError:
            # an exactly zero pivot: perturb the diagonal by round-off and factor again; Newton
            # absorbs the perturbation
            d = np.abs(A.diagonal())
            eps = 1e-13 * float(d.max(initial=1.0))
            B = A + eps * sp.eye(A.shape[0], format="csc")
            B = sp.csc_matrix((B.data, B.indices, B.indptr), shape=A.shape)
            if B.nnz != A.nnz:
                raise SolverError("the tangent's pattern changed") from None
            try:
                self._qd = _qdldl.Solver(B, upper=True)
            except RuntimeError:
                self._qd = None
                self._lu = splu_or_raise(self.view.full())
                return
        if inertia:
            _, D, _ = self._qd.factors()
            neg = int(np.count_nonzero(D < 0.0))
            self.report.negative = neg
            self.report.positive_definite = neg == 0 and bool(np.all(D > 0.0))

    def _solve(self, b) -> np.ndarray:
        if self._qd is None:
            if self._lu is None:
                raise SolverError("solve before factor")
            return self._lu.solve(b)
        x, r = self._refined(self._qd.solve, b)
        nb = float(np.linalg.norm(b))
        if nb > 0.0 and float(np.linalg.norm(r)) / nb > self.fallback_tol:
            # LDL^T without pivoting failed on an indefinite matrix: pivoting LU for this solve
            self.report.fallbacks += 1
            log.debug("LDL^T solve inaccurate (%.1e); SuperLU with pivoting", float(np.linalg.norm(r)) / nb)
            x = splu_or_raise(self.view.full()).solve(b)
        return x


class SuperLUTangent(TangentSolver):
    """SuperLU (partial pivoting) of a full, possibly nonsymmetric free-DOF matrix ``F``.

    For the ``"lu"`` path of the co-rotational solver (moments applied about fixed axes make the
    consistent tangent nonsymmetric). Gives no inertia. ``A`` here is the full matrix, not an
    upper triangle; :meth:`solve` is SuperLU's.
    """

    name = "lu"

    def __init__(self):
        super().__init__()
        self._lu = None

    def analyse(self, A, view=None) -> None:   # the full matrix: no SymmetricUpper view
        t0 = time.perf_counter()
        self.view = _FullView(A)
        self.report.nf = A.shape[0]
        self._pattern = (A.indptr, A.indices)
        self.report.analyses += 1
        self.report.analyse_seconds += time.perf_counter() - t0

    def _factor(self, A, inertia: bool) -> None:
        self._lu = splu_or_raise(A)

    def _solve(self, b) -> np.ndarray:
        return self._lu.solve(b)


class _FullView(SymmetricUpper):
    def full(self):
        return sp.csc_matrix(self.A)

    def matvec(self, x):
        return self.A @ x


#: name -> factory(**options) of the tangent solvers
TANGENT_SOLVERS: dict = {"ldl": QdldlTangent, "lu": SuperLUTangent}


def register_tangent_solver(name: str, factory) -> None:
    """Make ``make_tangent_solver(name)`` build ``factory(**options)`` (optional backends)."""
    TANGENT_SOLVERS[name] = factory


def make_tangent_solver(name: str = "ldl", **options) -> TangentSolver:
    """A tangent solver by name (``"ldl"``, ``"lu"``, or a registered one)."""
    if name not in TANGENT_SOLVERS:
        raise ValueError(f"tangent solver must be one of {tuple(TANGENT_SOLVERS)}, got {name!r}")
    return TANGENT_SOLVERS[name](**options)
