"""The engine's parts for knits, against closed forms: a rest state apart from the start geometry
(a ring of straight yarn stores pi EI / R and keeps it free; a bent cantilever springs back
straight; a natural curvature rolls a straight cantilever into the polygon of its rest shape; a
natural twist held straight carries GJ tau0), lattice vectors as unknowns (a 1-periodic yarn
stretched by its lattice carries EA strain, a dead lattice force stretches it by F a / EA, the
gradient and Hessian on the lattice are those of the potential, a ring pushed by its own
periodic image behaves as a ring between plates and never overlaps it), and the compressible
yarn contact (a yarn pressed by F onto a crossing one sits (F / k)^(1/n) inside the outer
surfaces; the plate-test fit)."""

import numpy as np
import pytest

import homtex
from homtex.contact.incremental import IncrementalSolver, NonlinearSettings
from homtex.model.rest import node_frames, start_rest, straight_rest

E, NU, R_Y = 2000.0, 0.3, 0.1


def chain(points, closed=False, periods=None, image_last=None, r=R_Y):
    """A frame of one yarn through points (k, 3); closed: back to the first (with an image)."""
    k = len(points)
    el = np.c_[np.arange(k - 1), np.arange(1, k)]
    images = None
    if closed:
        el = np.vstack([el, [k - 1, 0]])
        if periods is not None:
            images = np.zeros((len(el), len(periods)), dtype=int)
            images[-1] = image_last
    return homtex.Frame(points, el, radius=r, E=E, nu=NU, periods=periods, images=images)


def ring_frame(N, R=5.0):
    t = 2 * np.pi * np.arange(N) / N
    return chain(np.c_[R * np.cos(t), R * np.sin(t), np.zeros(N)], closed=True)


# ------------------------------------------------------------------------------------ rest state
def test_the_default_rest_state_is_the_start_geometry():
    fr = ring_frame(12)
    rs = start_rest(fr)
    assert np.array_equal(rs.length, fr.length) and np.array_equal(rs.frames[:, 0], fr.R)
    cor = homtex.Corotational(fr, geometric="consistent")
    cor.evaluate()
    assert np.abs(cor.energy).max() < 1e-30


@pytest.mark.parametrize("N", [16, 64])
def test_a_ring_of_straight_yarn_stores_pi_EI_over_R_and_stays_a_ring(N):
    R = 5.0
    fr = ring_frame(N, R)
    rest = straight_rest(fr)
    cor = homtex.Corotational(fr, geometric="consistent", rest=rest)
    cor.evaluate()
    EI = E * np.pi * R_Y ** 4 / 4
    Le = 2 * R * np.sin(np.pi / N)
    discrete = 2 * EI * (np.pi / N) ** 2 / Le * N         # (c - d) theta^2 per element, theta = pi / N
    assert cor.energy.sum() == pytest.approx(discrete, rel=1e-10)
    assert cor.energy[:, 2].sum() == pytest.approx(discrete, rel=1e-10)   # about local y (= z, the ring's axis)
    assert discrete == pytest.approx(np.pi * EI / R, rel=2.0 / N ** 2 * 10)
    # free (one node held), the ring is in equilibrium as it is: no iteration moves it
    res = homtex.solve_nonlinear(fr, {0: [0, 1, 2], 1: [2]}, None, rest=rest, steps=1)
    assert res.path.attrs["status"] == "ok"
    assert np.abs(res.x - fr.nodes).max() < 1e-8 * R


def test_a_cantilever_generated_bent_springs_back_straight():
    """A quarter circle of straight yarn, clamped at one end and free: it straightens (zero energy)
    with the tip at the polygon's length along the clamped end's tangent, and the ledger counts
    what the solver released."""
    N, R = 24, 4.0
    t = np.linspace(0, np.pi / 2, N + 1)
    fr = chain(np.c_[R * np.sin(t), R * (1 - np.cos(t)), np.zeros(N + 1)])
    rest = straight_rest(fr)
    # the ledger of a relaxation: the energy the solver releases is counted as released
    sol = IncrementalSolver(fr, {0: "all"}, None, [], homtex.Contact(), rest=rest,
                            settings=NonlinearSettings(stabilization="released"))
    U0 = float(sol.cor.energy.sum())
    sol.solve(motion=1.0)
    assert float(sol.cor.energy.sum()) < 1e-12 * U0
    assert sol.ledger["stabilization"] == pytest.approx(U0, rel=1e-6)
    assert abs(sol.balance()) < 1e-6
    L = fr.length.sum()
    u0 = fr.element_vectors[0] / fr.length[0]        # the clamped end's tangent: its first chord
    assert sol.positions[-1] == pytest.approx(L * u0, abs=1e-7 * L)


@pytest.mark.parametrize("N", [10, 40])
def test_a_natural_curvature_rolls_a_straight_cantilever_into_its_rest_polygon(N):
    L, kappa = 6.0, 0.4
    fr = chain(np.c_[np.linspace(0, L, N + 1), np.zeros(N + 1), np.zeros(N + 1)])
    rest = straight_rest(fr, curvature=(kappa, 0.0))          # about n1 = z (the ref): rolls in the xy plane
    # (a start away from equilibrium releases its energy: the ledger flags it unless relaxing)
    res = homtex.solve_nonlinear(fr, {0: "all"}, None, rest=rest, steps=4)
    assert sum(res.energy[k].sum() for k in res.energy) < 1e-12
    h = L / N      # chords of length h turning by kappa h at every node, the first by half that at the clamp
    ang = kappa * h * (np.arange(N) + 0.5)
    poly = np.cumsum(h * np.c_[np.cos(ang), np.sin(ang), np.zeros(N)], axis=0)[-1]
    assert np.abs(res.x[-1] - poly).max() < 1e-8
    arc = np.r_[np.sin(kappa * L), 1 - np.cos(kappa * L)] / kappa
    assert np.linalg.norm(res.x[-1, :2] - arc) < 0.5 * (kappa * h) ** 2 * L


def test_a_natural_twist_held_straight_carries_GJ_tau():
    L, N, tau = 5.0, 10, 0.2
    fr = chain(np.c_[np.linspace(0, L, N + 1), np.zeros(N + 1), np.zeros(N + 1)])
    rest = straight_rest(fr, twist=tau)
    res = homtex.solve_nonlinear(fr, {0: "all", N: "all"}, None, rest=rest, steps=1)
    GJ = E / (2 * (1 + NU)) * np.pi * R_Y ** 4 / 2
    assert res.reactions[N, 3] == pytest.approx(-GJ * tau, rel=1e-9)
    assert res.energy["torsion"].sum() == pytest.approx(0.5 * GJ * tau ** 2 * L, rel=1e-9)


def test_node_frames_close_over_the_periodic_boundary_with_the_holonomy_spread():
    """A helix closing over a 1-periodic boundary: the transported frames are orthonormal with
    their first axis along the node tangent, and consecutive frames differ by the same turn."""
    N, a = 32, 4.0
    s = np.arange(N) / N
    pts = np.c_[a * s, 0.5 * np.cos(2 * np.pi * s), 0.5 * np.sin(2 * np.pi * s)]
    fr = chain(pts, closed=True, periods=[[a, 0, 0]], image_last=[1])
    D = node_frames(fr)
    assert np.abs(np.einsum("nij,nik->njk", D, D) - np.eye(3)).max() < 1e-12
    rest = straight_rest(fr)
    cor = homtex.Corotational(fr, geometric="consistent", rest=rest)
    cor.evaluate()
    tw = cor.theta[:, 1, 0] - cor.theta[:, 0, 0]
    assert np.ptp(tw) < 1e-9                       # the turn is spread evenly
    assert np.ptp(cor.energy[:, 1]) < 1e-9 * cor.energy[:, 1].max() + 1e-15


def test_bad_rest_states_are_named():
    fr = ring_frame(8)
    rs = straight_rest(fr)
    with pytest.raises(homtex.InputError, match="shape"):
        homtex.solve_nonlinear(chain(np.c_[np.arange(4.0), np.zeros(4), np.zeros(4)]), {0: "all"}, None,
                               rest=rs)
    bad = homtex.RestState(length=-rs.length, frames=rs.frames)
    with pytest.raises(homtex.InputError, match="element 0"):
        homtex.solve_nonlinear(fr, {0: "all"}, None, rest=bad)
    branched = homtex.Frame(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]), [[0, 1], [0, 2], [0, 3]],
                            radius=0.1, E=E, nu=NU)
    with pytest.raises(homtex.InputError, match="node 0 joins 3"):
        straight_rest(branched)


# ------------------------------------------------------------------------------------ lattice
def periodic_yarn(a=4.0, N=8):
    pts = np.c_[np.linspace(0, a, N + 1)[:-1], np.zeros(N), np.zeros(N)]
    return chain(pts, closed=True, periods=[[a, 0.0, 0.0]], image_last=[1])


def test_a_periodic_yarn_stretched_by_its_lattice_carries_EA_strain():
    a, d = 4.0, 0.02
    fr = periodic_yarn(a)
    EA = E * np.pi * R_Y ** 2
    res = homtex.solve_nonlinear(fr, {0: "all"}, None, lattice=homtex.Lattice(motion={(0, 0): d}), steps=2)
    p = res.path
    assert p.attrs["status"] == "ok"
    assert float(p.periods[-1, 0, 0]) == pytest.approx(a + d, rel=1e-14)
    assert float(p.lattice_force[-1, 0, 0]) == pytest.approx(EA * d / a, rel=1e-8)
    assert float(p.axial[-1]) == pytest.approx(0.5 * EA * d ** 2 / a, rel=1e-8)
    assert float(p.external_work[-1]) == pytest.approx(0.5 * EA * d ** 2 / a, rel=1e-6)
    assert abs(float(p.energy_balance[-1])) < 1e-6


def test_a_dead_force_on_a_free_lattice_vector_stretches_the_cell_by_F_a_over_EA():
    a, F = 4.0, 3.0
    fr = periodic_yarn(a)
    EA = E * np.pi * R_Y ** 2
    lat = homtex.Lattice(free=[(0, 0)], force={(0, 0): F})
    res = homtex.solve_nonlinear(fr, {0: "all"}, None, lattice=lat, steps=1)
    assert float(res.path.periods[-1, 0, 0]) - a == pytest.approx(F * a / EA, rel=1e-8)
    assert float(res.path.lattice_force[-1, 0, 0]) == pytest.approx(F, rel=1e-8)   # the load on the lattice
    assert abs(float(res.path.energy_balance[-1])) < 1e-6


def wavy_on_straight(L=4.0, n=16, amp=0.3, r=0.1):
    """A wavy yarn on a straight one in a 2-periodic cell (periods L along x, 1 mm along y),
    touching across the cell boundary."""
    x = np.arange(n) * L / n
    A = np.c_[x, np.zeros(n), np.zeros(n)]
    B = np.c_[x + L / (2 * n), 0.15 * np.sin(2 * np.pi * x / L), 2 * r + 0.01 + amp * (1 + np.cos(2 * np.pi * x / L))]
    el = np.vstack([np.c_[np.arange(n), (np.arange(n) + 1) % n], n + np.c_[np.arange(n), (np.arange(n) + 1) % n]])
    img = np.zeros((2 * n, 2), dtype=int)
    img[n - 1, 0] = img[2 * n - 1, 0] = 1
    return homtex.Frame(np.vstack([A, B]), el, radius=r, E=E, nu=NU, yarn=np.r_[np.zeros(n, int), np.ones(n, int)],
                        periods=[[L, 0, 0], [0, 1.0, 0]], images=img)


def test_the_lattice_gradient_and_hessian_are_those_of_the_potential():
    """Finite differences of the total potential (beams + barrier across the moving boundary) in
    the lattice components against the engine's gradient, and of the gradient against the
    bordered Hessian."""
    fr = wavy_on_straight()
    n = fr.n_nodes
    lat = homtex.Lattice(free=[(0, 0), (0, 2), (1, 1)])
    nb = n // 2
    press = {nb + i: (0, 0, -0.02, 0, 0, 0) for i in range(nb)}
    sol = IncrementalSolver(fr, {0: "all", nb: [0, 1]}, press, [], homtex.Contact(), lattice=lat)
    sol.solve(loads=1.0)                 # pressed onto each other, contacts across the boundary active
    P0 = sol.lat.periods + [[-0.01, 0.0, 0.003], [0.002, 0.01, 0.0]]     # off equilibrium
    sol._set_periods(P0)
    ev = sol._evaluate(sol.positions, [], hessian=True)
    assert ev["pairs"].n_active > 0 and len(sol.lat.base) > 0
    g = ev["g"][sol.lat.rows, :3]
    h = 1e-6
    for (a, c) in [(0, 0), (0, 2), (1, 1)]:
        out = []
        for sgn in (1, -1):
            P = P0.copy()
            P[a, c] += sgn * h
            sol._set_periods(P)
            out.append(sol._evaluate(sol.positions, [], hessian=False)["Pi"])
        sol._set_periods(P0)
        fd = (out[0] - out[1]) / (2 * h)
        assert fd == pytest.approx(g[a, c], rel=1e-5, abs=1e-9 * np.abs(g).max())
    # the bordered Hessian times a step along a free lattice component and the nodes
    sol._assemble(ev)
    rng = np.random.default_rng(1)
    v = np.zeros((sol.N, 6))
    v[:n] = rng.normal(size=(n, 6)) * 1e-3
    v[sol.lat.rows[0], 0] = 1e-3
    v = np.where(sol.mask.reshape(sol.N, 6), 0.0, v)
    Hv = sol.sys.matvec(v.ravel()[sol.free])
    def grad_at(t):
        snap = sol.snapshot()
        sol._apply(t, v)
        gg = sol._evaluate(sol.positions, [], hessian=False)["g"].ravel()[sol.free]
        sol.restore(snap)
        return gg
    fdH = (grad_at(1e-4) - grad_at(-1e-4)) / 2e-4
    assert np.linalg.norm(Hv - fdH) < 2e-3 * np.linalg.norm(fdH)


def test_a_periodic_column_shortened_by_its_lattice_buckles_onto_the_elastica():
    """The engine's bifurcation handling with the lattice as unknowns: a perfect straight yarn,
    1-periodic along x (a = 4 mm, 32 elements, node 0 clamped), shortened 5 % by its lattice
    vector's x component with its y component free (the cell may shear). Nothing breaks the
    symmetry, so the straight state is left along its critical mode (a sway that moves the free
    lattice component: the bordered system's Hessian) by recorded perturbations; the yarn settles
    on the clamped-guided elastica: the lattice force is (2 K(m) / pi)^2 pi^2 EI / a^2 for the
    chord's shortening (less its axial strain; 32 elements: within 0.5 %), the sway is
    2 a sqrt(m) / K(m) (0.2 %), the state is stable and the ledger closes."""
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipk

    a, N, d = 4.0, 32, 0.2
    pts = np.c_[np.linspace(0, a, N + 1)[:-1], np.zeros(N), np.zeros(N)]
    fr = chain(pts, closed=True, periods=[[a, 0.0, 0.0]], image_last=[1])
    res = homtex.solve_nonlinear(fr, {0: "all"}, None, lattice=homtex.Lattice(free=[(0, 1)], motion={(0, 0): -d}),
                                 steps=2)
    p = res.path
    assert p.attrs["status"] == "ok" and np.abs(p.energy_balance.values).max() < 0.01
    assert len(p.attrs["branch_switches"]) >= 1 and bool(p.stable[-1])
    EI, EA = E * np.pi * R_Y ** 4 / 4, E * np.pi * R_Y ** 2
    P = -float(p.lattice_force[-1, 0, 0])
    assert float(p.periods[-1, 0, 0]) == pytest.approx(a - d, rel=1e-14)
    shortening = 1 - (a - d + P * a / EA) / a
    m = brentq(lambda m: 2 - 2 * ellipe(m) / ellipk(m) - shortening, 1e-12, 0.9999)
    assert P == pytest.approx((2 * ellipk(m) / np.pi) ** 2 * np.pi ** 2 * EI / a ** 2, rel=5e-3)
    assert abs(float(p.periods[-1, 0, 1])) == pytest.approx(2 * a * np.sqrt(m) / ellipk(m), rel=2e-3)


def ring_in_a_row(R=2.0, r=0.1, N=64, gap=0.05):
    """A ring in a 1-periodic cell along x, its image gap mm away."""
    t = 2 * np.pi * np.arange(N) / N
    fr = chain(np.c_[R * np.cos(t), R * np.sin(t), np.zeros(N)], closed=True, r=r)
    return homtex.Frame(fr.nodes, fr.elements, radius=r, E=E, nu=NU, periods=[[2 * R + 2 * r + gap, 0, 0]],
                        images=np.zeros((N, 1), dtype=int))


@pytest.mark.parametrize("steps", [1, 4])
def test_a_ring_pushed_by_its_own_periodic_image_is_a_ring_between_plates(steps):
    """The lattice shrinks until the ring presses on its image across the boundary: the contact
    force is the lattice force, and against the diameter change it follows the ring's
    delta = F R^3 / EI [(pi / 4 - 2 / pi) + pi / 4 (EI / (k G A R^2) + I / (A R^2))] (bending, with
    the shear and axial flexibility, Castigliano) at small deflection (delta / R = 0.5 %); no state
    overlaps its image (one step or four)."""
    R, r, N, gap = 2.0, 0.1, 64, 0.05
    fr = ring_in_a_row(R, r, N, gap)
    q = N // 4
    fixed = {q: [0, 1, 2], 3 * q: [0, 2], 0: [2]}
    shrink = gap + 0.01
    res = homtex.solve_nonlinear(fr, fixed, None, lattice=homtex.Lattice(motion={(0, 0): -shrink}), steps=steps)
    p = res.path
    assert p.attrs["status"] == "ok"
    assert (p.min_gap.values > 0).all() and int(p.active_yarn_yarn[-1]) > 0
    width = res.x[:, 0].max() - res.x[:, 0].min()
    delta = 2 * R - width
    F = -float(p.lattice_force[-1, 0, 0])
    EI, A = E * np.pi * r ** 4 / 4, np.pi * r ** 2
    kG = 6 * (1 + NU) / (7 + 6 * NU) * E / (2 * (1 + NU))
    c = (np.pi / 4 - 2 / np.pi) + np.pi / 4 * (EI / (kG * A * R ** 2) + EI / (E * A * R ** 2))
    assert delta == pytest.approx(c * F * R ** 3 / EI, rel=4e-3)
    assert np.abs(res.reactions).max() < 1e-6 * F           # the supports only hold rigid motions
    assert abs(float(p.energy_balance[-1])) < 0.01


def test_an_image_beyond_the_search_margin_is_found_before_the_lattice_carries_it_through():
    """The ring's image starts 0.5 mm away (beyond the 0.1 mm search margin, so no candidate pair)
    and one step shrinks the lattice by 0.52 mm: the search follows the images' motion, the
    collision check stops the ring at its image, and the final state presses on it."""
    R, r, N, gap = 2.0, 0.1, 64, 0.5
    fr = ring_in_a_row(R, r, N, gap)
    q = N // 4
    res = homtex.solve_nonlinear(fr, {q: [0, 1, 2], 3 * q: [0, 2], 0: [2]}, None,
                                 lattice=homtex.Lattice(motion={(0, 0): -(gap + 0.02)}), steps=1)
    p = res.path
    assert p.attrs["status"] == "ok"
    assert float(p.min_gap[-1]) > 0 and int(p.active_yarn_yarn[-1]) > 0
    assert 2 * R - (res.x[:, 0].max() - res.x[:, 0].min()) == pytest.approx(0.02, abs=2e-3)


# ------------------------------------------------------------------------------------ compression
def test_a_yarn_pressed_onto_a_crossing_one_sits_F_over_k_to_the_one_over_n_inside():
    R, h, k, n_exp, F = 0.5, 0.3, 2.0, 2.0, 0.5
    comp = homtex.YarnCompression(shell=h, stiffness=k, exponent=n_exp)
    m = 10
    s = np.linspace(-2, 2, m + 1)
    A = np.c_[s, np.zeros(m + 1), np.zeros(m + 1)]
    B = np.c_[np.zeros(m + 1), s, np.full(m + 1, 2 * R + 0.02)]
    el = np.vstack([np.c_[np.arange(m), np.arange(1, m + 1)], m + 1 + np.c_[np.arange(m), np.arange(1, m + 1)]])
    fr = homtex.Frame(np.vstack([A, B]), el, radius=R, E=1e5, nu=NU, yarn=np.r_[np.zeros(m, int), np.ones(m, int)])
    fixed = {i: "all" for i in range(m + 1)}
    fixed.update({m + 1 + i: [0, 1, 3, 4, 5] for i in range(m + 1)})
    mid_b = m + 1 + m // 2
    res = homtex.solve_nonlinear(fr, fixed, {mid_b: (0, 0, -F, 0, 0, 0)}, contact=homtex.Contact(compression=comp),
                                 steps=2)
    assert res.path.attrs["status"] == "ok"
    d = res.x[mid_b, 2] - res.x[m // 2, 2]
    assert 2 * R - d == pytest.approx((F / k) ** (1 / n_exp), rel=1e-6)
    assert comp.force(2 * R - d) == pytest.approx(F, rel=1e-6)
    assert float(res.path.contact_energy[-1]) > 0
    with pytest.raises(homtex.InputError, match="smaller than the yarns"):
        homtex.solve_nonlinear(fr, fixed, None, contact=homtex.Contact(compression=homtex.YarnCompression(0.6, 1.0)))
    with pytest.raises(homtex.InputError, match="solid yarns"):
        homtex.compress(homtex.load_cell("spacer_20mm"), strain=0.1, contact=homtex.Contact(compression=comp),
                        geometry="linear")


def test_the_plate_test_fit_recovers_a_power_law_and_reads_the_acrylic_test():
    t = np.array([0.5, 1.0, 1.5])
    law = homtex.YarnCompression.from_plate_test(t, 0.3 * t ** 2.5, diameter=2.0)
    assert law.stiffness == pytest.approx(0.3, rel=1e-10) and law.exponent == pytest.approx(2.5, rel=1e-12)
    assert law.shell == pytest.approx(0.85)
    acr = homtex.YarnCompression.from_plate_test([1.19, 1.85, 2.28], [0.1, 1.0, 2.9], diameter=2.66,
                                                 core_fraction=0.1)
    assert 4.5 < acr.exponent < 6.0
    assert np.abs(acr.force([1.19, 1.85, 2.28]) / [0.1, 1.0, 2.9] - 1).max() < 0.1
    with pytest.raises(homtex.InputError, match="more than the shells allow"):
        homtex.YarnCompression.from_plate_test([1.19, 1.85, 2.28], [0.1, 1.0, 2.9], diameter=2.66)
