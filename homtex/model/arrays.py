"""Turning user input into the arrays a Frame stores, or an InputError naming the argument.

Everything a user passes (lists, numpy arrays of any dtype, scalars) is checked before it is
converted: strings, booleans, complex numbers and objects are refused instead of coerced,
integer arguments must hold whole numbers, real arguments must be finite and within the range
double precision can carry through a stiffness (:data:`MAX_COORD` for lengths).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["MAX_COORD", "as_index", "as_real", "per_element", "to_array"]

#: largest coordinate, radius or period accepted, mm (1000 km): beyond it stiffness products and
#: squared lengths lose all precision long before they overflow
MAX_COORD = 1e9


def _kind_error(arr: np.ndarray, name: str, want: str) -> InputError | None:
    kind = arr.dtype.kind
    if kind in "USO":
        return InputError(f"{name} must hold {want}, got {arr.dtype.name} values such as {arr.ravel()[:1].tolist()}")
    if kind == "c":
        return InputError(f"{name} must hold real {want}, got complex values such as {arr.ravel()[:1].tolist()}")
    if kind == "b":
        return InputError(f"{name} must hold {want}, got booleans")
    if kind not in "iuf":
        return InputError(f"{name} must hold {want}, got {arr.dtype}")
    return None


def to_array(value, name: str) -> np.ndarray:
    """np.asarray of user input, InputError (naming ``name``) for None or ragged nesting."""
    if value is None:
        raise InputError(f"{name} is required")
    try:
        return np.asarray(value)
    except (ValueError, TypeError) as exc:      # ragged nested lists
        raise InputError(f"{name} must be a rectangular array of numbers ({exc})") from None


def as_real(value, name: str, *, ndim: int | None = None, width: int | None = None,
            limit: float | None = None, finite: bool = True) -> np.ndarray:
    """A contiguous float64 array of finite reals (|x| <= ``limit`` when given); ``ndim``/``width``
    check the shape ((n, width) for ndim 2)."""
    arr = to_array(value, name)
    err = _kind_error(arr, name, "numbers")
    if err:
        raise err
    if ndim is not None and arr.ndim != ndim:
        raise InputError(f"{name} must be a {ndim}-D array, got shape {arr.shape}")
    if width is not None and (arr.ndim != 2 or arr.shape[1] != width):
        raise InputError(f"{name} must have shape (n, {width}), got {arr.shape}")
    arr = np.array(arr, dtype=float, order="C")   # (ascontiguousarray would turn a scalar into (1,))
    bad = ~np.isfinite(arr) if finite else np.zeros(arr.shape, dtype=bool)
    if bad.any():
        i = np.unravel_index(int(np.flatnonzero(bad.ravel())[0]), arr.shape)
        raise InputError(f"{name} must be finite, got {arr[i]} at index {tuple(int(j) for j in i)} "
                         f"({int(bad.sum())} such values)")
    if limit is not None and arr.size and np.nanmax(np.abs(np.where(np.isfinite(arr), arr, 0.0))) > limit:
        i = np.unravel_index(int(np.argmax(np.abs(arr))), arr.shape)
        raise InputError(f"{name} must lie within +-{limit:g}, got {arr[i]:g} at index "
                         f"{tuple(int(j) for j in i)}")
    return arr


def as_index(value, name: str, *, ndim: int | None = None, lo: int | None = None,
             hi: int | None = None) -> np.ndarray:
    """A contiguous int64 array of whole numbers in [lo, hi] (floats must be integral)."""
    arr = to_array(value, name)
    err = _kind_error(arr, name, "integers")
    if err:
        raise err
    if ndim is not None and arr.ndim != ndim:
        raise InputError(f"{name} must be a {ndim}-D array, got shape {arr.shape}")
    if arr.dtype.kind == "f":
        bad = ~np.isfinite(arr) | (arr != np.round(arr)) | (np.abs(arr) > 2.0 ** 62)
        if bad.any():
            i = np.unravel_index(int(np.flatnonzero(bad.ravel())[0]), arr.shape)
            raise InputError(f"{name} must hold integers, got {arr[i]} at index {tuple(int(j) for j in i)}")
    elif arr.dtype.kind == "u" and arr.size and arr.max() > 2 ** 62:
        raise InputError(f"{name} must hold integers below 2**62, got {arr.max()}")
    arr = np.array(arr, dtype=np.int64, order="C")
    for bound, bad in ((lo, arr < lo if lo is not None else None), (hi, arr > hi if hi is not None else None)):
        if bad is not None and bad.any():
            i = np.unravel_index(int(np.flatnonzero(bad.ravel())[0]), arr.shape)
            rng = f"{'' if lo is None else lo}..{'' if hi is None else hi}"
            raise InputError(f"{name} must lie in {rng}, got {arr[i]} at index {tuple(int(j) for j in i)}")
    return arr


def per_element(value, m: int, name: str, *, index: bool = False, lo=None, hi=None, positive: bool = False,
                limit: float | None = None, yarn=None) -> np.ndarray:
    """A scalar broadcast to (m,), or an (m,) array, checked (see :func:`as_real`, :func:`as_index`);
    ``positive``: > 0; ``lo``/``hi``: bounds (exclusive for reals, inclusive for integers); ``yarn``
    (m,) yarn ids named in the message."""
    arr = as_index(value, name, lo=lo, hi=hi) if index else as_real(value, name, limit=limit, finite=False)
    if arr.ndim == 0:
        arr = np.full(m, arr, dtype=arr.dtype)
    if arr.shape != (m,):
        raise InputError(f"{name} must be a scalar or have shape ({m},) (one per element), got {arr.shape}")
    if not index:
        bad = ~np.isfinite(arr)
        want = ["finite"]
        if positive:
            bad |= ~(arr > 0)
            want.insert(0, "positive")
        if lo is not None:
            bad |= ~(arr > lo)
            want.append(f"> {lo:g}")
        if hi is not None:
            bad |= ~(arr < hi)
            want.append(f"< {hi:g}")
        if bad.any():
            e = int(np.flatnonzero(bad)[0])
            of = f" (yarn {yarn[e]})" if yarn is not None else ""
            raise InputError(f"{name} of element {e}{of} must be {' and '.join(want)}, got {arr[e]:g}")
    return np.ascontiguousarray(arr)
