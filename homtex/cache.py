"""The result cache: cell computations that the macro layer, the seam functions and the knit
tests reuse (compression laws, sewn cushion profiles, relaxed knit cells), kept in memory and on disk.

A result is found again by its key, a SHA-256 hash of what determines it: the kind of
computation, the cell's content (its data as read from the file, with any replacements; not its
file name), the parameters of the call and the package version. A changed cell file, another
parameter or a new homtex version is a new key; nothing is ever reused across them.

Where: ``$HOMTEX_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/homtex``, else ``~/.cache/homtex``
(:func:`cache_dir`). One netCDF file per result, written atomically (a temporary file in the same
folder moved into place), so concurrent study workers computing the same result never see a half
written file (the last writer wins; both wrote the same numbers). ``HOMTEX_CACHE=0`` turns the
disk cache off (the memory cache stays for the process). Clear it with :func:`clear_cache`
(``homtex.clear_cache()``) or ``homtex cache --clear``; ``homtex cache`` lists what it holds.

A file that cannot be read (truncated by a full disk, written by another version of netCDF) is
recomputed and replaced; a failed result is kept in memory only (a failure is not persisted); a
flagged one is stored with its flag (its ``status`` and ``status_detail`` travel with it).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
from pathlib import Path

import numpy as np

from ._version import __version__
from .output.io import read_netcdf, write_netcdf

__all__ = ["cache_dir", "cache_key", "cached", "clear_cache", "list_cache"]

log = logging.getLogger(__name__)

_MEMORY: dict = {}


def cache_dir() -> Path:
    """The folder of the disk cache (not created here)."""
    env = os.environ.get("HOMTEX_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg).expanduser() if xdg else Path.home() / ".cache") / "homtex"


def _disk_enabled() -> bool:
    return os.environ.get("HOMTEX_CACHE", "1").strip().lower() not in ("0", "false", "no", "off")


def _plain(v):
    """A JSON-able, order-independent form of a parameter value."""
    if isinstance(v, dict):
        return {str(k): _plain(w) for k, w in sorted(v.items(), key=lambda kv: str(kv[0]))}
    if isinstance(v, (list, tuple)):
        return [_plain(w) for w in v]
    if isinstance(v, np.ndarray):
        return [_plain(w) for w in v.tolist()]
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if hasattr(v, "__dataclass_fields__"):
        return {"__type__": type(v).__name__, **{k: _plain(getattr(v, k)) for k in v.__dataclass_fields__}}
    if v is None or isinstance(v, (bool, int, str)):
        return v
    return repr(v)


def cache_key(kind: str, cell, params: dict) -> str:
    """The key (hex SHA-256) of a computation ``kind`` on ``cell`` with ``params``."""
    content = cell.to_dict() if hasattr(cell, "to_dict") else repr(cell)
    blob = json.dumps({"kind": kind, "cell": _plain(content), "params": _plain(params), "version": __version__},
                      sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


def _path(kind: str, key: str) -> Path:
    return cache_dir() / f"{kind}-{key[:32]}.nc"


def cached(kind: str, cell, params: dict, compute):
    """The Dataset of ``compute()`` for (kind, cell, params): from memory, else from the disk cache,
    else computed and stored (on disk unless its status is "failed"). The caller gets its own
    copy (changing it does not change the cache)."""
    key = cache_key(kind, cell, params)
    hit = _MEMORY.get(key)
    if hit is not None:
        return hit.copy(deep=True)
    path = _path(kind, key)
    if _disk_enabled() and path.exists():
        try:
            ds = read_netcdf(path)
            if ds.attrs.get("cache_key") == key:
                _MEMORY[key] = ds
                log.debug("cache: %s from %s", kind, path)
                return ds.copy(deep=True)
        except (OSError, ValueError, RuntimeError, KeyError) as exc:
            log.warning("cache: %s unreadable (%s); recomputing", path, exc)
    ds = compute()
    ds.attrs["cache_key"] = key
    ds.attrs["cache_kind"] = kind
    _MEMORY[key] = ds
    if _disk_enabled() and ds.attrs.get("status", "ok") != "failed":
        try:
            write_netcdf(ds, path)
        except OSError as exc:
            log.warning("cache: could not write %s (%s); kept in memory only", path, exc)
    return ds.copy(deep=True)


def clear_cache(memory: bool = True, disk: bool = True) -> int:
    """Forget cached results (in this process and/or on disk); returns the number of files removed."""
    if memory:
        _MEMORY.clear()
    n = 0
    d = cache_dir()
    if disk and d.is_dir():
        for p in d.glob("*.nc"):
            try:
                p.unlink()
                n += 1
            except OSError:
                pass
        for p in d.glob(".*.tmp"):
            try:
                p.unlink()
            except OSError:
                pass
        if not any(d.iterdir()):
            shutil.rmtree(d, ignore_errors=True)
    return n


def list_cache() -> list:
    """[(file, kind, size in bytes)] of the disk cache."""
    d = cache_dir()
    if not d.is_dir():
        return []
    return [(p, p.name.split("-")[0], p.stat().st_size) for p in sorted(d.glob("*.nc"))]
