"""Where the linear model stops being valid: the compression strain up to which the linear
(small-rotation, re-linearised contact) stress stays within 10 % of the large-motion engine's on
the same cell.

For every shipped cell that can be compressed between plates (2-periodic in x-y, or finite), both
curves are computed on the same strain levels (the engine frictionless unless the cell file gives
friction); the limit is the first strain where |stress_linear / stress_engine - 1| reaches 10 %
(linear interpolation between levels). The value goes into the cell file's ``[validity]`` table
(``linear_strain_limit``), which ``compress(geometry="linear")`` reads: a curve that goes beyond it
is "flagged" with the limit named. Cells that plates cannot compress (3-periodic lattices, planar
lattices in x-y) have no such limit; nor do the weft knits, which homtex pulls (``homtex.tensile``, on the
engine only) rather than presses.

Usage::

    python studies/verification/linear_validity.py [--out DIR] [--quick]

Default: the spacer cell to 3 % in 0.1 % levels (about a minute). ``--quick``: to 1 % in 0.25 %
levels. Writes ``DIR/linear_validity.nc`` and ``DIR/linear_validity.png``.
"""
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import ROOT, parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

TOLERANCE = 0.10


def limit(strain, linear, engine, tol=TOLERANCE) -> float:
    """First strain where |linear / engine - 1| reaches ``tol`` (interpolated); NaN if never."""
    e = np.r_[0.0, np.asarray(strain, float)]
    err = np.r_[0.0, np.abs(np.asarray(linear, float) / np.asarray(engine, float) - 1.0)]
    above = np.flatnonzero(err >= tol)
    if not above.size:
        return float("nan")
    k = int(above[0])
    return float(e[k - 1] + (tol - err[k - 1]) / (err[k] - err[k - 1]) * (e[k] - e[k - 1]))


def compressible(cell) -> bool:
    if {"rest", "pattern"} <= set(getattr(cell, "info", {})):
        return False            # a weft knit: tested in tension on the engine (homtex.tensile), not pressed
    fr = cell.frame
    if fr.dim_periodic == 3:
        return False
    if fr.dim_periodic and np.any(np.abs(fr.periods[:, 2]) > 0):
        return False
    return float(np.ptp(fr.nodes[:, 2])) > 0.0           # planar lattices in x-y have no thickness


def main(argv=None):
    import homtex

    a = parser(__file__, __doc__).parse_args(argv)
    out = setup(a)
    top, dstrain = (0.01, 0.0025) if a.quick else (0.03, 0.001)
    levels = np.arange(1, int(round(top / dstrain)) + 1) * dstrain
    names, lims, curves = [], [], {}
    for path in sorted((ROOT / "cells").glob("*.toml")):
        cell = homtex.load_cell(path)
        if not compressible(cell):
            continue
        t0 = time.process_time()
        lin = homtex.compress(cell, strain=levels, geometry="linear")
        eng = homtex.compress(cell, strain=levels, geometry="nonlinear",    # as stored: frictionless
                              contact=homtex.Contact(friction=0.0))
        n = min(lin.sizes["strain"], eng.sizes["strain"])
        lim = limit(levels[:n], lin.stress.values[:n], eng.stress.values[:n])
        print(f"{cell.name}: the linear stress leaves 10 % of the engine's at strain {lim:.4g} "
              f"({100 * lim:.2f} %); linear {lin.attrs['status']}, engine {eng.attrs['status']}, "
              f"{time.process_time() - t0:.1f} s CPU")
        names.append(cell.name)
        lims.append(lim)
        curves[cell.name] = (levels[:n], lin.stress.values[:n], eng.stress.values[:n])
    m = max(len(c[0]) for c in curves.values())
    pad = lambda v: np.r_[v, np.full(m - len(v), np.nan)]           # noqa: E731
    ds = xr.Dataset(
        {"linear_strain_limit": ("cell", np.array(lims), {"units": "1", "long_name": "strain up to which the "
                                                          "linear stress stays within 10 % of the engine's"}),
         "stress_linear": (("cell", "level"), np.array([pad(c[1]) for c in curves.values()]),
                           {"units": "kPa", "long_name": "linear model (small rotations, re-linearised contact)"}),
         "stress_engine": (("cell", "level"), np.array([pad(c[2]) for c in curves.values()]),
                           {"units": "kPa", "long_name": "large-motion engine (frictionless unless the cell "
                                                         "file gives friction)"}),
         "strain": (("cell", "level"), np.array([pad(c[0]) for c in curves.values()]),
                    {"units": "1", "long_name": "compression strain"})},
        coords={"cell": ("cell", np.array(names), {"units": "1", "long_name": "shipped cell"}),
                "level": ("level", np.arange(m), {"units": "1", "long_name": "strain level"})},
        attrs={"tolerance": TOLERANCE, "quick": int(a.quick)})
    save_netcdf(ds, out / "linear_validity.nc")
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name, (e, sl, se) in curves.items():
        ax.plot(100 * e, sl, "--", label=f"{name}: linear model")
        ax.plot(100 * e, se, "-", label=f"{name}: large-motion engine")
        lim = float(ds.linear_strain_limit.sel(cell=name))
        if np.isfinite(lim):
            ax.axvline(100 * lim, color="0.5", lw=0.8)
            ax.text(100 * lim, ax.get_ylim()[1] * 0.95, f" linear valid to {100 * lim:.2f} %", va="top", fontsize=8)
    ax.set_xlabel("compression strain (%)")
    ax.set_ylabel("nominal stress (kPa)")
    ax.set_title("Validity of the linear model: its stress within 10 % of the engine's")
    ax.legend(fontsize=8)
    save_figure(fig, out / "linear_validity.png")
    return ds


if __name__ == "__main__":
    main()
