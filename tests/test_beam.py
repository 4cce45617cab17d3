"""Exact Timoshenko beam: closed forms, invariances, energies, assembly."""

import numpy as np
import pytest
from conftest import line_frame, random_frame

import homtex
from homtex.fem.assembly import Assembler, assemble_reference
from homtex.fem.beam import local_stiffness
from homtex.model.sections import section_properties

L, E, NU = 100.0, 2000.0, 0.3


def props(r=None, ab=None):
    a, b = ab if ab is not None else (r, r)
    p = section_properties(np.array([a]), np.array([b]), np.array([NU]))
    G = E / (2 * (1 + NU))
    return {k: float(v[0]) if np.ndim(v) else float(v) for k, v in p.items()} | {"G": G}


def cantilever(n_el, load, *, r=2.0, ab=None, direction=(1, 0, 0), ref=None, solver="direct"):
    kw = dict(E=E, nu=NU)
    kw.update(semi_axes=ab) if ab is not None else kw.update(radius=r)
    if ref is not None:
        kw["ref"] = ref
    f = line_frame(n_el, L, direction, **kw)
    res = homtex.solve_static(f, {0: "all"}, {n_el: load}, solver=solver, tol=1e-12)
    return f, res


@pytest.mark.parametrize("n_el", [1, 2, 3, 7, 20])
@pytest.mark.parametrize("r", [0.5, 2.0, 10.0])   # slender ... stocky (shear matters)
def test_cantilever_tip_force_with_shear(n_el, r):
    P = 3.0
    p = props(r)
    f, res = cantilever(n_el, (0, P, 0, 0, 0, 0), r=r)
    # default reference: e2 = z for a beam along x, so bending in y uses I about e3 = Iz
    EI = E * p["Iz"]
    kGA = p["k"] * p["G"] * p["A"]
    delta = P * L**3 / (3 * EI) + P * L / kGA
    theta = P * L**2 / (2 * EI)
    assert res.u[-1, 1] == pytest.approx(delta, rel=1e-8)
    assert res.u[-1, 5] == pytest.approx(theta, rel=1e-8)
    # the shear term matters for stocky beams and vanishes for slender ones
    eb = P * L**3 / (3 * EI)
    assert abs(res.u[-1, 1] / eb - 1) == pytest.approx((P * L / kGA) / eb, rel=1e-6)


def test_euler_bernoulli_limit():
    """Shear flexibility / bending flexibility falls like (r/L)^2."""
    P = 1.0
    ratios = []
    for r in [4.0, 2.0, 1.0, 0.5]:
        p = props(r)
        _, res = cantilever(4, (0, 0, P, 0, 0, 0), r=r)
        eb = P * L**3 / (3 * E * p["Iy"])
        ratios.append(res.u[-1, 2] / eb - 1)
    ratios = np.array(ratios)
    assert np.all(ratios > 0)
    np.testing.assert_allclose(ratios[:-1] / ratios[1:], 4.0, rtol=1e-6)


@pytest.mark.parametrize("n_el", [1, 5])
def test_cantilever_moment_torsion_axial(n_el):
    p = props(1.5)
    M, T, N = 7.0, 5.0, 40.0
    _, res = cantilever(n_el, (N, 0, 0, T, 0, M), r=1.5)
    EI = E * p["Iz"]
    assert res.u[-1, 5] == pytest.approx(M * L / EI, rel=1e-8)
    assert res.u[-1, 1] == pytest.approx(M * L**2 / (2 * EI), rel=1e-8)
    assert res.u[-1, 3] == pytest.approx(T * L / (p["G"] * p["J"]), rel=1e-8)
    assert res.u[-1, 0] == pytest.approx(N * L / (E * p["A"]), rel=1e-8)


@pytest.mark.parametrize("n_el", [1, 4])
def test_elliptical_section_both_axes(n_el):
    """Ellipse: semi-axis a along e2, b along e3; bending stiffness differs per axis."""
    a, b = 3.0, 1.0
    p = props(ab=(a, b))
    P = 2.0
    # beam along x with ref = z: e2 = z, e3 = x cross z = -y
    _, res = cantilever(n_el, (0, P, P, 0, 0, 0), ab=(a, b), ref=(0, 0, 1))
    kGA = p["k"] * p["G"] * p["A"]
    # load along e2 = z bends about e3 (Iz = pi a^3 b / 4), along y about e2 (Iy)
    dz = P * L**3 / (3 * E * p["Iz"]) + P * L / kGA
    dy = P * L**3 / (3 * E * p["Iy"]) + P * L / kGA
    assert p["Iz"] == pytest.approx(np.pi * a**3 * b / 4)
    assert res.u[-1, 2] == pytest.approx(dz, rel=1e-8)
    assert res.u[-1, 1] == pytest.approx(dy, rel=1e-8)
    assert p["J"] == pytest.approx(np.pi * a**3 * b**3 / (a**2 + b**2))


def test_rotated_cantilever_is_invariant(rng):
    """The same cantilever along an arbitrary direction gives the rotated answer."""
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    ref = np.cross(d, rng.normal(size=3))
    e3 = np.cross(d, ref / np.linalg.norm(ref))
    P = 1.3
    f, res = cantilever(3, (*(P * e3), 0, 0, 0), r=1.0, direction=d, ref=ref)
    p = props(1.0)
    delta = P * L**3 / (3 * E * p["Iz"]) + P * L / (p["k"] * p["G"] * p["A"])
    assert res.u[-1, :3] @ e3 == pytest.approx(delta, rel=1e-8)
    assert abs(res.u[-1, :3] @ d) < 1e-10 * delta


def test_prescribed_displacement_reaction():
    p = props(1.0)
    f = line_frame(3, L, radius=1.0, E=E, nu=NU)
    d = 0.7
    res = homtex.solve_static(f, {0: "all", 3: {1: d, 5: 0.0}}, None, solver="direct")
    assert res.u[3, 1] == pytest.approx(d)
    # guided cantilever (tip rotation held): F = 12 EI d / L^3 / (1 + Phi)
    EI = E * p["Iz"]
    phi = 12 * EI / (p["k"] * p["G"] * p["A"] * L**2)
    assert -res.reactions[0, 1] == pytest.approx(12 * EI * d / L**3 / (1 + phi), rel=1e-8)
    assert res.reactions[0, 1] + res.reactions[3, 1] == pytest.approx(0, abs=1e-10)


def test_rigid_body_motion_gives_zero_forces(rng):
    f = random_frame(3, ellipse=True)
    a, w = rng.normal(size=3), rng.normal(size=3) * 1e-2
    u = np.zeros((f.n_nodes, 6))
    u[:, :3] = a + np.cross(w, f.nodes)
    u[:, 3:] = w
    K = Assembler(f).stiffness()
    Ku = K @ u.ravel()
    assert np.abs(Ku).max() < 1e-10 * np.abs(K.data).max() * np.abs(u).max()
    from homtex.analysis.static import element_state
    forces, energy = element_state(f, u)
    assert np.abs(forces).max() < 1e-9 * np.abs(K.data).max() * np.abs(u).max()
    assert np.abs(energy).max() < 1e-18 * np.abs(K.data).max()


def test_free_frame_has_six_zero_eigenvalues():
    f = random_frame(5, n=10, extra=8)
    K = assemble_reference(f).toarray()
    # scale to unit diagonal so translations and rotations compare
    s = 1 / np.sqrt(np.diag(K))
    w = np.linalg.eigvalsh(K * s[:, None] * s[None, :])
    assert np.sum(np.abs(w) < 1e-10 * w.max()) == 6
    assert w[6] > 1e-8 * w.max()


def test_single_element_matrix_properties():
    k = local_stiffness(7.0, 1e4, 3e3, 2e4, 5e4, 2e3)
    assert np.allclose(k, k.T, atol=0)
    w = np.linalg.eigvalsh(k)
    assert np.sum(np.abs(w) < 1e-10 * w.max()) == 6
    assert np.all(w > -1e-10 * w.max())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_numba_assembly_matches_numpy_reference(seed):
    f = random_frame(seed, n=30, extra=40, ellipse=bool(seed % 2))
    K = Assembler(f).stiffness().toarray()
    Kr = assemble_reference(f).toarray()
    assert np.abs(K - Kr).max() <= 1e-13 * np.abs(Kr).max()
    assert np.abs(K - K.T).max() <= 1e-13 * np.abs(K).max()


def test_pattern_reused_when_values_change():
    """New material values re-fill the same BSR arrays; the pattern is built once."""
    f = random_frame(0)
    asm = Assembler(f)
    K1 = asm.stiffness().copy()
    K = asm.stiffness()
    R, Le, *stiff = asm.element_arrays()
    K2 = asm.stiffness((R, Le, *[2 * s for s in stiff]))
    assert K2 is K and np.array_equal(K1.indices, K2.indices)
    np.testing.assert_allclose(K2.data, 2 * K1.data, rtol=1e-14, atol=0)


def test_energy_split_sums_to_work(rng):
    f = random_frame(7, n=15, extra=12, ellipse=True)
    loads = {i: rng.normal(size=6) for i in range(3, 15)}
    res = homtex.solve_static(f, {0: "all", 1: [0, 1, 2]}, loads, solver="direct")
    K = Assembler(f).stiffness()
    x = res.u.ravel()
    W = 0.5 * x @ (K @ x)
    assert set(res.energy) == {"axial", "torsion", "bending_y", "bending_z", "shear"}
    assert all(v.shape == (f.n_elements,) for v in res.energy.values())
    assert res.total_energy == pytest.approx(W, rel=1e-12)
    for v in res.energy.values():
        assert np.all(v >= -1e-14 * W)


def test_energy_split_pure_modes():
    """Axial load stores only axial energy; a tip torque only torsion."""
    _, res = cantilever(3, (10.0, 0, 0, 0, 0, 0))
    assert res.energy["axial"].sum() == pytest.approx(res.total_energy, rel=1e-12)
    _, res = cantilever(3, (0, 0, 0, 10.0, 0, 0))
    assert res.energy["torsion"].sum() == pytest.approx(res.total_energy, rel=1e-12)
    # beam along x with e2 = z: a moment about global z bends about local e2 ("bending_y")
    _, res = cantilever(3, (0, 0, 0, 0, 0, 10.0))   # pure moment: no shear force
    assert res.energy["bending_y"].sum() == pytest.approx(res.total_energy, rel=1e-12)
    assert res.energy["shear"].sum() < 1e-20


def test_end_forces_equilibrium():
    P = 2.0
    f, res = cantilever(4, (0, 0, P, 0, 0, 0))      # along e2 = z
    # shear force constant, bending moment linear with the lever arm to the tip
    Vy = res.forces[:, 1]
    np.testing.assert_allclose(np.abs(Vy), P, rtol=1e-10)
    Mz1 = res.forces[:, 5]
    x1 = f.nodes[f.elements[:, 0], 0]
    np.testing.assert_allclose(np.abs(Mz1), P * (L - x1), rtol=1e-9)


def test_prestrain_equivalent_loads():
    """A clamped bar that wants to shorten carries N = EA eps0; a free one shortens eps0 L."""
    eps0 = 0.01
    p = props(1.0)
    f = line_frame(4, L, radius=1.0, E=E, nu=NU, prestrain=eps0)
    res = homtex.solve_static(f, {0: "all", 4: "all"}, None, solver="direct")
    np.testing.assert_allclose(res.axial_force, E * p["A"] * eps0, rtol=1e-10)
    res = homtex.solve_static(f, {0: "all"}, None, solver="direct")
    assert res.u[-1, 0] == pytest.approx(-eps0 * L, rel=1e-10)
    assert np.abs(res.axial_force).max() < 1e-9 * E * p["A"] * eps0


@pytest.mark.parametrize("f, g", [(0.1, 1.0), (4.0, 0.05)])
def test_bending_and_torsion_factors(f, g):
    """bending_factor multiplies Iy and Iz, torsion_factor J: the cantilever's tip deflection and
    twist follow the Timoshenko closed forms with f EI and g GJ (shear and axial unchanged)."""
    P, T, N, r = 3.0, 5.0, 40.0, 2.0
    p = props(r)
    fr = line_frame(4, L, E=E, nu=NU, radius=r, bending_factor=f, torsion_factor=g)
    res = homtex.solve_static(fr, {0: "all"}, {4: (N, P, 2 * P, T, 0, 0)}, solver="direct", tol=1e-12)
    kGA = p["k"] * p["G"] * p["A"]
    assert res.u[-1, 1] == pytest.approx(P * L**3 / (3 * f * E * p["Iz"]) + P * L / kGA, rel=1e-8)
    assert res.u[-1, 2] == pytest.approx(2 * P * L**3 / (3 * f * E * p["Iy"]) + 2 * P * L / kGA, rel=1e-8)
    assert res.u[-1, 0] == pytest.approx(N * L / (E * p["A"]), rel=1e-8)
    assert res.u[-1, 3] == pytest.approx(T * L / (g * p["G"] * p["J"]), rel=1e-8)
    assert np.all(fr.with_(prestrain=0.01).bending_factor == f) and np.all(fr.with_().torsion_factor == g)
    with pytest.raises(homtex.InputError, match=r"bending_factor of element 0 .* must be positive"):
        line_frame(2, L, E=E, nu=NU, radius=r, bending_factor=-1.0)
    with pytest.raises(homtex.InputError, match=r"torsion_factor of element 0 .* must be positive"):
        line_frame(2, L, E=E, nu=NU, radius=r, torsion_factor=np.inf)
