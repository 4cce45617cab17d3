"""Path following with large rotations against closed forms and published benchmarks: the rolled
cantilever, Euler's load and the elastica, prescribed shortening, Lee's frame through its limit
point and snap-back, convergence order and step independence, and the three silent failures of
the old solver (each solved on the stable branch or raised with what to do)."""

import numpy as np
import pytest
from conftest import line_frame
from scipy.optimize import brentq
from scipy.special import ellipe, ellipk
from test_corotational import bend_frame, planar

import homtex
from homtex import solve_nonlinear
from homtex.errors import StrainWarning

E, NU = 2000.0, 0.3


def lee_frame(n_per: int = 10):
    """Lee's frame: column (0,0)-(0,120) and beam (0,120)-(120,120), E = 720, A = 6, I = 2 (a circle
    of area 6 with bending_factor), pinned at (0,0) and (120,120), in the x-y plane; the load node
    is on the beam 24 from the corner. Returns (frame, fixed, load node)."""
    col = np.c_[np.zeros(n_per + 1), np.linspace(0, 120, n_per + 1), np.zeros(n_per + 1)]
    beam = np.c_[np.linspace(0, 120, n_per + 1)[1:], np.full(n_per, 120.0), np.zeros(n_per)]
    nodes = np.r_[col, beam]
    r = np.sqrt(6 / np.pi)
    fr = homtex.Frame(nodes, np.c_[np.arange(2 * n_per), np.arange(1, 2 * n_per + 1)], radius=r, E=720.0, nu=0.3,
                      bending_factor=2 / (np.pi * r ** 4 / 4))
    load = n_per + n_per // 5
    assert nodes[load, 0] == pytest.approx(24.0)
    fixed = planar(fr.n_nodes, {0: [0, 1], 2 * n_per: [0, 1]})
    return fr, fixed, load


def first_limit(lam):
    """Largest load factor before the first descent, refined by a parabola through three states."""
    k = int(np.flatnonzero(np.diff(lam) < 0)[0])
    a, b, c = lam[k - 1:k + 2]
    return b + (a - c) ** 2 / (8 * (2 * b - a - c))


# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("plane", [True, False])
def test_end_moment_rolls_the_cantilever_into_a_closed_circle(plane):
    """Load control of an end moment up to M = 2 pi EI / L: every state lies on the circular arc
    of curvature M / EI (tip at (sin t, 1 - cos t) / kappa, t = M L / EI), the tip meets the root at
    2 pi, the energy is M t / 2; in 3D the dead moment is not conservative and the static
    (divergence) stability test is used: the states stay stable."""
    L, r, n_el = 100.0, 1.0, 40
    fr = line_frame(n_el, L, (1, 0, 0), radius=r, E=E, nu=NU)
    EI = E * np.pi * r ** 4 / 4
    M = 2 * np.pi * EI / L
    fixed = planar(fr.n_nodes, {0: "all"}) if plane else {0: "all"}
    res = solve_nonlinear(fr, fixed, {n_el: (0, 0, 0, 0, 0, M)}, steps=8)
    p = res.path
    t = p.load_factor.values * 2 * np.pi
    tip = p.u.sel(node=n_el).values[:, :3] + [L, 0, 0]
    exact = np.c_[np.sin(t), 1 - np.cos(t), np.zeros_like(t)] * (L / t)[:, None]
    assert np.abs(tip - exact).max() < 0.05                   # chord polygon: L (t / n)^2 / 24 at most
    assert np.linalg.norm(res.x[n_el] - res.x[0]) < 1e-8 * L   # closed
    assert p.u.sel(node=n_el, dof="rz").values[-1] == pytest.approx(2 * np.pi, rel=1e-9)
    assert float(p.strain_energy[-1]) == pytest.approx(M * 2 * np.pi / 2, rel=1e-6)
    assert bool(p.stable.all())


def test_rotation_control_closes_the_circle_and_reports_the_moment():
    """A prescribed end rotation of 2 pi (rotation control, planar) closes the cantilever into a
    circle in one step or eight, with the reaction moment 2 pi EI / L."""
    L, r, n_el = 100.0, 1.0, 32
    fr = line_frame(n_el, L, (1, 0, 0), radius=r, E=E, nu=NU)
    EI = E * np.pi * r ** 4 / 4
    for steps in (1, 8):
        res = solve_nonlinear(fr, planar(fr.n_nodes, {0: "all", n_el: {5: 2 * np.pi}}), None,
                              control="displacement", steps=steps)
        assert np.linalg.norm(res.x[n_el] - res.x[0]) < 1e-8 * L
        assert res.reactions[n_el, 5] == pytest.approx(2 * np.pi * EI / L, rel=1e-7)
        assert res.stable


@pytest.mark.parametrize("steps", [3, 7, 29, 31])
def test_euler_load_of_a_perfect_column_under_load_control(steps):
    """Silent failure 1: a straight column loaded past P_cr under load control came back straight
    (unstable) unless a step landed on P_cr. Now the inertia of every state is checked: the
    critical load factor is P_cr (to 5e-4: the mesh), the column bends and the state returned is stable."""
    L, r, n_el = 100.0, 1.0, 30
    fr = line_frame(n_el, L, (1, 0, 0), radius=r, E=E, nu=NU)
    EI = E * np.pi * r ** 4 / 4
    Pcr = np.pi ** 2 * EI / (4 * L ** 2)
    res = solve_nonlinear(fr, planar(fr.n_nodes, {0: "all"}), {n_el: (-1.5 * Pcr, 0, 0, 0, 0, 0)}, steps=steps)
    assert res.critical_load_factor * 1.5 == pytest.approx(1.0, rel=5e-4)      # 30 elements: +1e-4
    assert res.stable and bool(res.path.stable.all())
    m = brentq(lambda m: (2 * ellipk(m) / np.pi) ** 2 - 1.5, 1e-9, 0.999)
    assert abs(res.x[n_el, 1]) / L == pytest.approx(2 * np.sqrt(m) / ellipk(m), rel=2e-3)


def test_arclength_switches_to_the_bent_branch_of_a_perfect_column():
    """Arc length through Euler's load of a perfect column: the bifurcation (critical mode
    orthogonal to the load) is recorded at P_cr and the path continues on the stable bent branch
    to the elastica at 1.5 P_cr. (A budget of increments too small to reach the reference load, as
    8 on Lee's frame, is warned, not hidden.)"""
    L, r, n_el = 100.0, 1.0, 30
    fr = line_frame(n_el, L, (1, 0, 0), radius=r, E=E, nu=NU)
    EI = E * np.pi * r ** 4 / 4
    Pcr = np.pi ** 2 * EI / (4 * L ** 2)
    loads = {n_el: (-1.5 * Pcr, 0, 0, 0, 0, 0)}
    res = solve_nonlinear(fr, planar(fr.n_nodes, {0: "all"}), loads, control="arclength", steps=60)
    assert res.load_factor == pytest.approx(1.0) and res.stable
    assert res.critical_load_factor * 1.5 == pytest.approx(1.0, rel=1e-3)
    m = brentq(lambda m: (2 * ellipk(m) / np.pi) ** 2 - 1.5, 1e-9, 0.999)
    assert abs(res.x[n_el, 1]) / L == pytest.approx(2 * np.sqrt(m) / ellipk(m), rel=2e-3)
    lee, fixed, load = lee_frame(5)
    with pytest.warns(RuntimeWarning, match="steps spent"):
        short = solve_nonlinear(lee, fixed, {load: (0, -3.0, 0, 0, 0, 0)}, control="arclength", steps=8)
    assert short.load_factor < 1.0 and short.path.attrs["status"] == "flagged"
    assert short.path.attrs["status_detail"].startswith("steps spent")


@pytest.mark.parametrize("steps", [7, 29, 30, 31, 57])
def test_elastica_of_a_cantilever_column_for_any_number_of_steps(steps):
    """Timoshenko and Gere's elastica (Art. 2.7) under plain load control with a lateral load of
    1e-4 P_cr: along the whole path up to a tip angle of 160 degrees P / P_cr = 4 K(p)^2 / pi^2,
    the tip deflection 2 p L / K and the tip position (2 E(p) / K - 1) L with p = sin(alpha / 2),
    for any number of load steps."""
    L, r, n_el = 100.0, 1.0, 40
    fr = line_frame(n_el, L, (1, 0, 0), radius=r, E=E, nu=NU)
    EI = E * np.pi * r ** 4 / 4
    Pcr = np.pi ** 2 * EI / (4 * L ** 2)
    top = 4 * ellipk(np.sin(np.radians(80)) ** 2) ** 2 / np.pi ** 2          # P / P_cr at 160 degrees
    res = solve_nonlinear(fr, planar(fr.n_nodes, {0: "all"}), {n_el: (-top * Pcr, 1e-4 * Pcr, 0, 0, 0, 0)},
                          steps=steps)
    p = res.path
    alpha = p.u.sel(node=n_el, dof="rz").values
    assert np.degrees(alpha[-1]) == pytest.approx(160.0, abs=0.05)
    m = np.sin(alpha / 2) ** 2
    K, Em = ellipk(m), ellipe(m)
    bent = alpha > np.radians(10)
    assert bent.sum() >= 3 and bool(p.stable.all())
    assert np.abs(p.load_factor.values * top / (4 * K ** 2 / np.pi ** 2) - 1)[bent].max() < 1e-3
    assert np.abs(p.u.sel(node=n_el, dof="uy").values / L - 2 * np.sqrt(m) / K)[bent].max() < 1e-3
    assert np.abs(1 + p.u.sel(node=n_el, dof="ux").values / L - (2 * Em / K - 1))[bent].max() < 1e-3


@pytest.mark.parametrize("steps", [1, 3, 30])
def test_prescribed_shortening_takes_the_bent_branch(steps):
    """Silent failure 2: under prescribed axial shortening the column stayed straight at thousands
    of P_cr. A pinned-pinned column shortened by 20 % now follows Euler's elastica: end force
    (2 K(m) / pi)^2 P_cr and mid deflection L sqrt(m) / K with 2 - 2 E(m) / K(m) = 0.2; the
    critical shortening is P_cr L / EA; any number of steps."""
    L, r, n_el = 100.0, 1.0, 40
    fr = line_frame(n_el, L, (1, 0, 0), radius=r, E=E, nu=NU)
    EI, EA = E * np.pi * r ** 4 / 4, E * np.pi * r ** 2
    Pcr = np.pi ** 2 * EI / L ** 2
    fixed = planar(fr.n_nodes, {0: [0, 1], n_el: {0: -0.2 * L, 1: 0.0}})
    res = solve_nonlinear(fr, fixed, None, control="displacement", steps=steps)
    m = brentq(lambda m: 2 - 2 * ellipe(m) / ellipk(m) - 0.2, 1e-9, 0.9999)
    assert -res.reactions[n_el, 0] == pytest.approx((2 * ellipk(m) / np.pi) ** 2 * Pcr, rel=1e-3)
    assert np.abs(res.u[:, 1]).max() == pytest.approx(L * np.sqrt(m) / ellipk(m), rel=1e-3)
    assert res.critical_load_factor * 0.2 * L == pytest.approx(Pcr * L / EA, rel=1e-3)
    assert res.stable and bool(res.path.stable.all())


def test_lee_frame_arclength_through_the_limit_point_and_the_snap_back():
    """Lee's frame with a reference load above its limit load, arc-length control: the path goes
    through the limit point (P L^2 / EI = 18.5, i.e. P = 1.85 for E = 720, I = 2, L = 120;
    Schweizerhof and Wriggers 1986), down to the minimum load (-0.94), through the snap-back of the
    load node's vertical displacement (it turns back near 61) and up to the reference load. The
    inertia changes at both limit points; states between them are unstable."""
    fr, fixed, load = lee_frame(10)
    res = solve_nonlinear(fr, fixed, {load: (0, -3.0, 0, 0, 0, 0)}, control="arclength", steps=300)
    p = res.path
    P = 3.0 * p.load_factor.values
    v = -p.u.sel(node=load, dof="uy").values
    assert res.load_factor == pytest.approx(1.0, abs=1e-12)
    Pmax = first_limit(P)
    assert Pmax * 120 ** 2 / (720 * 2) == pytest.approx(18.5, rel=0.01)
    assert P.min() == pytest.approx(-0.96, abs=0.03)
    kv = int(np.argmax(v[:int(np.argmin(P))]))
    assert v[kv] == pytest.approx(61.1, abs=0.5) and v[kv + 5] < v[kv] - 1     # snap-back
    lim = p.attrs["limit_load_factors"] * 3
    assert len(lim) >= 2 and lim[0] == pytest.approx(Pmax, rel=2e-3)
    neg = p.negative_eigenvalues.values
    assert neg[0] == 0 and neg.max() >= 1 and neg[-1] == 0
    k1 = int(np.flatnonzero(np.diff(P) < 0)[0])
    down = k1 + int(np.argmax(P[k1:] < 0.5 * Pmax))
    assert 0 < P[down] < 0.5 * Pmax and not bool(p.stable.values[down])     # on the way down: unstable
    assert abs(float(p.energy_balance[-1])) < 0.01


@pytest.mark.slow
def test_lee_frame_limit_load_converges_at_order_two():
    """The limit load of Lee's frame for 5, 10, 20 and 40 elements per member: the differences fall
    by 4 per halving (order 2) towards the fine-mesh value 1.8545."""
    lims = []
    for n in (5, 10, 20, 40):
        fr, fixed, load = lee_frame(n)
        res = solve_nonlinear(fr, fixed, {load: (0, -2.0, 0, 0, 0, 0)}, control="arclength", steps=300)
        lims.append(first_limit(2.0 * res.path.load_factor.values))
    d = -np.diff(lims)
    assert np.all(d > 0)
    assert d[0] / d[1] == pytest.approx(4.0, rel=0.15) and d[1] / d[2] == pytest.approx(4.0, rel=0.15)
    assert lims[-1] == pytest.approx(1.8545, abs=1e-3)


@pytest.fixture(scope="module")
def lee_arc():
    """Lee's frame by arc length: the reference load 3.0, and the prescribed motion v = 120."""
    fr, fixed, load = lee_frame(10)
    loaded = solve_nonlinear(fr, fixed, {load: (0, -3.0, 0, 0, 0, 0)}, control="arclength", steps=300)
    fixed[load] = {1: -120.0, 2: 0.0, 3: 0.0, 4: 0.0}
    with pytest.warns(StrainWarning):
        moved = solve_nonlinear(fr, fixed, None, control="arclength", steps=400)
    return loaded, moved


@pytest.mark.parametrize("steps", [2, 7, 20, 50])
def test_lee_frame_under_load_control_snaps_at_the_limit_point(steps, lee_arc):
    """Load control past the limit point: the limit load is recorded (within 0.5 %) where the frame
    snaps; it lands on the stable branch that arc length reaches and goes on to the full load (the
    same state to 1e-8); the energy the snap released is recorded and the path flagged for it."""
    fr, fixed, load = lee_frame(10)
    res = solve_nonlinear(fr, fixed, {load: (0, -3.0, 0, 0, 0, 0)}, steps=steps)
    p = res.path
    assert 3 * p.attrs["snap_load_factors"][0] == pytest.approx(1.8647, rel=5e-3)
    assert res.load_factor == 1.0 and res.stable and bool(p.stable.all())
    assert np.abs(res.x - lee_arc[0].x).max() < 1e-8 * 120
    released = float(p.stabilization_energy[-1])
    assert released > 0.3 * float(p.external_work[-1])
    assert abs(float(p.energy_balance[-1])) < 0.01          # the ledger closes with what the snap released
    assert p.attrs["status"] == "flagged" and "snap" in p.attrs["status_detail"]


@pytest.mark.parametrize("steps", [10, 27, 40, 57])
def test_lee_frame_displacement_control_snaps_at_the_turning_point(steps, lee_arc):
    """Silent failure 3: displacement control of the load node past the snap-back jumped to a far
    branch (12 % strain, a force of -1081) without a trace. Now the turning point (v = 61.1) is
    recorded where the frame snaps, onto the stable branch of the arc-length path (same final state
    to 1e-7), and the path is flagged for the energy released."""
    fr, fixed, load = lee_frame(10)
    fixed[load] = {1: -120.0, 2: 0.0, 3: 0.0, 4: 0.0}
    with pytest.warns(StrainWarning):
        res = solve_nonlinear(fr, fixed, None, control="displacement", steps=steps)
    p = res.path
    assert 120 * p.attrs["snap_load_factors"][0] == pytest.approx(61.1, abs=0.3)
    assert res.load_factor == 1.0 and res.stable
    assert np.abs(res.x - lee_arc[1].x).max() < 1e-7 * 120
    assert float(p.stabilization_energy[-1]) > 0.0 and abs(float(p.energy_balance[-1])) < 0.01
    assert p.attrs["status"] == "flagged" and "snap" in p.attrs["status_detail"]


def test_arclength_with_a_prescribed_motion_passes_the_turning_point():
    """The remedy of the turning point works: arc length driven by the prescribed vertical motion
    of the load node follows the snap-back (v goes back) with the same loads as load-driven arc
    length."""
    fr, fixed, load = lee_frame(10)
    fixed[load] = {1: -70.0, 2: 0.0, 3: 0.0, 4: 0.0}
    res = solve_nonlinear(fr, fixed, None, control="arclength", steps=200)
    p = res.path
    v = -p.u.sel(node=load, dof="uy").values
    assert 70 * first_limit(p.load_factor.values) == pytest.approx(61.1, abs=0.3)      # v turns back
    assert res.load_factor == pytest.approx(1.0) and v[-1] == pytest.approx(70.0)
    assert -p.force.sel(node=load, dof="uy").values.min() == pytest.approx(1.8647, rel=2e-3)


def test_bend_converges_at_order_two_and_matches_simo_vu_quoc():
    """Bathe and Bolourchi's 45-degree bend at P = 600: tip displacements near Simo and Vu-Quoc's
    (-23.5, -13.4, 53.4); the differences between 8, 16 and 32 elements fall by 4 per halving."""
    tips = []
    for n in (8, 16, 32):
        res = solve_nonlinear(bend_frame(n), {0: "all"}, {n: (0, 0, 600, 0, 0, 0)}, steps=10)
        tips.append(res.u[n, :3])
    tips = np.array(tips)
    assert np.allclose(tips[-1], (-23.5, -13.4, 53.4), atol=0.5)
    d = np.linalg.norm(np.diff(tips, axis=0), axis=1)
    assert d[0] / d[1] == pytest.approx(4.0, rel=0.1)


def test_path_independent_problems_are_step_independent():
    """The bend's end state does not depend on the number of load steps (1e-8), nor on the
    control: arc length with the same reference load ends on the same state."""
    fr = bend_frame(16)
    ref = None
    for steps in (3, 10, 30):
        res = solve_nonlinear(fr, {0: "all"}, {16: (0, 0, 600, 0, 0, 0)}, steps=steps, tol=1e-11)
        if ref is None:
            ref = res.u
        assert np.abs(res.u - ref).max() < 1e-8 * np.abs(ref).max()
    arc = solve_nonlinear(fr, {0: "all"}, {16: (0, 0, 600, 0, 0, 0)}, control="arclength", steps=10, tol=1e-11)
    assert arc.load_factor == pytest.approx(1.0)
    assert np.abs(arc.u - ref).max() < 1e-8 * np.abs(ref).max()


@pytest.mark.slow
def test_benchmark_against_opensees_runs_in_quick_mode(tmp_path):
    """studies/benchmarks/bench_corotational.py --quick (needs the bench extra, OpenSeesPy): both
    solvers agree on the bend within the h^2 discretisation difference and take the same number
    of Newton iterations per step."""
    import importlib.util
    from pathlib import Path

    try:
        import openseespy.opensees  # noqa: F401
    except Exception:                       # not installed, or its BLAS/LAPACK libraries missing
        pytest.skip("OpenSeesPy not available")
    path = Path(__file__).resolve().parents[1] / "studies" / "benchmarks" / "bench_corotational.py"
    spec = importlib.util.spec_from_file_location("bench_corotational", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    ds = bench.main(["--quick", "--out", str(tmp_path)])
    assert (tmp_path / "bench_corotational.nc").exists() and (tmp_path / "bench_corotational.png").exists()
    assert float(ds.difference.sel(case="bend16")) < 5e-4
    assert float(ds.difference.sel(case="bend8")) / float(ds.difference.sel(case="bend16")) == pytest.approx(4, rel=0.2)
    it = ds.iterations_per_step
    assert np.all(it.sel(solver="homtex").values <= it.sel(solver="opensees_force").values + 1e-9)
