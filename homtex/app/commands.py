"""The stage commands of the ``homtex`` command line: one function per subcommand, writing
netCDF + PNG into an output folder and returning the Dataset and the paths.

Output names start with the cell FILE's stem, sanitised (``cells/spacer_20mm.toml`` ->
``spacer_20mm_...``): two cells never overwrite each other's files, and a cell's ``name``
field (free text in the file) never becomes a path.
"""

from __future__ import annotations

import difflib
import logging
import math
from pathlib import Path

import numpy as np
import xarray as xr

from ..analysis.homogenize import homogenize
from ..cells import find_cell, load_cell, shipped_cells
from ..errors import InputError
from ..macro import LAW_STEPS, LAW_STRAIN, engine_law, macro_curve
from ..output.charts import save, seam_profile_chart
from ..output.charts_data import chart, generic_chart, homogenization_chart
from ..output.plot import plot_cell
from ..output.vtk import write_vtk
from ..seams import seam_profile
from .paths import check_image_path, heartbeat, stem_of
from .stages import _attrs, _save, describe, unseamed_stage

log = logging.getLogger(__name__)


# ----------------------------------------------------------------------------- cells


def load(cell_arg):
    """The cell of a command-line CELL argument (a file path or a shipped cell name); a wrong
    name is an InputError that lists the shipped cells and the closest one."""
    text = str(cell_arg)
    if not text.strip():
        raise InputError(f"CELL is empty: give a .toml cell file or a shipped cell name ({', '.join(shipped_cells())})")
    p = find_cell(text)
    if p.is_dir():
        raise InputError(f"{text}: is a folder, not a cell file (give a .toml cell file or a shipped cell name: "
                         f"{', '.join(shipped_cells())})")
    if not p.exists():
        names = shipped_cells()
        near = difflib.get_close_matches(Path(text).stem, names, n=1)
        raise InputError(f"{text}: no such cell file, nor a shipped cell of that name"
                         + (f" (did you mean {near[0]}?)" if near else "")
                         + f"; shipped cells: {', '.join(names)}")
    return load_cell(p)


def cell_summary(path, out: Path) -> dict:
    """Picture (yarn systems coloured), VTK (if meshio is installed) and a text summary,
    written as ``<stem>_cell.png/.vtu/.txt``."""

    cell = load(path)
    out = Path(out)
    stem = stem_of(cell)
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
    paths = {"picture": plot_cell(cell, out / f"{stem}_cell.png",
                                  title=f"{cell.name}: {f.n_elements} elements, {f.ndof} DOF")}
    try:

        paths["VTK"] = write_vtk(f, out / f"{stem}_cell.vtu")
    except InputError as exc:   # meshio missing
        log.warning("  (no VTK: %s)", exc)
    txt = out / f"{stem}_cell.txt"
    txt.write_text("\n".join(lines) + "\n")
    paths["summary"] = txt
    return paths


def homogenize_summary(ds) -> str:
    """One line: the engineering constants (moduli in the Dataset's units), the solver's largest
    relative residual and its time."""
    unit = str(ds["C"].attrs.get("units", ""))
    consts = [k for k in ds.data_vars if ds[k].ndim == 0 and k[:1] in ("E", "G", "n")]
    text = ", ".join(f"{k} {float(ds[k]) + 0.0:.4g}" + ("" if k.startswith("nu") else f" {unit}") for k in consts)
    seconds = float(ds.solve_seconds.sum()) + float(ds.attrs.get("setup_seconds", 0.0))
    return (f"{text or 'no engineering constants (a free or degenerate cell)'}; largest relative residual "
            f"{float(ds.residual.max()):.1e}; {seconds:.2g} s")


def homogenize_cell(path, out: Path, *, solver="amg"):
    """Effective stiffness of a periodic cell file: ``<stem>_homogenized.nc`` + a chart of C and
    the engineering constants. Returns (Dataset, [paths])."""

    cell = load(path)
    with heartbeat(f"homogenisation of {cell.name} ({solver})"):
        res = homogenize(cell.frame, solver=solver)
    ds = res.to_dataset()
    ds.attrs.update({f"cell_{k}": v for k, v in cell.attrs().items()})
    _attrs(ds, title=f"effective stiffness of {cell.name}")
    describe(ds, "homogenization", cell, coords={
        "row": ("1", "Voigt component (row of C)"), "col": ("1", "Voigt component (column of C)"),
        "row_full": ("1", "Voigt component (row of C_full)"), "col_full": ("1", "Voigt component (column of C_full)"),
        "case": ("1", "unit load case (Voigt component)")})
    out = Path(out)
    stem = stem_of(cell)
    nc = _save(ds, out / f"{stem}_homogenized.nc")
    png = save(homogenization_chart(ds), out / f"{stem}_homogenized.png")
    return ds, [nc, png]


def compress_cell(path, out: Path, *, strain=0.3, steps=20, geometry="nonlinear", friction=None):
    """Yarn-level compression between rigid plates, by default on the large-motion engine (as
    ``homtex.compress``): ``<stem>_compression.nc/.png`` (``<stem>_compression_linear`` with
    ``geometry="linear"``)."""
    cell = load(path)
    name = f"{stem_of(cell)}_compression" + ("" if geometry == "nonlinear" else "_linear")
    curve, summ, paths = unseamed_stage(cell, Path(out), strain=strain, steps=steps, progress=True, name=name,
                                        geometry=geometry, friction=friction)
    line = compress_summary(curve)
    log.info(line)
    return curve, list(paths.values()), line


def _levels(n: int, at_most: int = 5) -> list:
    """Indices of up to ``at_most`` levels spread evenly over ``n`` (first and last included)."""
    return sorted({int(round(i)) for i in np.linspace(0, n - 1, min(n, at_most))})


def compress_summary(ds) -> str:
    """One line: stress at up to five levels, the force on the 121 cm^2 plate at the end, the worst
    energy balance (engine), the status."""
    s, sig = ds.strain.values, ds.stress.values
    pick = _levels(len(s))
    parts = [f"{ds.attrs.get('geometry', '?')} model: stress " + " / ".join(f"{sig[i]:.4g}" for i in pick)
             + " kPa at " + " / ".join(f"{100 * s[i]:.3g}" for i in pick) + " %"]
    if len(s):
        parts.append(f"{sig[-1] * 12.1:.4g} N on a 121 cm^2 plate at {100 * s[-1]:.3g} %")
    if "energy_balance" in ds and ds.energy_balance.size:
        parts.append(f"energy balance within {100 * float(np.nanmax(np.abs(ds.energy_balance.values))):.2g} %")
    parts.append(f"status {ds.attrs.get('status', 'ok')}")
    return "; ".join(parts)


def seam_cell(path, out: Path, *, seam_distance, prestrain=None, method="yarn"):
    """Cushion profile of a seam: ``<stem>_seam_<d>mm_<method>.nc/.png``."""
    cell = load(path)
    with heartbeat(f"seam profile ({method} model), d = {float(seam_distance):g} mm"):
        prof = seam_profile(cell, seam_distance=seam_distance, prestrain=prestrain, method=method)
    out = Path(out)
    describe(prof, "seam_profile", cell)
    prof.attrs.setdefault("requested_seam_distance_mm", float(seam_distance))
    stem = f"{stem_of(cell)}_seam_{float(seam_distance):g}mm_{method}"
    nc = _save(_attrs(prof, title=f"{cell.name}: cushion profile, d = {seam_distance:g} mm"), out / f"{stem}.nc")
    png = save(seam_profile_chart(prof), out / f"{stem}.png")
    return prof, [nc, png]


# ----------------------------------------------------------------------------- knits
def knit_cells() -> list:
    """Names of the shipped weft-knit cells (their file's [cell] generator is "weft_knit")."""
    from ..cells import tomllib

    names = []
    for name in shipped_cells():
        try:
            with open(find_cell(name), "rb") as fh:
                if tomllib.load(fh).get("cell", {}).get("generator") == "weft_knit":
                    names.append(name)
        except (OSError, ValueError):
            continue
    return names


def tensile_summary(ds) -> str:
    """One line: force per width at up to five levels, the width, the peak filament stress, the
    first level beyond the failure stress, the worst energy balance, the status."""
    s, f = ds.strain.values, ds.force_per_width.values
    pick = _levels(len(s))
    fs = ds.attrs.get("failure_stress_MPa")
    first = float(ds.attrs.get("first_failure_strain", math.nan))
    if fs is None:
        fail = ""
    elif math.isfinite(first):
        fail = f"; first filament beyond {fs:g} MPa at {100 * first:.3g} %"
    else:
        fail = f"; no filament beyond {fs:g} MPa"
    bal = np.abs(ds.energy_balance.values)
    return (f"{ds.attrs['direction']} direction, friction {ds.attrs['friction']:g}: force per width "
            + " / ".join(f"{f[i]:.4g}" for i in pick) + " N/mm at " + " / ".join(f"{100 * s[i]:.3g}" for i in pick)
            + f" %; width {float(ds.width[0]):.4g} -> {float(ds.width[-1]):.4g} mm; peak filament stress "
            f"{ds.attrs['peak_filament_stress_MPa']:.4g} MPa at {100 * ds.attrs['peak_strain']:.3g} %{fail}; "
            f"energy balance within {100 * float(np.nanmax(bal)) if bal.size else math.nan:.2g} %; "
            f"status {ds.attrs.get('status', 'ok')}")


def tensile_cell(path, out: Path, *, strain, direction="wale", steps=None, friction=None):
    """A weft-knit cell relaxed (``homtex.relax(cell, friction=friction)``) and its periodic cell
    pulled (``homtex.tensile(relaxed, strain=..., direction=..., steps=..., friction=...)``), as
    ``homtex.tensile(cell, ...)`` computes it: ``<stem>_tensile_<direction>.nc``, the force per
    width chart ``.png`` and the energy split ``<stem>_tensile_<direction>_energy.png``. The
    relaxation is computed each time (the result cache keeps Datasets, not relaxed cells).
    Returns (Dataset, [paths], summary line)."""
    from ..knits import relax, tensile
    from ..knits.charts import energy_split_chart
    from ..output.charts_data import knit_tensile_chart

    cell = load(path)
    if getattr(cell, "generator", None) != "weft_knit":
        raise InputError(f"{path}: not a weft-knit cell (its generator is {getattr(cell, 'generator', None)!r}, "
                         f"not 'weft_knit'); homtex tensile takes a weft-knit cell: {', '.join(knit_cells())}")
    with heartbeat(f"relaxation of {cell.name}"):
        relaxed = relax(cell, friction=friction)
    with heartbeat(f"tensile test of {cell.name} along the {direction}s to {100 * float(strain):g} %"):
        ds = tensile(relaxed, strain=strain, direction=direction, steps=steps, friction=friction, progress=True)
    ra = relaxed.attrs
    ds.attrs.update({k: v for k, v in ra.items() if k.startswith(("relaxed_", "generated_"))})
    ds.attrs.update(relax_newton_iterations=ra["newton_iterations"], relax_cpu_seconds=ra["cpu_seconds"],
                    relax_energy_balance=ra["energy_balance"], take_down_N=ra["take_down_N"])
    ds.attrs.update({f"cell_{k}": v for k, v in cell.attrs().items()})
    describe(ds, "knit_tensile", cell)
    out = Path(out)
    stem = f"{stem_of(cell)}_tensile_{direction}"
    title = f"{cell.name}: periodic cell pulled along the {direction}s"
    nc = _save(_attrs(ds, title=title), out / f"{stem}.nc")
    png = save(knit_tensile_chart(ds), out / f"{stem}.png")
    energy = save(energy_split_chart(ds, title=f"{cell.name}: energy split over the extension ({direction}s, "
                                                f"friction {ds.attrs['friction']:g})"), out / f"{stem}_energy.png")
    line = tensile_summary(ds)
    log.info(line)
    return ds, [nc, png, energy], line


# ----------------------------------------------------------------------------- macro layer
def read_dataset(path, what="netCDF file") -> xr.Dataset:
    """A netCDF file loaded into memory; InputError naming the file when it is missing, a folder
    or not netCDF."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{p}: is a folder, not a {what}")
    if not p.exists():
        raise InputError(f"{p}: no such file")
    try:
        with xr.open_dataset(p, engine="netcdf4") as ds:
            return ds.load()
    except PermissionError:
        raise InputError(f"{p}: cannot read it (permission denied)") from None
    except (OSError, ValueError, RuntimeError, TypeError, KeyError, IndexError, UnicodeError) as exc:
        raise InputError(f"{p}: not a {what} homtex can read ({type(exc).__name__}: {exc})") from None


def _stored_curve(path) -> xr.Dataset:
    ds = read_dataset(path, "compression curve (netCDF)")
    if "stress" not in ds or "strain" not in ds.coords:
        raise InputError(f"{path}: not a compression curve (it has no 'stress' over 'strain'; `homtex compress` "
                         f"writes one); its variables: {', '.join(map(str, ds.data_vars)) or 'none'}")
    if not np.isfinite(ds.stress.values).any():
        raise InputError(f"{path}: the compression curve has no finite points (status: {ds.attrs.get('status', '?')})")
    return ds


def macro_summary(ds) -> str:
    """One line: max force, force at 30 % compression, first contact, status."""
    w, F = ds.plate_displacement.values, ds.force.values
    H0 = float(ds.attrs["thickness_mm"])
    i = int(np.nanargmax(F)) if np.isfinite(F).any() else 0
    w30 = 0.3 * H0
    f30 = float(np.interp(w30, w, F)) if w[-1] >= w30 - 1e-9 else math.nan
    touch = np.flatnonzero(F > 0)
    first = float(w[touch[0]]) if touch.size else math.nan
    return (f"max force {F[i]:.1f} N at {w[i]:.2f} mm ({100 * w[i] / H0:.0f} %); force at 30 % ({w30:.1f} mm) "
            f"{f30:.1f} N; first contact at {first:.2f} mm (crests {float(ds.attrs['first_contact_mm']):.2f} mm "
            f"below the {H0:g} mm plate distance); law: {ds.attrs.get('compression_law', '?')}; "
            f"status {ds.attrs.get('status', 'ok')}")


def macro_cell(path, out: Path, *, seam_distance=None, height_scatter=0.0, seed=0, pre_stress="thread",
               slack_travel=None, seam_method="yarn", steps=None, strain=None, curve=None, law="columns"):
    """Macro cushion layer of a seamed specimen under the 121 cm^2 plate:
    ``<stem>_macro_<noseam|d mm>.nc/.png``. The unseamed compression law comes from ``curve``
    (a stored ``homtex compress`` netCDF file) or is the large-motion engine's curve to 70 % in
    ``steps`` plate steps (default 35), as ``macro_curve(cell)`` computes it
    (:func:`homtex.macro.engine_law`, cached): the command and the API give the same answer.
    ``strain``: final punch travel / thickness (default 0.5; with a stored curve, where it ends, at most
    0.5). ``law``: macro_curve's ``law`` ("columns" or "cushion"). Returns (Dataset, [paths], summary line)."""

    cell = load(path)
    mode, law = law, None                 # (below, ``law`` is the unseamed compression law)
    if mode == "cushion" and seam_distance is None:
        raise InputError("--law cushion needs --distance (the seam distance, mm): without seams every column "
                         "follows the unseamed law (--law columns)")
    if curve is not None:
        law = _stored_curve(curve)
        if strain is None:
            strain = min(0.5, float(np.nanmax(law.strain.values)))
        source = f"stored curve {curve} ({law.sizes['strain']} points to {float(law.strain.max()):.3g})"
    else:
        strain = 0.5 if strain is None else strain
        n = LAW_STEPS if steps is None else int(steps)
        to = max(float(strain), LAW_STRAIN)
        with heartbeat(f"compression law of {cell.name}: the engine to {100 * to:g} % in {n} steps"):
            law = engine_law(cell, strain=to, steps=n)
        source = f"computed, the large-motion engine to {100 * to:g} % in {n} plate steps"
    ds = macro_curve(cell, seam_distance=seam_distance, height_scatter=height_scatter, seed=seed,
                     pre_stress=pre_stress, slack_travel=slack_travel, curve=law, strain=strain,
                     profile_options={"method": seam_method}, law=mode)
    ds.attrs.update(seam_method=seam_method, compression_law=source)
    describe(ds, "macro_curve", cell)
    out = Path(out)
    stem = f"{stem_of(cell)}_macro_" + ("noseam" if seam_distance is None else f"{float(seam_distance):g}mm")
    nc = _save(_attrs(ds, title=f"{cell.name}: macro cushion layer"), out / f"{stem}.nc")
    line = macro_summary(ds)
    log.info(line)
    return ds, [nc, plot_file(nc, out / f"{stem}.png")], line


# ----------------------------------------------------------------------------- plot
def parse_sel(items) -> dict:
    """["dim=value", ...] -> {dim: "value"}; InputError for an item without '='."""
    out = {}
    for it in items or []:
        dim, eq, val = str(it).partition("=")
        if not eq or not dim.strip():
            raise InputError(f"--sel {it}: write DIM=VALUE, e.g. --sel row=11")
        out[dim.strip()] = val.strip()
    return out


def plot_file(path, out=None, *, var=None, sel=None) -> Path:
    """The chart of a homtex netCDF file: the dedicated chart of its kind (compression curve, seam
    profile, macro curve, study result, homogenisation, ...), else one panel per unit.
    ``out``: image file (format from its extension; default: the file with .png)."""
    path = Path(path)
    png = check_image_path(Path(out) if out else path.with_suffix(".png"))
    ds = read_dataset(path)
    try:
        fig = chart(ds, var=var, sel=parse_sel(sel) if isinstance(sel, (list, tuple)) else sel)
    except InputError:
        raise
    except (KeyError, ValueError, IndexError, TypeError, AttributeError) as exc:
        log.warning("  the dedicated chart of %s failed (%s: %s); drawing the generic one", path.name,
                    type(exc).__name__, exc)
        fig = generic_chart(ds)
    return save(fig, png)


__all__ = ["cell_summary", "compress_cell", "compress_summary", "homogenize_cell", "homogenize_summary", "knit_cells",
           "load", "macro_cell", "macro_summary", "plot_file", "read_dataset", "seam_cell", "tensile_cell",
           "tensile_summary"]
