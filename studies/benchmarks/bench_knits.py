"""What the weft-knit computations cost (issue 23's speed targets): the relaxation of every shipped
knit cell and the periodic wale tensile tests of the E-glass and the acrylic 1x1 rib.

Cases (each timed in wall and process CPU seconds, with its Newton iterations and the CPU per
iteration, and the cell's element count):

1. ``homtex.relax`` of ``jersey_eglass``, ``rib_1x1_eglass``, ``milano_eglass``, ``jersey_acrylic``,
   ``rib_1x1_acrylic`` (take-down 0.06 N per 5 needles; target: the relaxed acrylic rib and the
   equivalent-yarn E-glass rib within 60 s each);
2. ``homtex.tensile`` of the relaxed E-glass rib along the wales to 45 % in 45 levels, with the cell
   file's friction (0: the paper's frictionless filaments);
3. ``homtex.tensile`` of the relaxed acrylic rib along the wales to 50 % in 25 levels, with the cell
   file's friction 0.3 (target: within 10 minutes);
4. ``homtex.relax`` of the E-glass rib as the paper's yarn of 20 filaments, each its own beam chain
   (``yarn_model.model = "filaments"``), on MKL PARDISO's LDL^T where the ``pardiso`` extra is
   installed (its bundles make the tangent's factor fill; qdldl ("ldl") otherwise: the solver is in the
   Dataset's attrs).

Usage::

    python studies/benchmarks/bench_knits.py [--quick] [--out DIR]

``--quick``: the E-glass jersey at 0.65 mm elements, relaxed and pulled in one 2 % level, and
relaxed as 3 filaments (seconds; not the benchmark's numbers). Writes ``bench_knits.nc`` (dim ``case``) and ``bench_knits.png`` into
OUT (default results/bench_knits). Full run: about half an hour of CPU on the 2-core machine, most
of it the acrylic rib's tensile test and the 20-filament rib's relaxation.
"""

from __future__ import annotations

import logging
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

import homtex
from homtex.linalg.tangent_backends import pardiso_available

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")
RELAX = ("jersey_eglass", "rib_1x1_eglass", "milano_eglass", "jersey_acrylic", "rib_1x1_acrylic")
TENSILE = (("rib_1x1_eglass", 0.45, 45), ("rib_1x1_acrylic", 0.5, 25))
TARGETS = {"relax rib_1x1_acrylic": 60.0, "relax rib_1x1_eglass": 60.0, "tensile rib_1x1_acrylic": 600.0}


def _timed(fn, *a, **k):
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn(*a, **k)
    return out, time.perf_counter() - t0, time.process_time() - c0


def chart(ds: xr.Dataset, path):
    plt = pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 4.8))
    y = np.arange(ds.sizes["case"])
    labels = [str(c) for c in ds.case.values]
    ax.barh(y, ds.cpu_s.values, color=["C0" if c.startswith("relax") else "C1" for c in labels])
    for i, c in enumerate(labels):
        if c in TARGETS:
            ax.plot([TARGETS[c]] * 2, [i - 0.4, i + 0.4], "k-", lw=2)
    ax.plot([], [], "k-", lw=2, label="the issue's target")
    ax.set_yticks(y, labels, fontsize=8)
    ax.set_xscale("log")
    ax.set_xlabel("process CPU time, s")
    ax.set_title(f"weft knits: relaxation and wale tensile tests ({ds.attrs['machine']})", fontsize=9)
    ax.grid(alpha=0.3, axis="x", which="both")
    ax.legend(fontsize=8)
    bx.scatter(ds.n_elements.values, 1e3 * ds.cpu_per_iteration_s.values,
               c=["C0" if c.startswith("relax") else "C1" for c in labels])
    for c, x, v in zip(labels, ds.n_elements.values, 1e3 * ds.cpu_per_iteration_s.values):
        bx.annotate(c, (x, v), textcoords="offset points", xytext=(4, 3), fontsize=7)
    bx.set_xscale("log")
    bx.set_yscale("log")
    bx.set_xlabel("beam elements in the cell")
    bx.set_ylabel("CPU per counted Newton iteration, ms")
    bx.set_title("CPU over the accepted steps' Newton iterations (a test's also pays\n"
                 "for halved sub-steps, buckling checks and perturbations)", fontsize=9)
    bx.grid(alpha=0.3, which="both")
    fig.tight_layout()
    return save_figure(fig, path)


def main(argv=None):
    args = parser(__file__, __doc__).parse_args(argv)
    out = setup(args)
    rows = []

    def row(case, cell, wall, cpu, iters, status):
        rows.append({"case": case, "wall_s": wall, "cpu_s": cpu, "newton_iterations": iters,
                     "cpu_per_iteration_s": cpu / max(iters, 1), "n_elements": cell.frame.n_elements,
                     "status": status})
        log.info("%s: %.1f s wall, %.1f s CPU, %d Newton iterations (%.1f ms each), %d elements, %s", case, wall,
                 cpu, iters, 1e3 * cpu / max(iters, 1), cell.frame.n_elements, status)

    relax_names = RELAX[:1] if args.quick else RELAX
    tensile_cases = (("jersey_eglass", 0.02, 1),) if args.quick else TENSILE
    relaxed = {}
    # compile the kernels first (numba's cache is rebuilt after a code change): the first case
    # timed would otherwise pay for it
    warm = homtex.load_cell("jersey_eglass").replace(**{"resolution.element_length": 0.65})
    homtex.tensile(homtex.relax(warm, cache=False), strain=0.02, direction="wale", steps=1, friction=0.0)
    for name in relax_names:
        cell = homtex.load_cell(name)
        if args.quick:
            cell = cell.replace(**{"resolution.element_length": 0.65})
        r, wall, cpu = _timed(homtex.relax, cell, cache=False)
        relaxed[name] = r
        row(f"relax {name}", cell, wall, cpu, int(r.attrs["newton_iterations"]), str(r.attrs["status"]))
    for name, strain, steps in tensile_cases:
        r = relaxed[name]
        ds, wall, cpu = _timed(homtex.tensile, r, strain=strain, direction="wale", steps=steps)
        row(f"tensile {name}", r.cell, wall, cpu, int(ds.newton_iterations.sum()), str(ds.attrs["status"]))
    # the paper's yarn of filaments (a tangent whose bundles couple N filaments at every node)
    name, n_fil = ("jersey_eglass", 3) if args.quick else ("rib_1x1_eglass", 20)
    cell = homtex.load_cell(name).replace(**{"parameters.yarn_model.model": "filaments",
                                             "parameters.yarn_model.filaments": n_fil,
                                             **({"resolution.element_length": 0.65} if args.quick else {})})
    solver = "pardiso" if pardiso_available() else "ldl"
    with homtex.set_options(tangent_solver=solver):
        r, wall, cpu = _timed(homtex.relax, cell, cache=False)
    row(f"relax {name}, {n_fil} filaments", cell, wall, cpu, int(r.attrs["newton_iterations"]),
        str(r.attrs["status"]))
    res = xr.Dataset(
        {k: ("case", np.array([r[k] for r in rows]), {"units": u, "long_name": k.replace("_", " ")})
         for k, u in (("wall_s", "s"), ("cpu_s", "s"), ("newton_iterations", "1"), ("cpu_per_iteration_s", "s"),
                      ("n_elements", "1"), ("status", "1"))},
        coords={"case": ("case", [r["case"] for r in rows], {"units": "1", "long_name": "computation"})},
        attrs={"title": "weft knits: what relaxation and tensile tests cost",
               "machine": f"{platform.machine()}, {os.cpu_count()} CPUs", "quick": int(args.quick),
               "targets_cpu_s": str(TARGETS), "filament_tangent_solver": solver})
    save_netcdf(res, out / "bench_knits.nc")
    chart(res, out / "bench_knits.png")
    return res


if __name__ == "__main__":
    main()
