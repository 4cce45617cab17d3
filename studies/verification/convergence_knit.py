"""Element-size convergence of the weft-knit cells (issue 23): the relaxed loop geometry and the
wale tensile curve of the E-glass jersey and 1x1 rib at several element lengths, and the accuracy
each buys against its run time.

Each cell (``cells/jersey_eglass.toml``, ``cells/rib_1x1_eglass.toml``, frictionless as shipped) is
rebuilt with ``resolution.element_length`` = 0.4 / 0.2 (shipped) / 0.1 mm, relaxed with
``homtex.relax`` (take-down 0.06 N per 5 needles) and pulled along the wales with
``homtex.tensile(..., specimen="cell")`` to 40 % in 8 levels. Recorded per element length: the
relaxed wale and course spacing and loop length, the force per width at every level, the status,
the Newton iterations and the process CPU seconds of relaxation and test. The error of a
resolution is its largest relative difference in force per width to the finest one over the levels
where the finest carries at least 1 % of its final force, and over those up to 30 % (the loops
lock up at the end, where the curve is steep and a small difference in strain is a large difference
in force: also reported as the strain where each curve reaches 1 N/mm).

Usage::

    python studies/verification/convergence_knit.py [--quick] [--out DIR] [--no-docs]

Writes ``convergence_knit.nc`` (dims ``cell``, ``element_length``, ``strain``) and
``convergence_knit.png`` (curves per resolution; error against CPU time) into OUT (default
results/convergence_knit) and copies the chart to docs/studies/ (not with --quick). Full run:
about ten minutes of CPU on the 2-core machine (the 0.1 mm rib most of it).
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

import homtex

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import add_docs_option, parser, publish, pyplot, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")
CELLS = ("jersey_eglass", "rib_1x1_eglass")
LENGTHS = (0.4, 0.2, 0.1)             # mm; 0.2 is what the cell files ship


def run_one(name: str, h: float, strain: float, steps: int) -> xr.Dataset:
    """Relax and pull one cell at element length ``h`` (mm); the curve with its geometry and CPU in attrs."""
    cell = homtex.load_cell(name).replace(**{"resolution.element_length": h})
    t0 = time.process_time()
    relaxed = homtex.relax(cell, cache=False)
    t1 = time.process_time()
    ds = homtex.tensile(relaxed, strain=strain, direction="wale", steps=steps)
    t2 = time.process_time()
    a = relaxed.attrs
    out = ds[["force_per_width", "newton_iterations"]].copy()
    out.attrs = {"status": ds.attrs["status"], "relax_cpu_s": t1 - t0, "tensile_cpu_s": t2 - t1,
                 "wale_spacing_mm": a["wale_spacing_mm"], "course_spacing_mm": a["course_spacing_mm"],
                 "loop_length_mm": a["loop_length_mm"], "n_elements": int(relaxed.cell.frame.n_elements)}
    log.info("%s at %.3g mm (%d elements): relaxed wale %.4f / course %.4f mm in %.1f s CPU; tensile %s in %.1f s "
             "CPU; force per width %s N/mm", name, h, out.attrs["n_elements"], a["wale_spacing_mm"],
             a["course_spacing_mm"], t1 - t0, ds.attrs["status"], t2 - t1,
             np.array2string(ds.force_per_width.values, precision=4))
    return out


def errors(ds: xr.Dataset, before: float = 0.3) -> xr.Dataset:
    """Per cell and resolution: largest relative force difference to the finest resolution (over the
    levels where the finest carries >= 1 % of its final force; and over those up to ``before``, ahead
    of the lock-up) and the strain at 1 N/mm."""
    fine = ds.force_per_width.isel(element_length=-1)
    mask = fine >= 0.01 * fine.isel(strain=-1)
    diff = np.abs(ds.force_per_width - fine) / fine
    rel = diff.where(mask).max("strain")
    early = diff.where(mask & (ds.strain <= before + 1e-9)).max("strain")
    shift = xr.apply_ufunc(_strain_at, ds.force_per_width, input_core_dims=[["strain"]], vectorize=True,
                           kwargs={"strain": ds.strain.values})
    return xr.Dataset({"force_error": rel.assign_attrs(units="1", long_name="largest relative force difference to "
                                                       "the finest resolution"),
                       "force_error_early": early.assign_attrs(units="1", long_name="largest relative force "
                                                               f"difference to the finest resolution to {before:g}"),
                       "strain_at_1Nmm": shift.assign_attrs(units="1", long_name="strain where the force per "
                                                            "width first reaches 1 N/mm")})


def _strain_at(f, strain, level=1.0):
    k = np.flatnonzero(f >= level)
    if k.size == 0 or k[0] == 0:
        return np.nan
    i = k[0]
    return strain[i - 1] + (level - f[i - 1]) / (f[i] - f[i - 1]) * (strain[i] - strain[i - 1])


def chart(ds: xr.Dataset, path):
    plt = pyplot()
    n = ds.sizes["cell"]
    fig, axes = plt.subplots(1, n + 1, figsize=(5 * (n + 1), 4.6))
    for ax, name in zip(axes[:n], ds.cell.values):
        for h in ds.element_length.values:
            d = ds.sel(cell=name, element_length=h)
            ax.semilogy(100 * ds.strain.values, d.force_per_width.values, marker=".",
                        label=f"{h:g} mm elements ({int(d.n_elements)}), {float(d.cpu_s):.0f} s CPU")
        ax.set_xlabel("strain along the wales (extension / gauge length), %")
        ax.set_ylabel("force per width, N/mm")
        ax.set_title(f"{name}: wale tensile test, periodic cell", fontsize=10)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    bx = axes[n]
    for name in ds.cell.values:
        d = ds.sel(cell=name).isel(element_length=slice(0, -1))
        line, = bx.loglog(d.cpu_s.values, 100 * d.force_error.values, marker="o", label=f"{name}, to the end")
        bx.loglog(d.cpu_s.values, 100 * d.force_error_early.values, marker="o", mfc="none", ls="--",
                  color=line.get_color(), label=f"{name}, to 30 %")
        for h, x, y in zip(d.element_length.values, d.cpu_s.values, 100 * d.force_error.values):
            bx.annotate(f"{h:g} mm", (x, y), textcoords="offset points", xytext=(5, 5), fontsize=8)
    bx.set_xlabel("CPU time, relaxation and test, s")
    bx.set_ylabel("largest force difference to the finest elements, %")
    bx.set_title(f"accuracy against run time (reference: {float(ds.element_length[-1]):g} mm elements)", fontsize=10)
    bx.grid(alpha=0.3, which="both")
    bx.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)


def main(argv=None):
    args = add_docs_option(parser(__file__, __doc__)).parse_args(argv)
    out = setup(args)
    cells, lengths, strain, steps = ((CELLS[:1], (0.65, 0.4), 0.04, 2) if args.quick
                                     else (CELLS, LENGTHS, 0.4, 8))
    rows = []
    for name in cells:
        runs = [run_one(name, h, strain, steps) for h in lengths]
        per = xr.concat(runs, dim="element_length", join="outer", combine_attrs="drop")
        for key in ("status", "wale_spacing_mm", "course_spacing_mm", "loop_length_mm", "n_elements"):
            per[key] = ("element_length", [r.attrs[key] for r in runs])
        per["cpu_s"] = ("element_length", [r.attrs["relax_cpu_s"] + r.attrs["tensile_cpu_s"] for r in runs],
                        {"units": "s", "long_name": "process CPU time, relaxation and tensile test"})
        rows.append(per)
    ds = xr.concat(rows, dim="cell", join="outer")
    ds = ds.assign_coords(cell=("cell", list(cells)),
                          element_length=("element_length", np.array(lengths),
                                          {"units": "mm", "long_name": "beam element length"}))
    ds = ds.merge(errors(ds))
    ds.attrs.update(title="Element-size convergence of the weft-knit cells (wale tensile test)",
                    machine="see README; process CPU seconds")
    save_netcdf(ds, out / "convergence_knit.nc")
    path = chart(ds, out / "convergence_knit.png")
    for name in ds.cell.values:
        d = ds.sel(cell=name)
        log.info("%s: force error %s (to 30 %%: %s), strain at 1 N/mm %s, wale spacing %s, CPU %s", name,
                 np.array2string(d.force_error.values, precision=4),
                 np.array2string(d.force_error_early.values, precision=4), np.array2string(d.strain_at_1Nmm.values,
                                                                                     precision=4),
                 np.array2string(d.wale_spacing_mm.values, precision=4), np.array2string(d.cpu_s.values, precision=1))
    publish(args, path)
    return ds


if __name__ == "__main__":
    main()
