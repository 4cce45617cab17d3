"""Study tasks: what a study point runs, ``task(cell, **options) -> xarray.Dataset``.

A study file names its task by a registered name, never by an import path: study and cell
files are data, and a file received from someone else must not be able to call arbitrary
code (``task = "json:dumps"`` is an InputError). The names come from a registry:

- the built-in tasks ``compress``, ``seam``, ``homogenize``, ``macro`` and ``analytic``;
- tasks that an installed package declares in the entry point group ``homtex.tasks``
  (:data:`ENTRY_POINT_GROUP`), e.g. in its ``pyproject.toml``::

      [project.entry-points."homtex.tasks"]
      my_task = "my_package.tasks:my_task"

  Pool and dask workers are fresh interpreters; they find such a task through the package's
  metadata, like the parent process. Installing a package already runs its code, so naming
  one of its declared tasks adds nothing a study file could not do anyway.
- tasks registered in this process with :func:`register_task` (scripts, notebooks). Worker
  processes do not see them, so a study with such a task runs with ``workers=1`` only
  (:func:`homtex.run_study` says so otherwise).

A built-in name wins over an entry point of the same name.
"""

from __future__ import annotations

import math
import time
from importlib import metadata
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

__all__ = ["ENTRY_POINT_GROUP", "TASKS", "analytic_task", "compress_task", "get_task", "homogenize_task",
           "in_process_only", "index_dim", "macro_task", "register_task", "seam_task", "task_names"]

#: entry point group in which installed packages declare study tasks (name = "module:function")
ENTRY_POINT_GROUP = "homtex.tasks"

#: task name -> callable(cell, **options) -> xarray.Dataset: the built-ins and tasks registered
#: in this process (entry point tasks are looked up when named, see :func:`get_task`)
TASKS: dict[str, Callable] = {}

_BUILTIN: frozenset = frozenset()   # set at the end of the module


def register_task(name: str):
    """Decorator: register ``fn(cell, **options) -> xr.Dataset`` under ``name`` in this process.

    Only this process sees the task: worker processes (the local pool, dask) start as fresh
    interpreters, so a study with it must run with ``workers=1``. To run a task of your own on
    workers, declare it in the entry point group ``homtex.tasks`` of an installed package (see
    the module docstring). A built-in task cannot be replaced (InputError).
    """
    if not isinstance(name, str) or not name.strip() or ":" in name:
        raise InputError(f"a task name must be a non-empty string without ':', got {name!r}")
    if name in _BUILTIN:
        raise InputError(f"task {name!r} is a built-in task and cannot be replaced; choose another name")

    def deco(fn):
        TASKS[name] = fn
        return fn
    return deco


def _entry_points() -> dict:
    """{name: EntryPoint} of the ``homtex.tasks`` group (read from the installed metadata now)."""
    return {ep.name: ep for ep in metadata.entry_points(group=ENTRY_POINT_GROUP)}


def task_names() -> list:
    """The names a study file may give as its task (built-in, declared, registered here)."""
    return sorted({*TASKS, *_entry_points()})


def in_process_only(name: str) -> bool:
    """True for a task registered with :func:`register_task` that no entry point declares
    (worker processes cannot find it)."""
    return name in TASKS and name not in _BUILTIN and name not in _entry_points()


def _how_to_declare() -> str:
    return (f"a task of your own is declared by an installed package in the entry point group "
            f"{ENTRY_POINT_GROUP!r} ([project.entry-points.\"{ENTRY_POINT_GROUP}\"] my_task = "
            f"\"my_package.module:my_task\" in its pyproject.toml)")


def get_task(name: str) -> Callable:
    """The task callable registered under ``name`` (built-in, entry point or this process).

    Raises StudyError (an InputError) for any other name, including ``"module:function"``
    import paths: a study file is data and cannot name code to import.
    """
    if not isinstance(name, str):
        raise StudyError(f"must be a task name, got {name!r}", table="study", key="task")
    if name in TASKS:
        return TASKS[name]
    eps = _entry_points()   # read now: the import system caches the modules themselves
    if name in eps:
        ep = eps[name]
        try:
            fn = ep.load()
        except Exception as exc:  # noqa: BLE001 - any import failure of a declared task
            raise StudyError(f"task {name!r}, declared as {ep.value!r} in the entry point group "
                             f"{ENTRY_POINT_GROUP!r}, cannot be loaded: {type(exc).__name__}: {exc}",
                             table="study", key="task") from None
        if not callable(fn):
            raise StudyError(f"task {name!r}, declared as {ep.value!r} in the entry point group "
                             f"{ENTRY_POINT_GROUP!r}, is not callable", table="study", key="task")
        return fn
    names = sorted({*TASKS, *eps})
    if ":" in name or "." in name:
        raise StudyError(f"task {name!r} looks like an import path; a study file names a registered task, "
                         f"not code to import (study files are data). Registered tasks: {names}; "
                         f"{_how_to_declare()}", table="study", key="task")
    raise StudyError(f"unknown task {name!r}; registered tasks: {names}; {_how_to_declare()}",
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
    ds = ds.drop_vars([v for v in ds.data_vars if "seconds" in str(v)])
    for name, long_name in _VOIGT_LABELS.items():  # the Voigt labels are names, not numbers
        if name in ds.coords:
            ds[name].attrs.update({"units": "1", "long_name": long_name})
    return ds


_VOIGT_LABELS = {"row": "Voigt component (row of C)", "col": "Voigt component (column of C)",
                 "row_full": "Voigt component (row of C_full)", "col_full": "Voigt component (column of C_full)",
                 "case": "unit load case (Voigt component)"}


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
    """Compression curve (``homtex.compress``: the large-motion engine, unless the study's options
    name ``geometry = "linear"``) over ``step`` (strain is a variable)."""
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


_BUILTIN = frozenset(TASKS)
