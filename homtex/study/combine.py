"""One Dataset from the per-point Datasets of a study (grids become dimensions, samples a
``sample`` dimension), with the status of every point."""

from __future__ import annotations

import json

import numpy as np
import xarray as xr

from .._version import __version__
from ..model.results import Status
from .files import Study, base_cell

__all__ = ["combine_points"]

STATUS_OK, STATUS_FAILED, STATUS_PENDING = Status.OK.code, Status.FAILED.code, Status.NOT_RUN.code


def _fill_like(ds):
    """A copy of a point Dataset with every value masked (NaN for numbers, '' for strings)."""
    out = ds.copy(deep=True)
    for name in out.data_vars:
        v = out[name]
        if v.dtype.kind in "iufb":
            out[name] = v.astype(float).fillna(np.nan) * np.nan
            out[name].attrs = dict(v.attrs)
        else:
            out[name] = v.copy(data=np.full(v.shape, "", dtype=object))
    return out


def combine_points(study: Study, points: list):
    """One Dataset from the per-point Datasets (None: not run yet) of ``study``.

    Grids: the parameters become dimensions (C order); samples: a ``sample`` dimension with
    the parameters as coordinates. ``status`` (0 ok, 1 failed, -1 not run), ``error`` and
    ``check`` (a warning the point's result carried, e.g. a force drop);
    values of failed/missing points are masked (NaN, '' for strings).
    """
    status = np.array([STATUS_PENDING if p is None else int(p["status"]) for p in points], dtype=np.int8)
    errors = np.array(["not run" if p is None else str(p["error"].values) for p in points], dtype=object)
    checks = np.array(["" if p is None or "check" not in p else str(p["check"].values) for p in points],
                      dtype=object)
    meta = ["status", "error", "check"]
    ok = [p.drop_vars(meta, errors="ignore") for p, s in zip(points, status) if s == STATUS_OK]
    if ok:
        tmpl = _fill_like(ok[0])
        parts = [p.drop_vars(meta, errors="ignore") if s == STATUS_OK else tmpl
                 for p, s in zip(points, status)]
        ds = xr.concat(parts, dim="sample", data_vars="all", coords="minimal", compat="override",
                       join="outer", combine_attrs="drop", fill_value=np.nan)
        # combine_attrs="drop" empties the variables' attrs too: the units and long names of
        # the task's variables and coordinates come back from the first finished point
        for name in [*ds.data_vars, *ds.coords]:
            if name in ok[0].variables:
                ds[name].attrs = dict(ok[0][name].attrs)
    else:
        ds = xr.Dataset()
    ds = ds.assign(status=("sample", status), error=("sample", errors), check=("sample", checks))
    ds["status"].attrs = {"units": "1", "long_name": "point status (0 ok, 1 failed, -1 not run)"}
    ds["error"].attrs = {"units": "1", "long_name": "error message of a failed point ('' if ok)"}
    ds["check"].attrs = {"units": "1", "long_name": "warning the point's result carries, e.g. a force drop "
                         "('' if none)"}
    for name in ds.data_vars:
        if name not in meta and ds[name].dtype.kind == "f":
            ds[name].attrs["masked_where"] = "status != 0"
    if study.layout == "grid":
        shape = [len(study.grid[k]) for k in study.names]
        new = {}
        for name in ds.data_vars:
            v = ds[name].transpose("sample", ...)
            rest = v.dims[1:]
            new[name] = (tuple(study.names) + rest, v.values.reshape(*shape, *v.shape[1:]), v.attrs)
        coords = {k: c for k, c in ds.coords.items() if "sample" not in c.dims}
        out = xr.Dataset(new, coords=coords)
        for k in study.names:
            out.coords[k] = (k, np.asarray(study.grid[k]),
                             {"units": study.unit(k), "long_name": f"study parameter {k}"})
    else:
        out = ds
        out.coords["sample"] = ("sample", np.arange(study.n_points),
                                {"units": "1", "long_name": "sample index"})
        for k in study.names:
            out.coords[k] = ("sample", np.array([p[k] for p in study.points]),
                             {"units": study.unit(k), "long_name": f"study parameter {k} (sampled)"})
    for name in [*out.data_vars, *out.coords]:  # labels without metadata (e.g. Voigt rows)
        out[name].attrs.setdefault("units", "1")
        out[name].attrs.setdefault("long_name", str(name))
    attrs = {"homtex_version": __version__, "study_name": study.name, "study_task": study.task,
             "study_file": study.path or "", "study_layout": study.layout,
             "study_description": study.description, "study_parameters": json.dumps(study.names),
             "study_options": json.dumps(study.options, sort_keys=True, default=str),
             "points_total": study.n_points, "points_ok": int((status == STATUS_OK).sum()),
             "points_failed": int((status == STATUS_FAILED).sum()),
             "points_not_run": int((status == STATUS_PENDING).sum()),
             "complete": int((status != STATUS_PENDING).all())}
    if study.sampling:
        attrs.update({f"sampling_{k}": (json.dumps(v) if isinstance(v, dict) else v)
                      for k, v in study.sampling.items()})
    if study.cell_path is not None:
        for k, v in base_cell(study.cell_path).attrs().items():
            attrs[k if k.startswith("cell.") else f"cell.{k}"] = v
    out.attrs = attrs
    return out
