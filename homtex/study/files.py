"""Study files (TOML data, nothing executed): parameters as grids or seeded samples.

A study file::

    [study]
    name = "square_stiffness"
    cell = "../cells/square.toml"      # relative to the study file (optional for cell-free tasks)
    task = "homogenize"                # compress | seam | homogenize | macro | analytic | a declared task
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

    [units]                            # optional: units of the parameters (else guessed from
                                       # the key: PARAMETER_UNITS, e.g. radius mm, E MPa)
    "yarns.strut.E" = "MPa"

Parameter names that start with a cell table (``cell``, ``parameters``, ``yarns``,
``resolution``) change the cell through :meth:`homtex.Cell.replace` (dotted keys); all other
names are keyword options of the task. String options whose name ends in ``_file`` are
input files, relative to the study file; a missing one is a StudyError when the study is
loaded (not a failure of every point). A study has at most :data:`MAX_POINTS` (1 000 000) points,
checked before any is made. The task is a registered name
(:mod:`homtex.study.tasks`), never an import path: a study file is data.
"""

from __future__ import annotations

import hashlib
import json
import math
import warnings
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.stats import qmc

from ..cells import TABLES, load_cell
from ..errors import StudyError
from ..validate import read_data_file
from .tasks import get_task

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - python 3.10
    import tomli as tomllib  # type: ignore

__all__ = ["MAX_POINTS", "PARAMETER_UNITS", "Study", "base_cell", "guess_unit", "load_study", "sample_points"]

#: most points a study may have (a grid's product of list lengths, or ``[sampling] n``): checked
#: before any point is made, so a typo such as n = 1e9 or a 200^4 grid is refused at once instead
#: of exhausting the memory (a million points are already days of compress runs)
MAX_POINTS = 1_000_000


@lru_cache(maxsize=4)
def base_cell(path: str):
    """The cell file of a study, loaded once per process."""
    return load_cell(path)


#: Units of study parameters guessed from the last part of their name (after the last dot) when
#: the study file's [units] table does not give them; the first matching rule wins. ``names``:
#: whole names; ``words``: words of a snake_case name ("seam_distance" has "distance").
#: Options the study does not vary keep their own units in the task's Dataset.
PARAMETER_UNITS = (
    {"unit": "MPa", "names": ("E", "G"), "words": ("modulus",)},
    {"unit": "1", "names": ("nu", "eps0", "tol", "seed", "steps", "n"), "words": ("strain", "prestrain", "ratio",
                                                                                   "fraction", "count")},
    {"unit": "N", "names": (), "words": ("force",)},
    {"unit": "kPa", "names": (), "words": ("stress", "pressure")},
    {"unit": "mm", "names": ("a", "b", "h", "d"),
     "words": ("radius", "semi_axes", "thickness", "gap", "distance", "length", "height", "scatter", "travel",
               "diameter", "width", "spacing", "pitch", "displacement", "offset")},
)


def guess_unit(name: str) -> str:
    """The unit of a study parameter from its name (:data:`PARAMETER_UNITS`); "1" if none fits."""
    last = str(name).split(".")[-1]
    padded = f"_{last.lower()}_"
    for rule in PARAMETER_UNITS:
        if last in rule["names"] or any(f"_{w}_" in padded for w in rule["words"]):
            return rule["unit"]
    return "1"


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
            for table in ("options", "parameters", "sampling"):
                if table in data and not isinstance(data[table], dict):
                    raise StudyError(f"must be a table, got {data[table]!r}", table=table)
            self.options = dict(data.get("options", {}))
            for k, v in self.options.items():  # file options: inputs relative to the study file
                if k.endswith("_file") and isinstance(v, str):
                    fp = Path(v) if Path(v).is_absolute() else (Path(path).parent if path is not None
                                                                else Path.cwd()) / v
                    if not fp.is_file():  # checked here: not once per point, as a failure of every point
                        raise StudyError(f"input file {str(fp)!r} does not exist" if not fp.exists() else
                                         f"input {str(fp)!r} is not a file", table="options", key=k)
                    self.options[k] = str(fp.resolve())
            units = data.get("units", {})
            if not isinstance(units, dict):
                raise StudyError(f"must be a table of {{parameter = \"unit\"}}, got {units!r}", table="units")
            for k, v in units.items():
                if not isinstance(v, str) or not v.strip():
                    raise StudyError(f"must be a unit string such as \"mm\", got {v!r}", table="units", key=k)
            self.units = {str(k): v for k, v in units.items()}
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
                total = math.prod(shape)
                if total > MAX_POINTS:
                    raise StudyError(f"the grid has {' x '.join(map(str, shape))} = {total:.3g} points, more than "
                                     f"the {MAX_POINTS:,} a study may have; use fewer values, or [sampling] (a Latin "
                                     "hypercube or Sobol sample covers many parameters with few points)",
                                     table="parameters", key=self.names[int(np.argmax(shape))])
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
            for k in self.units:
                if k not in self.names:
                    raise StudyError(f"not a parameter of the study (parameters: {self.names})", table="units", key=k)
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
        """Unit of parameter ``name``: the study file's [units] table, else :func:`guess_unit`."""
        if name in self.units:
            return self.units[name]
        if any(isinstance(v, str) for v in self.grid.get(name, ())):
            return "1"   # labels (e.g. method = ["yarn", "foundation"]) have no unit
        return guess_unit(name)


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
    for key in sampling:
        if key not in ("method", "n", "seed", "bounds"):
            raise StudyError("unknown key; allowed: method, n, seed, bounds", table="sampling", key=key)
    method = sampling.get("method", "lhs")
    if method not in ("lhs", "sobol"):
        raise StudyError(f"must be 'lhs' or 'sobol', got {method!r}", table="sampling", key="method")
    n = sampling.get("n")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise StudyError(f"must be a positive integer, got {n!r}", table="sampling", key="n")
    if n > MAX_POINTS:
        raise StudyError(f"must be at most {MAX_POINTS:,} points (a study's limit, checked before sampling), "
                         f"got {n:,}", table="sampling", key="n")
    seed = sampling.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise StudyError(f"must be an integer, got {seed!r}", table="sampling", key="seed")
    bounds = sampling.get("bounds")
    if not isinstance(bounds, dict) or not bounds:
        raise StudyError("missing table of {name = [lo, hi]}", table="sampling.bounds")
    names = list(bounds)
    lo, hi = [], []
    for k, b in bounds.items():
        if (not isinstance(b, list) or len(b) != 2
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in b)
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
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # balance warning for n not a power of 2
                u = eng.random(n)
    return names, qmc.scale(u, lo, hi)


def load_study(path) -> Study:
    """Read and validate a study file (StudyError names file, table and key)."""
    p = Path(path)
    if p.is_dir():
        raise StudyError("is a folder, not a study file; give the study's .toml file", file=path)
    try:
        data = tomllib.loads(read_data_file(p, error=StudyError, what="a TOML study file"))
    except FileNotFoundError:
        raise StudyError("no such file", file=path) from None
    except tomllib.TOMLDecodeError as exc:
        raise StudyError(f"not valid TOML: {exc}", file=path) from None
    except RecursionError:
        raise StudyError("not a study file: arrays or tables nested too deeply to read", file=path) from None
    return Study(data, p)
