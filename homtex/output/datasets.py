"""Self-describing Datasets: every variable and coordinate carries ``units`` and ``long_name``.

Stages build their results through :func:`curve_dataset` so that no variable leaves homtex
without its unit; :func:`check_meta` lists the ones that do.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

__all__ = ["check_meta", "curve_dataset", "set_meta"]


def curve_dataset(data: dict, coords: dict | None = None, attrs: dict | None = None) -> xr.Dataset:
    """A Dataset from ``{name: (dims, values, units, long_name)}`` and coordinates
    ``{name: (values, units, long_name)}`` (a coordinate's dimension is its name) or
    ``{name: (dims, values, units, long_name)}``."""
    variables = {}
    for name, (dims, values, units, long_name) in data.items():
        variables[name] = xr.Variable(dims, np.asarray(values), {"units": units, "long_name": long_name})
    cs = {}
    for name, spec in (coords or {}).items():
        if len(spec) == 3:
            values, units, long_name = spec
            dims = (name,)
        else:
            dims, values, units, long_name = spec
        cs[name] = (dims, np.asarray(values), {"units": units, "long_name": long_name})
    return xr.Dataset(variables, coords=cs, attrs=dict(attrs or {}))


def set_meta(da, units: str, long_name: str):
    """Set ``units`` and ``long_name`` on a DataArray / Variable (returned for chaining)."""
    da.attrs["units"] = units
    da.attrs["long_name"] = long_name
    return da


def check_meta(ds) -> list:
    """Names of data variables and coordinates of ``ds`` lacking ``units`` or ``long_name``."""
    return [str(n) for n in [*ds.data_vars, *ds.coords]
            if "units" not in ds[n].attrs or "long_name" not in ds[n].attrs]
