"""The stage commands of the ``homtex`` command line: one function per subcommand, writing
netCDF + PNG and returning the Dataset and the paths."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import xarray as xr

from ..analysis.homogenize import homogenize
from ..cells import load_cell
from ..errors import InputError
from ..macro import macro_curve
from ..output.plot import plot_cell, plot_profile
from ..output.vtk import write_vtk
from ..seams import seam_profile
from .stages import _attrs, _plt, _save, unseamed_stage

log = logging.getLogger(__name__)


def _load(path):

    return load_cell(path)


def cell_summary(path, out: Path) -> dict:
    """Picture (yarn systems coloured), VTK (if meshio is installed) and a text summary."""

    cell = _load(path)
    out = Path(out)
    f = cell.frame
    lines = [f"cell {cell.name} ({cell.path}): generator {cell.generator}",
             f"  {f.n_nodes} nodes, {f.n_elements} elements, {f.ndof} DOF, {f.dim_periodic}-periodic",
             *(f"  group {g}: {int(np.sum(m))} elements" for g, m in cell.groups.items()),
             *(f"  yarn {n}: {y}" for n, y in cell.yarns.items())]
    for key in ("thickness", "n_bonds", "overlaps"):
        if key in cell.info:
            v = cell.info[key]
            lines.append(f"  {key}: {len(v) if hasattr(v, '__len__') else v}")
    log.info("\n".join(lines))
    paths = {"picture": plot_cell(cell, out / f"{cell.name}.png")}
    try:

        paths["VTK"] = write_vtk(f, out / f"{cell.name}.vtu")
    except InputError as exc:   # meshio missing
        log.warning("  (no VTK: %s)", exc)
    txt = out / f"{cell.name}.txt"
    txt.write_text("\n".join(lines) + "\n")
    paths["summary"] = txt
    return paths


def homogenize_cell(path, out: Path, *, solver="amg"):
    """Effective stiffness of a periodic cell file: netCDF + a PNG of C and the constants.

    Returns (Dataset, [paths]).
    """

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
    cell = _load(path)
    curve, summ, paths = unseamed_stage(cell, Path(out), strain=strain, steps=steps, progress=True)
    log.info(f"modulus {summ['modulus_kPa']:.1f} kPa; stress at 10/25/40 %: {summ['stress_10_kPa']:.2f} / "
          f"{summ['stress_25_kPa']:.2f} / {summ['stress_40_kPa']:.2f} kPa; status {curve.attrs['status']}")
    return curve, list(paths.values())


def seam_cell(path, out: Path, *, seam_distance, prestrain=None, method="yarn"):

    cell = _load(path)
    prof = seam_profile(cell, seam_distance=seam_distance, prestrain=prestrain, method=method)
    out = Path(out)
    stem = f"{cell.name}_seam_{float(seam_distance):g}mm_{method}"
    nc = _save(_attrs(prof, title=f"cushion profile, d = {seam_distance} mm"), out / f"{stem}.nc")
    png = plot_profile(prof, out / f"{stem}.png")
    return prof, [nc, png]


def macro_cell(path, out: Path, *, seam_distance=None, height_scatter=0.0, seed=0, pre_stress="thread",
               slack_travel=None, seam_method="yarn"):

    cell = _load(path)
    ds = macro_curve(cell, seam_distance=seam_distance, height_scatter=height_scatter, seed=seed,
                     pre_stress=pre_stress, slack_travel=slack_travel,
                     profile_options={"method": seam_method})
    ds.attrs["seam_method"] = seam_method
    out = Path(out)
    stem = f"{cell.name}_macro_" + ("noseam" if seam_distance is None else f"{float(seam_distance):g}mm")
    nc = _save(_attrs(ds, title="macro cushion layer"), out / f"{stem}.nc")
    return ds, [nc, plot_file(nc, out / f"{stem}.png")]


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
