"""Weft-knitted fabrics: notation -> cell (bad notations named by course and needle, Crane's loop
curve at the loop length, overlaps at creation told apart by periodic image, a 2 x 2 supercell
storing 4x the cell's energy), relaxation (the released energy is the stored energy's decrease
plus the take-down's work, the yarn keeps its length, a 1x1 rib pulls its wales together), the
periodic tensile test (J-shaped along the wales, lateral contraction, the ledger within 1 %
frictionless and with friction 0.5, bending dominating the energy split, filaments beyond the
failure stress flagged, zero force across a course test) and the m / l^3 law where it must hold
exactly. Small cells and few steps: the whole module stays within ~20 s of CPU."""

import importlib

import numpy as np
import pytest

import homtex
import homtex.contact.ipc_system as ipc
from homtex.contact import engine
from homtex.errors import CellError
from homtex.geometry.weft_knit import CRANE, course_curve, knit_geometry, parse_notation, stitch_length
from homtex.knits.scaling import scaled_cell, xcf

CELLS = ("rib_1x1_eglass", "jersey_eglass", "milano_eglass", "rib_1x1_acrylic", "jersey_acrylic")
GEO = ("pitch", "c", "h", "d", "Z0", "a")


@pytest.mark.parametrize("name", CELLS)
def test_the_shipped_knit_cells_load_with_the_loop_length_asked_for(name):
    cell = homtex.load_cell(f"cells/{name}.toml")
    assert cell.frame.dim_periodic == 2 and cell.info["stitches"] >= 1
    L = cell.frame.length[cell.info["filament"] == 0].sum() / cell.info["stitches"]
    assert L == pytest.approx(cell.parameters["loop_length"], rel=1e-6)


@pytest.mark.parametrize("courses, needles, match", [
    (["fx"], None, "course 1, needle 2: unknown symbol 'x'"),
    (["fb", "--"], None, "course 2 knits no needle"),
    (["fbf"], 2, "course 1, needle 3: stitch outside the bed"),
    (["tt", "ff"], None, "course 1 knits no needle"),
    (["fb", "f"], None, "course 2 has 1 needle positions"),
    (["f-"], None, "needle 2 never knits"),
    (["f", "b"], None, "course 2, needle 1: a needle position knits on both beds"),
])
def test_bad_notations_name_the_course_and_the_needle(courses, needles, match):
    with pytest.raises(CellError, match=match):
        parse_notation(courses, needles)


def test_a_loop_too_short_to_close_is_named():
    pat = parse_notation(["fb"])
    with pytest.raises(CellError, match="course 1, needle 1: a loop too short to close"):
        knit_geometry(pat, 2.0, core_radius=0.5)
    with pytest.raises(CellError, match="course 1, needle 1: a loop too short to close"):
        knit_geometry(pat, 5.0, core_radius=0.01, wale_spacing=8.0, course_spacing=3.0)


def test_a_bad_cell_key_names_its_table():
    cell = homtex.load_cell("cells/jersey_eglass.toml")
    with pytest.raises(CellError, match="parameters.yarn_model"):
        cell.replace(**{"parameters.yarn_model.filament": 3})


def test_the_loop_model_is_crane_plain_knit_curve_at_the_loop_length():
    """Jersey: x = lambda (t + 3/2 sin 2t), y = h cos t, z = -d cos 2t with Crane's h = 4, d = 1,
    course spacing 4.5 (lambda = 1), scaled so that one loop is as long as asked."""
    pat = parse_notation(["f"])
    g = knit_geometry(pat, 12.0, core_radius=0.01)
    lam = g["pitch"] / (2 * np.pi)
    assert g["h"] == pytest.approx(CRANE["h"] * lam) and g["c"] == pytest.approx(CRANE["c"] * lam)
    cur = course_curve(pat, 0, **{k: g[k] for k in GEO}, samples=64)
    t = -np.pi + 2 * np.pi * np.arange(64) / 64
    ref = np.c_[g["pitch"] / 2 + lam * (t + 1.5 * np.sin(2 * t)), CRANE["h"] * lam * np.cos(t),
                -CRANE["d"] * lam * np.cos(2 * t)]
    assert np.abs(cur - ref).max() < 1e-12
    assert stitch_length(pat, **{k: g[k] for k in GEO}) == pytest.approx(12.0)
    assert xcf(6.0, 1.54) == pytest.approx(6.0 / 1.54 ** 3)


def test_a_float_runs_straight_across_the_missed_needle():
    """Milano's and interlock's misses: the yarn crosses the missed needle moving forward all the
    way (a float folding back on itself made the interlock's rest frames degenerate)."""
    pat = parse_notation(["fb", "f-", "-b"])
    g = knit_geometry(pat, 6.5, core_radius=0.01)
    cur = course_curve(pat, 1, **{k: g[k] for k in GEO}, samples=64).reshape(2, 64, 3)
    assert np.all(np.diff(cur[1, :, 0]) > 0)                                 # the float over needle 2
    assert np.any(np.diff(cur[0, :, 0]) < 0)                                 # a loop turns round
    cell = homtex.load_cell("cells/milano_eglass.toml").replace(**{"parameters.notation": ["f--b", "-bf-"]})
    assert cell.info["stitches"] == 4 and cell.info["n_overlaps"] == 0


def test_a_tuck_lies_behind_the_held_loop_up_to_its_head():
    """["ff", "ft"]: needle 2's loop of course 1 is held two courses; course 2's tuck there rises
    from its sinker level to the held loop's head, behind it (its depth below the knit profile),
    and the cell builds without overlaps."""
    pat = parse_notation(["ff", "ft"])
    assert pat.held()[0, 1] == 2 and pat.held()[0, 0] == 1 and pat.stitches() == 3
    g = knit_geometry(pat, 6.5, core_radius=0.01)
    c0 = course_curve(pat, 0, **{k: g[k] for k in GEO}, samples=64).reshape(2, 64, 3)
    c1 = course_curve(pat, 1, **{k: g[k] for k in GEO}, samples=64).reshape(2, 64, 3)
    held, tuck = c0[1], c1[1]
    assert tuck[:, 1].max() == pytest.approx(held[:, 1].max())             # one head height
    assert tuck[:, 1].min() == pytest.approx(g["c"] - g["h"])              # from course 2's sinker level
    t = -np.pi + 2 * np.pi * np.arange(64) / 64
    assert np.all(tuck[:, 2] <= -g["d"] * np.cos(2 * t) + 1e-12)           # behind a knit loop's profile
    cell = homtex.load_cell("cells/jersey_eglass.toml").replace(**{"parameters.notation": ["ff", "ft"]})
    assert cell.info["n_overlaps"] == 0 and cell.info["stitches"] == 3


def test_overlaps_at_creation_count_a_course_against_its_own_image():
    """The acrylic jersey (2.66 mm yarn, compressible) overlaps the copy of its one course across
    the wale vector by 2 r - 2 x the loop model's clear radius (half the closest approach of two
    courses); the hard cores stay clear. A thin E-glass yarn overlaps nothing."""
    cell = homtex.load_cell("cells/jersey_acrylic.toml")
    info = cell.info
    r = float(cell.frame.contact_radius[0])
    assert info["n_overlaps"] > 0 and info["n_core_overlaps"] == 0
    assert info["deepest_overlap_mm"] == pytest.approx(2 * r - 2 * info["geometry"]["clear_radius"], rel=0.03)
    assert homtex.load_cell("cells/jersey_eglass.toml").info["n_overlaps"] == 0


def test_a_2x2_supercell_stores_four_times_the_cells_energy():
    cell = homtex.load_cell("cells/jersey_eglass.toml")
    big = cell.replace(**{"parameters.repeat": [2, 2]})
    assert big.frame.n_elements == 4 * cell.frame.n_elements
    U = []
    for c in (cell, big):
        cor = homtex.Corotational(c.frame, geometric="consistent", rest=c.info["rest"])
        cor.evaluate()
        U.append(cor.energy.sum(axis=0))
    assert U[1] == pytest.approx(4 * U[0], rel=1e-9)
    assert U[0][2] + U[0][3] > 0.9 * U[0].sum()          # a loop of straight yarn stores bending


# ------------------------------------------------------------------------------ relaxation
@pytest.fixture(scope="module")
def jersey():
    """The E-glass jersey relaxed to 1e-12 (the scaling law compares two of them to 1e-8); its
    failure stress lowered to 3 MPa so that the wale test below passes it."""
    cell = homtex.load_cell("cells/jersey_eglass.toml").replace(**{"parameters.yarn_model.failure_stress": 3.0})
    return homtex.relax(cell, tol=1e-12)


def test_the_relaxed_jersey_released_its_stored_energy_and_kept_its_yarn_length(jersey):
    """What the solver counts as released iteration by iteration equals the end states' stored
    energy difference plus the take-down's work (computed here from the generated frame)."""
    a, cell = jersey.attrs, jersey.cell
    cor = homtex.Corotational(cell.frame, geometric="consistent", rest=cell.info["rest"])
    cor.evaluate()
    U0 = float(cor.energy.sum())
    wale_extension = jersey.frame.periods[1, 1] - cell.frame.periods[1, 1]
    W = a["take_down_on_cell_N"] * wale_extension
    released = U0 + a["generated_contact_energy_Nmm"] - a["strain_energy_Nmm"] - a["contact_energy_Nmm"] + W
    assert a["released_energy_Nmm"] == pytest.approx(released, rel=1e-6)
    assert a["status"] == "ok" and a["stable"] and 0 < a["strain_energy_Nmm"] < U0
    assert a["take_down_N"] == 0.06 and a["take_down_on_cell_N"] == pytest.approx(0.06 / 5)
    assert a["loop_length_mm"] == pytest.approx(a["input_loop_length_mm"], rel=1e-3)   # EA >> the forces
    for k in ("loop_height_mm", "loop_width_mm", "wale_spacing_mm", "course_spacing_mm"):
        assert a[f"relaxed_{k}"] > 0 and a[f"generated_{k}"] > 0
    assert jersey.frame.periods[0, 0] == pytest.approx(a["wale_spacing_mm"])


def test_a_yarn_of_three_filaments_relaxes_as_its_equivalent_yarn_does():
    """The filament model (3 filaments of 17 um on 0.3 mm elements, each its own beam chain in
    contact with the others) relaxes with no two filaments overlapping and its loop length kept;
    the loop's length-wise shape, set by the yarn's bending, is the equivalent yarn's (course
    spacing and loop height within 3 %; measured 0.6 and 1.4 %), while the bundle spreads sideways
    (wider loops: not asserted). Before the per-pair blend angles of the contact potential, the
    relaxation stalled at Newton iteration 29 with two filaments crossing unseen."""
    from homtex.geometry.knit_cell import creation_overlaps

    base = homtex.load_cell("cells/jersey_eglass.toml")
    out = {}
    for model in ("filaments", "equivalent"):
        cell = base.replace(**{"parameters.yarn_model.model": model, "parameters.yarn_model.filaments": 3,
                               "resolution.element_length": 0.3})
        r = homtex.relax(cell)
        assert r.attrs["status"] == "ok"
        assert r.attrs["loop_length_mm"] == pytest.approx(6.5, rel=1e-3)
        assert creation_overlaps(r.frame)["count"] == 0
        out[model] = r.attrs
    assert len(np.unique(base.replace(**{"parameters.yarn_model.model": "filaments",
                                         "parameters.yarn_model.filaments": 3}).frame.yarn)) == 3
    for k in ("course_spacing_mm", "relaxed_loop_height_mm", "wale_spacing_mm"):
        assert out["filaments"][k] == pytest.approx(out["equivalent"][k], rel=0.03)
    a = out["filaments"]
    # the filaments start laid around relaxed axes that kept the bundles apart (measured from the
    # generated loops their wale spacing came out 6.6 % under the equivalent yarn's; 1 % from the axes)
    assert a["axis_contact_radius_mm"] > 2 * 0.0085 and a["axis_newton_iterations"] > 0
    assert a["start_wale_spacing_mm"] < 0.6 * a["generated_wale_spacing_mm"]
    # the ledger counts from that start: released = stored energy's decrease + the take-down's work
    released = (a["start_strain_energy_Nmm"] + a["start_contact_energy_Nmm"] - a["strain_energy_Nmm"]
                - a["contact_energy_Nmm"] + a["take_down_work_Nmm"])
    assert a["released_energy_Nmm"] == pytest.approx(released, rel=1e-6)


def test_a_1x1_rib_pulls_its_wales_together():
    """A 1x1 rib relaxes to far less than its knitted width (its front and back wales close up);
    coarse elements keep this test cheap."""
    cell = homtex.load_cell("cells/rib_1x1_eglass.toml").replace(**{"resolution.element_length": 0.65})
    a = homtex.relax(cell).attrs
    assert a["status"] == "ok" and a["stable"]
    assert a["wale_spacing_mm"] < 0.5 * a["generated_wale_spacing_mm"]
    assert a["loop_length_mm"] == pytest.approx(a["input_loop_length_mm"], rel=1e-3)


def test_a_relaxed_cell_comes_back_from_the_result_cache_and_continues_as_computed(tmp_path, monkeypatch):
    """A relaxed cell is kept in the result cache (memory and disk, keyed by the cell's content and
    the arguments): read back from disk in a fresh process (memory cleared) it is the computed state
    bit for bit, the pairs touching at creation and the filaments' laid rest state included, and a
    tensile test from it gives the computed one's forces exactly; another take-down is another
    key. A 3-filament jersey, so the laid rest state is stored too."""
    from homtex import cache

    monkeypatch.setenv("HOMTEX_CACHE_DIR", str(tmp_path))
    cell = homtex.load_cell("cells/jersey_eglass.toml").replace(**{
        "resolution.element_length": 0.65, "parameters.yarn_model.model": "filaments",
        "parameters.yarn_model.filaments": 3})
    a = homtex.relax(cell)
    cache.clear_cache(disk=False)
    b = homtex.relax(cell)
    assert not a.attrs["from_cache"] and b.attrs["from_cache"] and a.cell_rest is not None
    for k in ("ut", "Q", "periods", "loads"):
        assert np.array_equal(getattr(a.state, k), getattr(b.state, k)), k
    assert all(np.array_equal(x, y) for x, y in zip(a.state.touch, b.state.touch)) and len(a.state.touch[0])
    assert a.state.ledger == b.state.ledger
    assert np.array_equal(a.cell_rest.frames, b.cell_rest.frames) and np.array_equal(a.rest.frames, b.rest.frames)
    assert np.array_equal(a.frame.nodes, b.frame.nodes) and np.array_equal(a.frame.periods, b.frame.periods)
    assert a.attrs.keys() == b.attrs.keys()
    same = [a.attrs[k] == b.attrs[k] or (a.attrs[k] != a.attrs[k] and b.attrs[k] != b.attrs[k]) for k in a.attrs]
    assert sum(same) == len(a.attrs) - 1          # all but from_cache (NaN for NaN)
    fa, fb = (homtex.tensile(r, strain=0.04, direction="wale", steps=2).force.values for r in (a, b))
    assert np.array_equal(fa, fb) and fa[-1] > fa[0]
    assert not homtex.relax(cell, take_down=0.05).attrs["from_cache"]


# ------------------------------------------------------------------------------ tensile
@pytest.fixture(scope="module")
def wale(jersey):
    return homtex.tensile(jersey, strain=0.2, direction="wale", steps=2)


def test_the_jersey_pulled_along_the_wales_is_j_shaped_and_contracts(wale):
    ds = wale
    assert ds.attrs["status"] == "ok" and np.abs(ds.energy_balance.values).max() < 0.01
    f = ds.force.values
    assert f[0] == pytest.approx(0.06 / 5)                             # the take-down it was relaxed under
    assert f[2] - f[1] > f[1] - f[0] > 0                               # stiffening
    assert np.all(np.diff(ds.width.values) < 0)                        # free lateral contraction
    assert ds.force_per_width.values == pytest.approx(f / ds.attrs["initial_width_mm"])
    assert ds.extension.values[-1] == pytest.approx(0.2 * ds.attrs["gauge_length_mm"])
    # the external work lies between the lower and upper sums of the rising force over the extension
    dx = np.diff(ds.extension.values)
    assert f[:-1] @ dx < ds.external_work.values[-1] < f[1:] @ dx
    bend = ds.bending_y + ds.bending_z
    assert np.all(bend.values > 10 * ds.axial.values) and np.all(bend.values > 10 * ds.torsion.values)
    for v in ("force", "force_per_width", "width", "extension", "axial", "contact_energy", "max_filament_stress"):
        assert ds[v].attrs["units"] and ds[v].attrs["long_name"]


def test_localising_snaps_less_finely_and_stepping_from_memory_leave_the_curve_unchanged(jersey, wale,
                                                                                          monkeypatch):
    """The knit tests stop bisecting a snap after 5 halvings (a jump no step size resolves) and
    start a step at the last size that passed (EngineStepper's max_refine and memory): the
    equilibria at the reported levels are those of the full bisection (max_refine = max_cuts = 10,
    every level tried whole first), whose extra tries were all rolled back."""
    init = engine.EngineStepper.__init__

    def full_bisection(self, *a, **k):
        k.pop("max_refine", None)
        k.pop("memory", None)
        init(self, *a, **k)

    monkeypatch.setattr(engine.EngineStepper, "__init__", full_bisection)
    ref = homtex.tensile(jersey, strain=0.2, direction="wale", steps=2)
    assert ref.attrs["status"] == "ok"
    for k in ("force", "width"):
        assert wale[k].values == pytest.approx(ref[k].values, rel=1e-6)


def test_filaments_beyond_the_failure_stress_are_flagged(wale):
    s, flag = wale.max_filament_stress.values, wale.beyond_failure_stress.values
    assert np.array_equal(flag, s > 3.0) and flag.any() and not flag.all()
    assert wale.attrs["first_failure_strain"] == pytest.approx(float(wale.strain[np.argmax(flag)]))


def test_the_jersey_pulled_along_the_courses_carries_no_force_across(jersey):
    """The take-down is let go first: the test starts at zero force and the wales contract."""
    ds = homtex.tensile(jersey, strain=0.02, direction="course", steps=1)
    assert ds.attrs["status"] == "ok" and abs(float(ds.energy_balance[-1])) < 0.01
    assert ds.attrs["take_down_released_Nmm"] > 0
    f = ds.force.values
    assert abs(f[0]) < 1e-6 * f[1] and f[1] > 0
    assert ds.width.values[1] < ds.width.values[0]


def test_with_friction_the_ledger_still_closes_and_the_fabric_is_stiffer(jersey, wale):
    ds = homtex.tensile(jersey, strain=0.015, direction="wale", steps=1, friction=0.5)
    assert ds.attrs["status"] == "ok" and ds.attrs["friction"] == 0.5
    W, D = float(ds.external_work[-1]), float(ds.friction_energy[-1])
    assert 0.05 * W < D < W and abs(float(ds.energy_balance[-1])) < 0.01
    # frictionless, the force at 10 % is below this one at 1.5 %
    assert float(ds.force[-1]) > float(wale.force[1])


def test_the_m_over_l_cubed_law_holds_exactly_for_a_similar_cell(jersey):
    """Every length x b, bending rigidity x a (EA and kGA x a / b^2, GJ x a), the take-down x a / b^2:
    relaxed spacings x b, energies x a / b, the force at the same strain x a / b^2 (1e-8); at the
    same extension in mm the force x a / b^3. With a and b powers of two every product in the
    scaled cell is the original's times a power of two, so round-off cannot enter the comparison
    (with b = 1.54 the force at 2 % agreed to 8e-8 with one BLAS's kernels and 1e-8 with another)."""
    a, b = 16.0, 2.0     # powers of two: the scaled cell's arithmetic is the original's, exactly
    big = scaled_cell(jersey.cell, length=b, bending=a)
    r1 = homtex.relax(big, take_down=0.06 * a / b ** 2, tol=1e-12)
    assert r1.attrs["wale_spacing_mm"] == pytest.approx(b * jersey.attrs["wale_spacing_mm"], rel=1e-8)
    assert r1.attrs["strain_energy_Nmm"] == pytest.approx(a / b * jersey.attrs["strain_energy_Nmm"], rel=1e-8)
    d0 = homtex.tensile(jersey, strain=0.02, direction="wale", steps=1, tol=1e-12)
    d1 = homtex.tensile(r1, strain=0.02, direction="wale", steps=1, tol=1e-12)
    assert d1.force.values == pytest.approx(d0.force.values * a / b ** 2, rel=1e-8)
    k0 = (d0.force.values[1] - d0.force.values[0]) / d0.extension.values[1]
    k1 = (d1.force.values[1] - d1.force.values[0]) / d1.extension.values[1]
    assert k1 == pytest.approx(k0 * xcf(a, b), rel=1e-6)
    e0 = sum(float(d0[k][-1]) for k in ("axial", "torsion", "bending_y", "bending_z", "shear"))
    e1 = sum(float(d1[k][-1]) for k in ("axial", "torsion", "bending_y", "bending_z", "shear"))
    assert e1 == pytest.approx(e0 * a / b, rel=1e-8)


def test_friction_between_compressible_yarns_does_not_depend_on_the_sub_steps(monkeypatch):
    """With friction, a thick compressible yarn's curve is the same however finely the engine
    subdivides its levels (the regularisation slip halves with the step; at a fixed slip the acrylic
    rib across read 0.024 / 0.010 / 0.0056 N/mm at 2 % with 5 / 8 / 10 halvings, docs/knits.md)."""
    cell = homtex.load_cell("cells/rib_1x1_acrylic.toml").replace(**{"resolution.element_length": 2.0})
    relaxed = homtex.relax(cell, friction=0.0)
    runs = []
    for halvings in (7, 10):
        monkeypatch.setitem(engine.FRICTION_STEPPING, "max_refine", halvings)
        runs.append(homtex.tensile(relaxed, strain=0.01, direction="wale", steps=1, friction=0.3))
    smooth = homtex.tensile(relaxed, strain=0.01, direction="wale", steps=1, friction=0.0)
    assert [ds.attrs["status"] for ds in runs] == ["ok", "ok"]
    assert float(runs[1].force[-1]) == pytest.approx(float(runs[0].force[-1]), rel=1e-3)
    assert float(runs[0].friction_energy[-1]) > 0                       # it dissipates
    assert float(runs[0].force[-1]) > 1.05 * float(smooth.force[-1])   # and friction stiffens


def test_a_rebuilt_pattern_that_takes_near_pairs_along_changes_the_path_only_by_round_off(monkeypatch):
    """Filaments settling on each other activate new contacts at nearly every Newton iteration, and
    each one outside the tangent's pattern rebuilds it (ordering and symbolic factor): with
    NonlinearSettings.pattern_reach the rebuild also takes the pairs within 3 ghat along. The 3-filament
    jersey relaxes to the same state to round-off with fewer rebuilds (measured 71 -> 39; the
    20-filament rib 589 -> 183 over 700 iterations, a fifth less CPU)."""
    relax_module = importlib.import_module("homtex.knits.relax")
    built = []

    class Counting(ipc.FreeSystem):
        def __init__(self, *a, **k):
            built.append(1)
            super().__init__(*a, **k)

    monkeypatch.setattr(ipc, "FreeSystem", Counting)
    cell = homtex.load_cell("cells/jersey_eglass.toml").replace(**{
        "resolution.element_length": 0.4, "parameters.yarn_model.model": "filaments",
        "parameters.yarn_model.filaments": 3})
    out = {}
    for reach in (0.0, relax_module.FILAMENT_PATTERN_REACH):
        monkeypatch.setattr(relax_module, "FILAMENT_PATTERN_REACH", reach)
        built.clear()
        r = homtex.relax(cell, cache=False)
        out[reach] = (r.attrs, len(built))
    (a0, n0), (a1, n1) = out.values()
    assert n1 < 0.8 * n0
    for k in ("wale_spacing_mm", "course_spacing_mm", "strain_energy_Nmm", "relaxed_loop_width_mm"):
        assert a1[k] == pytest.approx(a0[k], rel=1e-9)


def test_a_yarn_of_filaments_passes_the_lock_up_of_its_loops():
    """Where a knit's loops lock up, the filaments of a bundle are pressed together at small angles;
    with the default contact (parallel_sagitta 0.3) the nodal form pushed a closing crossing apart
    with at most about 21 kappa ghat, the collision check stopped every iteration and the 3-filament
    jersey (0.4 mm elements) failed at 12 % after 1000 Newton iterations per try. With the bundle's
    contact (FILAMENT_SAGITTA) it passes: the force per width at 12 % is over ten times the one at
    8 % (measured 32x: the lock-up) and the largest filament stress rises with it (measured 76 ->
    2207 MPa). The snaps before the lock-up are flagged, as the test below asks."""
    cell = homtex.load_cell("cells/jersey_eglass.toml").replace(**{
        "resolution.element_length": 0.4, "parameters.yarn_model.model": "filaments",
        "parameters.yarn_model.filaments": 3})
    ds = homtex.tensile(homtex.relax(cell), strain=0.12, direction="wale", steps=6)
    assert ds.attrs["status"] != "failed" and ds.strain.values[-1] == pytest.approx(0.12)
    f = ds.force_per_width.sel(strain=[0.08, 0.12], method="nearest").values
    s = ds.max_filament_stress.sel(strain=[0.08, 0.12], method="nearest").values
    assert f[1] > 10 * f[0] and s[1] > 5 * s[0]


def test_a_bundles_newton_steps_do_not_throw_a_factorisation_away(monkeypatch):
    """A bundle's exact Hessian stays indefinite over most Newton iterations (filaments buckling on
    each other); trying it first at each cost a factorisation thrown away (1.8 per iteration on the
    3-filament jersey to 8 %). With FILAMENT_EXACT_RETRY the knit tests go straight to the projected
    Hessian after an indefinite one and try the exact one every 8 iterations: about 1.1
    factorisations per iteration, the same forces at every level (to 1e-9 here: the path before
    the lock-up does not depend on the Hessian used, only the iterations to reach it)."""
    ipc = importlib.import_module("homtex.contact.ipc_system")
    record = importlib.import_module("homtex.knits.record")
    count = []
    factor = ipc.FreeSystem.factor
    monkeypatch.setattr(ipc.FreeSystem, "factor", lambda self, *a, **k: count.append(1) or factor(self, *a, **k))
    cell = homtex.load_cell("cells/jersey_eglass.toml").replace(**{
        "resolution.element_length": 0.4, "parameters.yarn_model.model": "filaments",
        "parameters.yarn_model.filaments": 3})
    relaxed = homtex.relax(cell)
    out = {}
    for retry in (1, record.FILAMENT_EXACT_RETRY):
        monkeypatch.setattr(record, "FILAMENT_EXACT_RETRY", retry)
        count.clear()
        ds = homtex.tensile(relaxed, strain=0.08, direction="wale", steps=4)
        out[retry] = (ds.force_per_width.values, len(count) / float(ds.newton_iterations.sum()))
    (f1, per1), (f8, per8) = out.values()
    assert per1 > 1.5 and per8 < 1.3
    np.testing.assert_allclose(f8, f1, rtol=1e-9)


def test_a_yarn_of_filaments_keeps_its_levels_whole_at_the_same_forces(monkeypatch):
    """A bundle of filaments settles in snaps of single filaments at every step size, so halving a
    level for its released energy (the 0.3 % refinement of the knit tests) only multiplies the work:
    yarns of filaments keep each converged level (``record.stepping``: no halving for accuracy) and
    the snaps' energy goes to the ledger, which flags the curve. The 3-filament jersey to 6 % in 2 %
    levels gives the same forces as with five halvings allowed (within 1 %) in under half the
    Newton iterations, and the energy the snaps release is flagged (with the bundle's contact,
    FILAMENT_SAGITTA, it shows as the balance: off by 11 % at 4 %; with the default contact, which
    stalls at the lock-up, it showed as stabilisation, 10 %)."""
    record = importlib.import_module("homtex.knits.record")
    tensile_module = importlib.import_module("homtex.knits.tensile")
    cell = homtex.load_cell("cells/jersey_eglass.toml").replace(**{
        "resolution.element_length": 0.4, "parameters.yarn_model.model": "filaments",
        "parameters.yarn_model.filaments": 3})
    relaxed = homtex.relax(cell)
    assert record.stepping(relaxed.cell.info, False)["max_refine"] == 0
    kept = homtex.tensile(relaxed, strain=0.06, direction="wale", steps=3)
    plain = record.stepping
    monkeypatch.setattr(tensile_module, "stepping", lambda info, friction: {**plain(info, friction), "max_refine": 5})
    halved = homtex.tensile(relaxed, strain=0.06, direction="wale", steps=3)
    np.testing.assert_allclose(kept.force_per_width.values, halved.force_per_width.values, rtol=0.01)
    assert kept.newton_iterations.sum() < 0.5 * halved.newton_iterations.sum()
    assert kept.attrs["status"] == "flagged"
