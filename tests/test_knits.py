"""Weft-knitted fabrics: notation -> cell (bad notations named by course and needle, the loop model
and its stitch length), relaxation (its ledger closes, the yarn keeps its length, a rib contracts
across its wales), the periodic tensile test (J-shaped, lateral contraction, the ledger, bending
dominating the energy split) and the m / l^3 law where it must hold exactly."""

import numpy as np
import pytest

import homtex
from homtex.errors import CellError
from homtex.geometry.weft_knit import CRANE, course_curve, knit_geometry, parse_notation, stitch_length
from homtex.knits.scaling import scaled_cell, xcf

CELLS = ("rib_1x1_eglass", "jersey_eglass", "milano_eglass", "rib_1x1_acrylic", "jersey_acrylic")


@pytest.mark.parametrize("name", CELLS)
def test_the_shipped_knit_cells_load(name):
    cell = homtex.load_cell(f"cells/{name}.toml")
    assert cell.frame.dim_periodic == 2 and cell.info["stitches"] >= 1
    L = cell.frame.length[cell.info["filament"] == 0].sum() / cell.info["stitches"]
    assert L == pytest.approx(cell.parameters["loop_length"], rel=5e-3)


@pytest.mark.parametrize("courses, needles, match", [
    (["fx"], None, "course 1, needle 2: unknown symbol 'x'"),
    (["fb", "--"], None, "course 2 knits no needle"),
    (["fbf"], 2, "course 1, needle 3: stitch outside the bed"),
    (["ft"], None, "course 1, needle 2: tuck"),
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


def test_the_loop_model_is_crane_plain_knit_curve_at_the_loop_length():
    """Jersey: x = lambda (t + 3/2 sin 2t), y = h cos t, z = -d cos 2t with Crane's h = 4, d = 1,
    course spacing 4.5 (lambda = 1), scaled so that one loop is as long as asked."""
    pat = parse_notation(["f"])
    g = knit_geometry(pat, 12.0, core_radius=0.01)
    lam = g["pitch"] / (2 * np.pi)
    assert g["h"] == pytest.approx(CRANE["h"] * lam) and g["c"] == pytest.approx(CRANE["c"] * lam)
    cur = course_curve(pat, 0, **{k: g[k] for k in ("pitch", "c", "h", "d", "Z0", "a")}, samples=64)
    t = -np.pi + 2 * np.pi * np.arange(64) / 64
    ref = np.c_[g["pitch"] / 2 + lam * (t + 1.5 * np.sin(2 * t)), CRANE["h"] * lam * np.cos(t),
                -CRANE["d"] * lam * np.cos(2 * t)]
    assert np.abs(cur - ref).max() < 1e-12
    assert stitch_length(pat, **{k: g[k] for k in ("pitch", "c", "h", "d", "Z0", "a")}) == pytest.approx(12.0)
    assert xcf(6.0, 1.54) == pytest.approx(1.643, abs=1e-3)


@pytest.fixture(scope="module")
def rib():
    return homtex.relax(homtex.load_cell("cells/rib_1x1_eglass.toml"))


def test_the_rib_relaxes_with_a_closed_ledger_and_contracts_across_its_wales(rib):
    a = rib.attrs
    assert a["status"] == "ok" and abs(a["energy_balance"]) < 1e-9 and a["stable"]
    assert a["loop_length_mm"] == pytest.approx(a["input_loop_length_mm"], rel=2e-3)     # the yarn keeps its length
    assert a["wale_spacing_mm"] < 0.5 * a["generated_wale_spacing_mm"]                  # a rib pulls its wales in
    assert a["released_energy_Nmm"] > 0 and a["strain_energy_Nmm"] > 0
    assert rib.frame.periods[0, 0] == pytest.approx(a["wale_spacing_mm"])


def test_the_periodic_rib_pulled_along_the_wales(rib):
    ds = homtex.tensile(rib, strain=0.1, direction="wale", steps=5)
    assert ds.attrs["status"] in ("ok", "flagged")
    assert np.abs(ds.energy_balance.values).max() < 0.02
    f = ds.force.values
    assert f[0] == pytest.approx(rib.attrs["take_down_on_cell_N"]) and np.all(np.diff(f) > 0)   # from the take-down on
    assert ds.force_per_width.values == pytest.approx(f / ds.attrs["initial_width_mm"])
    assert ds.width.values[-1] < ds.width.values[0]                                      # free lateral contraction
    bend = ds.bending_y + ds.bending_z
    assert np.all(bend.values > 10 * ds.axial.values) and np.all(bend.values > 10 * ds.torsion.values)
    assert ds.extension.values[-1] == pytest.approx(0.1 * ds.attrs["gauge_length_mm"])
    for v in ("force", "force_per_width", "width", "extension", "axial", "contact_energy", "max_filament_stress"):
        assert ds[v].attrs["units"] and ds[v].attrs["long_name"]


def test_the_m_over_l_cubed_law_holds_exactly_for_a_similar_cell():
    """Every length x b, bending rigidity x a (EA and kGA x a / b^2, GJ x a): the force at the same
    strain x a / b^2 (1e-8), the take-down scaled alike; at the same extension in mm the linear
    force x a / b^3."""
    cell = homtex.load_cell("cells/jersey_eglass.toml")
    a, b = 6.0, 1.54
    big = scaled_cell(cell, length=b, bending=a)
    r0 = homtex.relax(cell, tol=1e-12)
    r1 = homtex.relax(big, take_down=0.06 * a / b ** 2, tol=1e-12)
    assert r1.attrs["wale_spacing_mm"] == pytest.approx(b * r0.attrs["wale_spacing_mm"], rel=1e-8)
    d0 = homtex.tensile(r0, strain=0.02, direction="course", steps=2, tol=1e-12)
    d1 = homtex.tensile(r1, strain=0.02, direction="course", steps=2, tol=1e-12)
    assert d1.force.values[1:] == pytest.approx(d0.force.values[1:] * a / b ** 2, rel=1e-8)
    k0 = (d0.force.values[1] - d0.force.values[0]) / d0.extension.values[1]
    k1 = (d1.force.values[1] - d1.force.values[0]) / d1.extension.values[1]
    assert k1 == pytest.approx(k0 * xcf(a, b), rel=1e-8)
    e0 = sum(float(d0[k][-1]) for k in ("axial", "torsion", "bending_y", "bending_z", "shear"))
    e1 = sum(float(d1[k][-1]) for k in ("axial", "torsion", "bending_y", "bending_z", "shear"))
    assert e1 == pytest.approx(e0 * a / b, rel=1e-8)
