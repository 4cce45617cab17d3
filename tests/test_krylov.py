"""Multi-right-hand-side kernels: block products, block V-cycle, lockstep PCG, homogenize wiring."""

import numpy as np
import pytest
import scipy.sparse as sp

import homtex
from homtex import SolverError
from homtex.analysis.periodic import _Operator, unit_strains
from homtex.geometry.lattices import lattice_frame
from homtex.linalg.krylov import BlockOperator, bsr_gemm
from homtex.linalg.multirhs import BatchedVCycle, block_pcg, solve_many
from homtex.linalg.nullspace import rigid_body_modes
from homtex.linalg.solvers import LinearSolver, ScaledAMG


def _random_bsr(nbr, nbc, R, C, seed=0, per_row=3):
    rng = np.random.default_rng(seed)
    rows = np.repeat(np.arange(nbr), per_row)
    cols = rng.integers(0, nbc, rows.size)
    S = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(nbr, nbc))  # sums duplicates
    data = rng.standard_normal((S.nnz, R, C))
    return sp.bsr_matrix((data, S.indices, S.indptr), shape=(nbr * R, nbc * C))


@pytest.mark.parametrize("R,C", [(6, 6), (6, 3), (3, 6), (1, 1)])
@pytest.mark.parametrize("k", [1, 2, 6])
def test_block_product_equals_scipy(R, C, k):
    """A @ X from one pass over A equals scipy's column-by-column products (all kernels)."""
    A = _random_bsr(37, 29, R, C, seed=R * 10 + C)
    X = np.random.default_rng(1).standard_normal((A.shape[1], k))
    ref = np.column_stack([A @ X[:, c] for c in range(k)])
    got = bsr_gemm(A, X)
    assert got.shape == ref.shape
    assert np.abs(got - ref).max() <= 1e-13 * np.abs(ref).max()
    # fused forms: Y = alpha Z + s A X, also in place (Z is Y)
    op = BlockOperator(A)
    Z = np.random.default_rng(2).standard_normal((A.shape[0], k))
    Y = Z.copy()
    op.gemm(np.ascontiguousarray(X), Y, alpha=0.5, Z=Y, s=-2.0)
    assert np.abs(Y - (0.5 * Z - 2.0 * ref)).max() <= 1e-13 * np.abs(ref).max()
    # a CSR matrix is taken as 1x1 blocks
    assert np.allclose(bsr_gemm(A.tocsr(), X), ref, rtol=0, atol=1e-13 * np.abs(ref).max())


@pytest.fixture(scope="module")
def cell():
    """A wavy periodic octet 2x2x2 supercell (fluctuations are not affine), ~3.6k DOF."""
    fr = lattice_frame("octet", radius=0.02, E=1000.0, nu=0.3, elements_per_strut=3,
                       repeat=(2, 2, 2), periodic=True, waviness=0.1)
    op = _Operator(fr, "amg", 1e-10, None)
    # a deeper hierarchy than the default (2.5k DOF fit the 3000-unknown coarse grid)
    h = ScaledAMG(op.A, rigid_body_modes(fr.nodes), max_coarse=150)
    op.lin = LinearSolver(op.A, method="amg", hierarchy=h, tol=1e-10)
    return fr, op, op.rhs(unit_strains(fr))


def test_block_vcycle_equals_pyamg_preconditioner(cell):
    """The block V-cycle is pyamg's V-cycle (Chebyshev, R, coarse LU, P) column by column."""
    _, op, b = cell
    assert len(op.lin.ml.ml.levels) >= 3
    V = BatchedVCycle(op.lin.ml)
    rng = np.random.default_rng(3)
    Rr = np.column_stack([b.T, rng.standard_normal((b.shape[1], 2))])
    Rr[op.mask] = 0.0
    for cols in (Rr[:, :6], Rr[:, :1], Rr[:, 2:5]):
        Z = V(cols)
        ref = np.column_stack([op.lin.M @ cols[:, c] for c in range(cols.shape[1])])
        assert np.abs(Z - ref).max() <= 1e-12 * np.abs(ref).max()
    # a zero column stays zero next to nonzero ones (frozen CG columns rely on it)
    mixed = Rr[:, :6].copy()
    mixed[:, 2] = 0.0
    assert np.all(V(mixed)[:, 2] == 0.0)


def test_batched_vcycle_translations_nullspace_and_one_level():
    """Other block shapes (6x3 prolongation with 3 near-null vectors) go the general way;
    a one-level hierarchy is its coarse solve."""
    fr = lattice_frame("octet", radius=0.02, E=1000.0, nu=0.3, elements_per_strut=3,
                       repeat=(2, 2, 2), periodic=True, waviness=0.1)
    op = _Operator(fr, "amg", 1e-10, None, nullspace="translations")
    b = op.rhs(unit_strains(fr))
    V = BatchedVCycle(op.lin.ml)
    Z = V(b.T)
    ref = np.column_stack([op.lin.M @ b[c] for c in range(6)])
    assert np.abs(Z - ref).max() <= 1e-12 * np.abs(ref).max()
    h = ScaledAMG(op.A, rigid_body_modes(fr.nodes)[:, :3], max_coarse=150)
    assert len(h.ml.levels) >= 2 and h.ml.levels[0].P.blocksize == (6, 3)
    Z = BatchedVCycle(h)(b.T)
    M = h.aspreconditioner()
    ref = np.column_stack([M @ b[c] for c in range(6)])
    assert np.abs(Z - ref).max() <= 1e-12 * np.abs(ref).max()
    assert len(op.lin.ml.ml.levels) == 1  # default coarse limit: the whole 2.5k-DOF cell


def test_solve_many_equals_one_by_one(cell):
    """Lockstep block CG gives each case's iterates: same iterations, same answer to 1e-9."""
    _, op, b = cell
    X, reps = solve_many(op.lin, b)
    for q in range(len(b)):
        x, rep = op.lin.solve(b[q])
        assert abs(reps[q].iterations - rep.iterations) <= 1
        assert np.abs(X[q] - x).max() <= 1e-9 * np.abs(x).max()
        assert reps[q].residual <= op.lin.tol * 10
        r = b[q] - op.A @ X[q]
        assert np.linalg.norm(r) <= 10 * op.lin.tol * np.linalg.norm(b[q])
    # a zero right-hand side among others is solved by zero, with a zero residual
    b0 = b.copy()
    b0[2] = 0.0
    X0, reps0 = solve_many(op.lin, b0)
    assert np.all(X0[2] == 0.0) and reps0[2].residual == 0.0
    assert np.abs(X0[[0, 1, 3, 4, 5]] - X[[0, 1, 3, 4, 5]]).max() <= 1e-12 * np.abs(X).max()


def test_homogenize_batched_equals_sequential(cell):
    """homogenize(batched=True) == batched=False: C to 1e-9, fluctuations to 1e-9."""
    fr, _, _ = cell
    hb = homtex.homogenize(fr)
    hs = homtex.homogenize(fr, batched=False)
    assert hb.info["batched"] and not hs.info["batched"]
    assert np.abs(hb.C - hs.C).max() <= 1e-9 * np.abs(hs.C).max()
    assert np.abs(hb.fluctuation - hs.fluctuation).max() <= 1e-9 * np.abs(hs.fluctuation).max()
    # the direct solver is the reference for both
    hd = homtex.homogenize(fr, solver="direct")
    assert np.abs(hb.C - hd.C).max() <= 1e-8 * np.abs(hd.C).max()
    assert len(hb.reports) == 6 and all(r.iterations > 0 for r in hb.reports)


def test_homogenize_batched_membrane():
    """A 2-periodic cell (3 cases, padded to the 6-wide kernel) agrees with the sequential path."""
    fr = lattice_frame("honeycomb", radius=0.05, E=1000.0, nu=0.3, elements_per_strut=4,
                       repeat=(3, 3), periodic=True, waviness=0.1)
    hb = homtex.homogenize(fr)
    hs = homtex.homogenize(fr, batched=False)
    assert hb.C.shape == (3, 3)
    assert np.abs(hb.C - hs.C).max() <= 1e-9 * np.abs(hs.C).max()


def test_block_pcg_stops_each_column_and_detects_indefinite():
    """Columns stop at their own tolerance; p^T A p <= 0 raises naming the column."""
    n = 300
    main = np.linspace(1.0, 1e3, n)
    A = sp.bsr_matrix(sp.diags([main, -0.3 * np.ones(n - 1), -0.3 * np.ones(n - 1)],
                               [0, 1, -1]).tocsr(), blocksize=(6, 6))
    rng = np.random.default_rng(4)
    B = rng.standard_normal((n, 6))
    B[:, 1] *= 1e-3  # scale does not matter: the tolerance is relative
    ident = lambda R: R.copy()  # noqa: E731
    X, hists = block_pcg(A, B, ident, tol=1e-10, maxiter=1000)
    for c in range(6):
        assert hists[c][-1] <= 1e-10 and hists[c][-2] > 1e-10  # stopped where it converged
        assert np.linalg.norm(B[:, c] - A @ X[:, c]) <= 1e-9 * np.linalg.norm(B[:, c])
    # indefinite: p^T A p = 0 for b = ones in the first step of columns 3..5
    Aneg = sp.bsr_matrix(sp.diags(np.r_[np.ones(n // 2), -np.ones(n // 2)]).tocsr(),
                         blocksize=(6, 6))
    Bn = np.ones((n, 6))
    Bn[:, :3] = 0.0
    with pytest.raises(SolverError, match="column 3"):
        block_pcg(Aneg, Bn, ident, tol=1e-10, maxiter=100)


def test_solve_many_reports_failure_naming_the_case(cell):
    """An iteration limit too small raises SolverError naming the unconverged case."""
    _, op, b = cell
    lin = LinearSolver(op.A, method="amg", hierarchy=op.lin.ml, tol=1e-10, maxiter=5)
    with pytest.raises(SolverError, match="case 0") as err:
        solve_many(lin, b)
    assert len(err.value.history) == 6  # the initial residual and the 5 iterations
    with pytest.raises(ValueError, match="amg"):
        solve_many(LinearSolver(op.A, method="direct"), b)
