"""The large-motion engine through its public entry point, ``homtex.solve_nonlinear(..., contact=)``:
a yarn pressed onto a crossing yarn stays above it and the energy ledger closes for one step or
three; a frictional drag in one step dissipates mu N x slip with a balanced ledger; a pre-strain
ramp then a plate (two calls, the second continuing the first) keeps the ledger and the thread's
tension; a path built to miss its ledger is flagged; options the engine does not have are refused
up front."""

import numpy as np
import pytest
from test_contact_nonlinear import crossing_yarns, stitch_over_a_yarn

import homtex
from homtex.analysis.energy import ledger_check
from homtex.errors import InputError, SolverError


def pressed_crossing(down=0.6):
    fr, ends = crossing_yarns()
    fixed = {e: "all" for e in ends[:2]}
    for e in ends[2:]:
        fixed[e] = {0: 0.0, 1: 0.0, 2: -down, 3: 0.0, 4: 0.0, 5: 0.0}
    return fr, fixed, ends


@pytest.mark.parametrize("mu", [0.0, 0.3])
@pytest.mark.parametrize("steps", [1, 3])
def test_a_yarn_pressed_onto_a_crossing_yarn_stays_above_it_and_the_ledger_closes(mu, steps):
    fr, fixed, ends = pressed_crossing()
    res = homtex.solve_nonlinear(fr, fixed, None, contact=homtex.Contact(friction=mu), steps=steps)
    p = res.path
    assert p.attrs["status"] == "ok" and p.sizes["step"] == steps
    assert np.abs(p.energy_balance.values).max() < 0.01
    assert float(p.min_gap[-1]) > 0.0 and int(p.active_yarn_yarn[-1]) > 0
    # B (pressed 0.6 mm below A's top) wraps over A: its middle stays above A's middle
    n = 20
    mid_a, mid_b = res.x[n // 2], res.x[n + 1 + n // 2]
    assert mid_b[2] - mid_a[2] > 2 * 0.1
    # the work of the supports went into the two yarns and the barrier (no friction moves here)
    W = float(p.external_work[-1])
    assert W > 0 and float(p.strain_energy[-1] + p.contact_energy[-1]) == pytest.approx(W, rel=0.01)
    # the pressing force on B's held ends equals what A's supports carry
    assert res.reactions[list(ends[2:]), 2].sum() == pytest.approx(-res.reactions[list(ends[:2]), 2].sum(), rel=1e-6)


def yarn_on_plate(mu=0.3, N=1.0, eps=1e-6):
    r, n_el = 0.1, 4
    nodes = np.c_[np.linspace(0, 2.0, n_el + 1), np.zeros(n_el + 1), np.full(n_el + 1, r)]
    fr = homtex.Frame(nodes, np.c_[np.arange(n_el), np.arange(1, n_el + 1)], radius=r, E=1e5, nu=0.3)
    fixed = {i: [3] for i in range(n_el + 1)}
    press = {i: (0, 0, -N / (n_el + 1), 0, 0, 0) for i in range(n_el + 1)}
    return fr, fixed, press, homtex.Contact(friction=mu, friction_slip=eps)


def test_a_one_step_frictional_drag_slides_at_mu_N_with_a_balanced_ledger():
    mu, N, pull = 0.3, 1.0, 0.1
    fr, fixed, press, c = yarn_on_plate(mu, N)
    pressed = homtex.solve_nonlinear(fr, fixed, press, contact=c, plates=[homtex.Plate(z=-0.001, normal=1)], steps=1)
    assert pressed.path.attrs["status"] == "ok"
    assert float(pressed.path.plate_force[-1, 0]) == pytest.approx(N, rel=1e-6)      # the plate carries N
    drag = dict(fixed)
    drag[0] = {0: pull, 3: 0.0}
    res = homtex.solve_nonlinear(fr, drag, None, contact=c, steps=1, initial=pressed)
    p = res.path
    assert p.attrs["status"] == "ok" and bool(p.attrs["continued"])
    assert res.reactions[0, 0] == pytest.approx(mu * N, rel=1e-6)                      # sliding
    assert (res.x[:, 0] - fr.nodes[:, 0]) == pytest.approx(np.full(5, pull), abs=2e-4)
    dD = float(p.friction_energy[-1])                                                # the press dissipated none
    assert dD == pytest.approx(mu * N * pull, rel=3e-3)
    assert abs(float(p.energy_balance[-1])) < 0.01
    # the ledger carries on from the pressed state: its work is counted once, the drag's added
    assert float(p.external_work[-1]) == pytest.approx(float(pressed.path.external_work[-1]) + mu * N * pull,
                                                       rel=3e-3)


def test_a_prestrain_ramp_then_a_plate_continue_one_state():
    """Sewing then pressing is two calls: a thread's pre-strain ramped 0 -> 1 over a fixed yarn
    (tension EA eps0 everywhere, pressing with 2 T sin(theta)), then a plate lowered onto the
    thread from above with the pre-strain kept: the thread's tension stays and the plate's force
    appears in the path; the ledger closes across both calls."""
    eps0 = 0.05
    sol, EA, sin_t, m = stitch_over_a_yarn(eps0=eps0)
    fr, fixed = sol.frame, {i: [1, 3, 5] for i in range(1, m)} | {0: "all", m: "all", m + 1: "all", m + 2: "all"}
    sewn = homtex.solve_nonlinear(fr, fixed, None, contact=homtex.Contact(), prestrain=1.0, steps=4)
    p = sewn.path
    assert p.attrs["status"] == "ok"
    np.testing.assert_allclose(p.prestrain_scale.values, [0.25, 0.5, 0.75, 1.0])
    T = EA * eps0
    assert np.abs(sewn.axial_force[:m]).min() == pytest.approx(T, rel=2e-3)
    assert float(p.prestrain_work[-1]) == pytest.approx(float(p.strain_energy[-1] + p.contact_energy[-1]), rel=1e-3)
    top = float(sewn.x[:m + 1, 2].max()) + 0.05                 # the thread's top surface
    pressed = homtex.solve_nonlinear(fr, fixed, None, initial=sewn, steps=3,
                                     plates=[homtex.Plate(z=top + 0.01, normal=-1, force=0.5)])
    q = pressed.path
    assert q.attrs["status"] == "ok"
    assert float(q.prestrain_scale[-1]) == 1.0 and np.abs(pressed.axial_force[:m]).min() > 0.9 * T
    np.testing.assert_allclose(q.plate_force.values[:, 0], [0.5 / 3, 1.0 / 3, 0.5], rtol=1e-6)   # force control
    assert int(q.active_yarn_plate[-1]) > 0 and float(q.plate_z[-1, 0]) < top + 0.01      # the plate came down
    assert abs(float(q.energy_balance[-1])) < 0.01
    assert float(q.prestrain_work[-1]) == pytest.approx(float(p.prestrain_work[-1]))      # no ramp in the second call


def test_a_path_built_to_miss_its_ledger_is_flagged():
    """One step, no halving allowed: the trapezoidal work of a press onto a barrier misses the stored
    energy by far more than 1 % - flagged, with where; with halving it closes."""
    fr, fixed, _ = pressed_crossing()
    coarse = homtex.solve_nonlinear(fr, fixed, None, contact=homtex.Contact(), steps=1, max_cuts=0)
    assert coarse.path.attrs["status"] == "flagged"
    assert "energy balance is off" in coarse.path.attrs["status_detail"]
    assert abs(float(coarse.path.energy_balance[-1])) > 0.05
    fine = homtex.solve_nonlinear(fr, fixed, None, contact=homtex.Contact(), steps=1)
    assert fine.path.attrs["status"] == "ok"


def test_options_the_engine_does_not_have_are_refused_up_front():
    fr, fixed, _ = pressed_crossing()
    c = homtex.Contact()
    for kw, word in (({"control": "arclength"}, "arc length"), ({"atol": 1e-6}, "absolute tolerance"),
                     ({"arc_length": 1.0}, "arc length"), ({"solver": "lu"}, "factorisation")):
        with pytest.raises(InputError, match=word):
            homtex.solve_nonlinear(fr, fixed, None, contact=c, **kw)
    with pytest.raises(InputError, match="no pre-strain"):
        homtex.solve_nonlinear(fr, fixed, None, contact=c, prestrain=1.0)
    plain = homtex.solve_nonlinear(fr, {0: "all", 20: "all", 21: "all", 41: "all"}, {10: (0, 0, -1e-3, 0, 0, 0)})
    with pytest.raises(InputError, match="without contact"):
        homtex.solve_nonlinear(fr, fixed, None, contact=c, initial=plain)
    other = homtex.Frame(fr.nodes[:21], fr.elements[:20], radius=0.1, E=2000.0, nu=0.3)
    done = homtex.solve_nonlinear(fr, fixed, None, contact=c, steps=1)
    with pytest.raises(InputError, match="frame"):
        homtex.solve_nonlinear(other, {0: "all"}, None, contact=c, initial=done)
    with pytest.raises(InputError, match="Plate"):
        homtex.solve_nonlinear(fr, fixed, None, contact=c, plates=["plate"])


def test_a_step_that_cannot_be_taken_raises_with_the_path_up_to_it():
    """Supports that push yarn B straight through yarn A: no state without an overlap exists;
    SolverError names the step, and ``result`` holds the path before it."""
    fr, ends = crossing_yarns()
    fixed = {e: {2: -0.25} | {d: 0.0 for d in (0, 1, 3, 4, 5)} for e in ends[:2]}
    fixed |= {e: {2: -0.6} | {d: 0.0 for d in (0, 1, 3, 4, 5)} for e in ends[2:]}
    with pytest.raises(SolverError, match="failed at step") as err:
        homtex.solve_nonlinear(fr, fixed, None, contact=homtex.Contact(), steps=2,
                               plates=[homtex.Plate(z=-0.3, normal=1)], max_cuts=2)
    part = err.value.result
    assert part.path.attrs["status"] == "failed" and "step" in part.path.attrs["status_detail"]
    assert part.path.sizes["step"] <= 1 and np.all(np.isfinite(part.x))


def scaled_crossing(r):
    """Two crossing yarns of radius r (20 elements of 2 r each), B 0.5 r above A."""
    n, L = 20, 40 * r
    s = np.linspace(-L / 2, L / 2, n + 1)
    A = np.c_[s, np.zeros(n + 1), np.zeros(n + 1)]
    B = np.c_[np.zeros(n + 1), s, np.full(n + 1, 2.5 * r)]
    el = np.vstack([np.c_[np.arange(n), np.arange(1, n + 1)], n + 1 + np.c_[np.arange(n), np.arange(1, n + 1)]])
    fr = homtex.Frame(np.vstack([A, B]), el, radius=r, E=2000.0, nu=0.3, yarn=np.r_[np.zeros(n, int), np.ones(n, int)])
    return fr, (0, n, n + 1, 2 * n + 1)


@pytest.mark.parametrize("case", ["thin barrier", "stiff barrier", "thin yarns sliding", "thin yarns, friction"])
@pytest.mark.parametrize("steps", [1, 3])
def test_options_that_are_accepted_work_at_their_extremes(case, steps):
    """What the validation found failing: a barrier gap of 1e-4 r, a barrier 1e6 x stiffer than
    the default, thin yarns (r = 0.01 mm) pressed 1.2 r and slid 15 r in one or three steps (with
    and without friction): every case completes with a closed ledger and no overlap."""
    r = 0.01 if case.startswith("thin yarns") else 0.1
    fr, ends = scaled_crossing(r)
    contact = {"thin barrier": homtex.Contact(barrier_gap=1e-4),
               "stiff barrier": homtex.Contact(barrier_stiffness=1e6 * float(np.mean(fr.EA / fr.length))),
               "thin yarns sliding": homtex.Contact(), "thin yarns, friction": homtex.Contact(friction=0.3)}[case]
    slide = 15 * r if case.startswith("thin yarns") else 0.0
    fixed = {e: "all" for e in ends[:2]}
    fixed |= {e: {0: slide, 1: 0.0, 2: -1.2 * r, 3: 0.0, 4: 0.0, 5: 0.0} for e in ends[2:]}
    res = homtex.solve_nonlinear(fr, fixed, None, contact=contact, steps=steps)
    p = res.path
    assert p.attrs["status"] == "ok"
    assert np.abs(p.energy_balance.values).max() < 0.01
    assert float(p.min_gap.min()) > 0.0 and int(p.active_yarn_yarn[-1]) > 0
    if "friction" in case:
        assert float(p.friction_energy[-1]) > 0.3 * float(p.external_work[-1])     # most of the slide's work


def test_a_perfect_column_pressed_between_plates_buckles_onto_the_elastica():
    """A straight column (L = 20 mm, r = 0.1 mm, 40 elements) between two frictionless plates, its
    ends held laterally, the top plate pressed down 10 % of L in 5 steps. Perfect: nothing breaks
    the symmetry, so the engine stalls at Euler's load or converges to the unstable straight
    state; each such state is left along its critical mode by a recorded perturbation and the
    column buckles: the plate force and the mid-span deflection follow the pinned-pinned elastica
    for the chord's shortening (force within 0.1 %, deflection within 2 %); the ledger closes."""
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipk

    L, r, n_el, E = 20.0, 0.1, 40, 2000.0
    nodes = np.c_[np.zeros(n_el + 1), np.zeros(n_el + 1), np.linspace(0, L, n_el + 1)]
    fr = homtex.Frame(nodes, np.c_[np.arange(n_el), np.arange(1, n_el + 1)], radius=r, E=E, nu=0.3)
    Pcr = np.pi ** 2 * E * np.pi * r ** 4 / 4 / L ** 2
    plates = [homtex.Plate(z=-1.01 * r, normal=1), homtex.Plate(z=L + 1.01 * r, normal=-1, displacement=-0.1 * L)]
    res = homtex.solve_nonlinear(fr, {0: [0, 1, 5], n_el: [0, 1]}, None, contact=homtex.Contact(), plates=plates,
                                 steps=5)
    p = res.path
    assert p.attrs["status"] == "ok" and np.abs(p.energy_balance.values).max() < 0.01
    assert len(p.attrs["branch_switches"]) >= 2                      # recorded: (level, perturbation mm)
    d = 1 - (res.x[n_el, 2] - res.x[0, 2]) / L
    m = brentq(lambda m: 2 - 2 * ellipe(m) / ellipk(m) - d, 1e-9, 0.9999)
    assert float(p.plate_force[-1, 1]) == pytest.approx((2 * ellipk(m) / np.pi) ** 2 * Pcr, rel=1e-3)
    assert np.hypot(res.x[:, 0], res.x[:, 1]).max() == pytest.approx(L * np.sqrt(m) / ellipk(m), rel=0.02)
    assert bool(p.stable[-1])


def test_friction_that_gives_energy_back_is_named_with_its_cause():
    """Coulomb friction only dissipates: a ledger whose friction energy falls below zero (beyond 1 %
    of the driven work) is flagged with the cause, a round-off dip is not."""
    W, lv, zero = np.array([0.0, 1.0, 2.0, 3.0]), np.array([0.0, 1 / 3, 2 / 3, 1.0]), np.zeros(4)
    assert ledger_check(W, zero, zero, zero, lv, friction_energy=[0.0, 0.4, 0.8, 1.2]) == ""
    assert ledger_check(W, zero, zero, zero, lv, friction_energy=[0.0, -0.005, -0.01, -0.02]) == ""
    msg = ledger_check(W, zero, zero, zero, lv, friction_energy=[0.0, 0.1, -0.5, -0.9])
    assert "friction gave energy back" in msg and "-0.9 N mm" in msg and "load factor 1" in msg
    assert "not trustworthy" in msg
