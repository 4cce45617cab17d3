"""Reduced-order lookups of study results: ``Lookup``.

A :class:`Lookup` interpolates one output variable of a study Dataset over its parameters:

- grids (parameters are dimensions): tensor-product interpolation
  (:class:`scipy.interpolate.RegularGridInterpolator`, ``method="linear"`` or ``"cubic"``;
  one axis + linear uses :func:`numpy.interp`); exact at the nodes;
- samples (a ``sample`` dimension): radial basis functions
  (polyharmonic: thin-plate spline by default, with a linear polynomial tail; fitted by one
  dense solve, evaluated by a parallel numba kernel) on inputs scaled to the unit box, so
  parameters of different units weigh alike.

Failed or missing points (``status`` != 0 or NaN values) are left out of a sample fit; a grid
with masked nodes is rejected (name the node) since a tensor grid needs every node.

Every lookup reports a hold-out error (``holdout`` dict): for samples a seeded k-fold cross
validation; for grids the error at the nodes left out of a half-resolution grid (every other
interior node dropped along each axis with >= 3 nodes) — an upper estimate of the full
grid's error. Outputs may carry extra dimensions (e.g. a curve over ``strain``): a query then
returns the whole curve. Save and load as netCDF (``save``, ``Lookup.load``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .errors import InputError
from .output.io import read_netcdf, write_netcdf
from .validate import check_choice

__all__ = ["Lookup"]

#: kernel name -> (id, minimum polynomial degree); phi(r) of the scaled distance r
_KERNELS = {"thin_plate_spline": 0, "cubic": 1, "linear": 2}
_MIN_DEGREE = {"thin_plate_spline": 1, "cubic": 1, "linear": 0}


def _phi(r, kid):
    if kid == 0:
        return np.where(r > 0, r * r * np.log(np.where(r > 0, r, 1.0)), 0.0)
    if kid == 1:
        return r ** 3
    return -r


def _rbf_fit(pts, y, kernel, smoothing, degree):
    """Coefficients of a polyharmonic RBF with a linear (or constant) polynomial tail.

    pts (n, d) in the unit box, y (n, k). Returns (coef (n + 1 + d, k), tail flag array) where
    the tail is [1, x_1 .. x_d] for degree 1 and [1] for degree 0.
    """
    check_choice(kernel, "Lookup: kernel", sorted(_KERNELS))
    need = _MIN_DEGREE[kernel]
    deg = need if degree is None else int(degree)
    if deg < need or deg > 1:
        raise InputError(f"Lookup: kernel {kernel!r} needs polynomial degree {need} (0 or 1 supported), got {deg}")
    n, d = pts.shape
    r = np.sqrt(((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1))
    K = _phi(r, _KERNELS[kernel]) + smoothing * np.eye(n)
    P = np.ones((n, 1)) if deg == 0 else np.column_stack([np.ones(n), pts])
    m = P.shape[1]
    A = np.zeros((n + m, n + m))
    A[:n, :n] = K
    A[:n, n:] = P
    A[n:, :n] = P.T
    rhs = np.zeros((n + m, y.shape[1]))
    rhs[:n] = y
    try:
        coef = np.linalg.solve(A, rhs)
    except np.linalg.LinAlgError as exc:
        raise InputError(f"Lookup: the RBF system is singular ({exc}); are samples repeated?") from None
    return np.ascontiguousarray(coef), np.zeros(m)


try:
    from numba import njit, prange
except ImportError:  # pragma: no cover
    njit = None


def _rbf_eval_py(q, pts, coef, poly, kid, out):
    n = len(pts)
    for s in range(0, len(q), 4096):
        qq = q[s:s + 4096]
        r = np.sqrt(((qq[:, None, :] - pts[None, :, :]) ** 2).sum(-1))
        v = _phi(r, kid) @ coef[:n] + coef[n]
        if len(poly) > 1:
            v += qq @ coef[n + 1:]
        out[s:s + 4096] = v


if njit is not None:
    @njit(cache=True, parallel=True)
    def _rbf_eval(q, pts, coef, poly, kid, out):  # pragma: no cover - compiled
        n, d = pts.shape
        k = coef.shape[1]
        tail = len(poly) > 1
        for i in prange(q.shape[0]):
            for c in range(k):
                out[i, c] = coef[n, c]
                if tail:
                    for a in range(d):
                        out[i, c] += coef[n + 1 + a, c] * q[i, a]
            for j in range(n):
                r2 = 0.0
                for a in range(d):
                    t = q[i, a] - pts[j, a]
                    r2 += t * t
                r = np.sqrt(r2)
                if kid == 0:
                    ph = 0.5 * r2 * np.log(r2) if r2 > 0.0 else 0.0
                elif kid == 1:
                    ph = r2 * r
                else:
                    ph = -r
                for c in range(k):
                    out[i, c] += ph * coef[j, c]
else:  # pragma: no cover
    _rbf_eval = _rbf_eval_py


class Lookup:
    """Interpolating surrogate y(p) of a study output (see the module docstring).

    Construct with :meth:`from_dataset`, :meth:`from_grid` or :meth:`from_samples`.
    Call with an (n, d) array, a dict {name: (n,) array} or d positional arrays; returns
    (n, *extra) values (``extra`` = the output's non-parameter dimensions).
    """

    def __init__(self, kind: str, names: list, *, axes=None, points=None, values=None, method="linear",
                 kernel="thin_plate_spline", smoothing=0.0, degree=None, output="value", units="1",
                 long_name="", extra_dims=(), extra_coords=None, holdout_folds=5, seed=0,
                 extrapolate=False, compute_holdout=True, bounds=None):
        self.kind = kind
        self.names = [str(n) for n in names]
        self.method = method
        self.kernel = kernel
        self.smoothing = float(smoothing)
        self.degree = degree
        self.output = output
        self.units = units
        self.long_name = long_name or output
        self.extra_dims = tuple(extra_dims)
        self.extra_coords = dict(extra_coords or {})
        self.extrapolate = bool(extrapolate)
        self.seed = int(seed)
        self.holdout_folds = int(holdout_folds)
        values = np.asarray(values, dtype=float)
        if kind == "grid":
            self.axes = [np.asarray(a, dtype=float) for a in axes]
            if len(self.axes) != len(self.names):
                raise InputError(f"Lookup: {len(self.names)} names but {len(self.axes)} axes")
            for n, a in zip(self.names, self.axes):
                if a.ndim != 1 or a.size < 2 or not np.all(np.diff(a) > 0):
                    raise InputError(f"Lookup: axis {n!r} must be strictly increasing with >= 2 nodes, got {a}")
            check_choice(method, "Lookup: grid method", ("linear", "cubic"))
            if method == "cubic":
                for n, a in zip(self.names, self.axes):
                    if a.size < 4:
                        raise InputError(f"Lookup: method 'cubic' needs >= 4 nodes on axis {n!r}, got {a.size}")
            shape = tuple(a.size for a in self.axes)
            if values.shape[:len(shape)] != shape:
                raise InputError(f"Lookup: values shape {values.shape} does not start with the grid shape {shape}")
            bad = ~np.isfinite(values.reshape(*shape, -1)).all(axis=-1)
            if bad.any():
                idx = np.argwhere(bad)[0]
                node = {n: float(a[i]) for n, a, i in zip(self.names, self.axes, idx)}
                raise InputError(f"Lookup: output {output!r} is masked/NaN at grid node {node} "
                                 f"({int(bad.sum())} node(s)); a tensor grid needs every node")
            self.values = values
            self.dropped = 0
            self.lo = np.array([a[0] for a in self.axes])
            self.hi = np.array([a[-1] for a in self.axes])
        elif kind == "samples":
            pts = np.atleast_2d(np.asarray(points, dtype=float))
            if pts.shape[1] != len(self.names):
                raise InputError(f"Lookup: points have {pts.shape[1]} columns for {len(self.names)} names")
            keep = np.isfinite(pts).all(axis=1) & np.isfinite(values.reshape(len(values), -1)).all(axis=1)
            self.dropped = int((~keep).sum())
            self.points = pts[keep]
            self.values = values[keep]
            if len(self.points) < len(self.names) + 2:
                raise InputError(f"Lookup: {len(self.points)} usable samples for {len(self.names)} inputs; "
                                 f"need at least {len(self.names) + 2}")
            self.lo = self.points.min(axis=0)
            self.hi = self.points.max(axis=0)
            if bounds is not None:  # the sampled box (e.g. a study's [sampling.bounds])
                b = np.asarray(bounds, dtype=float).reshape(len(self.names), 2)
                self.lo = np.minimum(self.lo, b[:, 0])
                self.hi = np.maximum(self.hi, b[:, 1])
            span = self.hi - self.lo
            if np.any(span <= 0):
                raise InputError(f"Lookup: input {self.names[int(np.argmin(span))]!r} does not vary over the samples")
        else:
            raise InputError(f"Lookup: kind must be 'grid' or 'samples', got {kind!r}")
        self._fit()
        self.holdout = self._holdout() if compute_holdout else {}

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_grid(cls, axes: dict, values, **kw) -> "Lookup":
        """Lookup on a tensor grid: axes {name: (n_i,) increasing}, values (*n_i, *extra)."""
        return cls("grid", list(axes), axes=list(axes.values()), values=values, **kw)

    @classmethod
    def from_samples(cls, names, points, values, **kw) -> "Lookup":
        """RBF lookup on scattered samples: points (n, d), values (n, *extra)."""
        return cls("samples", list(names), points=points, values=values, **kw)

    @classmethod
    def from_dataset(cls, ds, output: str, *, inputs=None, **kw) -> "Lookup":
        """Lookup of ``ds[output]`` from a study Dataset (grid or ``sample`` layout).

        inputs : parameter names (default: the study's parameters, ``attrs["study_parameters"]``,
            else every 1-D numeric coordinate that is a dimension of the output (grid) or lies
            along ``sample``). Remaining dimensions of the output become ``extra_dims``.
        kw : bounds [(lo, hi)] per input (samples; default the study's ``sampling_bounds``
            attribute, else the samples' extent), method ("linear"/"cubic", grids), kernel
            (thin_plate_spline, cubic, linear)/smoothing/degree (samples),
            holdout_folds, seed, extrapolate.
        """
        if output not in ds.data_vars:
            raise InputError(f"Lookup: no variable {output!r} in the Dataset; have {sorted(map(str, ds.data_vars))}")
        da = ds[output]
        meta = dict(output=output, units=da.attrs.get("units", "1"), long_name=da.attrs.get("long_name", output))
        if inputs is None and "study_parameters" in ds.attrs:
            inputs = json.loads(ds.attrs["study_parameters"])
        if "sample" in da.dims:
            if inputs is None:
                inputs = [str(c) for c in ds.coords if ds[c].dims == ("sample",) and c != "sample"
                          and ds[c].dtype.kind in "if"]
            for n in inputs:
                if n not in ds.coords and n not in ds.data_vars:
                    raise InputError(f"Lookup: input {n!r} not found in the Dataset")
            da = da.transpose("sample", ...)
            if "status" in ds:
                da = da.where(ds["status"] == 0)
            pts = np.column_stack([np.asarray(ds[n].values, dtype=float) for n in inputs])
            if "bounds" not in kw and "sampling_bounds" in ds.attrs:
                sb = json.loads(ds.attrs["sampling_bounds"])
                if all(n in sb for n in inputs):
                    kw["bounds"] = [sb[n] for n in inputs]
            extra = da.dims[1:]
            return cls("samples", inputs, points=pts, values=da.values, extra_dims=extra,
                       extra_coords={d: np.asarray(ds[d].values) for d in extra if d in ds.coords}, **meta, **kw)
        if inputs is None:
            inputs = [str(d) for d in da.dims if d in ds.coords and ds[d].dtype.kind in "if"]
        for n in inputs:
            if n not in da.dims:
                raise InputError(f"Lookup: input {n!r} is not a dimension of {output!r} (dims {da.dims})")
        extra = tuple(d for d in da.dims if d not in inputs)
        if "status" in ds and (ds["status"] != 0).any():
            bad = ds["status"].where(ds["status"] != 0, drop=True)
            first = {k: float(v) for k, v in bad.isel({d: 0 for d in bad.dims}).coords.items() if k in inputs}
            raise InputError(f"Lookup: {int(bad.count())} grid point(s) failed (status != 0), e.g. at {first}; "
                             f"a tensor grid needs every node")
        da = da.transpose(*inputs, *extra)
        axes = [np.asarray(ds[n].values, dtype=float) for n in inputs]
        return cls("grid", inputs, axes=axes, values=da.values, extra_dims=extra,
                   extra_coords={d: np.asarray(ds[d].values) for d in extra if d in ds.coords}, **meta, **kw)

    # ------------------------------------------------------------------ fitting
    def _fit(self):
        self._interp = self._make(self.axes if self.kind == "grid" else self.points, self.values)

    def _make(self, where, values):
        """An evaluator q (n, d) -> (n, *extra) fitted to (where, values)."""
        if self.kind == "grid":
            axes = where
            if len(axes) == 1 and self.method == "linear":
                x = axes[0]
                y = values.reshape(len(x), -1)
                if y.shape[1] == 1:
                    yy = y[:, 0]
                    return lambda q: np.interp(q[:, 0], x, yy).reshape(len(q), *values.shape[1:])
                return lambda q: np.stack([np.interp(q[:, 0], x, y[:, k]) for k in range(y.shape[1])],
                                          axis=1).reshape(len(q), *values.shape[1:])
            from scipy.interpolate import RegularGridInterpolator

            kw = {}
            if self.method == "cubic":  # the default iterative spline solve is only ~1e-6 accurate
                from scipy.sparse.linalg import spsolve

                kw["solver"] = spsolve
            rgi = RegularGridInterpolator(tuple(axes), values, method=self.method, bounds_error=False,
                                          fill_value=None, **kw)
            return rgi
        pts = np.ascontiguousarray((where - self.lo) / (self.hi - self.lo))
        n = len(pts)
        y = values.reshape(n, -1)
        coef, poly = _rbf_fit(pts, y, self.kernel, self.smoothing, self.degree)
        lo, span, shp = self.lo, self.hi - self.lo, values.shape[1:]
        kid = _KERNELS[self.kernel]

        def ev(q):
            qs = np.ascontiguousarray((q - lo) / span)
            out = np.empty((len(qs), y.shape[1]))
            _rbf_eval(qs, pts, coef, poly, kid, out)
            return out.reshape(len(q), *shp)
        return ev

    def _holdout(self) -> dict:
        scale = float(np.nanmax(self.values) - np.nanmin(self.values)) or 1.0
        if self.kind == "samples":
            n = len(self.points)
            k = max(2, min(self.holdout_folds, n // 2))
            order = np.random.default_rng(self.seed).permutation(n)
            err = np.empty_like(self.values.reshape(n, -1))
            for f in range(k):
                test = order[f::k]
                train = np.setdiff1d(order, test)
                if len(train) < len(self.names) + 2:
                    return {"method": "k-fold", "note": "too few samples for a hold-out"}
                ev = self._make(self.points[train], self.values[train])
                err[test] = (ev(self.points[test]) - self.values[test]).reshape(len(test), -1)
            method, count = f"{k}-fold cross validation", n
        else:
            keep = []
            need = 4 if self.method == "cubic" else 2  # nodes a sub-grid axis needs
            for a in self.axes:
                idx = np.arange(a.size)
                sub = np.unique(np.r_[idx[::2], a.size - 1])
                keep.append(idx if (a.size < 3 or sub.size < need) else sub)
            if all(len(kp) == a.size for kp, a in zip(keep, self.axes)):
                return {"method": "half-resolution grid", "note": "no axis can be halved; no hold-out"}
            sub = self.values[np.ix_(*keep)]
            ev = self._make([a[kp] for a, kp in zip(self.axes, keep)], sub)
            mesh = np.meshgrid(*self.axes, indexing="ij")
            q = np.column_stack([m.ravel() for m in mesh])
            kept = np.zeros([a.size for a in self.axes], dtype=bool)
            kept[np.ix_(*keep)] = True
            left = ~kept.ravel()
            y = self.values.reshape(len(q), -1)
            err = (ev(q[left]).reshape(left.sum(), -1) - y[left])
            method, count = "half-resolution grid, error at the left-out nodes (upper estimate)", int(left.sum())
        rmse = float(np.sqrt(np.mean(err ** 2)))
        return {"method": method, "points": count, "rmse": rmse, "max_abs": float(np.abs(err).max()),
                "relative_rmse": rmse / scale, "units": self.units}

    # ------------------------------------------------------------------ evaluation
    def _queries(self, args, kwargs) -> np.ndarray:
        if kwargs:
            missing = [n for n in self.names if n not in kwargs]
            if missing:
                raise InputError(f"Lookup: missing input(s) {missing}; inputs are {self.names}")
            q = np.column_stack([np.asarray(kwargs[n], dtype=float).ravel() for n in self.names])
        elif len(args) == 1 and isinstance(args[0], dict):
            return self._queries((), args[0])
        elif len(args) == 1:
            q = np.asarray(args[0], dtype=float)
            q = q.reshape(-1, 1) if (q.ndim == 1 and len(self.names) == 1) else np.atleast_2d(q)
        else:
            q = np.column_stack([np.asarray(a, dtype=float).ravel() for a in args])
        if q.shape[1] != len(self.names):
            raise InputError(f"Lookup: queries have {q.shape[1]} columns, inputs are {self.names}")
        if not self.extrapolate:
            tol = 1e-9 * np.maximum(np.abs(self.hi - self.lo), 1e-300)
            out = (q < self.lo - tol) | (q > self.hi + tol)
            if out.any():
                i, j = np.argwhere(out)[0]
                raise InputError(f"Lookup: query {int(i)} input {self.names[j]!r} = {q[i, j]:g} is outside "
                                 f"[{self.lo[j]:g}, {self.hi[j]:g}] ({int(out.any(axis=1).sum())} queries out of "
                                 f"range; pass extrapolate=True to allow)")
        return np.ascontiguousarray(q)

    def __call__(self, *args, **kwargs) -> np.ndarray:
        """Values at the queries: (n, *extra), vectorised."""
        return self._interp(self._queries(args, kwargs))

    # ------------------------------------------------------------------ netCDF
    def to_dataset(self):
        """The lookup's data and settings as an xarray Dataset (what :meth:`save` writes)."""
        import xarray as xr

        vmeta = {"units": self.units, "long_name": f"{self.long_name} (lookup training data)"}
        coords = {d: (d, v, {"units": "1", "long_name": str(d)}) for d, v in self.extra_coords.items()}
        if self.kind == "grid":
            for n, a in zip(self.names, self.axes):
                coords[n] = (n, a, {"units": "1", "long_name": f"lookup input {n}"})
            data = {"values": (tuple(self.names) + self.extra_dims, self.values, vmeta)}
        else:
            data = {"values": (("sample",) + self.extra_dims, self.values, vmeta),
                    "points": (("sample", "input"), self.points, {"units": "1", "long_name": "sample inputs"})}
            coords["input"] = ("input", np.array(self.names, dtype=object), {"units": "1", "long_name": "input name"})
        attrs = {"lookup_kind": self.kind, "names": json.dumps(self.names), "method": self.method,
                 "kernel": self.kernel, "smoothing": self.smoothing,
                 "degree": "" if self.degree is None else int(self.degree), "output": self.output,
                 "units": self.units, "long_name": self.long_name, "extra_dims": json.dumps(self.extra_dims),
                 "holdout": json.dumps(self.holdout), "holdout_folds": self.holdout_folds, "seed": self.seed,
                 "extrapolate": int(self.extrapolate), "lo": self.lo, "hi": self.hi}
        return xr.Dataset(data, coords=coords, attrs=attrs)

    def save(self, path) -> Path:
        """Write the lookup to a netCDF file (atomic)."""

        return write_netcdf(self.to_dataset(), path)

    @classmethod
    def load(cls, path) -> "Lookup":
        """Read a lookup written by :meth:`save` (refits the interpolator; the hold-out is read back)."""

        ds = read_netcdf(path)
        a = ds.attrs
        if "lookup_kind" not in a:
            raise InputError(f"{path}: not a homtex Lookup file (no 'lookup_kind' attribute)")
        names = json.loads(a["names"])
        extra = tuple(json.loads(a["extra_dims"]))
        kw = dict(method=a["method"], kernel=a["kernel"], smoothing=float(a["smoothing"]),
                  degree=None if a["degree"] == "" else int(a["degree"]), output=a["output"], units=a["units"],
                  long_name=a["long_name"], extra_dims=extra,
                  extra_coords={d: ds[d].values for d in extra if d in ds.coords},
                  holdout_folds=int(a["holdout_folds"]), seed=int(a["seed"]), extrapolate=bool(a["extrapolate"]),
                  compute_holdout=False)
        if a["lookup_kind"] == "grid":
            lk = cls("grid", names, axes=[ds[n].values for n in names], values=ds["values"].values, **kw)
        else:
            lk = cls("samples", names, points=ds["points"].values, values=ds["values"].values,
                     bounds=np.column_stack([np.atleast_1d(a["lo"]), np.atleast_1d(a["hi"])]), **kw)
        lk.holdout = json.loads(a["holdout"])
        return lk

    def __repr__(self) -> str:
        h = self.holdout.get("relative_rmse")
        hs = f", holdout relative rmse {h:.3g}" if h is not None else ""
        return f"Lookup({self.output!r} over {self.names}, {self.kind}{hs})"
