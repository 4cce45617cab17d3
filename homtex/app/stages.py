"""The stages of the main job, each a function that computes, writes netCDF + PNG into an
output folder and returns what it wrote (the command line, the tests and the studies share them).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import matplotlib
import numpy as np
import xarray as xr

from .._version import __version__
from ..api import compress, solve_static
from ..contact.compress import compression_summary
from ..contact.options import Contact
from ..errors import InputError
from ..geometry.lattices import lattice_frame
from ..output.charts import (
    _tag,
    compression_chart,
    save,
)
from ..output.io import write_netcdf
from .paths import heartbeat

log = logging.getLogger(__name__)


def _attrs(ds: xr.Dataset, **extra) -> xr.Dataset:
    ds.attrs.update({"homtex_version": __version__, **{k: str(v) for k, v in extra.items()}})
    return ds


def describe(ds: xr.Dataset, kind: str, cell=None, coords: dict | None = None) -> xr.Dataset:
    """Mark what a Dataset is (``homtex_kind``: the chart ``homtex plot`` draws), which cell it
    belongs to (``cell_name``, ``cell_file``) and give its coordinates units and long names
    (``coords``: {name: (units, long_name)}; others without them get "1" and their name)."""
    ds.attrs["homtex_kind"] = kind
    if cell is not None:
        ds.attrs["cell_name"] = str(getattr(cell, "name", cell))
        if getattr(cell, "path", None):
            ds.attrs["cell_file"] = str(cell.path)
        if isinstance(getattr(cell, "info", None), dict) and "thickness" in cell.info:
            ds.attrs.setdefault("thickness_mm", float(cell.info["thickness"]))
    for name, (units, long_name) in (coords or {}).items():
        ds[name].attrs.update(units=units, long_name=long_name)
    for name in ds.coords:
        ds[name].attrs.setdefault("units", "1")
        ds[name].attrs.setdefault("long_name", str(name))
    return ds


def _save(ds: xr.Dataset, path: Path) -> Path:
    return write_netcdf(ds, path)


def _plt():
    """matplotlib.pyplot on the file-only Agg backend (no screen needed)."""
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# ----------------------------------------------------------------------------- lattice demo
def lattice_demo(out: Path, *, repeat=(6, 6, 6), radius=0.05, elements_per_strut=2) -> dict:
    """Octet-truss block (E = 2 GPa, struts L/r = 14) pressed by 1 % of its height.

    Solved with every solver; writes the per-node displacement, per-element axial force and
    energy, and the solver reports. Returns {name: path}.
    """

    f = lattice_frame("octet", radius=radius, E=2000.0, nu=0.35, repeat=repeat, periodic=False,
                      elements_per_strut=elements_per_strut)
    z = f.nodes[:, 2]
    h = z.max() - z.min()
    bottom = np.flatnonzero(z < z.min() + 1e-9)
    top = np.flatnonzero(z > z.max() - 1e-9)
    fixed = {int(i): "all" for i in bottom}
    fixed.update({int(i): {0: 0.0, 1: 0.0, 2: -0.01 * h} for i in top})
    results = {s: solve_static(f, fixed, None, solver=s, tol=1e-10) for s in ("amg", "direct", "cg")}
    r = results["amg"]
    force = -float(r.reactions[top, 2].sum())
    reps = [results[s].report for s in results]
    ds = xr.Dataset(
        {
            "displacement": (("node", "dof"), r.u,
                             {"units": "mm | rad", "long_name": "nodal displacement and rotation"}),
            "x": (("node", "xyz"), f.nodes, {"units": "mm", "long_name": "node coordinates"}),
            "axial_force": ("element", r.axial_force, {"units": "N", "long_name": "axial force (tension positive)"}),
            **{f"energy_{k}": ("element", v, {"units": "N mm", "long_name": f"{k} strain energy"})
               for k, v in r.energy.items()},
            "setup_seconds": ("solver", [p.setup_seconds for p in reps],
                              {"units": "s", "long_name": "solver setup time"}),
            "solve_seconds": ("solver", [p.solve_seconds for p in reps], {"units": "s", "long_name": "solve time"}),
            "iterations": ("solver", [p.iterations for p in reps], {"units": "1", "long_name": "CG iterations"}),
            "residual": ("solver", [p.residual for p in reps], {"units": "1", "long_name": "true relative residual"}),
            "max_difference": ("solver", [float(np.abs(results[s].u - r.u).max() / np.abs(r.u).max()) for s in results],
                               {"units": "1", "long_name": "max displacement difference to amg, relative"}),
            "force": ((), force, {"units": "N", "long_name": "reaction force at 1 % compression"}),
        },
        coords={"solver": list(results), "dof": ["ux", "uy", "uz", "rx", "ry", "rz"], "xyz": ["x", "y", "z"]},
    )
    _attrs(ds, title="octet lattice block under 1 % compression", ndof=f.ndof, n_elements=f.n_elements)
    describe(ds, "generic", "octet lattice block", coords={
        "solver": ("1", "linear solver"), "dof": ("1", "degree of freedom (translations mm, rotations rad)"),
        "xyz": ("1", "coordinate axis")})
    nc = _save(ds, out / "lattice_demo.nc")

    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.5))
    from matplotlib.collections import LineCollection

    seg = np.stack([f.nodes[f.elements[:, 0]][:, [0, 2]], f.nodes[f.elements[:, 1]][:, [0, 2]]], axis=1)
    lim = np.abs(r.axial_force).max()
    lc = LineCollection(seg, array=r.axial_force, cmap="coolwarm", linewidths=0.6)
    lc.set_clim(-lim, lim)
    _tag(ax[0], "mm", "z", lc)
    ax[0].add_collection(lc)
    ax[0].autoscale()
    ax[0].set_aspect("equal")
    fig.colorbar(lc, ax=ax[0], label="axial force, N")
    ax[0].set(xlabel="x, mm", title=f"octet lattice block {'x'.join(map(str, repeat))}, {f.ndof} DOF, 1 % "
              "compression:\naxial force (side view)")
    names = list(results)
    bars = ax[1].bar(names, [p.setup_seconds + p.solve_seconds for p in reps])
    _tag(ax[1], "s", "setup + solve time", *bars.patches)
    for i, p in enumerate(reps):
        ax[1].text(i, p.setup_seconds + p.solve_seconds, f"{p.iterations} iterations" if p.iterations
                   else "direct solve", ha="center", va="bottom")
    ax[1].set(xlabel="linear solver", title="octet lattice block: the solvers on the same system (they agree to "
              f"{float(ds['max_difference'].max()):.0e})")
    ax[0].title.set_fontsize(9)
    ax[1].title.set_fontsize(9)
    fig.tight_layout()
    png = save(fig, out / "lattice_demo.png")
    return {"lattice demo (netCDF)": nc, "lattice demo (chart)": png}


# ----------------------------------------------------------------------------- paper study
SPACER_CELL = "spacer_20mm"


def _markdown_table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def _timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t0


def unseamed_stage(cell, out: Path, *, strain=0.5, steps=25, progress=False, name="unseamed_compression",
                   geometry: str = "linear", friction: float | None = None, curve=None) -> tuple:
    """Yarn-level compression of the unseamed cell between plates: curve, modulus, DIN-style
    stresses, energy by yarn system; written as ``<name>.nc/.png``. ``geometry="nonlinear"``:
    the large-motion engine, with Coulomb ``friction`` (None: the cell file's, else 0).
    ``curve``: a curve computed before (e.g. the macro layer's cached law), written as it is.
    Returns (curve Dataset, summary dict, {name: path})."""

    contact = None if friction is None else Contact(friction=friction)
    what = "yarn-level" if geometry == "linear" else "large-motion"
    if curve is None:
        with heartbeat(f"{what} compression of {cell.name} to {100 * strain:g} % in {steps} steps"):
            curve, sec = _timed(compress, cell, strain=strain, steps=steps, progress=progress, geometry=geometry,
                                contact=contact)
    else:
        curve, sec = curve.copy(), float(curve.attrs.get("seconds", np.nan))
    if curve.sizes["strain"] == 0:
        raise InputError(f"unseamed compression of {cell.name} failed at once: {curve.attrs['status']}")
    summ = compression_summary(curve)
    curve.attrs.update({f"cell_{k}": v for k, v in cell.attrs().items()})
    # the linear model holds to its measured limit (the cell file's [validity]); the engine has no such bound
    lim = float((getattr(cell, "validity", None) or {}).get("linear_strain_limit", 0.30))
    curve.attrs.update(title=f"{cell.name}: {what} compression between rigid plates", seconds=sec,
                       modulus_kPa=summ["modulus_kPa"], validity_strain=lim if geometry == "linear" else 1.0)
    describe(curve, "compression", cell)
    nc = _save(_attrs(curve), out / f"{name}.nc")
    png = save(compression_chart(curve), out / f"{name}.png")
    return curve, summ, {"unseamed curve (netCDF)": nc, "unseamed curve (chart)": png}
