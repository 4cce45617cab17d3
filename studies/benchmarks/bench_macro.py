"""Macro cushion layer: run time of one curve over resolution, and the curves for d = none, 43, 24, 18 mm.

    python studies/benchmarks/bench_macro.py [--out DIR] [--curve FILE.nc] [--quick | --full]

The unseamed law is a compression curve from FILE.nc (``stress`` kPa over ``strain``, e.g. the
output of ``homtex compress``) or, by default, a stiffening stand-in sigma = 20 eps + 400 eps^3 kPa
(marked in the attributes). Cushion profiles come from ``homtex.seam_profile`` on
cells/spacer_20mm.toml (yarn level; computed once, outside the timing). Times are the best of 5
calls of ``macro_curve`` with the profile and curve injected, i.e. the macro layer alone.
``--full`` adds finer column/step resolutions; ``--quick``: d = none and 24 mm with the analytical
(foundation) profile, the coarsest resolution, best of 1 (seconds). Writes bench_macro.nc and
bench_macro.png into DIR (default results/bench_macro/).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402


def main(argv=None):
    import homtex
    from homtex.macro import macro_curve
    from homtex.output.io import read_netcdf

    ap = parser(__file__, __doc__)
    ap.add_argument("--curve", default=None, help="netCDF compression curve of the unseamed cell")
    ap.add_argument("--scatter", type=float, default=1.0, help="cushion height scatter, mm")
    ap.add_argument("--full", action="store_true", help="finer column/step resolutions in the timing")
    args = ap.parse_args(argv)
    out = setup(args)
    if args.curve:
        curve = read_netcdf(args.curve)
        source = f"compression curve {args.curve}"
    else:
        e = np.linspace(0.0, 0.6, 61)
        curve = xr.Dataset({"stress": ("strain", 20 * e + 400 * e ** 3)}, coords={"strain": e},
                           attrs={"thickness_mm": 20.0})
        source = "stand-in law sigma = 20 eps + 400 eps^3 kPa (not the yarn-level curve)"
    cell = homtex.load_cell("spacer_20mm", build=False)
    distances = [None, 24.0] if args.quick else [None, 43.0, 24.0, 18.0]
    method = "foundation" if args.quick else "yarn"
    profiles = {d: (None if d is None else homtex.seam_profile(cell, seam_distance=d, method=method))
                for d in distances}
    if args.quick:
        res = [(110, 51)]
    else:
        res = [(110, 51), (440, 201), (1760, 401)] + ([(7040, 801), (28160, 1601)] if args.full else [])
    repeat = 1 if args.quick else 5
    times = np.empty((len(distances), len(res)))
    for i, d in enumerate(distances):
        for j, (nc, ns) in enumerate(res):
            kw = dict(seam_distance=d, profile=profiles[d], curve=curve, n_columns=nc, steps=ns,
                      height_scatter=args.scatter if d else 0.0, seed=1, strain=0.5)
            macro_curve(**kw)
            best = np.inf
            for _ in range(repeat):
                t = time.perf_counter()
                macro_curve(**kw)
                best = min(best, time.perf_counter() - t)
            times[i, j] = best
            print(f"d = {d!s:5s} columns {nc:6d} steps {ns:5d}: {best * 1e3:8.3f} ms")
    curves = [macro_curve(seam_distance=d, profile=profiles[d], curve=curve, height_scatter=args.scatter if d else 0.0,
                          seed=1, strain=0.5) for d in distances]
    labels = np.array(["none" if d is None else f"{d:g}" for d in distances], dtype=object)
    ds = xr.Dataset(
        {"seconds": (("seam_distance", "resolution"), times,
                     {"units": "s", "long_name": f"run time of one macro_curve call (best of {repeat})"}),
         "n_columns": ("resolution", [r[0] for r in res], {"units": "1", "long_name": "cushion columns"}),
         "steps": ("resolution", [r[1] for r in res], {"units": "1", "long_name": "plate positions"}),
         "force": (("seam_distance", "plate_displacement"), np.array([c.force.values for c in curves]),
                   {"units": "N", "long_name": "punch force (440 columns, 201 steps)"}),
         "cushion_height": ("seam_distance", [c.attrs["cushion_height_mean_mm"] for c in curves],
                            {"units": "mm", "long_name": "mean cushion height under the plate (clipped at H0)"})},
        coords={"seam_distance": ("seam_distance", labels, {"units": "mm", "long_name": "seam distance"}),
                "resolution": ("resolution", np.arange(len(res)), {"units": "1", "long_name": "resolution level"}),
                "plate_displacement": ("plate_displacement", curves[0].plate_displacement.values,
                                       {"units": "mm", "long_name": "punch displacement from 20 mm"})},
        attrs={"law": source, "height_scatter_mm": args.scatter, "seed": 1, "profile_method": method})
    save_netcdf(ds, out / "bench_macro.nc")
    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for i, lab in enumerate(labels):
        ax[0].plot(ds.plate_displacement / 20.0 * 100, ds.force[i], label=f"d = {lab} mm")
        ax[1].loglog(ds.n_columns * ds.steps, ds.seconds[i] * 1e3, "o-", label=f"d = {lab} mm")
    ax[0].set(xlabel="compression from 20 mm (%)", ylabel="force (N)", title="macro cushion layer")
    ax[0].legend(fontsize=8)
    ax[1].set(xlabel="columns x steps", ylabel="ms per curve", title="run time")
    ax[1].legend(fontsize=8)
    fig.text(0.01, 0.01, source, fontsize=7)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    save_figure(fig, out / "bench_macro.png")
    print(f"wrote {out / 'bench_macro.nc'} and {out / 'bench_macro.png'}")
    return ds


if __name__ == "__main__":
    main()
