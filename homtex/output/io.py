"""Datasets on disk: atomic netCDF4 writes with netCDF-safe attributes.

``write_netcdf(ds, path)`` writes to a temporary file in the target folder and moves it
into place with :func:`os.replace`, so a reader (or a resumed study) never sees a half
written file. Attributes that netCDF cannot hold (booleans, dicts, None, nested lists)
are turned into strings (JSON where possible) on a copy; the caller's Dataset is untouched.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["file_mode", "read_netcdf", "sanitize_attrs", "write_failure", "write_netcdf"]

#: errno values of a write the file system refuses (not the disk's size): permission, read-only
_REFUSED = {errno.EACCES: "permission denied", errno.EPERM: "permission denied",
            errno.EROFS: "a read-only file system"}
#: errno values of a full disk or an exhausted quota
_FULL = {errno.ENOSPC: "the disk is full", getattr(errno, "EDQUOT", -1): "the disk quota is exhausted"}


def file_mode() -> int:
    """The mode a new file gets from ``open()`` under the process's umask (``0o666 & ~umask``)."""
    umask = os.umask(0o022)   # read it (there is no getter) and put it back at once
    os.umask(umask)
    return 0o666 & ~umask


def write_failure(folder, exc: BaseException) -> tuple[str, str]:
    """Why a write into ``folder`` failed: (kind, cause) with kind ``"refused"`` (permission
    denied, EACCES/EPERM, or a read-only file system, EROFS), ``"full"`` (ENOSPC, EDQUOT) or
    ``"other"``; the cause in words.

    The error number decides: a read-only folder on a full disk is read-only (the remedy is
    another folder or its permissions, not freeing space), and another number (a missing
    parent, ENOENT) is named as it is. Only an error without a system error number (None, or the
    netCDF library's negative codes) is judged from the folder: read-only (its mount's flag),
    not writable (``os.access``), and only then full when the disk has under 1 MB free.
    """
    code = getattr(exc, "errno", None)
    if code in _REFUSED:
        return "refused", _REFUSED[code]
    if code in _FULL:
        return "full", _FULL[code]
    if code not in errno.errorcode:   # no system error number (None, netCDF's negative codes): look at the folder
        try:
            if os.statvfs(folder).f_flag & os.ST_RDONLY:
                return "refused", "a read-only file system"
            if os.path.isdir(folder) and not os.access(folder, os.W_OK):
                return "refused", "permission denied"
        except (OSError, AttributeError):   # AttributeError: no statvfs (Windows)
            pass
        try:
            if shutil.disk_usage(folder).free < 1 << 20:
                return "full", "the disk is full (under 1 MB free)"
        except OSError:
            pass
    return "other", getattr(exc, "strerror", None) or str(exc) or type(exc).__name__


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
