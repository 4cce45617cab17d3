"""Large rotations in the spacer cell: what co-rotational beams change, and what they do not.

Two experiments, one Dataset each (netCDF) and one chart:

1. ``unseamed``: compression of the unseamed cell with the linear model and with the large-motion
   engine (``compress(geometry="nonlinear")``: co-rotational beams, barrier contact; its own study
   is ``spacer_nonlinear_compression.py``), stress against strain, Newton iterations, run time.
2. ``layer_rigidity``: the linear seam cell with the surface layers' Young's modulus (so their
   bending rigidity) scaled by 1, 5, 15, 50: how far the seam dip spreads into the cushion.

The study once also ran the former co-rotational contact solve (linearised contact, viscous
stabilisation at two factors) on the unseamed cell and ramped a co-rotational seam cell with it;
that solver was retired (the large-motion engine is the package's one geometrically nonlinear
contact solver; the seam on the engine is studied in docs/seams.md), and its curves with it.

Usage::

    python studies/experiments/nonlinear_spacer.py [--out DIR] [--strain 0.3] [--steps 60] [--quick] [--plot-only]

Default: minutes here. ``--quick``: the cell with 1 element per segment; unseamed to 1 % in 1
step; layer factors 1 and 15 on d = 12 mm with a 1-step ramp (seconds; the numbers are not the
study's). Writes DIR/unseamed.nc, DIR/layer_rigidity.nc and DIR/nonlinear_spacer.png (default
DIR = results/nonlinear_spacer).
"""
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402


def unseamed(cell, strain, steps):
    import homtex

    curves, rows = [], []
    for geometry, label in (("linear", "linear"), ("nonlinear", "large-motion engine (barrier, PTC)")):
        t = time.perf_counter()
        ds = homtex.compress(cell, strain=strain, steps=steps, geometry=geometry)
        sec = time.perf_counter() - t
        curves.append(ds[["stress", "newton_iterations"]].expand_dims(model=[label]))
        rows.append((label, sec, status_text(ds), int(ds.attrs["steps_done"])))
        print(f"  {label:36s} {sec:6.1f} s  steps {ds.attrs['steps_done']:3d}  {status_text(ds)[:90]}", flush=True)
    out = xr.concat(curves, dim="model", join="outer")
    out["stress"].attrs.update(units="kPa", long_name="nominal compressive stress")
    out["newton_iterations"].attrs.update(units="1", long_name="Newton iterations of the step (0: linear)")
    out["seconds"] = ("model", [r[1] for r in rows], {"units": "s", "long_name": "run time of the curve"})
    out["status"] = ("model", [r[2] for r in rows], {"long_name": "'ok' or why the curve ended"})
    out.attrs.update(experiment="unseamed compression, linear model vs large-motion engine", steps=int(steps))
    return out


def status_text(ds) -> str:
    """'ok', or 'failed: <why>' (curves and profiles carry attrs status and status_detail)."""
    st = str(ds.attrs.get("status", "ok"))
    return st if st == "ok" else f"{st}: {ds.attrs.get('status_detail', '')}"


def layer_rigidity(d, eps0, factors, resolution=None, steps=4):
    import homtex

    rows = []
    for f in factors:
        cell = homtex.load_cell("spacer_20mm")
        if resolution is not None:
            cell = cell.replace(**{"resolution.elements_per_segment": resolution})
        E = cell.frame.E.copy()
        layer = np.zeros(len(E), dtype=bool)
        for g, m in cell.groups.items():
            if g != "pile":
                layer |= np.asarray(m, dtype=bool)
        E[layer] *= f
        cell._frame = cell.frame.with_(E=E)       # a what-if: same geometry, stiffer layer yarns
        ds = homtex.seam_profile(cell, seam_distance=d, prestrain=eps0, steps=steps, method="yarn",
                                 geometry="linear")
        rows.append(ds.height.values)
        x = ds.x.values
        print(f"  layer E x{f:<4g}: seam {float(ds.seam_height):.2f} mm, mid-cushion "
              f"{float(ds.height.values[np.argmax(np.abs(x))]):.2f} mm, max {float(ds.cushion_height):.2f} mm "
              f"({status_text(ds)[:40]})", flush=True)
    out = xr.Dataset({"height": (("layer_factor", "x"), np.vstack(rows), {"units": "mm", "long_name": "fabric height"})},
                     coords={"layer_factor": ("layer_factor", np.asarray(factors, float),
                                              {"units": "1", "long_name": "factor on the surface layers' Young's modulus"}),
                             "x": ("x", x, {"units": "mm", "long_name": "position across the seam"})})
    out.attrs.update(experiment="seam dip against the layers' bending rigidity (linear beams)", prestrain=eps0,
                     seam_distance_mm=float(d))
    return out


def main(argv=None):
    import homtex

    p = parser(__file__, __doc__)
    p.add_argument("--strain", type=float, default=None, help="unseamed compression (default 0.3; --quick 0.01)")
    p.add_argument("--steps", type=int, default=None, help="unseamed load steps (default 60; --quick 1)")
    p.add_argument("--distance", type=float, default=24.0)
    p.add_argument("--prestrain", type=float, default=0.3)
    p.add_argument("--plot-only", action="store_true", help="redraw the chart from DIR's netCDF files")
    a = p.parse_args(argv)
    out = setup(a)
    strain = a.strain or (0.01 if a.quick else 0.3)
    steps = a.steps or (1 if a.quick else 60)
    t0 = time.perf_counter()
    if a.plot_only:
        un, lr = (xr.load_dataset(out / f) for f in ("unseamed.nc", "layer_rigidity.nc"))
    else:
        cell = homtex.load_cell("spacer_20mm")
        if a.quick:
            cell = cell.replace(**{"resolution.elements_per_segment": 1})
        print("1. unseamed compression", flush=True)
        un = unseamed(cell, strain, steps)
        save_netcdf(un, out / "unseamed.nc")
        print("2. layer rigidity", flush=True)
        if a.quick:
            lr = layer_rigidity(12.0, a.prestrain, (1.0, 15.0), resolution=1, steps=1)
        else:
            lr = layer_rigidity(a.distance, a.prestrain, (1.0, 5.0, 15.0, 50.0))
        save_netcdf(lr, out / "layer_rigidity.nc")

    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(10, 4.2))
    for m in un.model.values:
        s = un.stress.sel(model=m)
        ax[0].plot(100 * un.strain, s, "o-" if m == "linear" else ".-", ms=3, label=f"{m} ({float(un.seconds.sel(model=m)):.0f} s)")
    ax[0].set(xlabel="compression (%)", ylabel="stress (kPa)", title="unseamed cell: linear model vs large-motion engine")
    ax[0].legend(fontsize=7)
    for f in lr.layer_factor.values:
        ax[1].plot(lr.x, lr.height.sel(layer_factor=f), "o-", ms=3, label=f"layers E x{f:g}")
    ax[1].axhline(14.33, color="k", ls=":", lw=1, label="paper: cushion 14.33 mm")
    ax[1].set(xlabel="x across the seam (mm)", ylabel="height (mm)",
              title=f"linear seam cell, eps0 = {lr.attrs['prestrain']}: layer stiffness")
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out / "nonlinear_spacer.png")
    print(f"wrote {out}/unseamed.nc, layer_rigidity.nc, nonlinear_spacer.png in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
