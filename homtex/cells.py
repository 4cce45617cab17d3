"""Unit-cell files: ``cells/*.toml`` -> :class:`Cell` -> :class:`~homtex.Frame`.

A cell file is TOML data (read with tomllib / tomli); nothing in it is executed.
Schema::

    [cell]
    name = "..."
    generator = "honeycomb"        # key into cells.GENERATORS
    description = "..."            # optional
    [parameters]                   # generator-specific (may contain nested tables)
    ...
    [yarns.<name>]                 # one table per yarn type -> homtex.YarnType
    section = "circle"             # or "ellipse"
    radius = 0.1                   # circle (mm)  | semi_axes = [a, b] for an ellipse (mm)
    E = 3000.0                     # MPa
    nu = 0.3
    contact_radius = 0.1           # optional, mm
    bending_factor = 1.0           # optional: bending rigidity / the solid section's (default 1)
    torsion_factor = 1.0           # optional: torsional rigidity / the solid section's (default 1)
    strain_limit = 0.02            # optional: elastic limit of axial/shear strain (large-rotation solves warn beyond)
    source = "where the numbers come from"
    [resolution]
    elements_per_strut = 4         # generator-specific keys
    [contact]                      # optional: Coulomb friction of the large-motion engine
    friction = 0.2                 # every contact, yarn-yarn and yarn-plate (default 0)
    plate_friction = 0.3           # yarn-plate contacts (default: friction)
    [contact.pairs]                # particular pairs of yarn types (either order; "plate" = the plates)
    monofilament.multifilament = 0.25
    monofilament.plate = 0.35

A generator is a function ``build(parameters, yarns, resolution) -> Frame`` or
``-> (Frame, info)`` named in :data:`GENERATORS` as ``"module:function"`` (imported
on first use). ``info`` may carry ``"groups"`` ({name: (m,) bool element mask}) and
other data (e.g. ``"thickness"`` in mm). Builders report bad values with
:class:`CellError` (``table`` and ``key``); :func:`load_cell` adds the file.
"""

from __future__ import annotations

import copy
import hashlib
import json
from importlib import import_module
from pathlib import Path

import numpy as np

from .errors import CellError, InputError
from .model.frame import Frame
from .model.sections import DEFAULT_STRAIN_LIMIT, YarnType
from .validate import check_keys, get_list, get_number, get_str, get_table, read_data_file, type_name

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - python 3.10
    import tomli as tomllib  # type: ignore

__all__ = ["GENERATORS", "Cell", "CellError", "find_cell", "load_cell"]

#: generator name -> "module:function" (imported lazily)
GENERATORS: dict[str, str] = {
    "honeycomb": "homtex.geometry.lattices:build_honeycomb",
    "square": "homtex.geometry.lattices:build_square",
    "triangular": "homtex.geometry.lattices:build_triangular",
    "simple_cubic": "homtex.geometry.lattices:build_simple_cubic",
    "bcc": "homtex.geometry.lattices:build_bcc",
    "octet": "homtex.geometry.lattices:build_octet",
    "lattice": "homtex.geometry.lattices:build_lattice",
    "spacer": "homtex.geometry.spacer:build_cell",
    "weft_knit": "homtex.geometry.knit_cell:build_cell",
}

TABLES = ("cell", "parameters", "yarns", "resolution", "contact", "validity")
VALIDITY_KEYS = ("linear_strain_limit", "source", "mesh_convergence", "mesh_cell")
CONTACT_KEYS = ("friction", "plate_friction", "pairs")
#: largest friction coefficient a cell file may give
MAX_FRICTION = 10.0
CELL_KEYS = ("name", "generator", "description")
YARN_KEYS = ("section", "radius", "semi_axes", "E", "nu", "contact_radius", "source", "bending_factor",
             "torsion_factor", "strain_limit")


def _yarn(name: str, d: dict) -> YarnType:
    table = f"yarns.{name}"
    if not isinstance(d, dict):
        raise CellError(f"must be a table, got {type_name(d)} {d!r}", table=table)
    check_keys(d, YARN_KEYS, table)
    section = get_str(d, "section", table, choices=("circle", "ellipse"))
    if section == "circle":
        if "semi_axes" in d:
            raise CellError("a circle has 'radius', not 'semi_axes' (or set section = \"ellipse\")",
                            table=table, key="semi_axes")
        radius = get_number(d, "radius", table, gt=0)
        semi = None
    else:
        if "radius" in d:
            raise CellError("an ellipse has 'semi_axes' = [a, b], not 'radius' (or set section = \"circle\")",
                            table=table, key="radius")
        semi = get_list(d, "semi_axes", table, shape=(2,), gt=0)
        semi = (float(semi[0]), float(semi[1]))
        radius = max(semi)
    E = get_number(d, "E", table, gt=0)
    nu = get_number(d, "nu", table, gt=-1.0, lt=0.5)
    rc = get_number(d, "contact_radius", table, gt=0, required=False)
    source = get_str(d, "source", table)
    bf = get_number(d, "bending_factor", table, gt=0, default=1.0)
    tf = get_number(d, "torsion_factor", table, gt=0, default=1.0)
    sl = get_number(d, "strain_limit", table, gt=0, le=1.0, default=DEFAULT_STRAIN_LIMIT)
    return YarnType(name=name, radius=float(radius), E=E, nu=nu, contact_radius=rc,
                    semi_axes=semi, source=source, bending_factor=float(bf), torsion_factor=float(tf),
                    strain_limit=float(sl))


def _contact(d: dict, yarns: dict) -> dict:
    """The validated ``[contact]`` table: friction coefficients (see the module docstring)."""
    if not d:
        return {}
    check_keys(d, CONTACT_KEYS, "contact")
    out = {}
    for key in ("friction", "plate_friction"):
        v = get_number(d, key, "contact", ge=0.0, le=MAX_FRICTION, required=False)
        if v is not None:
            out[key] = v
    pairs = get_table(d, "pairs", "contact", required=False)
    seen: dict = {}
    for a, row in pairs.items():
        table = f"contact.pairs.{a}"
        if a not in yarns:
            raise CellError(f"unknown yarn type {a!r} (yarn types: {', '.join(yarns)}; 'plate' only as the second "
                            "name)", table="contact.pairs", key=a)
        row = get_table(pairs, a, "contact.pairs")
        for b in row:
            if b not in yarns and b != "plate":
                raise CellError(f"unknown yarn type {b!r} (yarn types: {', '.join(yarns)}, or 'plate')",
                                table=table, key=b)
            v = get_number(row, b, table, ge=0.0, le=MAX_FRICTION)
            key = tuple(sorted((a, b))) if b != "plate" else (a, b)
            if key in seen and seen[key] != v:
                raise CellError(f"the pair {a}/{b} is given twice with different coefficients ({seen[key]:g} and "
                                f"{v:g})", table=table, key=b)
            seen[key] = v
            out.setdefault("pairs", {}).setdefault(a, {})[b] = v
    return out


def _resolve(generator: str, file):
    if generator not in GENERATORS:
        raise CellError(f"unknown generator {generator!r}; choose from {sorted(GENERATORS)}",
                        file=file, table="cell", key="generator")
    target = GENERATORS[generator]
    mod, _, fn = target.partition(":")
    try:
        return getattr(import_module(mod), fn)
    except (ImportError, AttributeError) as exc:
        raise CellError(f"generator {generator!r} ({target}) is not available: {exc}",
                        file=file, table="cell", key="generator") from exc


def _validity(d: dict) -> dict:
    """The ``[validity]`` table: ``linear_strain_limit`` (the compression strain up to which the
    linear model's stress stays within 10 % of the large-motion engine's, measured by
    studies/verification/linear_validity.py) and its ``source``; ``mesh_convergence`` (what a
    convergence study showed for the cell's resolution) and ``mesh_cell`` (the fabric fingerprint of
    the cell it was shown on: another resolution or fabric is not covered by it)."""
    check_keys(d, VALIDITY_KEYS, "validity")
    out = {}
    lim = get_number(d, "linear_strain_limit", "validity", gt=0.0, lt=1.0, required=False)
    if lim is not None:
        out["linear_strain_limit"] = lim
        out["source"] = get_str(d, "source", "validity", default="the cell file's [validity] table")
    conv = get_str(d, "mesh_convergence", "validity", default="")
    if conv:
        out["mesh_convergence"] = conv
        out["mesh_cell"] = get_str(d, "mesh_cell", "validity")
    return out


# ----------------------------------------------------------------------------------
class Cell:
    """A validated unit cell: its generator, parameters, yarn types and resolution.

    Attributes
    ----------
    path : str or None; name, generator, description : str
    parameters : dict (generator-specific, nested tables as dicts)
    yarns : dict name -> YarnType
    resolution : dict
    frame : Frame, built by the generator on first access and cached
    groups : dict name -> (m,) bool element mask (from the generator, may be empty)
    info : dict of further generator output (e.g. "thickness", mm)
    validity : dict from the ``[validity]`` table ({"linear_strain_limit": strain, "source": str,
        "mesh_convergence": str, "mesh_cell": fingerprint}; empty when the file has none)
    """

    def __init__(self, data: dict, path=None):
        self.path = None if path is None else str(path)
        f = self.path
        try:
            if not isinstance(data, dict):
                raise CellError("a cell file must be a TOML document")
            for key in data:
                if key not in TABLES:
                    raise CellError(f"unknown table [{key}]; a cell file has [cell], [parameters], "
                                    f"[yarns.<name>], [resolution], [contact] and [validity]", table=key)
            cell = get_table(data, "cell", "")
            check_keys(cell, CELL_KEYS, "cell")
            self.name = get_str(cell, "name", "cell")
            self.generator = get_str(cell, "generator", "cell")
            self.description = get_str(cell, "description", "cell", default="")
            self.parameters = copy.deepcopy(get_table(data, "parameters", "", required=False))
            yarns = get_table(data, "yarns", "")
            if not yarns:
                raise CellError("at least one [yarns.<name>] table is required", table="yarns")
            self.yarns = {name: _yarn(name, d) for name, d in yarns.items()}
            self.resolution = copy.deepcopy(get_table(data, "resolution", "", required=False))
            self.contact = _contact(get_table(data, "contact", "", required=False), self.yarns)
            self.validity = _validity(get_table(data, "validity", "", required=False))
        except CellError as err:
            err.file = err.file or f
            raise
        self._builder = _resolve(self.generator, f)
        self._data = copy.deepcopy(data)
        self._frame = None
        self._info: dict = {}

    # ------------------------------------------------------------------
    def build(self) -> Frame:
        """Run the generator (once) and return the frame."""
        if self._frame is not None:
            return self._frame
        f = self.path
        try:
            out = self._builder(copy.deepcopy(self.parameters), dict(self.yarns),
                                copy.deepcopy(self.resolution))
        except CellError as err:
            err.file = err.file or f
            raise
        except InputError as err:
            raise CellError(f"building the frame failed: {err}", file=f, table="parameters") from err
        info = {}
        if isinstance(out, tuple):
            if len(out) != 2 or not isinstance(out[1], dict):
                raise CellError(f"generator {self.generator!r} must return a Frame or (Frame, dict)",
                                file=f, table="cell", key="generator")
            out, info = out
        if not isinstance(out, Frame):
            raise CellError(f"generator {self.generator!r} returned {type(out).__name__}, not a Frame",
                            file=f, table="cell", key="generator")
        groups = info.get("groups", {}) or {}
        for gname, gmask in groups.items():
            gm = np.asarray(gmask)
            if gm.shape != (out.n_elements,) or gm.dtype != bool:
                raise CellError(f"generator {self.generator!r}: group {gname!r} must be a "
                                f"({out.n_elements},) bool mask, got {gm.dtype} {gm.shape}",
                                file=f, table="cell", key="generator")
        self._info = dict(info)
        self._info["groups"] = {k: np.asarray(v) for k, v in groups.items()}
        self._frame = out
        return out

    @property
    def frame(self) -> Frame:
        return self.build()

    @property
    def info(self) -> dict:
        self.build()
        return self._info

    @property
    def groups(self) -> dict:
        return self.info["groups"]

    def friction_spec(self) -> dict | None:
        """The friction of the cell file's ``[contact]`` table as arrays, or None without one.

        Returns {"types": (m,) int yarn-type index of every element, "names": the yarn-type
        names, "table": (T, T) coefficients between yarn types, "plate": (T,) coefficients
        against the plates}. Elements get their yarn type from the generator (``info["yarn_type"]``,
        {yarn id: type name}); a cell with a single yarn type needs no mapping.
        """
        if not self.contact:
            return None
        names = list(self.yarns)
        T = len(names)
        d = self.contact
        mu = float(d.get("friction", 0.0))
        table = np.full((T, T), mu)
        plate = np.full(T, float(d.get("plate_friction", mu)))
        for a, row in d.get("pairs", {}).items():
            for b, v in row.items():
                if b == "plate":
                    plate[names.index(a)] = v
                else:
                    table[names.index(a), names.index(b)] = table[names.index(b), names.index(a)] = v
        frame = self.frame
        ytype = self.info.get("yarn_type")
        if ytype is None:
            if T != 1:
                raise CellError(f"friction per yarn type needs the yarn type of every element, and generator "
                                f"{self.generator!r} does not give it (info['yarn_type']); use one yarn type or a "
                                "single [contact] friction", file=self.path, table="contact")
            types = np.zeros(frame.n_elements, dtype=np.int64)
        else:
            lut = {int(k): names.index(v) for k, v in ytype.items()}
            types = np.array([lut[int(y)] for y in frame.yarn], dtype=np.int64)
        return {"types": types, "names": names, "table": table, "plate": plate}

    # ------------------------------------------------------------------
    def to_dict(self) -> dict:
        """The cell's data as nested dicts (as read from the file, with replacements)."""
        return copy.deepcopy(self._data)

    def fabric_fingerprint(self) -> str:
        """A short hash of what the fabric is made of: the generator, its parameters (the seam table
        left out), the yarn types and the resolution. A calibrated seam parameter records the
        fingerprint of the cell it was calibrated on, so reusing it on another cell is noticed."""
        data = copy.deepcopy(self._data)
        data.pop("cell", None)
        data.get("parameters", {}).pop("seam", None)
        data.pop("contact", None)             # friction is not what a layer rigidity was calibrated on
        data.pop("validity", None)            # what was measured on the fabric is not part of it
        for y in data.get("yarns", {}).values():
            if isinstance(y, dict):
                y.pop("source", None)
        data["generator"] = self.generator
        return hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()[:12]

    def attrs(self) -> dict:
        """Flat {dotted key: str | float | int} of the cell (for xarray/netCDF attributes).

        Arrays are written as JSON strings, booleans as 0/1.
        """
        out = {"cell.path": self.path or ""}

        def walk(prefix, d):
            for k, v in d.items():
                key = f"{prefix}.{k}" if prefix else k
                if isinstance(v, dict):
                    walk(key, v)
                elif isinstance(v, bool):
                    out[key] = int(v)
                elif isinstance(v, (int, float, str)):
                    out[key] = v
                else:
                    out[key] = json.dumps(v)
        walk("", self._data)
        return out

    def replace(self, **dotted) -> "Cell":
        """A new Cell with values changed by dotted keys, validated like a file.

        >>> cell.replace(**{"yarns.pile.radius": 0.1, "resolution.elements_per_strut": 2})

        A value of None removes the key. The frame of the new cell is built at once,
        so bad values raise CellError here.
        """
        data = copy.deepcopy(self._data)
        for dk, value in dotted.items():
            parts = dk.split(".")
            if len(parts) < 2 or parts[0] not in TABLES:
                raise CellError(f"replace: key {dk!r} must be 'table.key' with table one of {list(TABLES)}",
                                file=self.path, table=parts[0] if parts else None)
            d = data
            for i, p in enumerate(parts[:-1]):
                if p not in d:
                    if i == 0 and p in ("parameters", "resolution"):
                        d[p] = {}
                    else:
                        raise CellError(f"replace: no table [{'.'.join(parts[:i + 1])}]",
                                        file=self.path, table=".".join(parts[:i]) or None, key=p)
                d = d[p]
                if not isinstance(d, dict):
                    raise CellError(f"replace: [{'.'.join(parts[:i + 1])}] is not a table",
                                    file=self.path, table=".".join(parts[:i + 1]))
            if value is None:
                d.pop(parts[-1], None)
            else:
                d[parts[-1]] = _plain(value)
        new = Cell(data, self.path)
        new.build()
        return new

    def __repr__(self) -> str:
        return (f"Cell({self.name!r}, generator={self.generator!r}, yarns={sorted(self.yarns)}, "
                f"path={self.path!r})")


def _plain(v):
    """numpy scalars/arrays to plain Python (what TOML would give)."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    return v


def _cell_folders() -> list[Path]:
    import sys

    return [Path(__file__).resolve().parents[1] / "cells", Path(sys.prefix) / "share" / "homtex" / "cells"]


def shipped_cells() -> list[str]:
    """Names of the cell files that come with homtex (``load_cell(name)`` finds them)."""
    names = set()
    for folder in _cell_folders():
        if folder.is_dir():
            names.update(p.stem for p in folder.glob("*.toml"))
    return sorted(names)


def find_cell(name) -> Path:
    """Path of a cell file: ``name`` itself if it exists, else a shipped cell of that name
    (``"spacer_20mm"`` or ``"spacer_20mm.toml"``) from the source tree's ``cells/`` or the
    installed copy in ``<prefix>/share/homtex/cells``."""
    if not isinstance(name, (str, Path)):
        raise CellError(f"a cell is a file path or the name of a shipped cell (a string), got {name!r}")
    p = Path(name)
    if p.is_dir():
        raise CellError("is a folder, not a cell file (.toml)", file=p)
    if p.exists():
        return p
    fname = p.name if p.suffix == ".toml" else p.name + ".toml"
    for folder in _cell_folders():
        if (folder / fname).exists():
            return folder / fname
    return p


def load_cell(path: str | Path, *, build: bool = True) -> Cell:
    """Read, validate and (by default) build a cell file.

    Parameters
    ----------
    path : str or Path of a ``.toml`` cell file.
    build : build the frame at once (default), so every error shows here.

    Raises
    ------
    CellError (an InputError) naming the file, table and key of the culprit; also for a path that
    is not a regular file (a device such as ``/dev/zero``, a pipe) or a file over 10 MB
    (:data:`homtex.validate.MAX_FILE_BYTES`), refused before it is read.
    """
    if not isinstance(build, (bool, np.bool_)):
        raise CellError(f"build must be True or False, got {build!r}")
    p = find_cell(path)
    try:
        text = read_data_file(p, error=CellError, what="a cell file (.toml)")
    except FileNotFoundError:
        raise CellError(f"no such file, and no shipped cell of that name (shipped cells: {', '.join(shipped_cells())})",
                        file=path) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CellError(f"not valid TOML: {exc}", file=path) from None
    except RecursionError:
        raise CellError("not a cell file: arrays or tables nested too deeply to read", file=path) from None
    cell = Cell(data, p)
    if build:
        cell.build()
    return cell
