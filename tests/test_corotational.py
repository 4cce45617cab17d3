"""The co-rotational engine: consistent tangent, Newton's convergence, stability, energies,
strain monitor and input checks (path following itself: tests/test_path_following.py)."""

import warnings

import numpy as np
import pytest
from conftest import line_frame
from test_nonlinear import bent_frame, random_state

import homtex
import homtex.model.sections
from homtex import solve_nonlinear
from homtex.analysis.corotational import Corotational
from homtex.analysis.equilibrium import Equilibrium, Settings
from homtex.errors import InputError, SolverError, StrainWarning
from homtex.fem.corotational import expmap
from homtex.model.scene import parse_fixed, parse_loads

E, NU = 2000.0, 0.3


# ---------------------------------------------------------------------------------------------
# frames shared with tests/test_path_following.py
def bend_frame(n: int) -> homtex.Frame:
    """Bathe and Bolourchi's 45-degree bend: R = 100, a 1 x 1 section (a circle of area 1 with the
    square's I = 1/12 and J = 0.1406 through bending/torsion factors), E = 1e7, nu = 0."""
    ph = np.arange(n + 1) * np.pi / 4 / n
    nodes = np.c_[100 * np.sin(ph), 100 * (1 - np.cos(ph)), np.zeros(n + 1)]
    r = 1 / np.sqrt(np.pi)
    return homtex.Frame(nodes, np.c_[np.arange(n), np.arange(1, n + 1)], radius=r, E=1e7, nu=0.0,
                        bending_factor=np.pi / 3, torsion_factor=0.1406 * 2 * np.pi)


def planar(n_nodes, fixed=None):
    """Supports that keep a frame in the x-y plane (uz, rx, ry held everywhere) plus ``fixed``."""
    out = {k: [2, 3, 4] for k in range(n_nodes)}
    for k, v in (fixed or {}).items():
        if isinstance(v, dict):
            out[k] = {**{d: 0.0 for d in (2, 3, 4)}, **v}
        elif v == "all":
            out[k] = "all"
        else:
            out[k] = sorted(set(out[k]) | set(v))
    return out


def full_tangent(cor):
    """Dense global tangent assembled from the element tangents of the last evaluate_tangent."""
    n = cor.frame.n_nodes
    K = np.zeros((6 * n, 6 * n))
    for e, (i, j) in enumerate(cor.frame.elements):
        d = np.r_[6 * i:6 * i + 6, 6 * j:6 * j + 6]
        K[np.ix_(d, d)] += cor.Ke[e]
    return K


def fd_tangent(cor, h=1e-6):
    n = cor.frame.n_nodes
    K = np.zeros((6 * n, 6 * n))
    for a in range(n):
        for k in range(6):
            state = cor.copy_state()
            du = np.zeros((n, 6))
            du[a, k] = h
            cor.update(du)
            fp = cor.evaluate().ravel().copy()
            cor.set_state(state)
            cor.update(-du)
            fm = cor.evaluate().ravel().copy()
            cor.set_state(state)
            K[:, 6 * a + k] = (fp - fm) / (2 * h)
    return K


# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("periodic", [False, True])
def test_consistent_tangent_is_the_derivative_of_the_forces(periodic):
    """Central differences of the internal forces (translations and spatial spins) at a state with
    large rigid and deformational rotations reproduce the tangent to ~1e-7 (the h^2 error)."""
    cor = Corotational(bent_frame(1, periodic), geometric="consistent")
    random_state(cor, 2)
    cor.evaluate_tangent()
    assert cor.max_deformational_rotation() > 1.0
    K = full_tangent(cor)
    err = np.abs(K - fd_tangent(cor)).max() / np.abs(K).max()
    assert err < 1e-7
    # the approximate tangent of the contact code is far from it (so the check can fail)
    cor2 = Corotational(bent_frame(1, periodic), geometric="tension")
    random_state(cor2, 2)
    cor2.evaluate()
    assert np.abs(cor2.tangent().toarray() - K).max() / np.abs(K).max() > 1e-2


def test_skew_part_of_the_tangent_is_half_the_nodal_moment():
    """K = H - 1/2 [m]x on each node's rotation block (H symmetric: the Hessian of the energy;
    m the node's internal moment): at equilibrium without applied moments K is symmetric."""
    cor = Corotational(bent_frame(3), geometric="consistent")
    random_state(cor, 5)
    fint = cor.evaluate_tangent().copy()
    K = full_tangent(cor)
    skew = 0.5 * (K - K.T)
    pred = np.zeros_like(K)
    for a, m in enumerate(fint[:, 3:]):
        S = np.array([[0, -m[2], m[1]], [m[2], 0, -m[0]], [-m[1], m[0], 0]])
        pred[6 * a + 3:6 * a + 6, 6 * a + 3:6 * a + 6] = -0.5 * S
    assert np.abs(skew).max() > 1e-3 * np.abs(K).max()
    assert np.abs(skew - pred).max() < 1e-12 * np.abs(K).max()
    # the BSR tangent of the class is the same matrix, its symmetric option the symmetric part
    Kb = cor.tangent().toarray()
    assert np.allclose(Kb, K, rtol=0, atol=1e-12 * np.abs(K).max())
    assert np.allclose(cor.tangent(symmetric=True).toarray(), 0.5 * (K + K.T), atol=1e-12 * np.abs(K).max())


def test_rigid_motions_are_in_the_kernel_of_the_tangent():
    """At a stress-free state rotated by 2.4 rad the tangent maps the six rigid motions to zero."""
    frame = bent_frame(4).with_(prestrain=0.0)
    cor = Corotational(frame, geometric="consistent")
    Rg = expmap(np.array([1.2, -2.0, 0.4]))
    cor.ut[...] = frame.nodes @ Rg.T + np.array([5.0, -3.0, 7.0]) - frame.nodes
    cor.Q[...] = Rg
    cor.evaluate_tangent()
    K = full_tangent(cor)
    x = cor.positions
    for k in range(3):
        t = np.zeros((frame.n_nodes, 6))
        t[:, k] = 1.0
        w = np.zeros(3)
        w[k] = 1.0
        rot = np.zeros((frame.n_nodes, 6))
        rot[:, :3] = np.cross(w, x)
        rot[:, 3:] = w
        for v in (t, rot):
            assert np.abs(K @ v.ravel()).max() < 1e-9 * np.abs(K).max()


def test_newton_converges_quadratically_on_the_bend():
    """Bathe and Bolourchi's bend, a step of 5 % of the load from the converged half load: each
    Newton increment is bounded by C x the previous one squared once below 0.1 mm (C of the
    order of 1 / section size: a slender beam's membrane-bending coupling), and the residual
    reaches round-off in a few iterations."""
    fr = bend_frame(16)
    mask, ub = parse_fixed({0: "all"}, fr.n_nodes)
    eq = Equilibrium(fr, mask, parse_loads({16: (0, 0, 600, 0, 0, 0)}, fr.n_nodes), ub, Settings(tol=1e-14))
    eq.refresh()
    for k in range(1, 6):
        eq.correct(k / 10)
    it, _, _ = eq.correct(0.55)
    d = np.array(eq.increments)
    r = np.array(eq.history)
    assert it <= 6 and r[-1] < 1e-11 * r[0]
    pairs = [(a, b) for a, b in zip(d[:-1], d[1:]) if a < 0.1 and b > 1e-12]
    assert len(pairs) >= 2
    assert max(b / a ** 2 for a, b in pairs) < 1e3
    # the approximate (linear element + axial geometric) tangent converges only linearly
    cor = Corotational(fr, geometric="none")
    cor.set_state(eq.cor.copy_state())
    lam = 0.6
    f = parse_loads({16: (0, 0, 600, 0, 0, 0)}, fr.n_nodes)
    free = ~mask
    steps = []
    for _ in range(6):
        cor.evaluate()
        rr = (lam * f - cor.fint.ravel())[free]
        K = cor.tangent().tocsr()[free][:, free]
        du = np.zeros(6 * fr.n_nodes)
        du[free] = np.linalg.solve(K.toarray(), rr)
        steps.append(np.abs(du).max())
        cor.update(du.reshape(-1, 6))
    assert steps[-1] > 1e-9 and steps[-1] > 0.05 * steps[-2]


def test_symmetric_ldl_and_full_lu_need_the_same_iterations():
    """Without applied moments the skew part is the residual: LDL^T of the symmetric part keeps
    Newton quadratic (same iterations as LU of the full tangent, same answer)."""
    fr = bend_frame(8)
    out = {}
    for solver in ("ldl", "lu"):
        res = solve_nonlinear(fr, {0: "all"}, {8: (0, 0, 600, 0, 0, 0)}, steps=6, solver=solver, tol=1e-10)
        out[solver] = res
    assert np.array_equal(out["ldl"].path.iterations.values, out["lu"].path.iterations.values)
    assert np.allclose(out["ldl"].u, out["lu"].u, atol=1e-8)


def test_moments_out_of_their_plane_need_the_full_tangent():
    """Two end moments (Mz and Mx) wind a cantilever into a helix: the skew part -1/2 [M]x no
    longer vanishes at equilibrium, LDL^T of the symmetric part stalls (linear convergence), the
    default ("auto": LU of the full tangent where moments are applied) converges."""
    L, n_el = 100.0, 20
    fr = line_frame(n_el, L, (1, 0, 0), radius=1.0, E=E, nu=NU)
    EI = E * np.pi / 4
    loads = {n_el: (0, 0, 0, 0.5 * np.pi * EI / L, 0, np.pi * EI / L)}
    res = solve_nonlinear(fr, {0: "all"}, loads, steps=8)
    assert res.path.attrs["solver"] == "auto" and res.load_factor == 1.0
    assert res.path.iterations.values.max() <= 15
    with pytest.raises(SolverError, match="did not converge"):
        solve_nonlinear(fr, {0: "all"}, loads, steps=8, solver="ldl", max_cuts=2)


def test_inertia_of_a_straight_column_below_and_above_its_euler_loads():
    """A straight pinned-pinned column with an elliptic section (two Euler loads, weak and strong
    axis): 0 negative eigenvalues below the weak one, 1 between, 2 above the strong one."""
    L, n_el, a, b = 100.0, 24, 1.0, 0.6
    fr = line_frame(n_el, L, (1, 0, 0), semi_axes=(a, b), E=E, nu=NU)
    EIy, EIz = float(E * fr.Iy[0]), float(E * fr.Iz[0])
    P1, P2 = np.pi ** 2 * min(EIy, EIz) / L ** 2, np.pi ** 2 * max(EIy, EIz) / L ** 2
    fixed = {0: [0, 1, 2, 3], n_el: [1, 2]}
    mask, ub = parse_fixed(fixed, fr.n_nodes)
    f = parse_loads({n_el: (-1.0, 0, 0, 0, 0, 0)}, fr.n_nodes)
    eq = Equilibrium(fr, mask, f, ub, Settings())
    eq.refresh()
    counts = {}
    for P in (0.9 * P1, 1.1 * P1, 0.9 * P2, 1.1 * P2):
        eq.correct(P)                          # stays straight: perfect column
        counts[P / P1] = eq.negative
    assert list(counts.values()) == [0, 1, 1, 2]
    assert np.abs(eq.cor.ut[:, 1:]).max() < 1e-9


def test_energy_of_the_rolled_cantilever_and_the_balance():
    """End moment M: the strain energy is pure bending M^2 L / (2 EI) = M phi / 2; the external work
    of the moment (each step by the Hermite rule from the forces and path tangents at its ends) is
    exact for this linear moment-rotation path, and on the 45-degree bend, a nonlinear path, its
    error falls as the step to the fourth power (16x per halving)."""
    L, r, n_el = 100.0, 1.0, 20
    fr = line_frame(n_el, L, (1, 0, 0), radius=r, E=E, nu=NU)
    EI = E * np.pi * r ** 4 / 4
    phi = np.pi
    M = phi * EI / L
    for steps in (4, 8):
        res = solve_nonlinear(fr, planar(fr.n_nodes, {0: "all"}), {n_el: (0, 0, 0, 0, 0, M)}, steps=steps)
        p = res.path
        U = float(p.strain_energy[-1])
        assert U == pytest.approx(M * phi / 2, rel=1e-6)
        assert float(p.bending_y[-1] + p.bending_z[-1]) == pytest.approx(U, rel=1e-6)
        assert sum(float(v.sum()) for v in res.energy.values()) == pytest.approx(U, rel=1e-9)
        assert float(p.external_work[-1]) == pytest.approx(M * phi / 2, rel=1e-8)
        assert abs(float(p.energy_balance[-1])) < 1e-8
        for name in ("load_factor", "stable", "negative_eigenvalues", "iterations", "external_work", "energy_balance",
                     "stabilization_energy", "max_axial_strain", "max_shear_strain", "axial", "torsion", "shear"):
            assert name in p
        for name in list(p.data_vars) + list(p.coords):
            assert "units" in p[name].attrs and "long_name" in p[name].attrs, name
        assert p.stable.dtype == bool and p.negative_eigenvalues.dtype.kind == "i"
    bal = {}
    for steps in (4, 8):
        res = solve_nonlinear(bend_frame(16), {0: "all"}, {16: (0, 0, 600, 0, 0, 0)}, steps=steps, tol=1e-12)
        assert res.path.attrs["status"] == "ok" and res.path.sizes["step"] == steps
        bal[steps] = abs(float(res.path.energy_balance[-1]))
    assert bal[4] < 1e-3 and bal[4] / bal[8] == pytest.approx(16.0, rel=0.3)


def test_strain_monitor_flags_large_strain_and_passes_large_rotation():
    """Large rotation with small strain (the rolled cantilever) passes silently; a bar stretched by
    5 % is warned and recorded, and a frame with strain_limit 0.1 accepts it."""
    L, n_el = 100.0, 10
    fr = line_frame(n_el, L, (1, 0, 0), radius=1.0, E=E, nu=NU)
    EI, EA = E * np.pi / 4, E * np.pi
    with warnings.catch_warnings():
        warnings.simplefilter("error", StrainWarning)
        res = solve_nonlinear(fr, {0: "all"}, {n_el: (0, 0, 0, 0, 0, np.pi * EI / L)}, steps=4)
    assert res.path.attrs["check"].startswith("ok") and not bool(res.path.strain_exceeded.any())
    assert float(res.path.max_bending_strain[-1]) > 0.02          # fibre strain is not monitored
    with pytest.warns(StrainWarning, match="axial strain 0.05"):
        res = solve_nonlinear(fr, {0: "all"}, {n_el: (0.05 * EA, 0, 0, 0, 0, 0)}, steps=5)
    p = res.path
    assert bool(p.strain_exceeded[-1]) and not bool(p.strain_exceeded[0])
    assert float(p.max_axial_strain[-1]) == pytest.approx(0.05, rel=1e-9)
    assert "beyond the strain limit 0.02" in p.attrs["check"]
    with warnings.catch_warnings():
        warnings.simplefilter("error", StrainWarning)
        res = solve_nonlinear(fr.with_(strain_limit=0.1), {0: "all"}, {n_el: (0.05 * EA, 0, 0, 0, 0, 0)}, steps=5)
    with pytest.raises(InputError, match="strain_limit"):
        fr.with_(strain_limit=-1.0)


def test_strain_limit_comes_from_the_cell_file(tmp_path):
    """A yarn table's strain_limit reaches the yarn type and every element of its frame; the
    default is 0.02; a bad value names the table and key."""
    from homtex.cells import CellError, load_cell

    src = tmp_path / "sq.toml"
    src.write_text("""
[cell]
name = "sq"
generator = "square"
[parameters]
a = 2.0
[yarns.strut]
section = "circle"
radius = 0.1
E = 3000.0
nu = 0.3
strain_limit = 0.05
source = "test"
[resolution]
elements_per_strut = 2
""")
    cell = load_cell(src)
    assert cell.yarns["strut"].strain_limit == 0.05
    assert np.all(cell.frame.strain_limit == 0.05)
    assert homtex.YarnType("y", 0.1, 1.0, 0.3).strain_limit == homtex.model.sections.DEFAULT_STRAIN_LIMIT == 0.02
    src.write_text(src.read_text().replace("strain_limit = 0.05", "strain_limit = -1"))
    with pytest.raises(CellError, match="strain_limit"):
        load_cell(src)


@pytest.mark.parametrize("kw, match", [
    (dict(control="force"), "control"), (dict(steps=0), "steps"), (dict(steps=2.5), "steps"),
    (dict(steps=True), "steps"), (dict(tol=0.0), "tol"), (dict(tol=1.5), "tol"), (dict(tol=np.nan), "tol"),
    (dict(max_iter=0), "max_iter"), (dict(atol=-1.0), "atol"), (dict(perturbation=2.0), "perturbation"),
    (dict(solver="cg"), "solver"), (dict(geometric="tension"), "geometric"), (dict(monitor=[99]), "monitor"),
    (dict(arc_length=0.0), "arc_length"), (dict(max_cuts=-1), "max_cuts")])
def test_bad_arguments_are_named(kw, match):
    fr = line_frame(3, 10.0, (1, 0, 0), radius=0.5, E=E, nu=NU)
    with pytest.raises(InputError, match=match):
        solve_nonlinear(fr, {0: "all"}, {3: (0, 1, 0, 0, 0, 0)}, **kw)


def test_controls_need_what_they_drive():
    fr = line_frame(3, 10.0, (1, 0, 0), radius=0.5, E=E, nu=NU)
    with pytest.raises(InputError, match="prescribed"):
        solve_nonlinear(fr, {0: "all"}, {3: (0, 1, 0, 0, 0, 0)}, control="displacement")
    with pytest.raises(InputError, match="reference load"):
        solve_nonlinear(fr, {0: "all"}, None, control="arclength")
    with pytest.raises(InputError, match=r"loads\[3\] must be finite"):
        solve_nonlinear(fr, {0: "all"}, {3: (0, np.inf, 0, 0, 0, 0)})
    with pytest.raises(SolverError, match="held by nothing"):
        solve_nonlinear(fr, None, {3: (0, 1, 0, 0, 0, 0)})


def test_threaded_element_loops_give_the_plain_loop_bitwise_and_follow_the_threads_option():
    """The prange element kernels on one thread and on all give the plain loop's forces, tangents
    and energies to the last bit on a deformed frame (each element is computed alone, each node
    gathers its ends in a fixed order), so choosing them by speed changes no answer; the engine's
    rule: one thread below PARALLEL_ELEMENTS."""
    import numba

    from homtex.analysis import corotational as C
    from homtex.fem import corotational as K

    n = 300
    s = np.arange(n + 1) * 0.25
    fr = homtex.Frame(np.c_[s, 0.3 * np.sin(s), 0.2 * np.cos(0.7 * s)], np.c_[np.arange(n), np.arange(1, n + 1)],
                      radius=0.1, E=E, nu=NU)
    cor = Corotational(fr, geometric="consistent")
    rng = np.random.default_rng(3)
    cor.ut[...] = rng.normal(scale=0.05, size=cor.ut.shape)
    cor.Q[...] = np.array([expmap(w) for w in rng.normal(scale=0.1, size=(fr.n_nodes, 3))])
    cor.Ke = np.zeros((fr.n_elements, 12, 12))
    args = (np.ascontiguousarray(cor.positions), cor.Q, fr.elements, cor.shift, cor.E0, cor.L0, *cor.arrays,
            cor._prestrain(1.0))
    out = []
    threads = numba.get_num_threads()
    for fn, nt in ((K.corotational_tangent_serial, threads), (K.corotational_tangent, 1),
                   (K.corotational_tangent, threads)):
        numba.set_num_threads(nt)
        try:
            fn(*args, cor.fe, cor.Ke, cor.Rr, cor.lcur, cor.theta, cor.forces, cor.energy)
        finally:
            numba.set_num_threads(threads)
        out.append((cor.fe.copy(), cor.Ke.copy(), cor.energy.copy()))
    assert np.abs(out[0][1]).max() > 0 and np.abs(out[0][0]).max() > 0
    for fe, Ke, en in out[1:]:
        assert np.array_equal(fe, out[0][0]) and np.array_equal(Ke, out[0][1]) and np.array_equal(en, out[0][2])
    assert C.element_loop_serial(C.PARALLEL_ELEMENTS - 1) and not C.element_loop_serial(C.PARALLEL_ELEMENTS)
