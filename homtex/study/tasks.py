"""Study tasks: what a study point runs, ``task(cell, **options) -> xarray.Dataset``.

Built-in tasks are registered here under their names (``compress``, ``seam``, ``homogenize``,
``macro``, ``analytic``).
"""

from __future__ import annotations

import math
import time
from importlib import import_module
from typing import Callable

import numpy as np
import xarray as xr

from ..analysis.homogenize import homogenize
from ..api import compress
from ..errors import InputError, StudyError
from ..lookup import Lookup
from ..macro import macro_curve
from ..output.io import read_netcdf
from ..seams import seam_profile

__all__ = ["TASKS", "analytic_task", "compress_task", "get_task", "homogenize_task", "index_dim", "macro_task",
           "register_task", "seam_task"]

#: task name -> callable(cell, **options) -> xarray.Dataset
TASKS: dict[str, Callable] = {}


def register_task(name: str):
    """Decorator: register ``fn(cell, **options) -> xr.Dataset`` under ``name``.

    Worker processes (the local pool and dask) start as fresh interpreters and do not see
    tasks registered in ``__main__``: register the task in an importable module or name it
    ``"module:function"``; scripts that call :func:`run_study` need the usual
    ``if __name__ == "__main__":`` guard.
    """
    def deco(fn):
        TASKS[name] = fn
        return fn
    return deco


def get_task(name: str) -> Callable:
    """The task callable for a registered name or a ``"module:function"`` path."""
    if name in TASKS:
        return TASKS[name]
    if ":" in name:
        mod, _, fn = name.partition(":")
        try:
            return getattr(import_module(mod), fn)
        except (ImportError, AttributeError) as exc:
            raise StudyError(f"task {name!r} cannot be imported: {exc}", table="study", key="task") from exc
    raise StudyError(f"unknown task {name!r}; choose from {sorted(TASKS)} or give 'module:function'",
                     table="study", key="task")


@register_task("analytic")
def analytic_task(cell=None, *, x: float = 0.0, y: float = 0.0, z: float = 0.0, fail_above=None,
                  sleep: float = 0.0):
    """Cheap closed-form task (tests, examples): value = sin(x) + y^2 + x z; curve(t) = x t + y.

    ``fail_above``: raise InputError when x > fail_above (a failing point). ``sleep``: seconds
    to wait first (to make a point take time). With a cell, ``cell_a`` echoes parameters.a.
    """
    if sleep:
        time.sleep(float(sleep))
    if fail_above is not None and x > fail_above:
        raise InputError(f"analytic task: x = {x:g} exceeds fail_above = {fail_above:g}")
    t = np.linspace(0.0, 1.0, 5)
    ds = xr.Dataset(
        {"value": ((), math.sin(x) + y * y + x * z, {"units": "1", "long_name": "sin(x) + y^2 + x z"}),
         "curve": (("t",), x * t + y, {"units": "1", "long_name": "x t + y"}),
         "n_calls": ((), np.int64(1), {"units": "1", "long_name": "task evaluations"})},
        coords={"t": ("t", t, {"units": "1", "long_name": "curve parameter"})})
    if cell is not None:
        ds["cell_a"] = ((), float(cell.parameters.get("a", np.nan)),
                        {"units": "mm", "long_name": "cell parameter a"})
    return ds


@register_task("homogenize")
def homogenize_task(cell, *, solver: str = "direct", tol: float | None = None, free=None):
    """Effective stiffness of a periodic cell (``homtex.homogenize``); timings dropped."""
    ds = homogenize(cell.frame, solver=solver, tol=tol, free=free).to_dataset()
    return ds.drop_vars([v for v in ds.data_vars if "seconds" in str(v)])


def index_dim(ds, dim: str, new: str, long_name: str):
    """Replace the index coordinate ``dim`` (values that differ between study points, e.g. the
    profile's x over one seam distance) by an integer index ``new``; the old values become a
    data variable ``dim`` along ``new``. Points then combine without an outer join over
    slightly different float coordinates."""
    if dim not in ds.dims:
        return ds
    vals = ds[dim]
    out = ds.drop_vars(dim).rename_dims({dim: new})
    out[dim] = ((new,), vals.values, dict(vals.attrs))
    for c in list(out.coords):  # non-index coordinates along the old dim become data too
        if new in out[c].dims:
            out = out.reset_coords(c)
    return out.assign_coords({new: (new, np.arange(vals.size), {"units": "1", "long_name": long_name})})


@register_task("compress")
def compress_task(cell, **options):
    """Compression curve (``homtex.compress``) over ``step`` (strain is a variable)."""
    return index_dim(compress(cell, **options), "strain", "step", "load step (1-based order of the curve)")


@register_task("seam")
def seam_task(cell, **options):
    """Seam cushion profile (``homtex.seam_profile``) over ``profile_point`` (x is a variable)."""
    return index_dim(seam_profile(cell, **options), "x", "profile_point", "sample across one seam distance")


@register_task("macro")
def macro_task(cell, **options):
    """Macro cushion-layer curve (``homtex.macro_curve``) over ``step`` and ``column``.

    ``curve_file``: a netCDF compression curve (``stress`` kPa over ``strain``, as written by
    ``homtex compress``) or a saved strain Lookup, used instead of running ``compress``.
    """
    if "curve_file" in options:  # a saved compression curve (netCDF: stress over strain) or Lookup
        path = options.pop("curve_file")
        if "curve" in options:
            raise InputError("macro task: give 'curve_file' or 'curve', not both")
        data = read_netcdf(path)
        if "lookup_kind" in data.attrs:
            options["curve"] = Lookup.load(path)
        else:
            options["curve"] = data
    ds = index_dim(macro_curve(cell, **options), "plate_displacement", "step", "plate position index")
    return index_dim(ds, "column_x", "column", "cushion column index")
