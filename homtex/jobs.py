"""End-to-end jobs behind the ``homtex`` command (each writes netCDF + PNG).

``main_job`` is what README's first command runs. Each stage is a function that takes an
output folder and returns the paths it wrote, so the CLI, the tests and the studies share them.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import xarray as xr

from . import __version__
from .errors import InputError


def _attrs(ds: xr.Dataset, **extra) -> xr.Dataset:
    ds.attrs.update({"homtex_version": __version__, **{k: str(v) for k, v in extra.items()}})
    return ds


def _save(ds: xr.Dataset, path: Path) -> Path:
    try:
        from .io import write_netcdf
    except ImportError:  # io.py lands with the studies issue
        ds.to_netcdf(path, engine="netcdf4")
    else:
        write_netcdf(ds, path)
    return path


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# ----------------------------------------------------------------------------- lattice demo
def lattice_demo(out: Path, *, repeat=(6, 6, 6), radius=0.05, elements_per_strut=2) -> dict:
    """Octet-truss block (E = 2 GPa, struts L/r = 14) pressed by 1 % of its height.

    Solved with every solver; writes the per-node displacement, per-element axial force and
    energy, and the solver reports. Returns {name: path}.
    """
    from .geometry.lattices import lattice_frame
    from .static import solve_static

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
            "displacement": (("node", "dof"), r.u, {"units": "mm | rad", "long_name": "nodal displacement and rotation"}),
            "x": (("node", "xyz"), f.nodes, {"units": "mm", "long_name": "node coordinates"}),
            "axial_force": ("element", r.axial_force, {"units": "N", "long_name": "axial force (tension positive)"}),
            **{f"energy_{k}": ("element", v, {"units": "N mm", "long_name": f"{k} strain energy"})
               for k, v in r.energy.items()},
            "setup_seconds": ("solver", [p.setup_seconds for p in reps], {"units": "s", "long_name": "solver setup time"}),
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
    nc = _save(ds, out / "lattice_demo.nc")

    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.5))
    from matplotlib.collections import LineCollection

    seg = np.stack([f.nodes[f.elements[:, 0]][:, [0, 2]], f.nodes[f.elements[:, 1]][:, [0, 2]]], axis=1)
    lim = np.abs(r.axial_force).max()
    lc = LineCollection(seg, array=r.axial_force, cmap="coolwarm", linewidths=0.6)
    lc.set_clim(-lim, lim)
    ax[0].add_collection(lc)
    ax[0].autoscale()
    ax[0].set_aspect("equal")
    fig.colorbar(lc, ax=ax[0], label="axial force, N")
    ax[0].set(xlabel="x, mm", ylabel="z, mm", title=f"octet block, {f.ndof} DOF: axial force (side view)")
    names = list(results)
    ax[1].bar(names, [p.setup_seconds + p.solve_seconds for p in reps])
    for i, p in enumerate(reps):
        ax[1].text(i, p.setup_seconds + p.solve_seconds, f"{p.iterations} it", ha="center", va="bottom")
    ax[1].set(ylabel="setup + solve, s", title="solvers on the same system")
    fig.tight_layout()
    png = out / "lattice_demo.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return {"lattice demo (netCDF)": nc, "lattice demo (chart)": png}


# ----------------------------------------------------------------------------- main job
def main_job(out: Path, *, quick: bool = False) -> dict:
    """The README's main job. Returns {description: path} of everything written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    outputs = {}
    t0 = time.perf_counter()
    outputs.update(lattice_demo(out, repeat=(3, 3, 3) if quick else (6, 6, 6)))
    print(f"[{time.perf_counter() - t0:6.1f} s] lattice demo done", flush=True)
    return outputs


def cell_summary(path, out: Path) -> dict:
    raise InputError("cell summaries need homtex.cells (not available yet)")


def homogenize_cell(path, out: Path, *, solver="amg"):
    """Effective stiffness of a periodic cell file: netCDF + a PNG of C and the constants.

    Returns (Dataset, [paths]).
    """
    from .cells import load_cell
    from .periodic import homogenize

    cell = load_cell(path)
    res = homogenize(cell.frame, solver=solver)
    ds = res.to_dataset()
    ds.attrs.update({f"cell_{k}": v for k, v in cell.attrs().items()})
    _attrs(ds, title=f"effective stiffness of {cell.name}")
    out = Path(out)
    nc = _save(ds, out / f"{cell.name}_homogenized.nc")

    plt = _plt()
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    C = res.C
    im = ax.imshow(C, cmap="viridis")
    for (i, j), v in np.ndenumerate(C):
        ax.text(j, i, f"{v:.3g}", ha="center", va="center", fontsize=7, color="w")
    ax.set_xticks(range(len(res.components)), res.components)
    ax.set_yticks(range(len(res.components)), res.components)
    fig.colorbar(im, ax=ax, label=res.units)
    consts = ", ".join(f"{k}={v:.3g}" for k, v in res.engineering_constants().items())
    ax.set_title(f"{cell.name}: C ({res.units})\n{consts}", fontsize=8)
    fig.tight_layout()
    png = out / f"{cell.name}_homogenized.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return ds, [nc, png]


def compress_cell(path, out: Path, *, strain=0.3, steps=20):
    raise InputError("not available yet")


def seam_cell(path, out: Path, *, seam_distance, prestrain=None):
    raise InputError("not available yet")


def macro_cell(path, out: Path, *, seam_distance=None, height_scatter=0.0, seed=0):
    raise InputError("not available yet")


def plot_file(path, out=None) -> Path:
    """A chart of any homtex netCDF file: every 1-D variable against its dimension
    (one panel per dimension, variables with the same units share an axis)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such file: {path}")
    with xr.open_dataset(path) as ds:
        ds = ds.load()
    groups: dict = {}
    for name, v in ds.data_vars.items():
        if v.ndim == 1 and np.issubdtype(v.dtype, np.number):
            groups.setdefault(v.dims[0], []).append(name)
    if not groups:
        raise InputError(f"{path}: no 1-D numeric variable to plot")
    plt = _plt()
    fig, axes = plt.subplots(len(groups), 1, figsize=(7, 3.2 * len(groups)), squeeze=False)
    for ax, (dim, names) in zip(axes[:, 0], groups.items()):
        xdim = ds[dim] if dim in ds.coords else np.arange(ds.sizes[dim])
        for name in names[:8]:
            v = ds[name]
            ax.plot(np.asarray(xdim), v.values, marker=".",
                    label=f"{v.attrs.get('long_name', name)} [{v.attrs.get('units', '')}]")
        unit = ds[dim].attrs.get("units", "") if dim in ds.coords else ""
        ax.set(xlabel=f"{dim} [{unit}]" if unit else dim)
        ax.legend(fontsize=7)
    fig.suptitle(ds.attrs.get("title", path.name), fontsize=9)
    fig.tight_layout()
    png = Path(out) if out else path.with_suffix(".png")
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png
