"""Reduced-order lookups against known functions."""

import numpy as np
import pytest
import xarray as xr

from homtex.errors import InputError
from homtex.lookup import Lookup


def f(x, y):
    return np.sin(3 * x) * np.cos(2 * y) + x * y


def grid_ds(n):
    x = np.linspace(0, 1, n)
    y = np.linspace(0, 2, n + 1)
    X, Y = np.meshgrid(x, y, indexing="ij")
    return xr.Dataset({"value": (("x", "y"), f(X, Y), {"units": "N", "long_name": "test"})},
                      coords={"x": x, "y": y})


def test_grid_exact_at_nodes_and_converges():
    ds = grid_ds(6)
    lk = Lookup.from_dataset(ds, "value")
    X, Y = np.meshgrid(ds.x.values, ds.y.values, indexing="ij")
    np.testing.assert_allclose(lk(X.ravel(), Y.ravel()), f(X, Y).ravel(), rtol=0, atol=1e-14)
    q = np.random.default_rng(0).uniform([0, 0], [1, 2], (2000, 2))
    errs, hold = [], []
    for n in (5, 9, 17, 33):
        lk = Lookup.from_dataset(grid_ds(n), "value")
        errs.append(np.sqrt(np.mean((lk(q) - f(q[:, 0], q[:, 1])) ** 2)))
        hold.append(lk.holdout["rmse"])
    assert all(b < a / 3 for a, b in zip(errs, errs[1:]))  # linear interpolation: O(h^2)
    assert all(b < a for a, b in zip(hold, hold[1:]))
    # the half-resolution hold-out bounds the full grid's error from above
    assert all(h >= e for h, e in zip(hold, errs))


def test_cubic_grid_exact_at_nodes_and_more_accurate():
    ds = grid_ds(9)
    cub = Lookup.from_dataset(ds, "value", method="cubic")
    lin = Lookup.from_dataset(ds, "value")
    X, Y = np.meshgrid(ds.x.values, ds.y.values, indexing="ij")
    np.testing.assert_allclose(cub(X.ravel(), Y.ravel()), f(X, Y).ravel(), atol=1e-12)
    q = np.random.default_rng(1).uniform([0, 0], [1, 2], (2000, 2))
    err = [np.sqrt(np.mean((lk(q) - f(q[:, 0], q[:, 1])) ** 2)) for lk in (lin, cub)]
    assert err[1] < err[0] / 5
    assert cub.holdout["rmse"] < lin.holdout["rmse"]


def test_grid_with_extra_dimension_returns_curves():
    x = np.linspace(0, 1, 5)
    t = np.linspace(0, 1, 7)
    ds = xr.Dataset({"curve": (("x", "t"), x[:, None] * t[None, :] + 1.0)}, coords={"x": x, "t": t})
    lk = Lookup.from_dataset(ds, "curve", inputs=["x"])
    out = lk(np.array([0.3, 0.55]))
    np.testing.assert_allclose(out, np.array([0.3, 0.55])[:, None] * t + 1.0, rtol=1e-13)
    assert lk.extra_dims == ("t",)


def samples_ds(n, seed=1):
    p = np.random.default_rng(seed).uniform([0, 0], [1, 2], (n, 2))
    status = np.zeros(n, dtype=np.int8)
    val = f(p[:, 0], p[:, 1])
    status[0] = 1
    val[0] = np.nan  # a failed point: left out of the fit
    return xr.Dataset({"value": ("sample", val, {"units": "N", "long_name": "test"}),
                       "status": ("sample", status)},
                      coords={"sample": np.arange(n), "x": ("sample", p[:, 0]), "y": ("sample", p[:, 1])},
                      attrs={"study_parameters": '["x", "y"]'})


def test_rbf_samples_converge_and_holdout_tracks_error():
    errs, hold = [], []
    for n in (25, 100, 400):
        lk = Lookup.from_dataset(samples_ds(n), "value")
        q = np.random.default_rng(5).uniform(lk.lo, lk.hi, (3000, 2))
        assert lk.dropped == 1
        errs.append(np.sqrt(np.mean((lk(q) - f(q[:, 0], q[:, 1])) ** 2)))
        hold.append(lk.holdout["rmse"])
        # interpolating RBF: exact at the training samples
        np.testing.assert_allclose(lk(lk.points), lk.values, atol=1e-9)
    assert errs[0] > errs[1] > errs[2] and hold[0] > hold[1] > hold[2]
    for e, h in zip(errs, hold):  # k-fold is not optimistic (held-out points near the hull extrapolate)
        assert h > 0.5 * e


def test_rbf_matches_scipy():
    from scipy.interpolate import RBFInterpolator

    lk = Lookup.from_dataset(samples_ds(60), "value")
    q = np.random.default_rng(2).uniform(lk.lo, lk.hi, (500, 2))
    ref = RBFInterpolator((lk.points - lk.lo) / (lk.hi - lk.lo), lk.values)((q - lk.lo) / (lk.hi - lk.lo))
    np.testing.assert_allclose(lk(q), ref, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("kind", ["grid", "samples"])
def test_save_load_roundtrip(tmp_path, kind):
    ds = grid_ds(7) if kind == "grid" else samples_ds(50)
    lk = Lookup.from_dataset(ds, "value")
    path = lk.save(tmp_path / "lk.nc")
    lk2 = Lookup.load(path)
    q = np.random.default_rng(0).uniform(lk.lo, lk.hi, (200, 2))
    np.testing.assert_allclose(lk2(q), lk(q), rtol=1e-13, atol=1e-14)
    assert lk2.holdout == lk.holdout and lk2.units == "N"


def test_out_of_range_and_masked_grid_named():
    lk = Lookup.from_dataset(grid_ds(5), "value")
    with pytest.raises(InputError, match="'y' = 2.5"):
        lk(np.array([[0.5, 2.5]]))
    assert np.isfinite(Lookup.from_dataset(grid_ds(5), "value", extrapolate=True)(np.array([[0.5, 2.5]]))).all()
    ds = grid_ds(5)
    ds["value"][2, 3] = np.nan
    with pytest.raises(InputError, match="grid node"):
        Lookup.from_dataset(ds, "value")


@pytest.mark.parametrize("kernel", ["thin_plate_spline", "cubic", "linear"])
def test_rbf_kernels_compiled_match_numpy(kernel):
    from homtex import lookup as rom

    p = np.random.default_rng(3).uniform(0, 1, (40, 3))
    y = np.column_stack([np.sin(p.sum(1)), p[:, 0] * p[:, 2]])
    coef, poly = rom._rbf_fit(p, y, kernel, 0.0, None)
    q = np.random.default_rng(4).uniform(0, 1, (300, 3))
    a = np.empty((300, 2))
    b = np.empty((300, 2))
    rom._rbf_eval(q, p, coef, poly, rom._KERNELS[kernel], a)
    rom._rbf_eval_py(q, p, coef, poly, rom._KERNELS[kernel], b)
    np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)
    c = np.empty((40, 2))
    rom._rbf_eval(p, p, coef, poly, rom._KERNELS[kernel], c)
    np.testing.assert_allclose(c, y, atol=1e-8)  # interpolates the data


def test_unknown_kernel_named():
    with pytest.raises(InputError, match="kernel"):
        Lookup.from_dataset(samples_ds(20), "value", kernel="gaussian")
