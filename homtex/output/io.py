"""Datasets on disk: atomic netCDF4 writes with netCDF-safe attributes.

``write_netcdf(ds, path)`` writes to a temporary file in the target folder and moves it
into place with :func:`os.replace`, so a reader (or a resumed study) never sees a half
written file. Attributes that netCDF cannot hold (booleans, dicts, None, nested lists)
are turned into strings (JSON where possible) on a copy; the caller's Dataset is untouched.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["file_mode", "read_netcdf", "sanitize_attrs", "write_netcdf"]


def file_mode() -> int:
    """The mode a new file gets from ``open()`` under the process's umask (``0o666 & ~umask``)."""
    umask = os.umask(0o022)   # read it (there is no getter) and put it back at once
    os.umask(umask)
    return 0o666 & ~umask


def _attr_value(v):
    """One attribute value as something netCDF4 accepts (str, number, 1-D numeric array)."""
    if v is None:
        return "None"
    if isinstance(v, (bool, np.bool_)):
        return str(bool(v))
    if isinstance(v, (str, bytes)):
        return v if isinstance(v, str) else v.decode("utf-8", "replace")
    if isinstance(v, (int, float, np.integer, np.floating)):
        return v
    if isinstance(v, (list, tuple, np.ndarray)):
        arr = np.asarray(v)
        if arr.ndim == 1 and arr.size and arr.dtype.kind in "if":
            return arr
        try:
            return json.dumps(np.asarray(v).tolist() if isinstance(v, np.ndarray) else v, default=str)
        except (TypeError, ValueError):
            return str(v)
    if isinstance(v, dict):
        try:
            return json.dumps(v, default=str, sort_keys=True)
        except (TypeError, ValueError):
            return str(v)
    return str(v)


def sanitize_attrs(attrs: dict) -> dict:
    """A copy of ``attrs`` that netCDF4 can store (bools/None/dicts/lists -> strings)."""
    return {str(k): _attr_value(v) for k, v in attrs.items()}


def write_netcdf(ds, path) -> Path:
    """Write ``ds`` to ``path`` (netCDF4 engine) atomically; returns the path.

    The folder is created if needed. Object (string) variables are written as
    variable-length strings. A failure leaves no partial file at ``path``. The file gets the
    mode any new file of the user gets (``0o666 & ~umask``), not the temporary file's 0600.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    out = ds.copy(deep=False)
    out.attrs = sanitize_attrs(ds.attrs)
    for name in [*out.data_vars, *out.coords]:
        var = out[name]
        var.attrs = sanitize_attrs(var.attrs)
        if var.dtype == bool:
            out[name] = var.astype(np.int8)
            out[name].attrs.update(var.attrs)
            out[name].attrs["dtype_note"] = "boolean stored as int8 (0/1)"
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        out.to_netcdf(tmp, engine="netcdf4")
        os.chmod(tmp, file_mode())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return path


def read_netcdf(path):
    """Load a netCDF file fully into memory (the file is closed on return)."""
    import xarray as xr

    with xr.open_dataset(path, engine="netcdf4") as ds:
        return ds.load()
