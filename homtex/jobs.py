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
    raise InputError("not available yet")


def compress_cell(path, out: Path, *, strain=0.3, steps=20):
    raise InputError("not available yet")


def seam_cell(path, out: Path, *, seam_distance, prestrain=None):
    raise InputError("not available yet")


def macro_cell(path, out: Path, *, seam_distance=None, height_scatter=0.0, seed=0):
    raise InputError("not available yet")


def plot_file(path, out=None) -> Path:
    raise InputError("not available yet")
