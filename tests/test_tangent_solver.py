"""The tangent-solver interface (homtex.linalg.tangent_solver): analyse, factor, solve, report."""

import gc
import os

import numpy as np
import pytest
import scipy.sparse as sp

from homtex.errors import SolverError
from homtex.linalg.tangent_solver import (
    QdldlTangent,
    SymmetricUpper,
    TangentSolver,
    make_tangent_solver,
    register_tangent_solver,
)


def _upper(S):
    """Upper triangle (CSC, diagonal stored, sorted) of a symmetric matrix S."""
    U = sp.triu(sp.csc_matrix(S) + sp.eye(S.shape[0]) * 0.0, format="csc")
    U.sort_indices()
    return U


def _random_sym(n, seed, shift):
    rng = np.random.default_rng(seed)
    M = sp.random(n, n, density=0.15, random_state=rng)
    S = (M + M.T).toarray() + shift * np.eye(n)
    return S


@pytest.mark.parametrize("shift", [6.0, -0.7])
def test_ldl_solves_and_counts_negative_eigenvalues(shift):
    S = _random_sym(60, 1, shift)
    U = _upper(S)
    ts = make_tangent_solver("ldl")
    ts.factor(U, inertia=True)
    ev = np.linalg.eigvalsh(S)
    assert ts.negative == int(np.sum(ev < 0))
    assert ts.positive_definite == bool(np.all(ev > 0))
    b = np.arange(60.0) - 30.0
    x = ts.solve(b)
    assert np.linalg.norm(S @ x - b) <= 1e-9 * np.linalg.norm(b)
    rep = ts.report
    assert (rep.factorizations, rep.solves, rep.analyses) == (1, 1, 1)


def test_numeric_update_reuses_the_analysis():
    S = _random_sym(40, 2, 5.0)
    U = _upper(S)
    ts = QdldlTangent()
    ts.factor(U)
    U.data *= 2.0                       # same pattern, new values, in place
    ts.factor(U)
    b = np.ones(40)
    assert np.allclose(2.0 * S @ ts.solve(b), b, atol=1e-10)
    assert ts.report.analyses == 1 and ts.report.factorizations == 2


def test_refinement_and_pivoting_fallback_on_a_bad_indefinite_matrix():
    # LDL^T without pivoting meets a tiny pivot: refinement and, failing that, SuperLU with pivoting
    eps = 1e-14
    S = np.array([[eps, 1.0, 0.0], [1.0, eps, 1.0], [0.0, 1.0, 2.0]])
    ts = QdldlTangent()
    ts.factor(_upper(S))
    b = np.array([1.0, 2.0, 3.0])
    x = ts.solve(b)
    assert np.allclose(S @ x, b, atol=1e-10)
    assert ts.report.refinements + ts.report.fallbacks >= 1


def test_symmetric_view_products():
    S = _random_sym(30, 3, 1.0)
    U = _upper(S)
    v = SymmetricUpper(U)
    x = np.linspace(-1, 1, 30)
    assert np.allclose(v.matvec(x), S @ x)
    assert np.allclose(v.full().toarray(), S)


def test_lu_method_and_registry():
    rng = np.random.default_rng(4)
    F = sp.csc_matrix(rng.normal(size=(20, 20)) + 10 * np.eye(20))
    ts = make_tangent_solver("lu")
    ts.factor(F)
    b = rng.normal(size=20)
    assert np.allclose(F @ ts.solve(b), b)
    with pytest.raises(ValueError, match="tangent solver must be one of"):
        make_tangent_solver("nope")

    class Dense(TangentSolver):
        name = "dense"

        def _factor(self, A, inertia):
            self.M = self.view.full().toarray()

        def _solve(self, b):
            return np.linalg.solve(self.M, b)

    register_tangent_solver("dense_test", Dense)
    try:
        S = _random_sym(10, 5, 4.0)
        d = make_tangent_solver("dense_test")
        d.factor(_upper(S))
        assert np.allclose(S @ d.solve(np.ones(10)), 1.0)
    finally:
        from homtex.linalg.tangent_solver import TANGENT_SOLVERS
        TANGENT_SOLVERS.pop("dense_test")


def test_singular_matrix_raises():
    ts = make_tangent_solver("lu")
    with pytest.raises(SolverError, match="singular"):
        ts.factor(sp.csc_matrix(np.zeros((3, 3))))


def test_free_system_routes_through_the_interface():
    """FreeSystem's factor/solve/negative come from its tangent solver, with the answers of a direct
    qdldl factorisation of the same matrix (bit for bit: the same calls)."""
    import qdldl

    import homtex
    from homtex.analysis.tangent import FreeSystem
    from homtex.fem.assembly import Assembler

    nodes = np.c_[np.linspace(0, 10, 6), np.zeros(6), np.zeros(6)]
    frame = homtex.Frame(nodes, np.c_[np.arange(5), np.arange(1, 6)], radius=0.5, E=1000.0, nu=0.3)
    mask = np.zeros(36, dtype=bool)
    mask[:6] = True
    sys = FreeSystem(frame, mask)
    K = Assembler(frame).stiffness().toarray()[np.ix_(~mask, ~mask)]
    A = sys.A
    cols = np.repeat(np.arange(sys.nf), np.diff(A.indptr))
    A.data[:] = K[A.indices, cols]
    sys.factor(inertia=True)
    assert sys.negative == 0
    b = np.linspace(1.0, 2.0, sys.nf)
    x = sys.solve(b)
    assert np.array_equal(x, qdldl.Solver(A, upper=True).solve(b))
    assert np.allclose(K @ x, b)
    assert sys.report.factorizations == 1 and sys.report.solves == 1
    assert sys.refinements == 0 and sys.fallbacks == 0
    sys.shift_diagonal(-2.0)              # diag -> -diag: indefinite, negative pivots counted
    sys.factor(inertia=True)
    assert sys.negative == int(np.sum(np.linalg.eigvalsh(sys.symmetric().toarray()) < 0)) > 0


def _pardiso():
    pytest.importorskip("pypardiso")
    from homtex.linalg.tangent_backends import PardisoTangent

    return PardisoTangent


@pytest.mark.parametrize("shift", [6.0, -0.7, 0.0])
def test_pardiso_counts_the_inertia_and_solves_like_the_spectrum_says(shift):
    """PARDISO's LDL^T with Bunch-Kaufman pivoting (the optional ``"pardiso"`` tangent solver):
    its count of negative eigenvalues is the spectrum's, its solve is exact to round-off, and a
    new factorisation of the same pattern reuses the analysis."""
    PardisoTangent = _pardiso()
    S = _random_sym(60, 1, shift)
    U = _upper(S)
    ts = make_tangent_solver("pardiso")
    assert isinstance(ts, PardisoTangent)
    ts.factor(U, inertia=True)
    ev = np.linalg.eigvalsh(S)
    assert np.min(np.abs(ev)) > 1e-6
    assert ts.negative == int(np.sum(ev < 0)) and ts.positive_definite == bool(np.all(ev > 0))
    b = np.arange(60.0) - 30.0
    assert np.linalg.norm(S @ ts.solve(b) - b) <= 1e-9 * np.linalg.norm(b)
    U.data *= -2.0                      # same pattern: the inertia flips, the analysis is kept
    ts.factor(U, inertia=True)
    assert ts.negative == int(np.sum(ev > 0)) and ts.report.analyses == 1
    assert np.linalg.norm(-2.0 * S @ ts.solve(b) - b) <= 1e-9 * np.linalg.norm(b)


def test_a_new_pardiso_pattern_does_not_search_the_disk_for_mkl_again(monkeypatch):
    """pypardiso looks for MKL's library by a recursive directory search at every construction
    (0.3-0.7 s, once per contact pattern of the engine); after the first, homtex hands it the path
    it found, and leaves the environment as it was."""
    PardisoTangent = _pardiso()
    import pypardiso.pardiso_wrapper as pw

    S = _random_sym(40, 4, 6.0)
    U = _upper(S)
    PardisoTangent().analyse(U)                     # the first one may search
    monkeypatch.delenv("PYPARDISO_MKL_RT", raising=False)
    monkeypatch.setattr(pw, "find_library", lambda name: None)

    def no_search(*args, **kwargs):
        raise AssertionError("searched the disk for mkl_rt again")

    monkeypatch.setattr(pw.glob, "glob", no_search)
    ts = PardisoTangent()
    ts.analyse(U)
    ts.factor(U, inertia=True)
    b = np.ones(40)
    assert np.linalg.norm(S @ ts.solve(b) - b) <= 1e-9 * np.linalg.norm(b)
    assert "PYPARDISO_MKL_RT" not in os.environ


def test_a_dropped_pardiso_factor_hands_its_memory_back_to_mkl(monkeypatch):
    """PARDISO keeps its factor in MKL's memory until phase -1; the engine drops a solver at every
    new contact pattern (483 in the 43 mm seam's press, about 6.5 MB each on a 13 000-DOF
    Laplacian), so a dropped one frees it."""
    PardisoTangent = _pardiso()
    import pypardiso

    freed = []
    real = pypardiso.PyPardisoSolver.free_memory
    monkeypatch.setattr(pypardiso.PyPardisoSolver, "free_memory",
                        lambda self, everything=False: (freed.append(everything), real(self, everything)))
    U = _upper(_random_sym(40, 5, 6.0))
    ts = PardisoTangent()
    ts.factor(U, inertia=True)
    del ts
    gc.collect()
    assert freed == [True]


def test_pardiso_and_ldl_follow_the_same_engine_path(monkeypatch):
    """The spacer cell pressed past its pile's buckling on the large-motion engine (an indefinite
    beam tangent the engine shifts until no pivot is negative): the same stresses with either
    tangent solver, the option reaching the engine's factorisations."""
    PardisoTangent = _pardiso()
    import homtex

    used = []
    real = PardisoTangent._factor
    monkeypatch.setattr(PardisoTangent, "_factor", lambda self, A, inertia: (used.append(1), real(self, A, inertia)))

    cell = homtex.load_cell("spacer_20mm")
    out = {}
    for name in ("ldl", "pardiso"):
        with homtex.set_options(tangent_solver=name):
            ds = homtex.compress(cell, strain=[0.0025, 0.005, 0.01, 0.02], geometry="nonlinear")
        assert ds.attrs["status"] == "ok"
        out[name] = ds.stress.values
    assert np.all(out["ldl"] > 0) and len(used) > 10
    np.testing.assert_allclose(out["pardiso"], out["ldl"], rtol=1e-6)
