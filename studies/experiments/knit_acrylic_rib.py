"""The acrylic 1x1 rib of a hand-knitting yarn pulled along the wales and along the courses to 50 %
(issue 23): how much softer the rib is across than along, and where it stiffens along the wales.

``cells/rib_1x1_acrylic.toml`` (worsted-weight acrylic, Singal et al. 2024: 2.66 mm, B = 0.045
N mm^2, a compressible shell fitted to their plate test, loop length 16.1 mm, yarn-yarn friction 0.3)
is relaxed once with ``homtex.relax`` (take-down 0.06 N per 5 needles) and pulled with
``homtex.tensile(..., specimen="cell")`` (the periodic cell, free lateral contraction) along the
wales and along the courses to 50 % in 2 % levels, with the cell file's friction (``--friction 0``:
frictionless, for comparison; docs/knits.md).

Recorded: force per width (N/mm, over the width across the test direction at the start), the width,
the energy split and balance, the Newton iterations and process CPU seconds; the ratio wale / course
force per width at 20 %; the strain where the wale curve stiffens (its secant slope over a level first
exceeds ``STIFFEN`` times its mean slope over the first 20 %).

Usage::

    python studies/experiments/knit_acrylic_rib.py [--quick] [--out DIR] [--no-docs] [--friction MU]

Writes ``knit_acrylic_rib.nc`` (dims ``direction``, ``strain``) and ``knit_acrylic_rib.png`` into OUT
(default results/knit_acrylic_rib) and copies the chart to docs/studies/ (not with --quick). Full
run: about 20 minutes of CPU on the 2-core machine.
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

import homtex
from homtex.knits.relax import cell_friction

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import add_docs_option, parser, publish, pyplot, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")
DIRECTIONS = ("wale", "course")
STIFFEN = 10.0


def stiffening_strain(strain: np.ndarray, f: np.ndarray, base: float = 0.2) -> float:
    """First strain at which the level's secant slope exceeds STIFFEN x the mean slope to ``base``."""
    k0 = int(np.searchsorted(strain, base, side="right")) - 1
    if k0 < 1:
        return float("nan")
    mean = (f[k0] - f[0]) / (strain[k0] - strain[0])
    slope = np.diff(f) / np.diff(strain)
    hit = np.flatnonzero(slope > STIFFEN * max(mean, 1e-300))
    hit = hit[hit >= k0]
    return float(strain[hit[0]]) if hit.size else float("nan")


def summarise(tests: dict, relaxed_attrs: dict, relax_cpu: float, mu: float) -> xr.Dataset:
    """One Dataset over ``direction`` from {direction: (tensile Dataset, CPU seconds)}: the curves,
    the wale / course ratio at 20 % and where the wales stiffen in its attrs."""
    runs = []
    for d in DIRECTIONS:
        ds, cpu = tests[d]
        keep = ds[["force_per_width", "force", "width", "extension", "axial", "torsion", "bending_y", "bending_z",
                   "shear", "contact_energy", "friction_energy", "external_work", "energy_balance", "newton_iterations"]]
        keep["status"] = ((), str(ds.attrs["status"]))
        keep["cpu_s"] = ((), cpu, {"units": "s", "long_name": "process CPU time of the tensile test"})
        keep["gauge_length"] = ((), float(ds.attrs["gauge_length_mm"]), {"units": "mm", "long_name": "gauge length"})
        keep.attrs = {}
        runs.append(keep)
    res = xr.concat(runs, dim="direction", join="outer").assign_coords(direction=("direction", list(DIRECTIONS)))
    s20 = min(0.2, float(res.strain.max()))
    fw = res.force_per_width
    ratio = float(fw.sel(direction="wale").sel(strain=s20, method="nearest")
                  / fw.sel(direction="course").sel(strain=s20, method="nearest"))
    w = res.sel(direction="wale")
    st = stiffening_strain(w.strain.values, w.force_per_width.values)
    res.attrs.update(title=f"acrylic 1x1 rib along the wales and the courses (periodic cell, friction {mu:g})",
                     ratio_strain=s20, wale_over_course_at_20=ratio, wale_stiffening_strain=st,
                     stiffening_rule=f"secant slope over a level above {STIFFEN:g} x the mean slope to 20 %",
                     relax_cpu_s=relax_cpu, relaxed_wale_spacing_mm=relaxed_attrs["wale_spacing_mm"],
                     relaxed_course_spacing_mm=relaxed_attrs["course_spacing_mm"], friction=mu)
    return res


def chart(ds: xr.Dataset, path):
    plt = pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 4.8))
    for d in ds.direction.values:
        c = ds.sel(direction=d)
        label = f"along the {d}s (status {c.status.values})"
        f = c.force_per_width.values
        ax.plot(100 * c.strain.values, np.where(f > 1e-5, f, np.nan), marker=".", label=label)  # 0 at the start
        bx.plot(100 * c.strain.values, f, marker=".", label=label)
    s20 = float(ds.attrs["ratio_strain"])
    ax.set_yscale("log")
    ax.axvline(100 * s20, color="0.5", lw=0.8, ls=":")
    ax.annotate(f"wale / course at {100 * s20:.0f} %: {float(ds.attrs['wale_over_course_at_20']):.3g}x",
                (100 * s20, float(ds.force_per_width.sel(direction="course").sel(strain=s20, method="nearest"))),
                textcoords="offset points", xytext=(8, -20), fontsize=8)
    st = float(ds.attrs["wale_stiffening_strain"])
    if np.isfinite(st):
        bx.axvline(100 * st, color="C0", lw=0.8, ls="--", label=f"wales stiffen ({100 * st:.0f} %)")
    for a, scale in ((ax, "log"), (bx, "linear")):
        a.set_xlabel("strain (extension / gauge length), %")
        a.set_ylabel("force per width, N/mm")
        a.grid(alpha=0.3, which="both")
        a.legend(fontsize=8)
        mu = float(ds.attrs["friction"])
        a.set_title(f"acrylic 1x1 rib, periodic cell, {'frictionless' if mu == 0 else f'friction {mu:g}'} "
                    f"({scale} scale)", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def main(argv=None):
    p = add_docs_option(parser(__file__, __doc__))
    p.add_argument("--friction", type=float, default=None,
                   help="yarn-yarn friction (default the cell file's, 0.3)")
    args = p.parse_args(argv)
    out = setup(args)
    cell = homtex.load_cell("rib_1x1_acrylic")
    strain, steps = (0.04, 2) if args.quick else (0.5, 25)
    if args.quick:                      # coarse elements: the suite runs the quick mode
        cell = cell.replace(**{"resolution.element_length": 2.0})
    t0 = time.process_time()
    mu = cell_friction(cell, args.friction)
    relaxed = homtex.relax(cell, friction=mu, cache=False)
    relax_cpu = time.process_time() - t0
    tests = {}
    for d in DIRECTIONS:
        t1 = time.process_time()
        ds = homtex.tensile(relaxed, strain=strain, direction=d, steps=steps, friction=mu)
        tests[d] = (ds, time.process_time() - t1)
        log.info("%s: %s, %.0f s CPU; force per width %s N/mm", d, ds.attrs["status"], tests[d][1],
                 np.array2string(ds.force_per_width.values, precision=4))
    res = summarise(tests, relaxed.attrs, relax_cpu, mu)
    s20, ratio, st = res.attrs["ratio_strain"], res.attrs["wale_over_course_at_20"], res.attrs["wale_stiffening_strain"]
    save_netcdf(res, out / "knit_acrylic_rib.nc")
    path = chart(res, out / "knit_acrylic_rib.png")
    log.info("wale / course force per width at %.0f %%: %.4g; wales stiffen at %.3g; CPU relax %.0f s, tensile %s s",
             100 * s20, ratio, st, relax_cpu, np.array2string(res.cpu_s.values, precision=0))
    publish(args, path)
    return res


if __name__ == "__main__":
    main()
