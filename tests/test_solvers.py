"""Solvers: agreement on a 3D lattice, reports, failure detection."""

import numpy as np
import pytest
from conftest import line_frame

import homtex
from homtex.geometry.lattices import lattice_frame


def clamped_block(name, repeat, radius, eps=2, load=(0.3, 0.1, -1.0)):
    f = lattice_frame(name, radius=radius, E=1000.0, nu=0.3, repeat=repeat, periodic=False,
                      elements_per_strut=eps)
    z = f.nodes[:, 2]
    fixed = {int(i): "all" for i in np.flatnonzero(z < z.min() + 1e-9)}
    loads = {int(i): (*load, 0, 0, 0) for i in np.flatnonzero(z > z.max() - 1e-9)}
    return f, fixed, loads


@pytest.mark.parametrize("name, repeat", [("octet", (4, 4, 5)), ("bcc", (6, 6, 6))])
def test_solvers_agree_on_3d_lattice(name, repeat):
    f, fixed, loads = clamped_block(name, repeat, 0.07)
    assert f.ndof >= 10_000
    sol = {s: homtex.solve_static(f, fixed, loads, solver=s, tol=1e-11) for s in ("direct", "amg", "cg")}
    ref = sol["direct"].u
    scale = np.abs(ref).max()
    for s in ("amg", "cg"):
        assert np.abs(sol[s].u - ref).max() <= 1e-8 * scale
    for s, r in sol.items():
        rep = r.report
        assert rep.method.startswith(s)
        assert rep.residual <= 1e-10
        assert rep.setup_seconds >= 0 and rep.solve_seconds >= 0
    # AMG needs far fewer iterations than Jacobi (the point of the near-null space)
    assert sol["amg"].report.iterations * 5 < sol["cg"].report.iterations
    assert sol["amg"].report.operator_complexity > 1.0


def test_near_null_space_is_rigid_motion():
    from homtex.fem.assembly import Assembler
    from homtex.linalg.nullspace import rigid_body_modes
    f, _, _ = clamped_block("bcc", (2, 2, 2), 0.1)
    B = rigid_body_modes(f.nodes)
    K = Assembler(f).stiffness()
    assert B.shape == (f.ndof, 6)
    assert np.abs(K @ B).max() < 1e-12 * np.abs(K.data).max() * np.abs(B).max()


def test_floating_yarn_is_named():
    a = line_frame(3, 10.0, radius=0.5, E=1e3, nu=0.3).nodes
    b = a + [0, 5.0, 0]
    nodes = np.vstack([a, b])
    el = np.array([[0, 1], [1, 2], [2, 3], [4, 5], [5, 6], [6, 7]])
    f = homtex.Frame(nodes, el, radius=0.5, E=1e3, nu=0.3, yarn=[1, 1, 1, 7, 7, 7])
    with pytest.raises(homtex.SolverError, match=r"yarn\(s\) \[7\] \(nodes 4-7\)"):
        homtex.solve_static(f, {0: "all"}, {3: (0, 1, 0, 0, 0, 0)})
    # held by a pin alone, the yarn can still spin about its axis: named as such
    with pytest.raises(homtex.SolverError, match=r"\[7\].*rotation about x"):
        homtex.solve_static(f, {0: "all", 4: [0, 1, 2], 7: [0, 1, 2]}, {3: (0, 1, 0, 0, 0, 0)})
    # held properly: solves
    r = homtex.solve_static(f, {0: "all", 4: "all"}, {3: (0, 1, 0, 0, 0, 0)}, solver="direct")
    assert np.abs(r.u[4:]).max() == 0.0


def test_jacobi_cg_stall_is_reported_not_returned():
    """A slender tower (cond ~ 1e8): Jacobi-CG stalls far from the answer within 300 iterations and
    that is raised with the residual history; given 5000 iterations its answer is the exact answer of
    a system within 1e-12 of the given one (backward error) and agrees with the direct solve."""
    f, fixed, loads = clamped_block("simple_cubic", (2, 2, 60), 0.02, eps=4, load=(1e-3, 0, 0))
    with pytest.raises(homtex.SolverError, match="did not converge.*stalled") as exc:
        homtex.solve_static(f, fixed, loads, solver="cg", tol=1e-8, maxiter=300)
    hist = exc.value.history
    assert len(hist) == 301 and hist[-1] > 1e-8
    r = homtex.solve_static(f, fixed, loads, solver="direct", tol=1e-8)
    assert r.report.backward_error < 1e-15
    c = homtex.solve_static(f, fixed, loads, solver="cg", tol=1e-8)
    assert c.report.residual > 1e-8 and c.report.backward_error <= 1e-8        # accepted on the backward error
    assert np.abs(c.u - r.u).max() < 1e-6 * np.abs(r.u).max()
    # AMG-CG with the rigid-body near-null space converges in few iterations
    a = homtex.solve_static(f, fixed, loads, solver="amg", tol=1e-8)
    assert a.report.iterations < 100
    assert np.abs(a.u - r.u).max() < 1e-6 * np.abs(r.u).max()   # cond ~ 1e8


def test_maxiter_too_small_raises():
    f, fixed, loads = clamped_block("bcc", (6, 6, 6), 0.1)   # large enough for a 2-level hierarchy
    with pytest.raises(homtex.SolverError, match="after 3 iterations"):
        homtex.solve_static(f, fixed, loads, solver="amg", tol=1e-12, maxiter=3)


def test_zero_load_gives_zero():
    f, fixed, _ = clamped_block("bcc", (2, 2, 2), 0.1)
    r = homtex.solve_static(f, fixed, None)
    assert np.all(r.u == 0) and r.report.residual == 0.0


def test_unattainable_tolerance_is_explained():
    """cond ~ 1e8: neither a 1e-17 relative residual nor a 1e-17 backward error is attainable in
    double precision (the backward error bottoms out at a few 1e-17)."""
    f, fixed, loads = clamped_block("simple_cubic", (2, 2, 60), 0.02, eps=4, load=(1e-3, 0, 0))
    with pytest.raises(homtex.SolverError, match="too ill-conditioned for this tolerance"):
        homtex.solve_static(f, fixed, loads, solver="amg", tol=1e-17)


def _cantilever(n=100, L=1000.0, r=0.5, E=1000.0, contrast=1.0):
    nodes = np.c_[np.linspace(0, L, n + 1), np.zeros(n + 1), np.zeros(n + 1)]
    Es = np.where(np.arange(n) < n // 2, E, E * contrast)
    return homtex.Frame(nodes, np.c_[np.arange(n), np.arange(1, n + 1)], radius=r, E=Es, nu=0.3)


@pytest.mark.parametrize("solver", ["direct", "amg"])
def test_slender_cantilever_is_accepted_with_the_right_answer(solver):
    """100 elements, L = 1000 mm, r = 0.5 mm (cond ~ 1e12): the relative residual cannot reach 1e-10
    in double precision, the backward error does; the tip deflection is P L^3 / 3 E I (shear adds
    P L / (k G A), 1e-6 of it)."""
    n, L, r, E, P = 100, 1000.0, 0.5, 1000.0, 0.01
    res = homtex.solve_static(_cantilever(n, L, r, E), {0: "all"}, {n: (0, 0, -P, 0, 0, 0)}, solver=solver)
    I, A, nu = np.pi * r ** 4 / 4, np.pi * r ** 2, 0.3
    k = 6 * (1 + nu) / (7 + 6 * nu)
    exact = P * L ** 3 / (3 * E * I) + P * L / (k * E / (2 * (1 + nu)) * A)
    assert res.report.residual > 1e-10 and res.report.backward_error < 1e-10
    assert res.u[n, 2] == pytest.approx(-exact, rel=1e-8)


@pytest.mark.parametrize("contrast", [1e2, 1e3, 1e4])
@pytest.mark.parametrize("solver", ["direct", "amg"])
def test_stiff_soft_contrast_is_accepted(solver, contrast):
    """The tip half of a slender cantilever 'contrast' times stiffer: accepted, and the tip deflection
    is the unit-load closed form."""
    n, L, r, E, P = 40, 400.0, 0.5, 1000.0, 0.01
    res = homtex.solve_static(_cantilever(n, L, r, E, contrast), {0: "all"}, {n: (0, 0, -P, 0, 0, 0)},
                              solver=solver)
    I, A, nu = np.pi * r ** 4 / 4, np.pi * r ** 2, 0.3
    k, G = 6 * (1 + nu) / (7 + 6 * nu), E / (2 * (1 + nu))
    a = L / 2   # unit-load method: M = P (L - x); bending plus shear of both halves
    exact = P / (3 * E * I) * (L ** 3 - (L - a) ** 3 + (L - a) ** 3 / contrast) \
        + P * a / (k * G * A) * (1 + 1 / contrast)
    assert res.report.backward_error < 1e-10
    # forward error <= cond x backward error: the direct factor is at round-off, AMG-CG stops at
    # a backward error of tol = 1e-10 (measured 1.5e-8 off at contrast 1e3)
    assert res.u[n, 2] == pytest.approx(-exact, rel=1e-8 if solver == "direct" else 1e-6)


@pytest.mark.parametrize("tol", [1.0, 0.0, -1e-3, float("nan"), float("inf"), 2.0, "1e-8", True])
def test_bad_tolerances_are_input_errors(tol):
    f = _cantilever(4, 40.0)
    with pytest.raises(homtex.InputError, match="tol"):
        homtex.solve_static(f, {0: "all"}, {4: (0, 0, -1.0, 0, 0, 0)}, tol=tol)


@pytest.mark.parametrize("maxiter", [0, -1, 2.5, "10"])
def test_bad_maxiter_is_an_input_error(maxiter):
    f = _cantilever(4, 40.0)
    with pytest.raises(homtex.InputError, match="maxiter"):
        homtex.solve_static(f, {0: "all"}, {4: (0, 0, -1.0, 0, 0, 0)}, solver="amg", maxiter=maxiter)


@pytest.mark.parametrize("P", [1e-300, 1e-150, 1e150])
def test_loads_of_any_magnitude_solve_linearly(P):
    f = _cantilever(10, 100.0)
    one = homtex.solve_static(f, {0: "all"}, {10: (0, 0, -1.0, 0, 0, 0)}, solver="direct").u
    res = homtex.solve_static(f, {0: "all"}, {10: (0, 0, -P, 0, 0, 0)}, solver="direct")
    assert np.abs(res.u).max() > 0
    assert np.allclose(res.u / P, one, rtol=1e-12, atol=0)


def test_overflowing_answer_is_a_solver_error():
    f = _cantilever(10, 100.0)
    with pytest.raises(homtex.SolverError, match="overflow|not finite"):
        homtex.solve_static(f, {0: "all"}, {10: (0, 0, -1e300, 0, 0, 0)}, solver="direct")


def test_singular_factorisation_is_a_solver_error():
    import scipy.sparse as sp

    from homtex.linalg.solvers import LinearSolver

    A = sp.csc_matrix(np.array([[1.0, 1.0], [1.0, 1.0]]))
    with pytest.raises(homtex.SolverError, match="singular"):
        LinearSolver(A, method="direct").solve(np.ones(2))


def test_amg_on_a_singular_matrix_is_a_solver_error():
    """pyamg factorises its coarse grid inside the first V-cycle: a singular matrix escaped as a bare
    RuntimeError ("Factor is exactly singular")."""
    import scipy.sparse as sp

    from homtex.linalg.solvers import LinearSolver

    A = sp.csc_matrix(np.array([[1.0, 1.0], [1.0, 1.0]]))
    with pytest.raises(homtex.SolverError, match="coarse-grid factorisation.*singular"):
        LinearSolver(A, method="amg").solve(np.ones(2))


@pytest.mark.parametrize("solver", ["amg", "direct", "cg"])
def test_an_element_of_no_stiffness_is_named(solver):
    """A frame whose stiffness matrix is singular although every part is supported (an element of
    E = 1e-300 MPa among 1000 MPa ones): a SolverError naming the element, with every solver."""
    nodes = np.c_[np.linspace(0, 10, 5), np.zeros(5), np.zeros(5)]
    fr = homtex.Frame(nodes, np.c_[np.arange(4), np.arange(1, 5)], radius=0.5, E=np.array([1e3, 1e3, 1e-300, 1e3]),
                      nu=0.3)
    with pytest.raises(homtex.SolverError, match=r"element 2 \(yarn 0, nodes \[2, 3\]\) has almost no stiffness"):
        homtex.solve_static(fr, {0: "all"}, {4: (0, 0, -1.0, 0, 0, 0)}, solver=solver)
    ok = homtex.solve_static(fr.with_(E=np.full(4, 1e3)), {0: "all"}, {4: (0, 0, -1.0, 0, 0, 0)}, solver=solver)
    assert np.isfinite(ok.u).all()
