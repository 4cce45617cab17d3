"""Co-rotational (large-rotation) beams: exact gradient, rigid motions, elastica closed forms."""

import numpy as np
import pytest
from conftest import line_frame
from scipy.optimize import brentq
from scipy.special import ellipe, ellipk

import homtex
from homtex import solve_nonlinear
from homtex.analysis.nonlinear import Corotational
from homtex.errors import InputError, SolverError
from homtex.fem.corotational import expmap, logmap

E, NU = 2000.0, 0.3


def bent_frame(seed=0, periodic=False):
    """A curved 3-element yarn with an elliptic section and pre-strain (optionally periodic)."""
    rng = np.random.default_rng(seed)
    nodes = np.array([[0, 0, 0], [3.0, 0.5, 0.2], [6.0, 0.4, 1.0], [9.0, -0.3, 0.9]]) + 0.1 * rng.normal(size=(4, 3))
    if periodic:
        els = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
        return homtex.Frame(nodes, els, semi_axes=(0.4, 0.25), E=E, nu=NU, prestrain=0.02,
                            periods=[[12.0, 0.0, 0.0]], images=[[0], [0], [0], [1]])
    return homtex.Frame(nodes, [[0, 1], [1, 2], [2, 3]], semi_axes=(0.4, 0.25), E=E, nu=NU, prestrain=0.02)


def random_state(cor, seed, scale=0.3):
    rng = np.random.default_rng(seed)
    n = cor.frame.n_nodes
    cor.ut[...] = 0.2 * rng.normal(size=(n, 3))
    big = expmap(np.array([0.3, -1.1, 0.7]))          # a large common rotation plus small differences
    for i in range(n):
        cor.Q[i] = expmap(scale * rng.normal(size=3)) @ big


def energy(cor):
    cor.evaluate()
    return float(cor.energy.sum())


@pytest.mark.parametrize("periodic", [False, True])
def test_internal_force_is_the_energy_gradient(periodic):
    cor = Corotational(bent_frame(1, periodic))
    random_state(cor, 2)
    f = cor.evaluate().copy()
    assert cor.max_deformational_rotation() > 0.2      # well beyond the small-rotation range
    h = 1e-6
    n = cor.frame.n_nodes
    fd = np.zeros((n, 6))
    for a in range(n):
        for k in range(6):
            state = cor.copy_state()
            du = np.zeros((n, 6))
            du[a, k] = h
            cor.update(du)
            up = energy(cor)
            cor.set_state(state)
            cor.update(-du)
            um = energy(cor)
            cor.set_state(state)
            fd[a, k] = (up - um) / (2 * h)
    assert np.allclose(f, fd, rtol=1e-6, atol=1e-6 * np.abs(f).max())


def test_rigid_motion_of_any_size_gives_zero_force():
    frame = bent_frame(3).with_(prestrain=0.0)
    cor = Corotational(frame)
    Rg = expmap(np.array([1.2, -2.0, 0.4]))            # 2.4 rad
    t = np.array([5.0, -3.0, 7.0])
    x = frame.nodes @ Rg.T + t
    cor.ut[...] = x - frame.nodes
    cor.Q[...] = Rg
    f = cor.evaluate()
    assert np.abs(f).max() < 1e-10 * E
    assert np.abs(cor.forces).max() < 1e-9
    assert cor.max_deformational_rotation() < 1e-12


def test_log_and_exp_are_inverse_up_to_pi():
    rng = np.random.default_rng(0)
    for ang in (0.0, 1e-9, 0.3, 2.0, 3.1):
        v = rng.normal(size=3)
        v *= ang / max(np.linalg.norm(v), 1e-300)
        assert np.allclose(logmap(expmap(v)), v, atol=1e-9)


@pytest.mark.parametrize("phi", [np.pi / 2, np.pi, 2 * np.pi])
def test_end_moment_rolls_a_cantilever_into_an_arc(phi):
    """A cantilever under an end moment M bends into a circular arc of curvature M/EI:
    tip at (sin(phi), 1 - cos(phi)) / kappa with phi = M L / EI (pure bending, no shear)."""
    L, r, n_el = 100.0, 1.0, 40
    frame = line_frame(n_el, L, (1, 0, 0), radius=r, E=E, nu=NU)
    EI = E * np.pi * r ** 4 / 4
    M = phi * EI / L
    res = solve_nonlinear(frame, {0: "all"}, {n_el: (0, 0, 0, 0, 0, M)}, steps=4 if phi < 4 else 8)
    kappa = M / EI
    tip = res.x[n_el]
    exact = np.array([np.sin(phi), 1 - np.cos(phi), 0.0]) / kappa
    # the chord polygon of an arc: error ~ L (phi / n_el)^2 / 24 in length terms
    assert np.linalg.norm(tip - exact) < 1e-3 * L
    assert np.allclose(res.Q[n_el], expmap(np.array([0.0, 0.0, phi])), atol=1e-6)   # tip turned by phi
    # pure bending: no axial force, uniform moment M
    assert np.abs(res.axial_force).max() < 1e-6 * M / L
    # (e2 = global z for this beam, so the moment is M_y of the local frame)
    assert np.allclose(np.abs(res.forces[:, [4, 10]]), M, rtol=1e-6)


def test_small_loads_agree_with_the_linear_solve():
    """The nonlinear answer differs from the linear one by second-order terms: 10x smaller
    loads give a 100x smaller difference."""
    L, n_el = 50.0, 10
    frame = line_frame(n_el, L, (1, 0.3, 0.2), radius=0.8, E=E, nu=NU)
    load = np.array([0.0, 1e-4, -2e-4, 1e-4, 0.0, 3e-4])
    diff = []
    for s in (1.0, 0.1):
        lin = homtex.solve_static(frame, {0: "all"}, {n_el: s * load}, solver="direct", tol=1e-12)
        nl = solve_nonlinear(frame, {0: "all"}, {n_el: s * load}, steps=1)
        scale = np.abs(lin.u).max()
        diff.append(np.abs(nl.u - lin.u).max())
        assert diff[-1] < 0.1 * scale
    assert diff[0] / diff[1] == pytest.approx(100.0, rel=0.05)


@pytest.mark.parametrize("steps", [29, 30, 31])
def test_column_buckling_amplification_and_elastica(steps):
    """Pinned-free column (cantilever) under a dead axial load with a small lateral imperfection
    load: below P_cr = pi^2 EI / (4 L^2) the lateral tip deflection stays small; above it the column
    buckles to a large deflection. The amplification below P_cr follows 1 / (1 - P/P_cr).
    (Any number of load steps: before the stability check only 30 landed on the bent branch.)"""
    L, r, n_el = 100.0, 1.0, 30
    frame = line_frame(n_el, L, (1, 0, 0), radius=r, E=E, nu=NU)
    EI = E * np.pi * r ** 4 / 4
    Pcr = np.pi ** 2 * EI / (4 * L ** 2)
    q = 1e-4 * Pcr
    lin = homtex.solve_static(frame, {0: "all"}, {n_el: (0, q, 0, 0, 0, 0)}, solver="direct", tol=1e-12).u[n_el, 1]
    defl = {}
    for frac in (0.5, 0.8):
        res = solve_nonlinear(frame, {0: "all"}, {n_el: (-frac * Pcr, q, 0, 0, 0, 0)}, steps=5)
        defl[frac] = res.u[n_el, 1]
        amp = defl[frac] / lin
        assert amp == pytest.approx(1 / (1 - frac), rel=0.05)
    # post-buckled (elastica): P / P_cr = (2 K(m) / pi)^2, tip deflection 2 k L / K, tip x (2 E(m) / K - 1) L
    ratio = 1.5
    res = solve_nonlinear(frame, {0: "all"}, {n_el: (-ratio * Pcr, q, 0, 0, 0, 0)}, steps=steps, geometric="full")
    assert res.stable and bool(res.path.stable.all())
    m = brentq(lambda m: (2 * ellipk(m) / np.pi) ** 2 - ratio, 1e-9, 0.999)
    K, Em = ellipk(m), ellipe(m)
    assert res.x[n_el, 1] / L == pytest.approx(2 * np.sqrt(m) / K, rel=2e-3)
    assert res.x[n_el, 0] / L == pytest.approx(2 * Em / K - 1, rel=2e-3)


def test_bad_input_is_named():
    frame = line_frame(3, 10.0, (1, 0, 0), radius=0.5, E=E, nu=NU)
    with pytest.raises(InputError, match="geometric"):
        Corotational(frame, geometric="maybe")
    # (prescribed rotations are allowed since rotation control exists: tests/test_path_following.py)
    with pytest.raises(InputError, match="steps"):
        solve_nonlinear(frame, {0: "all"}, {3: (0, 1, 0, 0, 0, 0)}, steps=0)
    with pytest.raises(SolverError, match="did not converge"):
        solve_nonlinear(frame, {0: "all"}, {3: (0, 0, 0, 0, 0, 1e9)}, steps=1, max_iter=3)


def test_ring_between_plates_with_large_rotations_matches_the_dead_load_solve():
    """A thin ring squeezed to 15 % between frictionless plates (nonlinear compress: the large-motion
    engine) carries the same force as the ring under two opposite dead point loads
    (solve_nonlinear) at the same closure, while the linear model is off by more than 5 % there."""
    from test_contact import ring

    R, r, N = 10.0, 0.1, 48
    fr, fixed = ring(N, R, r)
    ds = homtex.compress(fr, strain=0.15, steps=3, fixed=fixed, geometry="nonlinear")
    lin = homtex.compress(fr, strain=0.15, steps=3, fixed=fixed, geometry="linear")
    assert ds.attrs["status"] == "ok" and ds.attrs["geometry"] == "nonlinear"
    assert int(ds.active_yarn_plate[-1]) == 2          # only the two poles touch
    F = float(ds.force[-1])
    # the centre line's closure: the plate travel less what the barrier gaps gave back
    ghat = ds.attrs["barrier_gap_mm"]
    closure = float(ds.plate_displacement[-1]) - 2 * (ghat - float(ds.min_gap[-1]))
    fx = {i: list(v) for i, v in fixed.items()}
    fx[0] = sorted(set(fx[0]) | {2})
    dead = solve_nonlinear(fr, fx, {N // 2: (0, 0, -F, 0, 0, 0)}, steps=3)
    assert -dead.u[N // 2, 2] == pytest.approx(closure, rel=1e-6)
    assert float(lin.force[-1]) > 1.05 * F              # large rotations soften the ring
    # rigid motions stay force free: the bottom plate carries the same force
    assert float(ds.bottom_force[-1]) == pytest.approx(F, rel=1e-9)


def test_small_compression_agrees_with_the_linear_contact_solve():
    """At 0.05 % closure the nonlinear and linear contact answers differ by second-order terms
    (compared at the same closure of the ring: the barrier gives back up to ghat per contact)."""
    from test_contact import ring

    fr, fixed = ring(32, 10.0, 0.1)
    lin = homtex.compress(fr, strain=5e-4, steps=1, fixed=fixed, geometry="linear")
    nl = homtex.compress(fr, strain=5e-4, steps=1, fixed=fixed, geometry="nonlinear")
    closure = float(nl.plate_displacement[-1]) - 2 * (nl.attrs["barrier_gap_mm"] - float(nl.min_gap[-1]))
    assert float(nl.force[-1]) / closure == pytest.approx(float(lin.force[-1] / lin.plate_displacement[-1]), rel=2e-3)
    assert int(nl.newton_iterations[-1]) >= 2 and int(lin.newton_iterations[-1]) == 0


def test_the_former_viscous_stabilisation_is_refused():
    from test_contact import ring

    fr, fixed = ring(32, 10.0, 0.1)
    with pytest.raises(InputError, match="stabilize"):
        homtex.compress(fr, strain=0.1, steps=2, fixed=fixed, geometry="nonlinear", stabilize=1e-6)
    with pytest.raises(InputError, match="stabilize"):
        homtex.compress(fr, strain=0.1, steps=2, fixed=fixed, geometry="nonlinear", stabilize=-1.0)
    with pytest.raises(InputError, match="geometry"):
        homtex.compress(fr, strain=0.1, steps=2, fixed=fixed, geometry="large")


def test_seam_cell_with_large_rotations_matches_the_linear_cell_at_small_pretension():
    """A weak stitch pre-strain (2 %) dips the seam line by a few tenths of a mm: the co-rotational
    and the linear seam cells agree there (the geometric terms are second order)."""
    cell = homtex.load_cell("spacer_20mm")
    lin = homtex.seam_profile(cell, seam_distance=24, prestrain=0.02, steps=2)
    nl = homtex.seam_profile(cell, seam_distance=24, prestrain=0.02, steps=2, geometry="nonlinear")
    assert lin.attrs["status"] == "ok" and nl.attrs["status"] == "ok" and nl.attrs["geometry"] == "nonlinear"
    dip = 20.0 - float(lin.seam_height)
    assert 0.1 < dip < 1.0
    assert np.abs(nl.height.values - lin.height.values).max() < 0.1 * dip
