"""Parameter studies: ``studies/*.toml`` -> points run in parallel -> one xarray Dataset.

A study file (TOML data, nothing executed)::

    [study]
    name = "square_stiffness"
    cell = "../cells/square.toml"      # relative to the study file (optional for cell-free tasks)
    task = "homogenize"                # compress | seam | homogenize | macro | analytic | "module:function"
    description = "..."                # optional

    [options]                          # fixed keyword options of the task
    solver = "direct"

    [parameters]                       # a grid: every combination (C order, first name slowest)
    "yarns.strut.E" = [1000.0, 2000.0, 3000.0]
    "yarns.strut.radius" = [0.04, 0.05]

    # or, instead of [parameters], samples:
    [sampling]
    method = "lhs"                     # "lhs" (Latin hypercube) or "sobol" (scrambled), scipy.stats.qmc
    n = 16
    seed = 1
    [sampling.bounds]
    "yarns.strut.radius" = [0.03, 0.06]

    [units]                            # optional: units of the parameters (else guessed from the key)
    "yarns.strut.E" = "MPa"

Parameter names that start with a cell table (``cell``, ``parameters``, ``yarns``,
``resolution``) change the cell through :meth:`homtex.Cell.replace` (dotted keys); all other
names are keyword options of the task. String options whose name ends in ``_file`` are
paths relative to the study file.

Execution: every point is an independent job ``_run_point(job)`` that writes
``out_dir/points/NNNNN.nc`` atomically (temp file + ``os.replace``), so a killed study
resumes where it stopped: finished point files are skipped. A point whose task raises is
recorded (``status`` = 1, ``error`` = message, its values masked) and the others complete.
Executors: in-process for ``workers=1``, a local process pool by default, dask.distributed
when ``scheduler`` is an address or a ``distributed.Client`` (same job function).

The combined Dataset is always assembled from the point files, so a resumed study gives a
Dataset identical to an uninterrupted one. Per-point wall times stay in the point files'
attributes (``seconds``), not in the combined Dataset.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import time
from concurrent.futures import BrokenExecutor
from functools import lru_cache
from importlib import import_module
from pathlib import Path
from typing import Callable

import numpy as np

from ..cells import TABLES, CellError, load_cell
from ..output.progress import Progress
from ..errors import InputError

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - python 3.10
    import tomli as tomllib  # type: ignore

__all__ = ["Study", "StudyError", "TASKS", "register_task", "get_task", "load_study", "run_study",
           "sample_points", "combine_points"]

STATUS_OK, STATUS_FAILED, STATUS_PENDING = 0, 1, -1


class StudyError(CellError):
    """A bad study file or option, naming the file, table and key (formatted like CellError)."""


# ------------------------------------------------------------------------------------ tasks
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
    import xarray as xr

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
def homogenize_task(cell, *, solver: str = "direct", tol: float = 1e-10, free=None):
    """Effective stiffness of a periodic cell (``homtex.homogenize``); timings dropped."""
    from ..analysis.periodic import homogenize

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
    from ..contact import compress

    return index_dim(compress(cell, **options), "strain", "step", "load step (1-based order of the curve)")


@register_task("seam")
def seam_task(cell, **options):
    """Seam cushion profile (``homtex.seam_profile``) over ``profile_point`` (x is a variable)."""
    from ..seams import seam_profile

    return index_dim(seam_profile(cell, **options), "x", "profile_point", "sample across one seam distance")


@register_task("macro")
def macro_task(cell, **options):
    """Macro cushion-layer curve (``homtex.macro_curve``) over ``step`` and ``column``.

    ``curve_file``: a netCDF compression curve (``stress`` kPa over ``strain``, as written by
    ``homtex compress``) or a saved strain Lookup, used instead of running ``compress``.
    """
    from ..output.io import read_netcdf
    from ..macro import macro_curve

    if "curve_file" in options:  # a saved compression curve (netCDF: stress over strain) or Lookup
        path = options.pop("curve_file")
        if "curve" in options:
            raise InputError("macro task: give 'curve_file' or 'curve', not both")
        data = read_netcdf(path)
        if "lookup_kind" in data.attrs:
            from ..lookup import Lookup

            options["curve"] = Lookup.load(path)
        else:
            options["curve"] = data
    ds = index_dim(macro_curve(cell, **options), "plate_displacement", "step", "plate position index")
    return index_dim(ds, "column_x", "column", "cushion column index")


# ------------------------------------------------------------------------------------ study file
_UNIT_GUESS = {"E": "MPa", "G": "MPa", "nu": "1", "radius": "mm", "contact_radius": "mm", "a": "mm",
               "thickness": "mm", "seam_distance": "mm", "height_scatter": "mm", "strain": "1",
               "stitch_length": "mm", "prestrain": "1", "eps0": "1", "tol": "1"}


class Study:
    """A parsed study: points (list of {name: value}), layout (grid or samples), task, cell."""

    def __init__(self, data: dict, path=None):
        self.path = None if path is None else str(Path(path))
        f = self.path
        try:
            for key in data:
                if key not in ("study", "options", "parameters", "sampling", "units"):
                    raise StudyError("unknown table; a study has [study], [options], [parameters] or "
                                     "[sampling], [units]", table=key)
            st = data.get("study")
            if not isinstance(st, dict):
                raise StudyError("missing table [study]", table="study")
            for key in st:
                if key not in ("name", "cell", "task", "description"):
                    raise StudyError("unknown key; allowed: name, cell, task, description", table="study", key=key)
            self.name = _str(st, "name", "study")
            self.task = _str(st, "task", "study")
            self.description = st.get("description", "")
            self.cell_path = None
            if "cell" in st:
                cp = Path(_str(st, "cell", "study"))
                if not cp.is_absolute():
                    cp = (Path(path).parent if path is not None else Path.cwd()) / cp
                if not cp.exists():
                    raise StudyError(f"cell file {str(cp)!r} does not exist", table="study", key="cell")
                self.cell_path = str(cp.resolve())
            get_task(self.task)
            self.options = dict(data.get("options", {}))
            for k, v in self.options.items():  # file options are relative to the study file
                if k.endswith("_file") and isinstance(v, str) and not Path(v).is_absolute():
                    self.options[k] = str(((Path(path).parent if path is not None else Path.cwd()) / v).resolve())
            self.units = {str(k): str(v) for k, v in data.get("units", {}).items()}
            grid = data.get("parameters")
            sampling = data.get("sampling")
            if grid is not None and sampling is not None:
                raise StudyError("give either [parameters] (a grid) or [sampling], not both", table="sampling")
            if grid is None and sampling is None:
                raise StudyError("missing [parameters] (grid lists) or [sampling]", table="parameters")
            if grid is not None:
                self.layout = "grid"
                self.names = list(grid)
                if not self.names:
                    raise StudyError("no parameters", table="parameters")
                self.grid = {}
                for k, v in grid.items():
                    if not isinstance(v, list) or not v:
                        raise StudyError(f"must be a non-empty list of values, got {v!r}", table="parameters", key=k)
                    if len(set(map(repr, v))) != len(v):
                        raise StudyError(f"values must be distinct, got {v!r}", table="parameters", key=k)
                    self.grid[k] = list(v)
                shape = [len(v) for v in self.grid.values()]
                idx = np.indices(shape).reshape(len(shape), -1).T
                self.points = [{k: self.grid[k][i] for k, i in zip(self.names, row)} for row in idx]
                self.sampling = {}
            else:
                self.layout = "samples"
                self.sampling = dict(sampling)
                self.names, values = sample_points(self.sampling)
                self.grid = {}
                self.points = [{k: float(values[i, j]) for j, k in enumerate(self.names)}
                               for i in range(len(values))]
            for k in self.names:
                if k in self.options:
                    raise StudyError(f"parameter {k!r} is also a fixed option", table="options", key=k)
                if _is_cell_key(k) and self.cell_path is None:
                    raise StudyError(f"parameter {k!r} changes the cell but the study names no cell",
                                     table="study", key="cell")
        except StudyError as err:
            err.file = err.file or f
            raise

    @property
    def n_points(self) -> int:
        return len(self.points)

    def job(self, i: int, out_dir: Path) -> dict:
        """The picklable job of point i."""
        p = self.points[i]
        cell_values = {k: v for k, v in p.items() if _is_cell_key(k)}
        task_values = {k: v for k, v in p.items() if not _is_cell_key(k)}
        job = {"index": i, "task": self.task, "cell": self.cell_path, "cell_values": cell_values,
               "options": {**self.options, **task_values},
               "file": str(Path(out_dir) / "points" / f"{i:05d}.nc")}
        job["key"] = _hash({k: job[k] for k in ("task", "cell", "cell_values", "options")})
        return job

    def unit(self, name: str) -> str:
        return self.units.get(name, _UNIT_GUESS.get(name.split(".")[-1], "1"))


def _str(d, key, table):
    v = d.get(key)
    if not isinstance(v, str) or not v.strip():
        raise StudyError(f"must be a non-empty string, got {v!r}", table=table, key=key)
    return v


def _is_cell_key(name: str) -> bool:
    return "." in name and name.split(".", 1)[0] in TABLES


def _hash(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


def sample_points(sampling: dict) -> tuple[list, np.ndarray]:
    """Seeded Latin-hypercube or scrambled-Sobol samples from a ``[sampling]`` table.

    Returns (names, values (n, d)) scaled into ``bounds`` {name: [lo, hi]}.
    """
    from scipy.stats import qmc

    for key in sampling:
        if key not in ("method", "n", "seed", "bounds"):
            raise StudyError("unknown key; allowed: method, n, seed, bounds", table="sampling", key=key)
    method = sampling.get("method", "lhs")
    if method not in ("lhs", "sobol"):
        raise StudyError(f"must be 'lhs' or 'sobol', got {method!r}", table="sampling", key="method")
    n = sampling.get("n")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise StudyError(f"must be a positive integer, got {n!r}", table="sampling", key="n")
    seed = sampling.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise StudyError(f"must be an integer, got {seed!r}", table="sampling", key="seed")
    bounds = sampling.get("bounds")
    if not isinstance(bounds, dict) or not bounds:
        raise StudyError("missing table of {name = [lo, hi]}", table="sampling.bounds")
    names = list(bounds)
    lo, hi = [], []
    for k, b in bounds.items():
        if (not isinstance(b, list) or len(b) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in b)
                or not b[0] < b[1]):
            raise StudyError(f"must be [lo, hi] with lo < hi, got {b!r}", table="sampling.bounds", key=k)
        lo.append(float(b[0]))
        hi.append(float(b[1]))
    d = len(names)
    rng = np.random.default_rng(seed)
    if method == "lhs":
        eng = qmc.LatinHypercube(d, rng=rng)
        u = eng.random(n)
    else:
        eng = qmc.Sobol(d, scramble=True, rng=rng)
        m = int(round(math.log2(n)))
        if 2 ** m == n:
            u = eng.random_base2(m)
        else:
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # balance warning for n not a power of 2
                u = eng.random(n)
    return names, qmc.scale(u, lo, hi)


def load_study(path) -> Study:
    """Read and validate a study file (StudyError names file, table and key)."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise StudyError("no such file", file=path) from None
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"not valid TOML: {exc}", file=path) from None
    return Study(data, p)


# ------------------------------------------------------------------------------------ one point
@lru_cache(maxsize=4)
def _base_cell(path: str):
    return load_cell(path)


def _point_cell(path, values):
    if path is None:
        return None
    cell = _base_cell(path)
    return cell.replace(**values) if values else cell


def _limit_threads(n: int) -> None:
    try:
        import numba

        numba.set_num_threads(max(1, min(n, numba.config.NUMBA_NUM_THREADS)))
    except Exception:  # noqa: BLE001 - best effort
        pass
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(n)
    except Exception:  # noqa: BLE001
        pass


def _run_point(job: dict) -> dict:
    """Run one study point and write its file atomically; returns {index, status, error, seconds}."""
    import xarray as xr

    from .. import __version__
    from ..output.io import write_netcdf

    if job.get("threads"):  # one point per process: no nested BLAS/numba thread pools
        _limit_threads(int(job["threads"]))
    t0 = time.perf_counter()
    status, error, check = STATUS_OK, "", ""
    try:
        cell = _point_cell(job["cell"], job["cell_values"])
        ds = get_task(job["task"])(cell, **job["options"])
        if not isinstance(ds, xr.Dataset):
            raise InputError(f"task {job['task']!r} returned {type(ds).__name__}, not an xarray Dataset")
        check = str(ds.attrs.get("check", ""))   # a warning the result carries (e.g. a force drop)
        ds = ds.copy()
        ds.attrs = {}
    except Exception as exc:  # noqa: BLE001 - a failed point is recorded, not raised
        status, error = STATUS_FAILED, f"{type(exc).__name__}: {exc}"
        ds = xr.Dataset()
    seconds = time.perf_counter() - t0
    ds["status"] = ((), np.int8(status), {"units": "1", "long_name": "point status (0 ok, 1 failed)"})
    ds["error"] = ((), error, {"units": "1", "long_name": "error message of a failed point"})
    ds["check"] = ((), check, {"units": "1", "long_name": "warning of the point's result"})
    ds.attrs = {"point_key": job["key"], "index": job["index"], "seconds": seconds,
                "homtex_version": __version__}
    write_netcdf(ds, job["file"])
    return {"index": job["index"], "status": status, "error": error, "seconds": seconds}


def _read_point(path: Path, key: str):
    """The point Dataset if its file exists and belongs to this study point, else None."""
    from ..output.io import read_netcdf

    if not path.exists():
        return None
    try:
        ds = read_netcdf(path)
    except Exception:  # noqa: BLE001 - an unreadable file counts as not done
        return None
    if ds.attrs.get("point_key") != key:
        raise StudyError(f"{path} belongs to a different study or point (key {ds.attrs.get('point_key')!r}, "
                         f"expected {key!r}); use a fresh output folder", file=path)
    return ds


# ------------------------------------------------------------------------------------ executors
class _Serial:
    def __init__(self):
        self.n_workers = 1

    def run(self, fn, jobs):
        for j in jobs:
            yield fn(j)

    def close(self):
        pass


class _Pool:
    def __init__(self, workers):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        self.n_workers = workers
        # fresh interpreters: a fork of a process whose numba / BLAS thread pools already ran
        # (any homtex computation before run_study) kills its workers on their first kernel
        self.ex = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))

    def run(self, fn, jobs):
        from concurrent.futures import as_completed

        futs = [self.ex.submit(fn, j) for j in jobs]
        try:
            for f in as_completed(futs):
                yield f.result()
        finally:
            for f in futs:
                f.cancel()

    def close(self):
        self.ex.shutdown(wait=True, cancel_futures=True)


class _Dask:
    def __init__(self, scheduler):
        try:
            from distributed import Client
        except ImportError as exc:
            raise InputError("scheduler given but dask.distributed is not installed "
                             "(pip install 'dask[distributed]')") from exc
        if isinstance(scheduler, Client):
            self.client, self.own = scheduler, False
        else:
            self.client, self.own = Client(scheduler), True
        self.n_workers = max(1, len(self.client.scheduler_info().get("workers", {})))

    def run(self, fn, jobs):
        from distributed import as_completed

        futs = [self.client.submit(fn, j, pure=False, key=f"homtex-point-{j['key']}-{j['index']}") for j in jobs]
        try:
            for f in as_completed(futs):
                yield f.result()
        finally:
            for f in futs:
                f.cancel()

    def close(self):
        if self.own:
            self.client.close()


def _executor(scheduler, workers, n_todo):
    if scheduler is not None:
        return _Dask(scheduler)
    if workers is None:
        workers = min(os.cpu_count() or 1, max(n_todo, 1))
    if int(workers) < 1:
        raise InputError(f"workers must be >= 1, got {workers!r}")
    return _Serial() if int(workers) == 1 else _Pool(int(workers))


class _Progress(Progress):
    """The study's progress: points done, failures noted."""

    def __init__(self, total, done, name, enabled):
        super().__init__(total, f"study {name}", done=done, unit="points", enabled=enabled)

    def step(self, failed: bool):
        super().step("a point failed" if failed else "")


# ------------------------------------------------------------------------------------ combine
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
    import xarray as xr

    from .. import __version__

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
        for k, v in _base_cell(study.cell_path).attrs().items():
            attrs[k if k.startswith("cell.") else f"cell.{k}"] = v
    out.attrs = attrs
    return out


# ------------------------------------------------------------------------------------ runner
def run_study(path, out_dir, *, scheduler=None, workers: int | None = None, progress: bool = True,
              max_points: int | None = None, retry_failed: bool = False):
    """Run (or resume) a study and return its Dataset; writes ``out_dir/result.nc``.

    Parameters
    ----------
    path : study TOML file (see the module docstring).
    out_dir : output folder; ``points/NNNNN.nc`` hold finished points (resume state).
    scheduler : None (local), a dask.distributed scheduler address ("tcp://host:8786") or a
        ``distributed.Client`` (e.g. on a ``LocalCluster``).
    workers : local processes (default: CPU count, capped by the points left); 1 runs in-process.
    progress : show a progress bar (rich) or plain progress lines.
    max_points : stop after this many new points (a budget; the Dataset is then partial with
        ``status`` = -1 for points not run and ``attrs["complete"]`` = 0, and result.nc is
        not written).
    retry_failed : run failed points again instead of keeping their recorded error.

    Returns
    -------
    xarray.Dataset: the task's variables over the grid parameters (dimensions) or over
    ``sample``; ``status`` and ``error`` per point; cell definition, study and version in attrs.
    """
    from ..output.io import write_netcdf

    study = load_study(path)
    out = Path(out_dir)
    (out / "points").mkdir(parents=True, exist_ok=True)
    for tmp in (out / "points").glob(".*.tmp"):  # leftovers of a killed write
        try:
            tmp.unlink()
        except OSError:
            pass
    jobs = [study.job(i, out) for i in range(study.n_points)]
    points = [_read_point(Path(j["file"]), j["key"]) for j in jobs]
    todo = [j for j, p in zip(jobs, points)
            if p is None or (retry_failed and int(p["status"]) == STATUS_FAILED)]
    if max_points is not None:
        todo = todo[:max(int(max_points), 0)]
    bar = _Progress(study.n_points, study.n_points - len([p for p in points if p is None]) if not retry_failed
                    else study.n_points - len(todo), study.name, progress)
    if todo:
        ex = _executor(scheduler, workers, len(todo))
        if isinstance(ex, _Pool):  # share the cores between the worker processes
            per = max(1, (os.cpu_count() or 1) // ex.n_workers)
            todo = [{**j, "threads": per} for j in todo]
        try:
            for res in ex.run(_run_point, todo):
                bar.step(res["status"] != STATUS_OK)
        except BrokenExecutor as exc:
            # a worker died without a Python error (killed for memory, a crash in native code):
            # which point it ran is unknown, so nothing is recorded as failed; finished points stay
            done = sum(_read_point(Path(j["file"]), j["key"]) is not None for j in jobs)
            raise StudyError(f"a worker process died ({exc}); {done} of {study.n_points} points are "
                             f"finished and kept in {out / 'points'}; run the study again to resume "
                             "(fewer workers if memory ran out)", file=path) from exc
        finally:
            ex.close()
            bar.close()
    else:
        bar.close()
    points = [_read_point(Path(j["file"]), j["key"]) for j in jobs]
    ds = combine_points(study, points)
    if ds.attrs["complete"]:
        write_netcdf(ds, out / "result.nc")
    return ds
