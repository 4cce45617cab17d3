"""Macro cushion layer: closed forms, engagement order, scatter, reproducibility."""

import numpy as np
import pytest

from homtex.errors import InputError
from homtex.macro import macro_curve

H0 = 20.0
A = 12100.0


def linear(e):
    return 40.0 * np.asarray(e)  # kPa


def stiffening(e):
    e = np.asarray(e)
    return 10.0 * e + 200.0 * e ** 3


def bump(hs=6.0, hc=16.0):
    """Cushion profile: seam height hs at x = 0 and d, cushion height hc in the middle."""
    return lambda x, d: hs + (hc - hs) * np.sin(np.pi * np.asarray(x) / d)


def test_no_seams_linear_law_closed_form():
    ds = macro_curve(curve=linear, thickness=H0, strain=0.4, steps=41)
    w = ds.plate_displacement.values
    np.testing.assert_allclose(ds.force.values, 40.0 * (w / H0) * A * 1e-3, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ds.stress.values, 40.0 * w / H0, rtol=1e-12, atol=1e-12)
    assert ds.plate_displacement.attrs["units"] == "mm" and ds.force.attrs["units"] == "N"
    assert ds.stress.attrs["units"] == "kPa"
    assert w[-1] == pytest.approx(0.4 * H0)


def test_no_seams_from_dataset_curve():
    import xarray as xr

    e = np.linspace(0.05, 0.5, 10)
    curve = xr.Dataset({"stress": ("strain", stiffening(e))}, coords={"strain": e}, attrs={"thickness_mm": H0})
    ds = macro_curve(curve=curve, strain=0.5, steps=11)
    # the lookup is linear between the curve's nodes and the plate strains hit them
    np.testing.assert_allclose(ds.stress.values[1:], stiffening(ds.strain.values[1:]), rtol=1e-12)


def test_engagement_order_force_zero_until_tallest_cushion():
    ds = macro_curve(curve=linear, thickness=H0, seam_distance=24.0, profile=bump(6.0, 16.0), steps=401,
                     strain=0.6, n_columns=880, pre_stress="held")
    h = ds.column_height.values
    w = ds.plate_displacement.values
    first = H0 - h.max()
    assert first == pytest.approx(4.0, abs=0.01)
    assert np.all(ds.force.values[w <= first] == 0.0)
    assert np.all(ds.force.values[w > first + 0.05] > 0.0)
    # engaged area = fraction of columns taller than the plate gap
    gap = H0 - w
    expected = (h[None, :] > gap[:, None]).mean(axis=1)
    np.testing.assert_allclose(ds.engaged_fraction.values, expected)
    # "held": each engaged column adds 40 kPa * (w - (H0 - h)) / H0: closed form
    F = (40.0 * np.clip(w[:, None] - (H0 - h[None, :]), 0, None) / H0).sum(axis=1) * (A / 880) * 1e-3
    np.testing.assert_allclose(ds.force.values, F, rtol=1e-10, atol=1e-12)
    # force is nondecreasing and the stiffness grows as columns engage
    assert np.all(np.diff(ds.force.values) >= -1e-12)


def test_released_prestress_bounds_held():
    kw = dict(curve=stiffening, thickness=H0, seam_distance=18.0, profile=bump(6.0, 12.0), strain=0.5)
    held = macro_curve(pre_stress="held", **kw).force.values
    rel = macro_curve(pre_stress="released", **kw).force.values
    assert np.all(rel >= held - 1e-12) and rel[-1] > held[-1]


def test_thread_law_is_a_thread_and_a_column_in_parallel():
    """pre_stress="thread" against an explicit two-spring model, column by column: the pile column
    (law sigma_u) pre-compressed to its height by a tension-only elastic thread whose pull drops by
    k_t per mm of punch travel; k_t is such that the thread is slack after delta."""
    hs = np.array([19.0, 17.5, 16.0, 14.0, 11.0])  # a stepped cushion: five heights, equal widths
    d, delta, n = 25.0, 0.7, 500

    def profile(x, dd):
        return hs[np.minimum((np.asarray(x) / dd * hs.size).astype(int), hs.size - 1)]

    for law in (linear, stiffening):
        ds = macro_curve(curve=law, thickness=H0, seam_distance=d, profile=profile, strain=0.5, steps=301,
                         n_columns=n, pre_stress="thread", slack_travel=delta)
        h = ds.column_height.values
        w = ds.plate_displacement.values
        F = np.zeros_like(w)
        for hi in h:
            e0 = 1.0 - hi / H0
            T0 = law(e0)                    # thread pull (kPa over the column) balances the pre-load
            k_t = T0 / delta                # thread stiffness: slack after delta
            for j, wj in enumerate(w):
                dw = wj - (H0 - hi)         # punch travel past the column's top
                if dw > 0:
                    T = max(0.0, T0 - k_t * dw)
                    F[j] += (law(wj / H0) - T) * (A / n) * 1e-3
        np.testing.assert_allclose(ds.force.values, F, rtol=1e-10, atol=1e-9)


def test_thread_law_between_its_limits():
    kw = dict(curve=stiffening, thickness=H0, seam_distance=18.0, profile=bump(6.0, 12.0), strain=0.5)
    held = macro_curve(pre_stress="held", **kw).force.values
    rel = macro_curve(pre_stress="released", **kw).force.values
    np.testing.assert_allclose(macro_curve(pre_stress="thread", slack_travel=0.0, **kw).force.values, rel,
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(macro_curve(pre_stress="thread", slack_travel=np.inf, **kw).force.values, held,
                               rtol=1e-12, atol=1e-12)
    prev = rel
    for delta in (0.1, 0.5, 2.0, 8.0):  # a softer / longer thread holds more of the pre-load
        f = macro_curve(pre_stress="thread", slack_travel=delta, **kw).force.values
        assert np.all(f <= prev + 1e-9) and np.all(f >= held - 1e-9) and (f < rel - 1e-6).any()
        prev = f
    # a callable profile carries no thread: the slack travel must be given
    with pytest.raises(InputError, match="slack_travel"):
        macro_curve(**kw)
    with pytest.raises(InputError, match="slack_travel"):
        macro_curve(slack_travel=-1.0, **kw)


def transition(ds):
    f = ds.engaged_fraction.values
    w = ds.plate_displacement.values
    return w[np.argmax(f >= 0.999)] - w[np.argmax(f > 0)]


def test_scatter_widens_transition_and_is_seeded():
    kw = dict(curve=linear, thickness=H0, seam_distance=24.0, profile=bump(12.0, 16.0), strain=0.6, steps=601,
              slack_travel=0.2)
    base = macro_curve(height_scatter=0.0, **kw)
    sc = macro_curve(height_scatter=1.5, seed=3, **kw)
    assert transition(sc) > transition(base) + 0.5
    again = macro_curve(height_scatter=1.5, seed=3, **kw)
    np.testing.assert_array_equal(sc.force.values, again.force.values)
    other = macro_curve(height_scatter=1.5, seed=4, **kw)
    assert not np.array_equal(sc.force.values, other.force.values)
    # scatter is between cushions: all columns of one cushion are scaled by the same factor
    ratio = sc.column_height.values / base.column_height.values
    for k in np.unique(sc.column_cushion.values):
        r = ratio[sc.column_cushion.values == k]
        assert np.ptp(r[(sc.column_height.values[sc.column_cushion.values == k] < H0)]) < 1e-12


def test_more_seams_longer_first_region():
    # cushion height falls with seam distance (as the paper's Table 1: 20, 15, 8 mm)
    def profile(x, d):
        hc = H0 * (1.0 - np.exp(-d / 12.0))
        return 5.0 + (hc - 5.0) * np.sin(np.pi * np.asarray(x) / d)

    first = []
    for d in (43.0, 24.0, 18.0):
        ds = macro_curve(curve=stiffening, thickness=H0, seam_distance=d, profile=profile, strain=0.6, steps=601,
                         slack_travel=0.3)
        f = ds.force.values
        w = ds.plate_displacement.values
        first.append(w[np.argmax(f > 0.05 * f[-1])])
    assert first[0] < first[1] < first[2]


def test_errors_name_the_culprit():
    with pytest.raises(InputError, match="seam_distance"):
        macro_curve(curve=linear, thickness=H0, seam_distance=-1.0, profile=bump())
    with pytest.raises(InputError, match="thickness"):
        macro_curve(curve=linear)
    with pytest.raises(InputError, match="pre_stress"):
        macro_curve(curve=linear, thickness=H0, pre_stress="x")


def test_truncated_curve_is_reported():
    import xarray as xr

    e = np.linspace(0.05, 0.2, 4)
    curve = xr.Dataset({"stress": ("strain", 40 * e)}, coords={"strain": e},
                       attrs={"thickness_mm": H0, "status": "failed", "status_detail": "failed at step 5"})
    ds = macro_curve(curve=curve, strain=0.5)
    assert ds.strain.values[-1] == pytest.approx(0.2)
    assert ds.attrs["status"] == "failed"
    assert "truncated" in ds.attrs["status_detail"] and "failed at step 5" in ds.attrs["status_detail"]


def test_cell_path_uses_seam_profile_and_compress(monkeypatch):
    """Without injected inputs macro_curve calls homtex.seam_profile and homtex.compress."""
    from pathlib import Path

    seams = pytest.importorskip("homtex.seams")
    import xarray as xr

    import homtex.macro as macro

    cell_file = Path(__file__).resolve().parents[1] / "cells" / "spacer_20mm.toml"
    if not cell_file.exists():
        pytest.skip("no spacer cell")
    import homtex

    cell = homtex.load_cell(cell_file, build=False)
    calls = []

    real = macro.compress

    def fake_compress(c, *, strain, **kw):  # the engine's law to 70 % is slow: a linear stand-in
        if np.ndim(strain) == 0:  # seam_profile's own small-strain modulus: the real thing
            return real(c, strain=strain, **kw)
        calls.append(float(np.max(strain)))
        e = np.linspace(0.0, float(np.max(strain)), 11)[1:]
        return xr.Dataset({"stress": ("strain", 40.0 * e)}, coords={"strain": e},
                          attrs={"thickness_mm": H0, "status": "ok"})

    monkeypatch.setattr(macro, "compress", fake_compress)
    monkeypatch.setattr(macro, "engine_law", lambda c, strain, **k: fake_compress(c, strain=np.array([strain])))
    first = {}
    for d in (43.0, 24.0, 18.0):
        ds = macro_curve(cell, seam_distance=d, strain=0.6, steps=301,
                         profile_options={"method": "foundation"})
        prof = seams.seam_profile(cell, seam_distance=d, method="foundation")
        hc = min(float(prof["cushion_height"]), H0)
        # the punch first meets the tallest column: the profile's cushion height (clipped at H0)
        assert ds.attrs["first_contact_mm"] == pytest.approx(H0 - hc, abs=0.05)
        first[d] = ds.attrs["first_contact_mm"]
    assert calls == [0.7, 0.7, 0.7]             # the default law: the engine's curve to 70 %
    assert first[43.0] < first[24.0] < first[18.0]


def test_the_default_law_is_the_engines_curve_to_70_percent_computed_once(monkeypatch):
    """macro_curve's default unseamed law: compress(geometry="nonlinear") to 70 % on the cell file's
    friction, once per cell and process (the result cache), whatever strain the caller asks for."""
    import xarray as xr

    import homtex
    import homtex.macro as macro
    from homtex import cache

    cache.clear_cache(disk=False)
    cell = homtex.load_cell("spacer_20mm", build=False)
    calls = []

    def fake(c, *, strain, **kw):
        calls.append((float(np.max(strain)), kw.get("geometry"), kw.get("contact")))
        e = np.asarray(strain, dtype=float)
        return xr.Dataset({"stress": ("strain", 40.0 * e, {"units": "kPa"})}, coords={"strain": e},
                          attrs={"thickness_mm": H0, "status": "ok"})

    monkeypatch.setattr(macro, "compress", fake)
    a = macro_curve(cell, strain=0.3, steps=11)
    b = macro_curve(cell, strain=0.5, steps=11)
    assert calls == [(0.7, "nonlinear", None)]
    assert a.attrs["status"] == b.attrs["status"] == "ok"
    np.testing.assert_allclose(b.force.values[-1], 40.0 * 0.5 * a.attrs["plate_area_mm2"] * 1e-3, rtol=1e-12)
    cache.clear_cache()


def test_cushion_law_is_the_cushion_curve_shifted_by_each_cushions_height(monkeypatch):
    """law="cushion": every cushion follows the seamed cushion's own curve; without scatter the
    plate's stress is that curve, with scatter each cushion's curve is shifted by its height
    difference delta_k (a linear curve sigma = K eps, none before contact, gives the closed form
    K sum_i (eps + delta_i / H0)+ / n over the columns); a curve shorter than the travel is
    truncated and reported."""
    import xarray as xr

    from homtex.macro import column_heights, cushion_shifts

    K = 50.0
    e = np.linspace(0.0, 0.8, 81)
    cc = xr.Dataset({"stress": ("strain", K * e)}, coords={"strain": e})
    kw = dict(curve=linear, thickness=H0, seam_distance=24.0, profile=bump(), slack_travel=0.1, law="cushion",
              cushion_curve=cc, steps=51, strain=0.5)
    ds = macro_curve(**kw)
    eps = ds.strain.values
    np.testing.assert_allclose(ds.stress.values, K * eps, atol=1e-9)
    assert ds.attrs["law"] == "cushion"
    sc = macro_curve(**kw, height_scatter=1.5, seed=3)
    _, _, cushion = column_heights(H0, seam_distance=24.0, profile=bump(), plate_area=A, n_columns=440)
    d = cushion_shifts(cushion, 1.5, 3)
    ref = K * np.maximum(eps[:, None] + d[None, :] / H0, 0.0).mean(axis=1)
    np.testing.assert_allclose(sc.stress.values, ref, atol=1e-9)
    assert np.ptp(d) > 1.0 and np.any(sc.stress.values != ds.stress.values)
    short = macro_curve(**{**kw, "strain": 0.9})
    assert short.attrs["status"] == "failed" and "cushion's curve ends" in short.attrs["status_detail"]
    # computed from the cell, the cushion's curve is pressed as far as the tallest cushion goes
    asked = []

    def law(cell, *, seam_distance, strain, steps):
        asked.append((strain, steps))
        return cc

    import homtex.macro as macro

    monkeypatch.setattr(macro, "cushion_law", law)
    computed = macro_curve(cell=object(), **{**kw, "cushion_curve": None}, height_scatter=1.5, seed=3)
    (to, n), = asked
    assert to >= 0.5 + d.max() / H0 and to - 0.02 < 0.5 + d.max() / H0 and to == pytest.approx(0.02 * n)
    assert computed.attrs["status"] == "ok"
    np.testing.assert_allclose(computed.stress.values, sc.stress.values, atol=1e-12)
    with pytest.raises(InputError, match="needs seam_distance"):
        macro_curve(curve=linear, thickness=H0, law="cushion")


def test_a_flag_on_the_law_a_curve_comes_from_is_the_curves_flag():
    """A yarn-level curve whose energy ledger failed its check (status "flagged") gives the macro
    curve built on it the same flag and its reason; the numbers are unchanged."""
    import xarray as xr

    e = np.linspace(0.0, 0.8, 81)
    why = "the stabilisation absorbed 16.8 % of the driven work by strain 0.28"
    clean = xr.Dataset({"stress": ("strain", 50.0 * e)}, coords={"strain": e}, attrs={"status": "ok"})
    flagged = clean.assign_attrs(status="flagged", status_detail=why)
    kw = dict(thickness=H0, seam_distance=24.0, profile=bump(), slack_travel=0.1, steps=51, strain=0.5)
    ok = macro_curve(curve=linear, law="cushion", cushion_curve=clean, **kw)
    fl = macro_curve(curve=linear, law="cushion", cushion_curve=flagged, **kw)
    assert ok.attrs["status"] == "ok" and fl.attrs["status"] == "flagged"
    assert "cushion's yarn-level curve is flagged" in fl.attrs["status_detail"] and why in fl.attrs["status_detail"]
    np.testing.assert_array_equal(ok.force.values, fl.force.values)
    col = macro_curve(curve=flagged, **kw)                  # the column model on a flagged unseamed law
    assert col.attrs["status"] == "flagged" and "unseamed compression curve is flagged" in col.attrs["status_detail"]
    assert macro_curve(curve=clean, **kw).attrs["status"] == "ok"
