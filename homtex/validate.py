"""Validation of values read from TOML tables (cell and study files).

Each getter returns the checked value or raises :class:`~homtex.errors.CellError` naming the
table and key; callers that know the file add it. Generators written elsewhere use the same
getters, so every cell file reports bad values the same way.
"""

from __future__ import annotations

import math
import os
import stat
import sys
from pathlib import Path

import numpy as np

from .config import option
from .errors import CellError, InputError

__all__ = ["MAX_FILE_BYTES", "check_choice", "check_int", "check_keys", "check_number", "check_seed", "check_size",
           "check_tol", "get_int", "get_list", "get_number", "get_str", "get_table", "read_data_file", "type_name"]

#: largest cell or study file read, bytes (10 MB; the shipped cells are a few kB): a larger file,
#: or something that is not a regular file (``/dev/zero``, a pipe), is refused before it is read
MAX_FILE_BYTES = 10 * 1024 * 1024


def is_number(v) -> bool:
    """True for int and float values (not booleans)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


INT64_MIN, INT64_MAX = -(2 ** 63), 2 ** 63 - 1


def _short(v, n: int = 80) -> str:
    """repr(v) cut to about n characters (a 400-digit integer or a long array in a message)."""
    r = repr(v)
    return r if len(r) <= n else f"{r[:n - 20]}...({len(r)} characters)"


def type_name(v) -> str:
    """'a string', 'a boolean', ... for error messages."""
    return {str: "a string", bool: "a boolean", int: "an integer", float: "a number",
            list: "an array", dict: "a table"}.get(type(v), type(v).__name__)


def get_number(d: dict, key: str, table: str, *, default=None, gt=None, ge=None, lt=None,
               le=None, required: bool = True) -> float | None:
    """A finite number d[key] with optional bounds, else CellError(table, key)."""
    if key not in d:
        if default is not None or not required:
            return default
        raise CellError("missing key (a number)", table=table, key=key)
    v = d[key]
    if not is_number(v):
        raise CellError(f"must be a number, got {type_name(v)} {_short(v)}", table=table, key=key)
    try:
        v = float(v)
    except OverflowError:   # an integer beyond double precision (TOML integers have no size limit here)
        raise CellError(f"must be a finite number (at most {sys.float_info.max:.3g}), got an integer of "
                        f"{len(str(abs(v)))} digits", table=table, key=key) from None
    if not math.isfinite(v):
        raise CellError(f"must be finite, got {v}", table=table, key=key)
    for bound, op, ok in ((gt, ">", lambda x, b: x > b), (ge, ">=", lambda x, b: x >= b),
                          (lt, "<", lambda x, b: x < b), (le, "<=", lambda x, b: x <= b)):
        if bound is not None and not ok(v, bound):
            raise CellError(f"must be {op} {bound}, got {v:g}", table=table, key=key)
    return v


def get_int(d: dict, key: str, table: str, *, default=None, ge=None, le=None) -> int | None:
    """An integer d[key] (>= ge, <= le, and within the 64-bit range numpy computes with), else
    CellError(table, key)."""
    if key not in d:
        if default is not None:
            return default
        raise CellError("missing key (an integer)", table=table, key=key)
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, int):
        raise CellError(f"must be an integer, got {type_name(v)} {_short(v)}", table=table, key=key)
    rng = f" (at most {le})" if le is not None else ""
    if ge is not None and v < ge:
        raise CellError(f"must be >= {ge}{rng}, got {_short(v)}", table=table, key=key)
    if le is not None and v > le:
        raise CellError(f"must be <= {le}" + (f" (and >= {ge})" if ge is not None else "") + f", got {_short(v)}",
                        table=table, key=key)
    if not INT64_MIN <= v <= INT64_MAX:
        raise CellError(f"must be a 64-bit integer (magnitude below 2^63), got {_short(v)}", table=table, key=key)
    return int(v)


def get_str(d: dict, key: str, table: str, *, default=None, choices=None) -> str | None:
    """A non-empty string d[key] (one of ``choices``), else CellError(table, key)."""
    if key not in d:
        if default is not None:
            return default
        raise CellError("missing key (a string)", table=table, key=key)
    v = d[key]
    if not isinstance(v, str):
        raise CellError(f"must be a string, got {type_name(v)} {v!r}", table=table, key=key)
    if choices is not None and v not in choices:
        raise CellError(f"must be one of {list(choices)}, got {v!r}", table=table, key=key)
    if choices is None and not v.strip() and default is None:
        raise CellError("must not be empty", table=table, key=key)
    return v


def get_list(d: dict, key: str, table: str, *, shape=None, integer: bool = False, default=None,
             gt=None) -> np.ndarray | None:
    """A numeric array d[key] of the given shape (None entries: any size)."""
    if key not in d:
        if default is not None:
            return np.asarray(default)
        raise CellError("missing key (an array)", table=table, key=key)
    v = d[key]
    if not isinstance(v, list):
        raise CellError(f"must be an array, got {type_name(v)} {v!r}", table=table, key=key)
    try:
        flat = list(_flatten(v))
    except CellError as err:
        raise CellError(err.message, table=table, key=key) from None
    kind = "integers" if integer else "numbers"
    if not all((isinstance(x, int) and not isinstance(x, bool)) if integer else is_number(x) for x in flat):
        raise CellError(f"must be an array of {kind}, got {_short(v)}", table=table, key=key)
    big = [x for x in flat if isinstance(x, int) and not (INT64_MIN <= x <= INT64_MAX)]
    if big:   # numpy would raise OverflowError; such integers are no sizes, indices or lengths
        raise CellError(f"must be an array of {'64-bit integers' if integer else 'finite numbers'}, got "
                        f"{_short(big[0])} in {_short(v)}", table=table, key=key)
    try:
        arr = np.asarray(v, dtype=np.int64 if integer else float)
    except (ValueError, OverflowError):
        raise CellError(f"must be a rectangular array of {kind}, got {_short(v)}", table=table, key=key) from None
    if shape is not None:
        ok = arr.ndim == len(shape) and all(s is None or s == a for s, a in zip(shape, arr.shape))
        if not ok:
            want = "x".join("n" if s is None else str(s) for s in shape)
            raise CellError(f"must have shape {want}, got {list(arr.shape)}", table=table, key=key)
    if not integer and not np.isfinite(arr).all():
        raise CellError(f"must be finite, got {v!r}", table=table, key=key)
    if gt is not None and arr.size and not (arr > gt).all():
        raise CellError(f"entries must be > {gt}, got {v!r}", table=table, key=key)
    return arr


def _flatten(v, max_depth: int = 16):
    """The leaves of nested lists, depth first (iterative: no recursion limit to hit)."""
    stack = [(iter(v), 1)]
    while stack:
        it, depth = stack[-1]
        for x in it:
            if isinstance(x, list):
                if depth >= max_depth:
                    raise CellError(f"arrays nested deeper than {max_depth} levels")
                stack.append((iter(x), depth + 1))
                break
            yield x
        else:
            stack.pop()


def check_keys(d: dict, allowed, table: str) -> None:
    """CellError for the first key of d not in ``allowed``."""
    for key in d:
        if key not in allowed:
            raise CellError(f"unknown key; allowed keys are {sorted(allowed)}", table=table, key=key)


def get_table(d, key, table, required=True) -> dict:
    """The sub-table d[key] ({} when absent and not required), else CellError."""
    if key not in d:
        if required:
            raise CellError(f"missing table [{key}]" if not table else "missing table",
                            table=table or None, key=key if table else None)
        return {}
    v = d[key]
    if not isinstance(v, dict):
        if table:      # [table] key 'key': must be a table ([table.key]), ...
            raise CellError(f"must be a table ([{table}.{key}]), got {type_name(v)} {_short(v)}", table=table, key=key)
        raise CellError(f"must be a table, got {type_name(v)} {_short(v)}", table=key)
    return v


def read_data_file(path, *, error=CellError, what: str = "a cell file (.toml)", limit: int | None = None) -> str:
    """The UTF-8 text of a small data file (cell or study TOML), else ``error(message, file=path)``.

    Refused before anything is read: a folder, something that is not a regular file (a device
    such as ``/dev/zero`` or a named pipe would be read forever or block), a file larger than
    ``limit`` bytes (default :data:`MAX_FILE_BYTES`, 10 MB). At most ``limit`` + 1 bytes are read,
    so a file that grows while it is read is refused too. A missing file raises FileNotFoundError
    (the caller knows what to suggest).
    """
    limit = MAX_FILE_BYTES if limit is None else int(limit)
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise error(f"cannot be read: {exc.strerror or exc}", file=path) from None
    if stat.S_ISDIR(st.st_mode):
        raise error(f"is a folder, not {what}", file=path)
    if not stat.S_ISREG(st.st_mode):
        raise error(f"is not a regular file (a device, pipe or socket), not {what}", file=path)
    if st.st_size > limit:
        raise error(f"is {st.st_size / 1e6:.3g} MB, larger than the {limit / 1e6:.3g} MB a data file may have; "
                    f"it is not {what}", file=path)
    try:
        with open(p, "rb") as fh:
            raw = fh.read(limit + 1)
    except OSError as exc:
        raise error(f"cannot be read: {exc.strerror or exc}", file=path) from None
    if len(raw) > limit:
        raise error(f"grew beyond the {limit / 1e6:.3g} MB a data file may have while it was read; it is not {what}",
                    file=path)
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"is not UTF-8 text ({what}): {exc}", file=path) from None


# ------------------------------------------------------------------ arguments of the public API
def _fail(name: str, want: str, value) -> InputError:
    return InputError(f"{name} must be {want}, got {_short(value)}")


def check_number(value, name: str, *, gt=None, ge=None, lt=None, le=None, finite: bool = True) -> float:
    """A real number (not a boolean, not complex, finite unless ``finite=False``) within the
    bounds, as float; else InputError naming ``name`` and the allowed range."""
    bounds = [f"> {gt:g}" if gt is not None else "", f">= {ge:g}" if ge is not None else "",
              f"< {lt:g}" if lt is not None else "", f"<= {le:g}" if le is not None else ""]
    want = "a finite number" + "".join(f" {b}" for b in bounds if b).replace("  ", " ")
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise _fail(name, want, value)
    try:
        v = float(value)
    except OverflowError:      # an integer beyond double precision
        raise _fail(name, want, value) from None
    if math.isnan(v) or (finite and not math.isfinite(v)):
        raise _fail(name, want, value)
    if (gt is not None and not v > gt) or (ge is not None and not v >= ge) or \
            (lt is not None and not v < lt) or (le is not None and not v <= le):
        raise _fail(name, want, value)
    return v


def check_int(value, name: str, *, ge=None, le=None) -> int:
    """An integer (Python or numpy, not a boolean, not a float) within the bounds; else InputError."""
    want = "an integer" + (f" >= {ge}" if ge is not None else "") + (f" <= {le}" if le is not None else "")
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise _fail(name, want, value)
    v = int(value)
    if (ge is not None and v < ge) or (le is not None and v > le):
        raise _fail(name, want, value)
    return v


def check_choice(value, name: str, choices) -> str:
    """One of ``choices``; else InputError listing them."""
    if not isinstance(value, str) or value not in choices:
        raise InputError(f"{name} must be one of {tuple(choices)}, got {value!r}")
    return value


def check_tol(value, name: str = "tol") -> float:
    """A relative tolerance: a finite number in (0, 1)."""
    return check_number(value, name, gt=0.0, lt=1.0)


def check_seed(value, name: str = "seed"):
    """None or a non-negative integer (a random seed)."""
    return None if value is None else check_int(value, name, ge=0)


def check_size(n_elements: int, what: str) -> int:
    """``n_elements`` if it is within the option ``max_elements`` (checked before a generator
    allocates anything), else InputError with the number and how to raise the limit."""
    limit = option("max_elements")
    if n_elements > limit:
        raise InputError(f"{what} would have {n_elements:.3g} elements, more than max_elements = {limit:g} "
                         "(lower the resolution or repeats, or raise the limit with "
                         "homtex.set_options(max_elements=...))")
    return int(n_elements)
