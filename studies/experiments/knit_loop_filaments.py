"""Loop length and filament count of the E-glass jersey (issue 23): how the wale tensile curve moves
with the two design parameters a knitter sets, and how well the knit paper's structure size factor
Xcf = m / l^3 (bending rigidity over loop length cubed) orders the forces.

``cells/jersey_eglass.toml`` (17 um E-glass filaments as one equivalent yarn: axial stiffness N E A_f,
bending and torsion rigidity N E I_f and N G J_f, contact radius of the packed bundle) is rebuilt with
loop length l = 5.5 / 6.5 (shipped) / 8 mm and N = 10 / 20 (shipped) / 40 filaments, relaxed with
``homtex.relax`` (take-down 0.06 N per 5 needles) and pulled along the wales with ``homtex.tensile``
(periodic cell, free lateral contraction, frictionless as shipped) to 40 % in 8 levels. Recorded per
case: the force per width over the strain, the relaxed wale and course spacing, status, CPU seconds;
the rise of the force per width from the start (the take-down's pre-load, the same 0.06 N per 5
needles in every case, taken off) at 10 % and 20 % against Xcf = N E I_f / l^3 (N / mm): the law
predicts force proportional to Xcf where bending dominates (the yarn's radius here grows with
sqrt(N), so the cells are not exactly similar: the log-log slope measures how far the law carries).

Usage::

    python studies/experiments/knit_loop_filaments.py [--quick] [--out DIR] [--no-docs]

Writes ``knit_loop_filaments.nc`` (dims ``loop_length``, ``filaments``, ``strain``) and
``knit_loop_filaments.png`` into OUT (default results/knit_loop_filaments) and copies the chart to
docs/studies/ (not with --quick). Full run: a few minutes of CPU on the 2-core machine.
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
LOOPS = (5.5, 6.5, 8.0)          # mm
FILAMENTS = (10, 20, 40)
E, R_F = 73000.0, 0.0085         # MPa, mm: the E-glass filament of the cell file


def xcf(n: int, loop: float) -> float:
    """The structure size factor N E I_f / l^3, N / mm (I_f = pi r^4 / 4)."""
    return n * E * np.pi * R_F ** 4 / 4.0 / loop ** 3


def run_one(loop: float, n: int, strain: float, steps: int, element: float | None) -> xr.Dataset:
    changes = {"parameters.loop_length": loop, "parameters.yarn_model.filaments": n}
    if element is not None:
        changes["resolution.element_length"] = element
    cell = homtex.load_cell("jersey_eglass").replace(**changes)
    t0 = time.process_time()
    relaxed = homtex.relax(cell, cache=False)
    ds = homtex.tensile(relaxed, strain=strain, direction="wale", steps=steps)
    cpu = time.process_time() - t0
    a = relaxed.attrs
    log.info("l = %g mm, N = %d: relaxed wale %.3f / course %.3f mm; %s, %.0f s CPU; force per width %s N/mm",
             loop, n, a["wale_spacing_mm"], a["course_spacing_mm"], ds.attrs["status"], cpu,
             np.array2string(ds.force_per_width.values, precision=4))
    out = ds[["force_per_width"]].copy()
    out["status"] = ((), str(ds.attrs["status"]))
    out["cpu_s"] = ((), cpu, {"units": "s", "long_name": "process CPU time, relaxation and test"})
    out["wale_spacing"] = ((), a["wale_spacing_mm"], {"units": "mm", "long_name": "relaxed wale spacing"})
    out["course_spacing"] = ((), a["course_spacing_mm"], {"units": "mm", "long_name": "relaxed course spacing"})
    out.attrs = {}
    return out


def rise(ds: xr.Dataset, s: float) -> np.ndarray:
    """Force per width at strain ``s`` less the one at the start (the take-down), flattened, N/mm."""
    f = ds.force_per_width
    return (f.sel(strain=s, method="nearest") - f.isel(strain=0)).values.ravel()


def slope(x: np.ndarray, y: np.ndarray) -> float:
    ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    return float(np.polyfit(np.log(x[ok]), np.log(y[ok]), 1)[0]) if ok.sum() >= 2 else float("nan")


def chart(ds: xr.Dataset, path):
    plt = pyplot()
    fig, (ax, bx, cx) = plt.subplots(1, 3, figsize=(18, 4.8))
    for i, loop in enumerate(ds.loop_length.values):
        for j, n in enumerate(ds.filaments.values):
            c = ds.sel(loop_length=loop, filaments=n)
            ax.semilogy(100 * ds.strain.values, c.force_per_width.values, color=f"C{i}",
                        ls=("-", "--", ":")[j % 3], marker=".", label=f"l = {loop:g} mm, N = {n}")
    ax.set_xlabel("strain along the wales (extension / gauge length), %")
    ax.set_ylabel("force per width, N/mm")
    ax.set_title("E-glass jersey, periodic cell, frictionless", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, ncol=2)
    X = ds.xcf.values.ravel()
    for s, m in ((0.1, "o"), (0.2, "s")):
        if s > float(ds.strain.max()) + 1e-9:
            continue
        F = rise(ds, s)
        k = float(ds.attrs[f"slope_{int(round(100 * s))}"])
        bx.loglog(X, F, m, label=f"at {100 * s:.0f} % (log-log slope {k:.2f})")
    x = np.geomspace(X.min(), X.max(), 20)
    F10 = rise(ds, 0.1)
    bx.loglog(x, np.exp(np.nanmean(np.log(F10) - np.log(X))) * x, "k:", lw=0.8, label="force proportional to Xcf")
    bx.set_xlabel("Xcf = N E I_f / l^3, N/mm")
    bx.set_ylabel("rise of the force per width from the start, N/mm")
    bx.set_title("the knit paper's structure size factor (take-down pre-load taken off)", fontsize=10)
    bx.grid(alpha=0.3, which="both")
    bx.legend(fontsize=8)
    # why: the take-down stretches the more flexible loops further along the wales before the test
    for i, loop in enumerate(ds.loop_length.values):
        c = ds.sel(loop_length=loop)
        cx.semilogx(c.xcf.values, c.course_spacing.values / loop, "o-", color=f"C{i}", label=f"l = {loop:g} mm")
        for n, x, y in zip(c.filaments.values, c.xcf.values, c.course_spacing.values / loop):
            cx.annotate(f"N = {n}", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
    cx.set_xlabel("Xcf = N E I_f / l^3, N/mm")
    cx.set_ylabel("relaxed course spacing / loop length, 1")
    cx.set_title("relaxed under the take-down: how far the loops already reach along the wales", fontsize=10)
    cx.grid(alpha=0.3, which="both")
    cx.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)


def main(argv=None):
    args = add_docs_option(parser(__file__, __doc__)).parse_args(argv)
    out = setup(args)
    loops, fils, strain, steps, element = ((LOOPS[1:2], FILAMENTS[1:], 0.1, 1, 0.65) if args.quick
                                           else (LOOPS, FILAMENTS, 0.4, 8, None))
    rows = [xr.concat([run_one(loop, n, strain, steps, element) for n in fils], dim="filaments", join="outer")
            for loop in loops]
    ds = xr.concat(rows, dim="loop_length", join="outer")
    ds = ds.assign_coords(loop_length=("loop_length", np.array(loops), {"units": "mm", "long_name": "loop length"}),
                          filaments=("filaments", np.array(fils), {"units": "1", "long_name": "filaments per yarn"}))
    ds["xcf"] = (("loop_length", "filaments"), np.array([[xcf(n, lo) for n in fils] for lo in loops]),
                 {"units": "N/mm", "long_name": "structure size factor N E I_f / l^3"})
    for s in (0.1, 0.2):
        if s <= strain + 1e-9:
            F = rise(ds, s)
            ds.attrs[f"slope_{int(round(100 * s))}"] = slope(ds.xcf.values.ravel(), F)
    ds.attrs.update(title="E-glass jersey: loop length and filament count (wale tensile test)")
    save_netcdf(ds, out / "knit_loop_filaments.nc")
    path = chart(ds, out / "knit_loop_filaments.png")
    log.info("log-log slope of force per width on Xcf: %s",
             {k: round(v, 3) for k, v in ds.attrs.items() if k.startswith("slope")})
    publish(args, path)
    return ds


if __name__ == "__main__":
    main()
