"""Periodic frames and homogenisation: closed forms, invariances, solver agreement."""

import numpy as np
import pytest

import homtex
from homtex import Frame, InputError, SolverError
from homtex.analysis.compression import compression_modulus
from homtex.analysis.macrostrain import solve_macro
from homtex.analysis.periodic import jump_load, rotate_stiffness
from homtex.fem.assembly import assemble_reference
from homtex.fem.beam import local_stiffness
from homtex.geometry.lattices import lattice_frame
from homtex.geometry.tiling import periodize

E_WALL, NU_WALL = 3000.0, 0.3


# ----------------------------------------------------------------------------------
# closed forms (derived in the docstrings; independent of the FE code)
def _wall(a, b, E=E_WALL, nu=NU_WALL):
    """In-plane EA, EI, kGA of a wall with semi-axes a (out of plane) and b (in plane)."""
    A = np.pi * a * b
    EI = E * np.pi * a * b**3 / 4.0
    G = E / (2 * (1 + nu))
    k = 6 * (1 + nu) / (7 + 6 * nu)  # Cowper, circle
    return E * A, EI, k * G * A


def honeycomb_closed_form(h, l, theta, a, b):
    """Membrane moduli (N/mm) of a honeycomb of Timoshenko walls (Masters & Evans 1996 style).

    Wall compliances: axial c_a(L) = L/EA; transverse under an S-shape (both ends clamped
    against rotation) c_f(L) = L^3/(12 EI) + L/(kGA). Cell: vertical wall h, inclined walls
    l at angle theta, width 2 l cos(theta), height h + l sin(theta).

    Loading 1 (N1 per unit length): inclined wall force P = N1 (h + l s), vertical wall
    unloaded, joints do not rotate (symmetry):
        E1 = l c / ((h + l s) (s^2 c_f + c^2 c_a)),  nu12 = s c^2 l (c_f - c_a) / ((h + l s)(s^2 c_f + c^2 c_a))
    Loading 2 (N2): inclined wall force W = N2 l c, vertical wall force 2W:
        E2 = (h + l s) / (l c (c^2 c_f + s^2 c_a + 2 h / EA))
    Shear (gamma): the C2 symmetry about wall midpoints gives equal joint rotations phi,
    the mirror x -> -x gives w_y(B) = w_y(A); with q = gamma l s / 2 - (w_B - w_A)_x and
    p = gamma l c / 2 the cell energy is
        U = (X - q + h phi)^2 / (2 c_f(h)) + (q c + p s)^2 / c_a(l) + (-q s + p c - l phi)^2 / c_f(l),
    X = gamma (h + l s)/2 (a wall with equal end rotations phi and transverse chord
    displacement delta stores (delta - L phi)^2 / (2 c_f(L))). Minimising over (q, phi)
    (2x2 linear system) gives G12 = 2 U / (gamma^2 area).
    """
    EA, EI, kGA = _wall(a, b)
    t = np.radians(theta)
    c, s = np.cos(t), np.sin(t)
    cf = lambda L: L**3 / (12 * EI) + L / kGA  # noqa: E731
    ca, cl, ch = l / EA, cf(l), cf(h)
    Hc = h + l * s
    E1 = l * c / (Hc * (s**2 * cl + c**2 * ca))
    nu12 = s * c**2 * l * (cl - ca) / (Hc * (s**2 * cl + c**2 * ca))
    E2 = Hc / (l * c * (c**2 * cl + s**2 * ca + 2 * h / EA))
    g = 1.0
    p = g * l * c / 2
    X = g * Hc / 2
    M = np.array([[1 / ch + 2 * c**2 / ca + 2 * s**2 / cl, -h / ch + 2 * s * l / cl],
                  [-h / ch + 2 * s * l / cl, h * h / ch + 2 * l * l / cl]])
    r = np.array([X / ch - 2 * c * s * p / ca + 2 * s * c * p / cl, -h * X / ch + 2 * l * c * p / cl])
    q, phi = np.linalg.solve(M, r)
    U = (X - q + h * phi)**2 / (2 * ch) + (q * c + p * s)**2 / ca + (-q * s + p * c - l * phi)**2 / cl
    G12 = 2 * U / (g * g * 2 * l * c * Hc)
    return {"E1": E1, "E2": E2, "nu12": nu12, "G12": G12}


def gibson_ashby(h, l, theta, EI):
    """Bending-only (Gibson & Ashby) membrane moduli (N/mm), EI the in-plane wall bending stiffness."""
    t = np.radians(theta)
    c, s = np.cos(t), np.sin(t)
    k = 12 * EI / l**3
    return {"E1": k * l * c / ((h + l * s) * s**2),
            "E2": k * (h + l * s) / (l * c**3),
            "nu12": c**2 * l / ((h + l * s) * s),
            "G12": k * (h / l + s) / ((h / l)**2 * (1 + 2 * h / l) * c)}


HONEYCOMBS = [
    # h, l, theta, (a, b) semi-axes
    (1.0, 1.0, 30.0, (0.05, 0.05)),       # regular, circular
    (1.5, 0.8, 40.0, (0.12, 0.12)),       # stubby walls: stretching and shear matter
    (2.0, 1.0, -30.0, (0.08, 0.04)),      # re-entrant, elliptical
    (1.2, 1.0, -15.0, (0.06, 0.09)),      # re-entrant, ellipse wide in plane
    (0.7, 1.3, 60.0, (0.03, 0.07)),
]


@pytest.mark.parametrize("h,l,theta,ab", HONEYCOMBS)
@pytest.mark.parametrize("solver", ["direct", "amg"])
def test_honeycomb_matches_closed_form(h, l, theta, ab, solver):
    fr = lattice_frame("honeycomb", h=h, l=l, theta=theta, semi_axes=ab, E=E_WALL, nu=NU_WALL)
    res = homtex.homogenize(fr, solver=solver)
    got = res.engineering_constants()
    want = honeycomb_closed_form(h, l, theta, *ab)
    for key, val in want.items():
        assert got[key] == pytest.approx(val, rel=1e-6), key
    assert res.units == "N/mm" and res.C.shape == (3, 3)
    assert res.measure == pytest.approx(2 * l * np.cos(np.radians(theta)) * (h + l * np.sin(np.radians(theta))))
    # reciprocity and no normal-shear coupling
    assert got["nu12"] / got["E1"] == pytest.approx(got["nu21"] / got["E2"], rel=1e-9)
    assert np.abs(res.C_full[:2, 2]).max() < 1e-9 * np.abs(res.C_full).max()
    assert res.consistency < 1e-8
    if theta < 0:
        assert got["nu12"] < 0  # auxetic


@pytest.mark.parametrize("h,l,theta", [(1.0, 1.0, 30.0), (2.0, 1.0, -30.0)])
def test_honeycomb_gibson_ashby_limit(h, l, theta):
    """Relative distance to the bending-only result shrinks like (r/l)^2."""
    errs = []
    ratios = [0.1, 0.03, 0.01, 0.003]
    for rl in ratios:
        r = rl * l
        fr = lattice_frame("honeycomb", h=h, l=l, theta=theta, radius=r, E=E_WALL, nu=NU_WALL)
        got = homtex.homogenize(fr, solver="direct").engineering_constants()
        ga = gibson_ashby(h, l, theta, E_WALL * np.pi * r**4 / 4)
        errs.append(max(abs(got[k] / ga[k] - 1) for k in ga))
    errs = np.array(errs)
    assert np.all(np.diff(errs) < 0)
    assert errs[-1] < 5e-4
    scaled = errs / np.array(ratios)**2
    assert scaled.max() / scaled.min() < 1.5  # second order in the slenderness r/l


def test_square_lattice_stretch_dominated():
    a, r = 2.0, 0.1
    fr = lattice_frame("square", a=a, radius=r, E=E_WALL, nu=NU_WALL, elements_per_strut=3)
    res = homtex.homogenize(fr, solver="direct")
    EA, EI, kGA = _wall(r, r)
    C = res.C
    assert C[0, 0] == pytest.approx(EA / a, rel=1e-10)
    assert C[1, 1] == pytest.approx(EA / a, rel=1e-10)
    assert abs(C[0, 1]) < 1e-10 * C[0, 0]
    # shear: each strut bends as an S with joints not rotating
    assert C[2, 2] == pytest.approx(1.0 / (2 * (a**3 / (12 * EI) + a / kGA)), rel=1e-10)
    ec = res.engineering_constants()
    assert ec["E1"] == pytest.approx(EA / a, rel=1e-10)
    assert abs(ec["nu12"]) < 1e-10


def test_one_periodic_chain_axial_stiffness():
    # a zig-zag-free chain along x: C = EA (N)
    nodes = np.array([[0.0, 0, 0], [0.4, 0, 0], [1.0, 0, 0]])
    fr = Frame(nodes, [[0, 1], [1, 2], [2, 0]], radius=0.1, E=E_WALL, nu=NU_WALL,
               periods=[[1.5, 0, 0]], images=[[0], [0], [1]])
    res = homtex.homogenize(fr, solver="direct")
    assert res.C.shape == (1, 1) and res.units == "N"
    assert res.C[0, 0] == pytest.approx(E_WALL * np.pi * 0.01, rel=1e-12)


# ----------------------------------------------------------------------------------
@pytest.mark.parametrize("name,nel", [("octet", 2), ("bcc", 1)])
def test_supercell_symmetric_positive_definite(name, nel):
    fr1 = lattice_frame(name, a=1.0, radius=0.05, E=E_WALL, nu=NU_WALL, elements_per_strut=nel)
    fr2 = lattice_frame(name, a=1.0, radius=0.05, E=E_WALL, nu=NU_WALL, elements_per_strut=nel,
                        repeat=(2, 2, 2))
    C1 = homtex.homogenize(fr1, solver="direct").C
    res2 = homtex.homogenize(fr2, solver="amg")
    C2 = res2.C
    assert fr2.n_nodes == 8 * fr1.n_nodes
    assert np.abs(C2 - C1).max() <= 1e-8 * np.abs(C1).max()
    assert np.abs(C1 - C1.T).max() <= 1e-12 * np.abs(C1).max()
    assert np.linalg.eigvalsh(C1).min() > 0
    assert res2.consistency < 1e-8
    assert all(r.residual <= 1e-9 for r in res2.reports)
    # cubic symmetry of these lattices
    assert C1[0, 0] == pytest.approx(C1[2, 2], rel=1e-10)
    assert C1[3, 3] == pytest.approx(C1[5, 5], rel=1e-10)


def test_honeycomb_supercell():
    kw = dict(h=1.3, l=0.9, theta=-20.0, semi_axes=(0.05, 0.03), E=E_WALL, nu=NU_WALL)
    C1 = homtex.homogenize(lattice_frame("honeycomb", **kw)).C
    C2 = homtex.homogenize(lattice_frame("honeycomb", repeat=(3, 2), elements_per_strut=2, **kw)).C
    assert np.abs(C2 - C1).max() <= 1e-8 * np.abs(C1).max()


def _rotation(seed):
    rng = np.random.default_rng(seed)
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def test_rotated_lattice_rotates_C():
    # elliptical struts: the reference vectors rotate with the lattice
    fr = lattice_frame("octet", a=1.0, semi_axes=(0.05, 0.03), E=E_WALL, nu=NU_WALL)
    Q = _rotation(3)
    rot = fr.with_(nodes=fr.nodes @ Q.T, periods=fr.periods @ Q.T, ref=fr.R[:, 1] @ Q.T)
    C = homtex.homogenize(fr, solver="direct").C
    Cr = homtex.homogenize(rot, solver="amg").C
    assert np.abs(Cr - rotate_stiffness(C, Q)).max() <= 1e-8 * np.abs(C).max()
    # the octet is not isotropic: the rotation changes C
    assert np.abs(Cr - C).max() > 1e-3 * np.abs(C).max()


def test_rotated_honeycomb_membrane():
    fr = lattice_frame("honeycomb", h=1.5, l=1.0, theta=25.0, semi_axes=(0.06, 0.04), E=E_WALL, nu=NU_WALL)
    t = np.radians(37.0)
    Q = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])
    rot = fr.with_(nodes=fr.nodes @ Q.T, periods=fr.periods @ Q.T, ref=fr.R[:, 1] @ Q.T)
    C = homtex.homogenize(fr).C
    Cr = homtex.homogenize(rot).C
    assert np.abs(Cr - rotate_stiffness(C, Q)).max() <= 1e-8 * np.abs(C).max()
    assert np.abs(Cr - rotate_stiffness(C, Q[:2, :2])).max() <= 1e-8 * np.abs(C).max()


def test_amg_rigid_and_translation_nullspace_agree_with_direct():
    fr = lattice_frame("bcc", a=1.0, radius=0.04, E=E_WALL, nu=NU_WALL, elements_per_strut=3,
                       repeat=(3, 3, 3))
    Cd = homtex.homogenize(fr, solver="direct").C
    r1 = homtex.homogenize(fr, solver="amg", nullspace="rigid")
    r2 = homtex.homogenize(fr, solver="amg", nullspace="translations")
    for r in (r1, r2):
        assert np.abs(r.C - Cd).max() <= 1e-8 * np.abs(Cd).max()
    assert r1.reports[0].reused_setup is False
    assert r1.fluctuation.shape == (6, fr.n_nodes, 6)
    assert r1.energy.shape == (6, 5)


# ----------------------------------------------------------------------------------
def test_jump_load_matches_dense_element_matrices():
    fr = lattice_frame("bcc", a=1.0, semi_axes=(0.05, 0.03), E=E_WALL, nu=NU_WALL, elements_per_strut=2)
    rng = np.random.default_rng(0)
    H = rng.normal(size=(2, 3, 3))
    b = jump_load(fr, H)
    ref = np.zeros((2, fr.n_nodes, 6))
    d = fr.element_vectors
    for e, (i, j) in enumerate(fr.elements):
        k = local_stiffness(fr.length[e], fr.E[e] * fr.A[e], fr.G[e] * fr.J[e], fr.E[e] * fr.Iy[e],
                            fr.E[e] * fr.Iz[e], fr.k[e] * fr.G[e] * fr.A[e])
        T = np.kron(np.eye(4), fr.R[e])
        ke = T.T @ k @ T
        for q in range(2):
            a = np.zeros(12)
            a[6:9] = H[q] @ d[e]
            f = -ke @ a
            ref[q, i] += f[:6]
            ref[q, j] += f[6:]
    assert np.abs(b - ref).max() <= 1e-12 * np.abs(ref).max()
    # consistency with the assembled stiffness: a uniform H x field has no fluctuation load
    # in a non-periodic frame: K (H x) = -b
    K = assemble_reference(fr).toarray()
    x = fr.nodes
    fin = Frame(x, fr.elements[fr.images.any(axis=1) == 0], radius=0.04, E=E_WALL, nu=NU_WALL)
    Kf = assemble_reference(fin).toarray()
    u = np.zeros((fin.n_nodes, 6))
    u[:, :3] = x @ H[0].T
    assert np.abs(Kf @ u.ravel() + jump_load(fin, H[0])[0].ravel()).max() < 1e-9 * np.abs(Kf).max()
    assert K.shape[0] == fr.ndof


def test_free_components_uniaxial_stress():
    h, l, theta, ab = 1.2, 1.0, -25.0, (0.07, 0.05)
    fr = lattice_frame("honeycomb", h=h, l=l, theta=theta, semi_axes=ab, E=E_WALL, nu=NU_WALL)
    want = honeycomb_closed_form(h, l, theta, *ab)
    res = homtex.homogenize(fr, free=["22", "12"])
    assert res.components == ("11",) and res.free == ("22", "12")
    assert res.C[0, 0] == pytest.approx(want["E1"], rel=1e-6)
    assert res.strain[0, 1] == pytest.approx(-want["nu12"], rel=1e-6)
    assert np.abs(res.stress[0, 1:]).max() < 1e-8 * abs(res.stress[0, 0])
    for solver in ("direct", "amg"):
        st = solve_macro(fr, {"11": 0.01}, free=["22", "12"], solver=solver)
        assert st.strain[1] == pytest.approx(-0.01 * want["nu12"], rel=1e-6)
        assert st.stress[0] == pytest.approx(0.01 * want["E1"], rel=1e-6)
        assert np.abs(st.stress[1:]).max() < 1e-8 * abs(st.stress[0])
        assert st.energy == pytest.approx(0.5 * want["E1"] * 1e-4 * res.measure, rel=1e-6)
        # same fluctuation as the condensed homogenisation
        assert np.abs(st.fluctuation - 0.01 * res.fluctuation[0]).max() <= 1e-6 * np.abs(st.fluctuation).max()


def test_bad_inputs():
    fr = Frame([[0.0, 0, 0], [1, 0, 0]], [[0, 1]], radius=0.1, E=1.0, nu=0.3)
    with pytest.raises(InputError, match="periodic"):
        homtex.homogenize(fr)
    sq = lattice_frame("square", a=1.0, radius=0.05, E=1.0, nu=0.3)
    with pytest.raises(InputError, match="unknown strain component"):
        homtex.homogenize(sq, free=["33"])
    with pytest.raises(InputError, match="solver"):
        homtex.homogenize(sq, solver="magic")
    tilted = Frame([[0.0, 0, 0]], [[0, 0], [0, 0]], radius=0.05, E=1.0, nu=0.3,
                   periods=[[1.0, 0, 0], [0, 1.0, 0.5]], images=[[1, 0], [0, 1]])
    with pytest.raises(InputError, match="x-y"):
        homtex.homogenize(tilted)
    # a strut floating inside the cell (connected to nothing) is named
    nodes = np.array([[0.0, 0, 0], [0.3, 0.3, 0], [0.6, 0.3, 0]])
    fl = Frame(nodes, [[0, 0], [0, 0], [1, 2]], radius=0.05, E=1.0, nu=0.3,
               periods=[[1.0, 0, 0], [0, 1.0, 0]], images=[[1, 0], [0, 1], [0, 0]])
    with pytest.raises(SolverError, match="nodes 1-2"):
        homtex.homogenize(fl)


# ----------------------------------------------------------------------------------
def _box_grid(n, a, nel=1):
    """A simple cubic lattice of n^3 cells drawn in the box [0, n a]^3 (faces included)."""
    g = np.arange(n + 1) * a
    X, Y, Z = np.meshgrid(g, g, g, indexing="ij")
    nodes = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    idx = np.arange(len(nodes)).reshape(n + 1, n + 1, n + 1)
    el = []
    el.append(np.column_stack([idx[:-1].ravel(), idx[1:].ravel()]))
    el.append(np.column_stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()]))
    el.append(np.column_stack([idx[:, :, :-1].ravel(), idx[:, :, 1:].ravel()]))
    return nodes, np.vstack(el)


def test_periodize_box_drawn_lattice():
    n, a = 2, 1.5
    nodes, el = _box_grid(n, a)
    fr = Frame(nodes, el, radius=0.1, E=E_WALL, nu=NU_WALL)
    box = np.array([[0, 0, 0], [n * a] * 3], dtype=float)
    per = periodize(fr, box)
    assert per.n_nodes == n**3 and per.n_elements == 3 * n**3
    ref = lattice_frame("simple_cubic", a=a, radius=0.1, E=E_WALL, nu=NU_WALL, repeat=(n, n, n))
    C1 = homtex.homogenize(per, solver="direct").C
    C2 = homtex.homogenize(ref, solver="direct").C
    assert np.abs(C1 - C2).max() <= 1e-10 * np.abs(C2).max()
    # a 2-periodic slab: periodic in x and y only
    per2 = periodize(fr, box, axes=[0, 1])
    assert per2.dim_periodic == 2
    assert per2.n_nodes == n * n * (n + 1)
    # the bending factor survives periodisation: same stiffness as the lattice generator's, and
    # the shear stiffness of the cubic frame (bending-governed) scales with it
    per3 = periodize(fr.with_(bending_factor=3.0), box)
    ref3 = lattice_frame("simple_cubic", a=a, radius=0.1, E=E_WALL, nu=NU_WALL, repeat=(n, n, n), bending_factor=3.0)
    C3 = homtex.homogenize(per3, solver="direct").C
    assert np.abs(C3 - homtex.homogenize(ref3, solver="direct").C).max() <= 1e-10 * np.abs(C3).max()
    assert C3[3, 3] > 2.5 * C1[3, 3] and C3[0, 0] == pytest.approx(C1[0, 0], rel=1e-8)


def test_periodize_reports_unpaired_nodes():
    nodes, el = _box_grid(2, 1.0)
    nodes = nodes.copy()
    moved = int(np.flatnonzero((nodes[:, 0] == 2.0) & (nodes[:, 1] == 1.0) & (nodes[:, 2] == 1.0))[0])
    nodes[moved, 1] += 0.01
    fr = Frame(nodes, el, radius=0.1, E=E_WALL, nu=NU_WALL)
    with pytest.raises(InputError, match=rf"node {moved} at .*no partner"):
        periodize(fr, [[0, 0, 0], [2, 2, 2]], tol=1e-6)


# ----------------------------------------------------------------------------------
def _pillar_cell(ax, ay, H, r, nel=4, grid_r=0.2):
    """Two square grids (z = 0 and z = H) joined by a vertical pillar per cell."""
    zs = np.linspace(0, H, nel + 1)
    pillar = np.column_stack([np.zeros(nel + 1), np.zeros(nel + 1), zs])
    elements = [[i, i + 1] for i in range(nel)]
    images = [[0, 0]] * nel
    radius = [r] * nel
    for node in (0, nel):
        elements += [[node, node], [node, node]]
        images += [[1, 0], [0, 1]]
        radius += [grid_r, grid_r]
    return Frame(pillar, elements, radius=radius, E=E_WALL, nu=NU_WALL,
                 periods=[[ax, 0, 0], [0, ay, 0]], images=images)


@pytest.mark.parametrize("tie", ["xyz", "z"])
def test_compression_modulus_pillars(tie):
    ax, ay, H, r = 1.5, 2.0, 3.0, 0.1
    fr = _pillar_cell(ax, ay, H, r)
    res = compression_modulus(fr, solver="direct", tie=tie, plane_tol=0.25)
    EA = E_WALL * np.pi * r**2
    # the planes touch the grid yarns (contact radius 0.2) at z = -0.2 and H + 0.2
    assert res.thickness == pytest.approx(H + 0.4)
    assert res.stiffness == pytest.approx(EA / H, rel=1e-10)
    assert res.modulus == pytest.approx(EA / H * res.thickness / (ax * ay), rel=1e-10)
    assert res.force_per_area == pytest.approx(res.modulus * res.strain, rel=1e-12)
    amg = compression_modulus(fr, tie=tie, plane_tol=0.25)
    assert amg.modulus == pytest.approx(res.modulus, rel=1e-8)


def test_compression_needs_membrane_cell():
    fr = lattice_frame("simple_cubic", a=1.0, radius=0.1, E=1.0, nu=0.3)
    with pytest.raises(InputError, match="2-periodic"):
        compression_modulus(fr)


def test_wavy_struts_converge_with_resolution():
    """Curved struts: the chord discretisation converges at second order."""
    vals = []
    nels = [8, 16, 32, 64]
    for nel in nels:
        fr = lattice_frame("square", a=1.0, radius=0.03, E=E_WALL, nu=NU_WALL, waviness=0.1,
                           elements_per_strut=nel)
        vals.append(homtex.homogenize(fr, solver="direct").C[0, 0])
    d = np.abs(np.diff(vals))
    rates = np.log2(d[:-1] / d[1:])
    assert np.all(rates > 1.8) and np.all(rates < 2.2)
    # bending of the bow makes it much softer than the straight strut (EA / a)
    assert vals[-1] < 0.5 * E_WALL * np.pi * 0.03**2
