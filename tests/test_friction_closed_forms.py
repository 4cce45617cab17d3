"""Friction of the large-motion engine against closed forms: the capstan law T2 / T1 = exp(mu theta)
(a slender yarn pulled over a fixed stiff yarn, within 1 % as the bending rigidity and the
regularisation shrink), a yarn pressed on a plate by N that slides at mu N and sticks below it,
the dissipated energy mu N x slip and the energy balance of that drag; friction per pair of yarn
types from cell files; the linear model refuses friction."""

import numpy as np
import pytest

import homtex
from homtex.cells import Cell
from homtex.contact.engine import EngineStepper
from homtex.contact.incremental import IncrementalSolver, NonlinearSettings
from homtex.errors import CellError, InputError, SolverError


# ----------------------------------------------------------------------------------------
def capstan(mu=0.3, theta=np.pi, bf=1e-3, eps=1e-4, n_arc=48, Rc=1.0, r=0.05, E=1e5, T1=1.0, pull=0.3, steps=6,
            settings=None, iterations=None):
    """A rope (contact radius r) over a fixed stiff yarn of radius Rc (its axis along y), wrapped by
    ``theta`` in the x-z plane, end A loaded by T1 along its tail, end B pulled along its tail by
    ``pull`` in ``steps``. Returns T2 / T1 after each pull step (T2: the force holding B); the Newton
    iterations and friction rounds of the pull steps are appended to the list ``iterations``."""
    rho = Rc + r + 0.01 * r                               # centre-line radius (rests at gap ghat)
    ph = np.linspace(-theta / 2, theta / 2, n_arc + 1)
    arc = np.c_[rho * np.sin(ph), np.zeros_like(ph), rho * np.cos(ph)]
    dA = -np.array([np.cos(ph[0]), 0, -np.sin(ph[0])])    # tangent pointing away from the arc at A
    dB = np.array([np.cos(ph[-1]), 0, -np.sin(ph[-1])])   # ... and at B
    h = rho * theta / n_arc                               # the tails have the arc's element length
    s = h * np.arange(1, int(np.ceil(2.0 / h)) + 1)
    rope = np.vstack([arc[0] + s[::-1, None] * dA, arc, arc[-1] + s[:, None] * dB])
    m = len(rope) - 1
    nodes = np.vstack([rope, [[0, -3.0, 0], [0, 3.0, 0]]])
    el = np.vstack([np.c_[np.arange(m), np.arange(1, m + 1)], [[m + 1, m + 2]]])
    ref = np.r_[np.tile([0, 1.0, 0], (m, 1)), [[1.0, 0, 0]]]
    fr = homtex.Frame(nodes, el, radius=np.r_[np.full(m, r), Rc], E=np.r_[np.full(m, E), 1e6], nu=0.3,
                      yarn=np.r_[np.zeros(m, int), 1], ref=ref, bending_factor=np.r_[np.full(m, bf), 1.0])
    fixed = {i: [1, 3, 5] for i in range(m + 1)}          # a plane problem (x-z)
    fixed[m + 1] = fixed[m + 2] = "all"                   # the fixed yarn
    fixed[m] = {0: pull * dB[0], 1: 0.0, 2: pull * dB[2], 3: 0.0, 5: 0.0}
    sol = IncrementalSolver(fr, fixed, {0: (*(T1 * dA), 0, 0, 0)}, [],
                            homtex.Contact(friction=mu, friction_slip=eps), settings=settings)
    sol.solve(loads=1.0)                                  # T1 on A, B held: the rope presses on the yarn
    out = []
    for k in range(1, steps + 1):
        info = sol.solve(motion=k / steps)
        out.append(float(info.extra["reactions"][m, :3] @ dB) / T1)
        if iterations is not None:
            iterations.append((info.iterations, info.friction_rounds))
    return np.array(out)


def test_capstan_law_within_one_percent_as_bending_and_regularisation_shrink():
    exact = np.exp(0.3 * np.pi)
    errs = []
    for bf, eps in ((1e-1, 1e-3), (1e-2, 1e-4), (1e-3, 1e-5)):
        ratio = capstan(bf=bf, eps=eps)
        errs.append(abs(ratio[-1] / exact - 1))
    # bending rigidity props the rope off the yarn where it leaves it: the error falls with it
    assert errs[0] > errs[1] > errs[2]
    assert errs[0] > 0.01 and errs[2] < 0.002
    assert errs[1] < 0.01


def test_friction_rounds_before_the_settled_one_solved_loosely_reach_the_same_state():
    """Rounds of the friction lag before the one that settles stop at round_tol = 1e-5 (the lag they
    measure moves anyway); the settled round is finished at tol. The lag they hand on is off by about
    round_tol, so the rope's pull differs from that of every round solved to tol by about that much:
    two orders inside the lag's own settling tolerance (friction_tol, 1e-3 of the normal forces)."""
    loose, tight = [], []
    kw = {"mu": 0.5, "theta": np.pi / 2, "bf": 1e-3, "eps": 1e-5}
    a = capstan(**kw, iterations=loose)
    b = capstan(**kw, iterations=tight, settings=NonlinearSettings(round_tol=1e-8))
    assert max(r for _, r in loose) > 2                   # the lag was updated twice within a step
    assert np.allclose(a, b, rtol=1e-4, atol=0)
    assert sum(i for i, _ in loose) <= sum(i for i, _ in tight)


def test_capstan_law_at_a_quarter_turn_and_another_coefficient():
    ratio = capstan(mu=0.5, theta=0.5 * np.pi, bf=1e-3, eps=1e-5)
    assert ratio[-1] == pytest.approx(np.exp(0.5 * 0.5 * np.pi), rel=0.01)
    # without friction the rope passes the tension on unchanged
    assert capstan(mu=0.0, bf=1e-3, steps=2)[-1] == pytest.approx(1.0, rel=2e-3)


# ----------------------------------------------------------------------------------------
def yarn_on_plate(mu=0.3, N=1.0, eps=1e-6, E=1e5, pull=None):
    """A straight yarn (4 elements, 2 mm, r = 0.1) pressed on a plate by N (dead loads)."""
    r, n_el = 0.1, 4
    nodes = np.c_[np.linspace(0, 2.0, n_el + 1), np.zeros(n_el + 1), np.full(n_el + 1, r)]
    fr = homtex.Frame(nodes, np.c_[np.arange(n_el), np.arange(1, n_el + 1)], radius=r, E=E, nu=0.3)
    fixed = {i: [3] for i in range(n_el + 1)}            # no spin about its axis (friction acts on the centre line)
    if pull is not None:
        fixed[0] = {0: pull, 3: 0.0}                      # node 0 dragged along x
    press = {i: (0, 0, -N / (n_el + 1), 0, 0, 0) for i in range(n_el + 1)}
    sol = IncrementalSolver(fr, fixed, press, [homtex.Plate(z=-0.01 * r, normal=1, displacement=0.0)],
                            homtex.Contact(friction=mu, friction_slip=eps))
    sol.solve(loads=1.0)
    return sol, press


def test_a_dragged_yarn_slides_at_mu_N_and_dissipates_mu_N_times_its_slip():
    mu, N, pull = 0.3, 1.0, 0.1
    sol, _ = yarn_on_plate(mu, N, pull=pull)
    x0 = sol.positions.copy()
    # short first steps: friction builds up over the stick slip and the stretch of the yarn, and
    # the trapezoidal work of the pull needs that ramp resolved
    for t in np.r_[0.002, 0.01, np.arange(1, 11) / 10]:
        info = sol.solve(motion=t)
        if t >= 0.01:
            assert info.extra["reactions"][0, 0] == pytest.approx(mu * N, rel=1e-6)     # Coulomb: sliding
    slip = (sol.positions - x0)[:, 0]
    assert slip == pytest.approx(np.full(5, pull), abs=2e-4)      # a stiff yarn slides as a whole
    L = sol.ledger
    exact = mu * N / 5 * slip.sum()                               # each node: mu N_i x its slip
    assert L["dissipation"] == pytest.approx(exact, rel=1e-3)
    assert L["dissipation"] == pytest.approx(mu * N * pull, rel=3e-3)
    # energy balance: the pull's work went into friction (and a little stretch)
    assert L["external_work"] == pytest.approx(mu * N * pull, rel=3e-3)
    assert abs(sol.balance()) < 2e-3
    assert L["stabilization"] < 1e-6 * L["external_work"]


@pytest.mark.parametrize("halvings", [0, 4, 8])
def test_a_drag_rubs_at_mu_N_however_finely_the_engine_subdivides_it(halvings):
    """With the regularisation slip per step (``slip_per_step``, the knit tests' stepping), a level
    the engine halves 8 times (256 sub-steps of 2e-4 mm, below the 1e-3 mm slip set for the level)
    still slides at mu N and dissipates mu N x slip; at a fixed slip those sub-steps mobilise a third
    of mu N (the acrylic rib's friction fading as its steps were refined, docs/knits.md)."""
    mu, N, pull = 0.3, 1.0, 0.05
    sol, _ = yarn_on_plate(mu, N, eps=1e-3, pull=pull)
    sol.solve(motion=0.05)                  # friction built up over a first short step (trapezoidal work)
    stepper = EngineStepper(sol, lambda t: sol.solve(motion=t), max_cuts=halvings, refine=-1.0,  # always halve
                            start=0.05, slip_per_step=True)
    before = dict(sol.ledger)
    info = stepper.advance(1.0)
    d = {k: sol.ledger[k] - before[k] for k in ("dissipation", "external_work")}
    assert stepper.totals["substeps"] == 2 ** halvings
    assert sol.eps_v == 1e-3                                      # restored after the recursion
    assert info.extra["reactions"][0, 0] == pytest.approx(mu * N, rel=1e-3)
    assert d["dissipation"] == pytest.approx(mu * N * 0.95 * pull, rel=2e-3)
    assert d["external_work"] == pytest.approx(d["dissipation"], rel=2e-3)     # the pull's work went to friction
    if halvings == 8:                                             # the fixed slip fades, as measured
        sol, _ = yarn_on_plate(mu, N, eps=1e-3, pull=pull)
        sol.solve(motion=0.05)
        fixed = EngineStepper(sol, lambda t: sol.solve(motion=t), max_cuts=8, refine=-1.0, start=0.05).advance(1.0)
        assert fixed.extra["reactions"][0, 0] < 0.4 * mu * N


def test_a_yarn_pushed_below_mu_N_sticks_and_above_it_slides_away():
    mu, N, eps, steps = 0.3, 1.0, 1e-5, 10
    for frac in (0.5, 0.9, 1.1):
        sol, press = yarn_on_plate(mu, N, eps=eps)
        x0 = sol.positions.copy()
        try:
            for k in range(1, steps + 1):
                loads = dict(press)
                loads[0] = (frac * mu * N * k / steps, 0, -N / 5, 0, 0, 0)
                sol.set_loads(loads)
                sol.solve()
        except SolverError as err:
            assert frac > 1 and "converge" in str(err)
            continue
        assert frac < 1
        moved = float(np.abs(sol.positions - x0)[:, 0].max())
        # stuck: no more than the stick regularisation per step (plus the stretch of the yarn)
        assert moved < steps * eps


# ----------------------------------------------------------------------------------------
def spacer_with_friction_table(table):
    data = homtex.load_cell("spacer_20mm").to_dict()
    data["contact"] = table
    return Cell(data, None)


def test_friction_per_pair_of_yarn_types_from_the_cell_file():
    cell = spacer_with_friction_table({"friction": 0.1, "pairs": {
        "monofilament": {"multifilament": 0.35, "monofilament": 0.2, "plate": 0.45}}})
    spec = cell.friction_spec()
    names = spec["names"]
    mo, mf = names.index("monofilament"), names.index("multifilament")
    assert spec["table"][mo, mf] == spec["table"][mf, mo] == 0.35
    assert spec["table"][mo, mo] == 0.2 and spec["table"][mf, mf] == 0.1
    assert spec["plate"][mo] == 0.45 and spec["plate"][mf] == 0.1
    pile = cell.groups["pile"]
    assert (spec["types"][pile] == mo).all() and (spec["types"][~pile & ~cell.groups["interlacing"]] == mf).all()
    # the engine picks the pair's coefficient from the element types
    from homtex.contact.compress import CompressionTest

    test = CompressionTest.build(cell.frame, info=cell.info, groups=cell.groups)
    sol = IncrementalSolver(cell.frame, test.fixed, None, [], homtex.Contact(), friction_spec=spec)
    sc = sol.scene
    sc.search(cell.frame.nodes, 1.0)
    ta, tb = spec["types"][sc.stencil.a], spec["types"][sc.stencil.b]
    assert np.array_equal(sc.mu_pair, spec["table"][ta, tb]) and len(np.unique(sc.mu_pair)) > 1
    # Contact(friction=...) overrides the table; the curve says where its friction came from
    over = IncrementalSolver(cell.frame, test.fixed, None, [], homtex.Contact(friction=0.05), friction_spec=spec)
    assert over.scene.mu_table.max() == 0.05
    ds = homtex.compress(cell, strain=0.002, steps=1, geometry="nonlinear")
    assert ds.attrs["friction_source"] == "cell file [contact] table" and ds.attrs["friction_max"] == 0.45
    ds = homtex.compress(cell, strain=0.002, steps=1, geometry="nonlinear", contact=homtex.Contact(friction=0.0))
    assert ds.attrs["friction_max"] == 0.0


@pytest.mark.parametrize("table, culprit", [
    ({"friction": -0.1}, "friction"), ({"friction": "high"}, "friction"), ({"mu": 0.2}, "mu"),
    ({"pairs": {"cotton": {"monofilament": 0.2}}}, "cotton"), ({"pairs": {"plate": {"monofilament": 0.2}}}, "plate"),
    ({"pairs": {"monofilament": {"wool": 0.2}}}, "wool"), ({"pairs": {"monofilament": {"plate": 11.0}}}, "plate"),
    ({"pairs": {"monofilament": {"multifilament": 0.2}, "multifilament": {"monofilament": 0.3}}}, "twice"),
])
def test_bad_friction_tables_are_named(table, culprit):
    with pytest.raises(CellError, match=culprit):
        spacer_with_friction_table(table)


def test_the_linear_model_refuses_friction():
    cell = homtex.load_cell("spacer_20mm")
    with pytest.raises(InputError, match="geometry=.nonlinear"):
        homtex.compress(cell, strain=0.01, steps=1, contact=homtex.Contact(friction=0.3), geometry="linear")
    with pytest.raises(InputError, match="friction"):
        homtex.compress(cell, strain=0.01, steps=1, contact=homtex.Contact(plate_friction=0.3), geometry="linear")
    for bad in ({"friction": -0.3}, {"friction": np.nan}, {"friction": 11.0}, {"plate_friction": -1},
                {"friction_slip": 0.0}, {"friction_slip": "1e-4"}, {"barrier_gap": 0.0}, {"barrier_gap": 0.9},
                {"barrier_stiffness": -1.0}):
        with pytest.raises(InputError, match=next(iter(bad))):
            homtex.Contact(**bad)
