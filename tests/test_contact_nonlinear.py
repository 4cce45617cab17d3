"""The large-motion contact engine (``compress(..., geometry="nonlinear")``, IncrementalSolver):
two crossing yarns pressed, slid and turned over each other never pass through (every accepted
state has a positive gap, also when the whole motion is one step); a ring crushed to half its
height between plates against the elastica of a ring (three meshes converge on it); the
stabilisation stays small on smooth paths and a snap-through is flagged; force control; the
2-periodic spacer cell with friction; equality with the linear model at small strain; bad
arguments are named."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import homtex
from homtex.contact.incremental import IncrementalSolver
from homtex.contact.nl_compress import first_buckling_strain
from homtex.contact.potential import pair_gaps
from homtex.errors import InputError, SolverError

E0, NU = 1000.0, 0.3


# ----------------------------------------------------------------------------------------
def crossing_yarns(r=0.1, n=20, L=4.0):
    s = np.linspace(-L / 2, L / 2, n + 1)
    A = np.c_[s, np.zeros(n + 1), np.zeros(n + 1)]
    B = np.c_[np.zeros(n + 1), s, np.full(n + 1, 2 * r + 0.05)]
    nodes = np.vstack([A, B])
    el = np.vstack([np.c_[np.arange(n), np.arange(1, n + 1)], n + 1 + np.c_[np.arange(n), np.arange(1, n + 1)]])
    fr = homtex.Frame(nodes, el, radius=r, E=2000.0, nu=0.3, yarn=np.r_[np.zeros(n, int), np.ones(n, int)])
    return fr, (0, n, n + 1, 2 * n + 1)


def b_ends(fr, ends, t, r=0.1, L=4.0):
    """B's ends at t in [0, 3]: pushed 0.6 mm down (below A's centre line: B must wrap over A),
    carried 1.5 mm along A (sliding) and turned 60 degrees about z (rolling over A)."""
    down = min(t, 1.0) * 0.6
    slide = np.clip(t - 1.0, 0, 1) * 1.5
    turn = np.clip(t - 2.0, 0, 1) * np.radians(60)
    out = {}
    for node, y in ((ends[2], -L / 2), (ends[3], L / 2)):
        p = np.array([slide - y * np.sin(turn), y * np.cos(turn), 2 * r + 0.05 - down])
        out[node] = dict(enumerate(p - fr.nodes[node]))
    return out


@pytest.mark.parametrize("mu", [0.0, 0.3])
@pytest.mark.parametrize("steps", [3, 30])
def test_crossing_yarns_pressed_slid_and_turned_never_pass_through(mu, steps):
    fr, ends = crossing_yarns()
    sol = IncrementalSolver(fr, {e: "all" for e in ends}, None, [], homtex.Contact(friction=mu))
    for k in range(1, steps + 1):
        sol.solve(prescribed=b_ends(fr, ends, 3.0 * k / steps))
        assert pair_gaps(sol.positions, sol.scene.stencil).min() > 0.0      # every accepted state
    # B lies over A where they cross (its closest point is above A's), now well along A
    x = sol.positions
    st = sol.scene.stencil
    q = int(np.argmin(pair_gaps(x, st)))
    a_pts, b_pts = (x[st.nodes[q]] + st.shift[q])[:2], (x[st.nodes[q]] + st.shift[q])[2:]
    if st.a[q] > st.b[q] or fr.yarn[st.a[q]] == 1:
        a_pts, b_pts = b_pts, a_pts
    assert b_pts[:, 2].mean() > a_pts[:, 2].mean() + 0.1
    assert 0.5 < a_pts[:, 0].mean() < 2.0
    if mu > 0:
        assert sol.ledger["dissipation"] > 0.0


def test_a_support_that_pushes_a_yarn_through_another_is_refused():
    """A's ends are moved onto B's line of motion and B's ends straight through A: the engine
    cannot reach that state without an overlap and says so; the state stays as it was."""
    fr, ends = crossing_yarns()
    sol = IncrementalSolver(fr, {e: "all" for e in ends}, None, [homtex.Plate(z=-0.3, normal=1, displacement=0.0)],
                            homtex.Contact())
    before = sol.positions.copy()
    with pytest.raises(SolverError, match="overlap|converge"):
        sol.solve(prescribed={e: {2: -0.6} for e in ends[2:]} | {e: {2: -0.25} for e in ends[:2]})
    assert np.array_equal(sol.positions, before)


# ----------------------------------------------------------------------------------------
def _shoot(p, k0, c):
    """Quarter of an inextensible unit ring (EI = 1) from its top, loaded by the plate force
    P = p (both plates: P, each quarter P / 2): a flat part of length c on the plate, then the
    free arc with psi(c) = 0, psi' = 1 + k0 + P / 2 (x - c); returns psi, x, y at s = pi / 2."""
    def f(s, u):
        return [1.0 + k0 + 0.5 * p * (u[1] - c), np.cos(u[0]), -np.sin(u[0])]
    return solve_ivp(f, (c, 0.5 * np.pi), [0.0, c, 0.0], rtol=1e-11, atol=1e-13).y[:, -1]


def ring_elastica(p):
    """Closure delta / (2 R) of a thin inextensible ring squeezed between two frictionless plates by
    P = p EI / R^2: point contact (the top's moment M0 = k0 EI / R from psi(pi/2) = pi / 2) until
    the top's curvature vanishes, then a flat contact zone of half-length c (M = -EI / R on it)."""
    g = lambda k0: _shoot(p, k0, 0.0)[0] - 0.5 * np.pi    # noqa: E731
    if g(-1.0) * g(10.0) < 0:
        k0, c = brentq(g, -1.0, 10.0), 0.0
    else:
        k0 = -1.0
        c = brentq(lambda c: _shoot(p, k0, c)[0] - 0.5 * np.pi, 0.0, 0.999 * 0.5 * np.pi)
    return 1.0 + _shoot(p, k0, c)[2], c


def ring(N, R=10.0, r=0.1):
    th = 2 * np.pi * np.arange(N) / N
    nodes = np.column_stack([R * np.sin(th), 0 * th, R - R * np.cos(th)])
    el = np.column_stack([np.arange(N), (np.arange(N) + 1) % N])
    fr = homtex.Frame(nodes, el, radius=r, E=E0, nu=NU, ref=(0, 1, 0))
    fixed = {i: [1, 3, 5] for i in range(N)}
    fixed[0] = [0, 1, 3, 5]
    fixed[N // 2] = [0, 1, 3, 5]
    return fr, fixed


def test_the_ring_elastica_reference():
    # small loads: the linear thin ring, delta = 0.1488 P R^3 / EI (Roark)
    assert ring_elastica(0.01)[0] / 0.01 == pytest.approx(0.1488 / 2, rel=2e-3)
    # the top flattens onto the plate between p = 2 and 4
    assert ring_elastica(2.0)[1] == 0.0 and ring_elastica(4.0)[1] > 0.2


def test_a_ring_crushed_to_half_its_height_converges_to_the_elastica():
    R, r = 10.0, 0.1
    EI = E0 * np.pi * r ** 4 / 4
    errs = []
    for N in (32, 64, 128):
        fr, fixed = ring(N, R, r)
        ds = homtex.compress(fr, strain=0.5, steps=10, fixed=fixed, geometry="nonlinear")
        assert ds.attrs["status"] == "ok"
        # a smooth path: the stabilisation absorbs nothing worth mentioning, the energy balances
        assert float(ds.stabilization_energy[-1]) < 1e-5 * float(ds.external_work[-1])
        assert np.abs(ds.energy_balance.values).max() < 0.01
        ghat = ds.attrs["barrier_gap_mm"]
        e = []
        for i in (1, 3, 5, 7, 9):                          # 10 % ... 50 % of the height
            closure = float(ds.plate_displacement[i]) - 2 * (ghat - float(ds.min_gap[i]))
            p = brentq(lambda p: ring_elastica(p)[0] - closure / (2 * R), 1e-6, 20.0)
            e.append(abs(float(ds.force[i]) * R ** 2 / EI / p - 1))
        errs.append(max(e))
        if N == 128:
            assert int(ds.active_yarn_plate[-1]) > 2       # crushed flat onto the plates
    # O(h^2): 2.8e-2, 5e-3, 8e-4 measured
    assert errs[0] > 3 * errs[1] > 9 * errs[2]
    assert errs[2] < 2e-3


# ----------------------------------------------------------------------------------------
def arch(N=20, a=10.0, h=1.0, r=0.1):
    Rc = (a * a + h * h) / (2 * h)
    th0 = np.arcsin(a / Rc)
    th = np.linspace(-th0, th0, N + 1)
    nodes = np.c_[Rc * np.sin(th), np.zeros(N + 1), Rc * np.cos(th) - (Rc - h)]
    fr = homtex.Frame(nodes, np.c_[np.arange(N), np.arange(1, N + 1)], radius=r, E=E0, nu=NU, ref=(0, 1, 0))
    fixed = {0: "all", N: "all"} | {i: [1, 3, 5] for i in range(1, N)}
    return fr, fixed


def test_a_snap_through_is_flagged_and_a_smooth_path_is_not():
    """A shallow clamped arch pressed at its crown by the top plate snaps through (it jumps off
    the plate onto the bottom one): the stabilisation absorbs it and the curve is "flagged"."""
    fr, fixed = arch()
    with pytest.warns(UserWarning, match="force falls"):
        ds = homtex.compress(fr, strain=0.6, steps=6, fixed=fixed, geometry="nonlinear")
    assert ds.attrs["status"] == "flagged" and "stabilisation absorbed" in ds.attrs["status_detail"]
    assert int(ds.sizes["strain"]) == 6                      # complete, though
    # the step where the force falls is the one whose stabilisation jumps (the energy the snap releases)
    f, S, W = ds.force.values, ds.stabilization_energy.values, ds.external_work.values
    k = int(np.argmax(np.maximum.accumulate(f) - f))
    assert f[k] < 0.5 * f[:k].max()
    assert (S[k] - S[k - 1]) / W[k] > 0.01 and S[k - 1] < 1e-6 * W[k - 1]
    # the same arch pressed gently stays on its smooth branch
    ds = homtex.compress(fr, strain=0.2, steps=4, fixed=fixed, geometry="nonlinear")
    assert ds.attrs["status"] == "ok"
    assert float(ds.stabilization_energy[-1]) < 1e-3 * float(ds.external_work[-1])


def test_force_control_reaches_the_displacement_controlled_state():
    fr, fixed = ring(32)
    disp = homtex.compress(fr, strain=0.2, steps=4, fixed=fixed, geometry="nonlinear")
    kpa = float(disp.stress[-1])
    force = homtex.compress(fr, control="force", pressure=kpa, steps=4, fixed=fixed, geometry="nonlinear")
    assert force.attrs["status"] == "ok" and force.attrs["control"] == "force"
    assert float(force.strain[-1]) == pytest.approx(float(disp.strain[-1]), rel=1e-5)
    assert float(force.force[-1]) == pytest.approx(float(disp.force[-1]), rel=1e-6)


# ----------------------------------------------------------------------------------------
def test_spacer_cell_with_friction_two_percent():
    """The 2-periodic spacer cell (16 pairs touching in the generated geometry start at zero force),
    two 1 % levels with friction 0.2: complete, energies recorded with units, balanced."""
    cell = homtex.load_cell("spacer_20mm")
    ds = homtex.compress(cell, strain=0.02, steps=2, geometry="nonlinear", contact=homtex.Contact(friction=0.2))
    assert ds.attrs["status"] == "ok", ds.attrs.get("status_detail")
    assert ds.attrs["initial_touching_pairs"] == 16
    for v in ("stress", "force", "active_contacts", "axial", "torsion", "bending_y", "bending_z", "shear",
              "contact_energy", "friction_energy", "stabilization_energy", "external_work", "energy_balance"):
        assert v in ds and ds[v].attrs["units"]
    assert (ds.friction_energy.values > 0).all() and (ds.stress.values > 0).all()
    assert np.abs(ds.energy_balance.values).max() < 0.01
    assert (ds.min_gap.values > 0).all() and (ds.max_penetration.values == 0).all()
    assert 0.002 < ds.attrs["first_buckling_strain"] < 0.02


def test_spacer_cell_agrees_with_the_linear_model_at_small_strain():
    """At 0.005 % the bowed pile legs carry 0.5 % of their Euler load and the two models agree to
    0.5 % once the barrier is stiff and thin (the default one gives back up to ghat = 1 um per
    contact: 2 % of the 1 um plate travel here); from there on the nonlinear model softens as
    the legs approach their Euler load (studies/experiments/spacer_nonlinear_compression.py)."""
    cell = homtex.load_cell("spacer_20mm")
    lin = homtex.compress(cell, strain=5e-5, steps=1, geometry="linear")
    nl = homtex.compress(cell, strain=5e-5, steps=1, geometry="nonlinear",
                         contact=homtex.Contact(barrier_stiffness=1e5, barrier_gap=1e-3))
    assert float(nl.stress[-1]) == pytest.approx(float(lin.stress[-1]), rel=5e-3)
    default = homtex.compress(cell, strain=5e-5, steps=1, geometry="nonlinear")
    assert float(default.stress[-1]) == pytest.approx(float(lin.stress[-1]), rel=0.03)


def test_first_buckling_strain_marks_the_knee():
    e = np.linspace(0.001, 0.05, 50)
    straight = np.minimum(e, 0.02)                           # a strut bifurcating at 2 %
    assert first_buckling_strain(e, straight) == pytest.approx(0.02, abs=1e-3)
    smooth = np.tanh(e / 0.01)                               # a bowed one: slope halves at 0.881 % x ...
    x = 0.01 * np.arccosh(np.sqrt(2.0))
    assert first_buckling_strain(e, smooth) == pytest.approx(x, abs=5e-4)
    assert np.isnan(first_buckling_strain(e, e))              # linear: never


# ----------------------------------------------------------------------------------------
def test_bad_arguments_of_the_engine_are_named():
    fr, ends = crossing_yarns()
    with pytest.raises(InputError, match="frame"):
        IncrementalSolver("frame")
    with pytest.raises(InputError, match="contact"):
        IncrementalSolver(fr, contact="barrier")
    sol = IncrementalSolver(fr, {e: "all" for e in ends}, None,
                            [homtex.Plate(z=-1.0, normal=1, force=1.0), homtex.Plate(z=1.0, normal=-1, displacement=0)])
    with pytest.raises(InputError, match="prescribed"):
        sol.solve(prescribed={5: {2: 0.1}})                  # node 5 has no support
    with pytest.raises(InputError, match="force-controlled"):
        sol.solve(plate_z={0: 0.0})
    with pytest.raises(InputError, match="displacement-controlled"):
        sol.solve(plate_force={1: 1.0})
    with pytest.raises(InputError, match="loads"):
        sol.set_loads({0: (1, 2)})


# ----------------------------------------------------------------------------------------
def wavy_on_straight(periods_in_cell: int, n_per_period: int = 16, L: float = 4.0, amp: float = 0.3,
                     r: float = 0.1):
    """A 1-periodic stack along x: a straight yarn on the bottom plate and a sinusoidal yarn on it
    (its troughs touching the straight yarn, its crests the top plate); the cell holds
    ``periods_in_cell`` waves."""
    n = periods_in_cell * n_per_period
    x = np.arange(n) * L / n_per_period
    zs = (np.full(n, r), 3 * r + amp * (1 - np.cos(2 * np.pi * x / L)))
    nodes = np.vstack([np.c_[x, np.zeros(n), z] for z in zs])
    els = np.vstack([np.c_[np.arange(n) + k * n, (np.arange(n) + 1) % n + k * n] for k in (0, 1)])
    images = np.tile(np.r_[np.zeros(n - 1, int), 1], 2)[:, None]
    return homtex.Frame(nodes, els, radius=r, E=3000.0, nu=0.3, yarn=np.repeat([0, 1], n), ref=(0, 1, 0),
                        periods=[(periods_in_cell * L, 0.0, 0.0)], images=images)


@pytest.mark.parametrize("mu", [0.0, 0.3])
def test_a_one_periodic_stack_gives_the_same_stress_for_one_and_two_periods(mu):
    """Periodicity is exact: a 1-periodic cell of one wave and of two waves, compressed by 6 %
    with large rotations, yarn-yarn and yarn-plate contact and friction, give the same stress
    (force per area) and the same work per wave. (Near 7 % the flattened crest splits into two
    contacts with a small jump, where a two-wave cell may also take a period-doubled path.)"""
    out = []
    for k in (1, 2):
        fr = wavy_on_straight(k)
        # a plane problem; one node of each yarn held along x (nothing else holds them there
        # without friction)
        fixed = {i: [1, 3, 5] for i in range(fr.n_nodes)} | {0: [0, 1, 3, 5], fr.n_nodes // 2: [0, 1, 3, 5]}
        ds = homtex.compress(fr, strain=0.06, steps=6, fixed=fixed, area=k * 4.0 * 1.0, geometry="nonlinear",
                             contact=homtex.Contact(friction=mu))
        assert ds.attrs["status"] == "ok", ds.attrs.get("status_detail")
        assert int(ds.active_yarn_yarn[-1]) > 0 and int(ds.active_yarn_plate[-1]) > 0
        out.append((ds.stress.values, float(ds.external_work[-1]) / k))
    np.testing.assert_allclose(out[1][0], out[0][0], rtol=1e-5)
    assert out[1][1] == pytest.approx(out[0][1], rel=1e-5)
    assert out[0][0][-1] > 5 * out[0][0][0] > 0


def test_a_two_periodic_cell_and_its_two_by_one_supercell_agree_before_buckling():
    """The spacer cell and the same cell tiled 2 x 1, compressed with the large-motion engine to
    0.5 % (below the first buckling strain, 0.71 %), give the same stress."""
    from homtex.geometry.tiling import tile_frame

    cell = homtex.load_cell("spacer_20mm")
    # the same contact for both: a bare frame has no cell file's friction
    c = homtex.Contact(friction=0.0)
    one = homtex.compress(cell, strain=0.005, steps=2, geometry="nonlinear", contact=c)
    big, *_ = tile_frame(cell.frame, 2, 1)
    two = homtex.compress(big, strain=0.005, steps=2, geometry="nonlinear", thickness=cell.info["thickness"], contact=c)
    assert one.attrs["status"] == two.attrs["status"] == "ok"
    assert float(two.attrs["area_mm2"]) == pytest.approx(2 * float(one.attrs["area_mm2"]))
    np.testing.assert_allclose(two.stress.values, one.stress.values, rtol=1e-4)


# ----------------------------------------------------------------------------------------
def stitch_over_a_yarn(theta=0.3, leg=2.0, n_arc=16, n_leg=12, r=0.05, Rc=0.5, E=1e4, eps0=0.05, bf=1e-4):
    """A thread (pre-strain eps0) wrapped by +-theta over a fixed stiff yarn (along y, radius Rc),
    resting on it at the barrier's gap, with straight tangent legs of length ``leg`` whose ends
    are held. Returns the solver, the thread's EA, sin(theta) and its element count."""
    rho = Rc + r + 0.01 * r
    ph = np.linspace(-theta, theta, n_arc + 1)
    arc = np.c_[rho * np.sin(ph), np.zeros_like(ph), rho * np.cos(ph)]
    s = leg * np.arange(1, n_leg + 1) / n_leg
    dR = np.array([np.cos(theta), 0.0, -np.sin(theta)])
    dL = np.array([-np.cos(theta), 0.0, -np.sin(theta)])
    thread = np.vstack([arc[0] + s[::-1, None] * dL, arc, arc[-1] + s[:, None] * dR])
    m = len(thread) - 1
    nodes = np.vstack([thread, [[0, -3.0, 0], [0, 3.0, 0]]])
    el = np.vstack([np.c_[np.arange(m), np.arange(1, m + 1)], [[m + 1, m + 2]]])
    fr = homtex.Frame(nodes, el, radius=np.r_[np.full(m, r), Rc], E=np.r_[np.full(m, E), 1e6], nu=0.3,
                      yarn=np.r_[np.zeros(m, int), 1], ref=np.r_[np.tile([0, 1.0, 0], (m, 1)), [[1.0, 0, 0]]],
                      bending_factor=np.r_[np.full(m, bf), 1.0], prestrain=np.r_[np.full(m, eps0), 0.0])
    fixed = {i: [1, 3, 5] for i in range(1, m)} | {0: "all", m: "all", m + 1: "all", m + 2: "all"}
    sol = IncrementalSolver(fr, fixed, None, [], homtex.Contact())
    return sol, E * np.pi * r ** 2, np.sin(theta), m


def test_a_prestrained_stitch_pulls_on_the_yarn_it_wraps_by_two_T_sin_theta():
    """The seam's physics with the large-motion engine: a thread's pre-strain ramped 0 -> eps0 over
    a fixed yarn; frictionless, it carries the same T = EA eps0 s everywhere (its length is held by
    the yarn and its ends) and presses on the yarn with 2 T sin(theta); all of the pre-strain's
    work is strain and barrier energy (nothing is dissipated or absorbed)."""
    eps0 = 0.05
    sol, EA, sin_t, m = stitch_over_a_yarn(eps0=eps0)
    for s in (0.0, 0.25, 0.5, 1.0):
        info = sol.solve(prestrain_scale=s)
        if s == 0.0:
            start = dict(sol.ledger)            # the solver starts at scale 1: count the ramp 0 -> 1
            continue
        T = EA * eps0 * s
        N = sol.cor.forces[:m, 6]
        assert np.abs(N).min() == pytest.approx(T, rel=2e-3) and np.abs(N).max() == pytest.approx(T, rel=2e-3)
        press = info.extra["reactions"][[m + 1, m + 2], 2].sum()        # the supports hold the yarn up
        assert press == pytest.approx(2 * T * sin_t, rel=5e-3)
    d = {k: sol.ledger[k] - start[k] for k in start}
    assert d["dissipation"] == 0.0 and d["stabilization"] < 1e-8 * abs(d["prestrain_work"])
    # the ramp's work on the thread is what it stores (strain, barrier): 1e-3 of it
    assert d["prestrain_work"] == pytest.approx(d["strain_energy"] + d["contact_energy"], rel=1e-3)
