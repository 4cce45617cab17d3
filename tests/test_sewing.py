"""The seam sewn on the large-motion engine (``seam_profile``'s default), the thread fed at a
constant tension, and the result cache that keeps sewn states."""

import warnings

import numpy as np
import pytest

import homtex
from homtex import cache
from homtex.contact.tension import ConstantTension
from homtex.errors import InputError
from homtex.geometry.seam import seam_cell
from homtex.seams.sew import SewnSeam, sew

D_SMALL = 8.5    # 2 fabric repeats (4 wales): the smallest seam cell with a cushion between seams


@pytest.fixture(scope="module")
def cell():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return homtex.load_cell("cells/spacer_20mm.toml")


@pytest.fixture(scope="module")
def sewn(cell):
    """The small seam cell sewn frictionless to eps0 = 0.3 in 3 levels, and to 0.15 in 2 levels of
    the same size (the first two levels of the same path)."""
    kw = dict(seam_distance=D_SMALL, contact=homtex.Contact(friction=0.0))
    return {0.3: sew(cell, prestrain=0.3, steps=3, **kw), 0.2: sew(cell, prestrain=0.2, steps=2, **kw)}


def _check_derivatives(term, x, scale, nodes_to_check, rel, atol_g, atol_h):
    """The term's gradient and Hessian blocks against central differences of its energy and
    gradient at positions x, for every coordinate of the given nodes."""
    _, g, nodes, H = term.evaluate(x, scale, True)
    h = 1e-6
    for k in nodes_to_check:
        for c in range(3):
            xp, xm = x.copy(), x.copy()
            xp[k, c] += h
            xm[k, c] -= h
            ep, gp, _, _ = term.evaluate(xp, scale, False)
            em, gm, _, _ = term.evaluate(xm, scale, False)
            assert (ep - em) / (2 * h) == pytest.approx(g[k, c], rel=rel, abs=atol_g)
            col = np.zeros_like(x)          # Hessian column (k, c), assembled from the element blocks
            for r, (a, b) in enumerate(nodes):
                for j, node in enumerate((a, b)):
                    if node == k:
                        blk = H[r][:, 3 * j + c].reshape(2, 3)
                        col[a] += blk[0]
                        col[b] += blk[1]
            np.testing.assert_allclose((gp - gm) / (2 * h), col, atol=atol_h)


def test_constant_tension_is_the_gradient_of_its_potential(cell):
    """V = s sum T_e l_e: the gradient is T_e along each element, the Hessian the derivative of the
    gradient (central differences), and both vanish for a straight thread pulled along itself only
    in the transverse directions."""
    fr, info = seam_cell(cell, seam_distance=D_SMALL, prestrain=0.0)
    m0 = int(info["fabric_elements"])
    el = np.arange(m0, fr.n_elements)
    term = ConstantTension(fr, el, np.linspace(0.5, 1.5, len(el)))
    rng = np.random.default_rng(1)
    x = fr.nodes + 0.05 * rng.standard_normal(fr.nodes.shape)
    e, g, nodes, H = term.evaluate(x, 0.7, True)
    assert e == pytest.approx(0.7 * term.rate(x), rel=1e-14)
    _check_derivatives(term, x, 0.7, rng.choice(np.unique(nodes), 4, replace=False), rel=1e-6, atol_g=1e-9,
                       atol_h=1e-6)
    with pytest.raises(InputError, match=">= 0"):
        ConstantTension(fr, el, -1.0)


def test_sewing_balances_energy_and_pinches_at_the_seam(sewn, cell):
    s = sewn[0.3]
    assert s.status == "ok", s.detail
    p = s.path
    assert p.sizes["step"] == 3 and np.all(np.abs(p.energy_balance.values) < 0.01)
    H = cell.info["thickness"]
    x, h = s.profile()
    i0 = int(np.argmin(np.abs(x)))
    # the stitch pulls the layers together at the seam line: the seam line is the lowest point
    assert h[i0] == h.min() < H - 1.0
    assert float(p.seam_height[-1]) < float(p.seam_height[0]) < H
    # the legs are in tension, and the stitch touches the fabric
    assert np.all(p.leg_tension.values > 0) and p.stitch_fabric_contacts.values[-1] > 0
    # the pre-strain's work went into strain, contact and stabilisation energy (no friction here)
    assert float(p.friction_energy[-1]) == 0.0
    assert float(p.prestrain_work[-1]) > 0


def test_sewing_is_path_independent_without_friction(sewn):
    """Frictionless contact is conservative: eps0 = 0.2 reached in 2 levels and as level 2/3 of the
    ramp to 0.3 are the same equilibrium (the legs stay short of buckling there)."""
    a, b = sewn[0.2], sewn[0.3]
    assert float(b.path.prestrain_scale[1]) * 0.3 == pytest.approx(0.2)
    assert float(a.path.seam_height[-1]) == pytest.approx(float(b.path.seam_height[1]), abs=2e-3)
    assert float(a.path.cushion_height[-1]) == pytest.approx(float(b.path.cushion_height[1]), abs=2e-3)


def test_a_sewn_state_survives_the_disk_cache(sewn, cell, tmp_path):
    from homtex.output.io import read_netcdf, write_netcdf
    from homtex.seams.profile import profile_dataset

    s = sewn[0.3]
    ds = read_netcdf(write_netcdf(s.to_dataset(), tmp_path / "sewn.nc"))
    back = SewnSeam.from_dataset(cell, ds, contact=s.contact)
    p0, p1 = profile_dataset(s), profile_dataset(back)
    np.testing.assert_array_equal(p1.height.values, p0.height.values)
    np.testing.assert_array_equal(back.u, s.u)
    np.testing.assert_array_equal(back.profile()[1], s.profile()[1])
    assert back.prestrain == 0.3 and back.stitch == "length"
    with pytest.raises(InputError, match="does not belong"):
        SewnSeam.from_dataset(cell.replace(**{"resolution.pile_segments": 4}), ds)


def test_result_cache_memory_disk_and_keys(tmp_path, monkeypatch, cell):
    """A result is computed once per (kind, cell content, parameters, version): again from memory,
    then from disk after the memory is cleared; another cell or parameter is a new computation;
    a failed result is not written to disk, a flagged one is (with its flag); clear_cache empties the
    folder."""
    import xarray as xr

    monkeypatch.setenv("HOMTEX_CACHE_DIR", str(tmp_path / "c"))
    cache.clear_cache()
    calls = []

    def compute(v, status="ok"):
        def f():
            calls.append(v)
            ds = xr.Dataset({"a": ("i", np.arange(3.0) * v, {"units": "1", "long_name": "a"})})
            ds.attrs["status"] = status
            return ds
        return f

    one = cache.cached("law", cell, {"p": 1.0}, compute(1.0))
    again = cache.cached("law", cell, {"p": 1.0}, compute(99.0))
    assert calls == [1.0] and again.equals(one)
    again["a"][:] = -1.0                                  # the caller's copy: the cache keeps its own
    cache.clear_cache(disk=False)
    disk = cache.cached("law", cell, {"p": 1.0}, compute(99.0))
    assert calls == [1.0] and np.array_equal(disk.a.values, one.a.values)
    cache.cached("law", cell, {"p": 2.0}, compute(2.0))
    cache.cached("law", cell.replace(**{"yarns.monofilament.E": 4000.0}), {"p": 1.0}, compute(3.0))
    assert calls == [1.0, 2.0, 3.0]
    cache.cached("law", cell, {"p": 4.0}, compute(4.0, status="failed"))
    assert len(cache.list_cache()) == 3                   # the failed one stays in memory only
    # a flagged result is kept on disk with its flag (it is the answer, and says what to doubt)
    cache.cached("law", cell, {"p": 5.0}, compute(5.0, status="flagged"))
    cache.clear_cache(disk=False)
    back = cache.cached("law", cell, {"p": 5.0}, compute(55.0))
    assert calls == [1.0, 2.0, 3.0, 4.0, 5.0] and back.attrs["status"] == "flagged"
    assert cache.clear_cache() == 4 and cache.list_cache() == []


def test_seam_profile_defaults_to_the_engine_and_is_cached(tmp_path, monkeypatch, cell, sewn):
    """``seam_profile(method="yarn")`` sews on the engine; a second call with the same arguments
    does not sew again."""
    from homtex.seams import profile as prof_mod
    from homtex.seams import sew as sew_mod

    monkeypatch.setenv("HOMTEX_CACHE_DIR", str(tmp_path / "c"))
    cache.clear_cache()
    count = []

    def counting(*a, **k):
        count.append(1)
        return sewn[0.3]

    monkeypatch.setattr(prof_mod, "sew", counting)
    kw = dict(seam_distance=D_SMALL, prestrain=0.3, steps=3, contact=homtex.Contact(friction=0.0))
    p1 = homtex.seam_profile(cell, **kw)
    p2 = homtex.seam_profile(cell, **kw)
    assert count == [1] and p2.equals(p1)
    assert p1.attrs["geometry"] == "nonlinear" and p1.attrs["status"] == "ok"
    x, h = sewn[0.3].profile()
    np.testing.assert_array_equal(p1.height.values, h)
    assert float(p1.cushion_height) == h.max()
    assert "calibrated" in p1.attrs["validity"]
    cache.clear_cache()
    del sew_mod


def test_stitch_arguments_are_checked(cell):
    with pytest.raises(InputError, match="tension= is for stitch='tension'"):
        sew(cell, seam_distance=24.0, tension=1.0)
    with pytest.raises(InputError, match="prestrain= is for stitch='length'"):
        sew(cell, seam_distance=24.0, stitch="tension", prestrain=0.2)
    with pytest.raises(InputError, match="stitch"):
        sew(cell, seam_distance=24.0, stitch="glue")
    with pytest.raises(InputError, match="prestrain"):
        sew(cell, seam_distance=24.0, prestrain=1.2)


def test_paper_setting_maps_the_machine_dial_in_proportion(cell):
    from homtex.seams import paper_setting

    eps = float(cell.parameters["seam"]["prestrain"])
    assert paper_setting(cell, 0.40) == {"prestrain": pytest.approx(eps)}
    assert paper_setting(cell, 0.15) == {"prestrain": pytest.approx(eps * 0.15 / 0.40)}
    with pytest.raises(InputError, match="relative"):
        paper_setting(cell, 1.5)


def test_pressing_a_sewn_cell_from_the_unseamed_thickness(sewn, cell):
    """The punch starts at the unseamed thickness: no force until it meets the sewn specimen, then
    a rising force; stress = force / cell area. (The ledger of this small cell misses 2.3 % just
    after first contact, whatever the step: flagged, not hidden; docs/seams.md.)"""
    from homtex.seams.press import press_sewn

    s = sewn[0.3]
    H0 = cell.info["thickness"]
    first = float(press_sewn(s, [1e-3], thickness=H0).attrs["first_contact_mm"]) / H0
    assert 0.0 < first < 0.5                  # the cushion is lower than the unseamed fabric
    levels = [0.5 * first, first + 0.005, first + 0.01, first + 0.02, first + 0.03]
    ds = press_sewn(s, levels, thickness=H0)
    assert ds.attrs["status"] in ("ok", "flagged"), ds.attrs.get("status_detail")
    assert ds.sizes["strain"] == len(levels)
    F = ds.force.values
    assert F[0] == 0.0 and np.all(np.diff(F[1:]) > 0) and F[1] > 0
    np.testing.assert_allclose(ds.stress.values, F / ds.attrs["area_mm2"] * 1e3)
    np.testing.assert_allclose(ds.plate_displacement.values, np.array(levels) * H0)
    assert ds.attrs["status"] == "ok" or "energy balance" in ds.attrs["status_detail"]
    assert ds.attrs["sewn_thickness_mm"] == pytest.approx(H0 * (1 - first))


def test_the_cache_command_lists_and_clears(tmp_path, monkeypatch, capsys, cell):
    import xarray as xr

    from homtex.app.cli import main

    monkeypatch.setenv("HOMTEX_CACHE_DIR", str(tmp_path / "c"))
    cache.clear_cache()
    cache.cached("law", cell, {"p": 1}, lambda: xr.Dataset({"a": ("i", np.zeros(2), {"units": "1",
                                                                                   "long_name": "a"})}))
    assert main(["cache"]) == 0
    assert "1 cached result(s)" in capsys.readouterr().out
    assert main(["cache", "--clear"]) == 0
    assert "removed 1 cached result(s)" in capsys.readouterr().out and cache.list_cache() == []


def test_calibrate_stitch_finds_the_prestrain_of_a_target_cushion(sewn, cell):
    """A target between the cushions of eps0 = 0.2 and 0.3 (frictionless, so the ramp is path
    independent) is met by an eps0 between them, checked by a sewing of its own."""
    from homtex.seams.calibrate import calibrate_stitch

    p = sewn[0.3].path
    h2, h3 = float(p.cushion_height[1]), float(p.cushion_height[2])
    assert h3 < h2 - 0.5                                 # the cushion falls over the bracket
    target = 0.5 * (h2 + h3)
    r = calibrate_stitch(cell, seam_distance=D_SMALL, cushion_height=target, eps_max=0.3, steps=3, max_checks=2,
                         contact=homtex.Contact(friction=0.0))
    assert 0.2 < r["prestrain"] < 0.3
    assert abs(r["cushion_height"] - target) <= 0.005 * target
    with pytest.raises(InputError, match="raise eps_max"):
        calibrate_stitch(cell, seam_distance=D_SMALL, cushion_height=5.0, eps_max=0.05, steps=1,
                         contact=homtex.Contact(friction=0.0))


def test_a_tension_only_thread_pulls_when_stretched_and_not_when_shortened(cell):
    """Force k (l - L) / L along a stretched element, none along a shorter one; the gradient and
    Hessian are the derivatives of the potential (central differences)."""
    from homtex.contact.tension import TensionOnly

    fr, info = seam_cell(cell, seam_distance=D_SMALL, prestrain=0.0)
    el = np.arange(int(info["fabric_elements"]), fr.n_elements)
    v = fr.nodes[fr.elements[el, 1]] + fr.shift[el] - fr.nodes[fr.elements[el, 0]]
    L0 = np.linalg.norm(v, axis=1)
    free = L0 * np.where(np.arange(len(el)) % 2 == 0, 0.95, 1.05)     # every other element slack
    term = TensionOnly(fr, el, 100.0, free)
    f = term.forces(fr.nodes)
    np.testing.assert_allclose(f[::2], 100.0 * (L0[::2] - free[::2]) / free[::2], rtol=1e-12)
    assert np.all(f[1::2] == 0.0)
    rng = np.random.default_rng(2)
    x = fr.nodes + 1e-3 * rng.standard_normal(fr.nodes.shape)
    _check_derivatives(term, x, 1.0, rng.choice(np.unique(term.nodes), 3, replace=False), rel=1e-5, atol_g=1e-7,
                       atol_h=1e-4)
    with pytest.raises(InputError, match="TensionOnly"):
        TensionOnly(fr, el, 100.0, 0.0)


def test_a_strip_of_identical_seams_is_the_seam_cell_twice(sewn, cell):
    """Two seams sewn alike side by side (a 2-seam strip, x period 2 d) are the periodic seam cell
    repeated: each cushion and the seam line as in the single cell, twice its pre-strain work
    (frictionless; the strip's one level to eps0 = 0.1 is the first level of the single cell's
    ramp to 0.2); pre-strains per seam land on their own stitch."""
    from homtex.seams.sew import seam_frame
    from homtex.seams.strip import strip_cushions

    one = sewn[0.2]
    assert float(one.path.prestrain_scale[0]) * 0.2 == pytest.approx(0.1)
    two = sew(cell, seam_distance=D_SMALL, prestrain=[0.1, 0.1], seams=2, steps=1,
              contact=homtex.Contact(friction=0.0))
    assert two.status == "ok", two.detail
    assert two.frame.n_nodes == 2 * one.frame.n_nodes
    np.testing.assert_allclose(strip_cushions(two), float(one.path.cushion_height[0]), atol=2e-3)
    assert float(two.path.seam_height[-1]) == pytest.approx(float(one.path.seam_height[0]), abs=2e-3)
    assert float(two.path.prestrain_work[-1]) == pytest.approx(2 * float(one.path.prestrain_work[0]), rel=1e-3)
    f, info = seam_frame(cell, seam_distance=D_SMALL, prestrain=[0.1, 0.3], seams=2)
    pre = np.asarray(f.prestrain)
    xs = f.nodes[f.elements[:, 0], 0]
    st = np.arange(f.n_elements) >= info["fabric_elements"]
    near = np.abs(xs - info["seam_xs"][1]) < 1e-9
    assert np.all(pre[st & near] == 0.3) and np.all(pre[st & ~near] == 0.1) and np.all(pre[~st] == 0.0)
    with pytest.raises(InputError, match="one per seam"):
        seam_frame(cell, seam_distance=D_SMALL, prestrain=[0.1, 0.2, 0.3], seams=2)
