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
    """A slender tower: Jacobi-CG stalls; the error carries the residual history."""
    f, fixed, loads = clamped_block("simple_cubic", (2, 2, 60), 0.02, eps=4, load=(1e-3, 0, 0))
    with pytest.raises(homtex.SolverError, match="did not converge") as exc:
        homtex.solve_static(f, fixed, loads, solver="cg", tol=1e-8)
    hist = exc.value.history
    assert len(hist) > 1000 and hist[-1] > 1e-8
    # the direct solver does solve it, and AMG-CG with the rigid-body near-null space too
    r = homtex.solve_static(f, fixed, loads, solver="direct", tol=1e-8)
    assert r.report.residual < 1e-8
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
    """cond ~ 1e8: a 1e-12 residual is below what double precision can attain here."""
    f, fixed, loads = clamped_block("simple_cubic", (2, 2, 60), 0.02, eps=4, load=(1e-3, 0, 0))
    with pytest.raises(homtex.SolverError, match="too ill-conditioned for this tolerance"):
        homtex.solve_static(f, fixed, loads, solver="amg", tol=1e-12)
