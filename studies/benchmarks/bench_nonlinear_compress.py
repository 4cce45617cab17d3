"""Run time of the large-motion compression curve: the spacer cell to 70 % with friction 0.2
(``homtex.compress(cell, strain=0.7, steps=70, geometry="nonlinear", contact=Contact(friction=0.2))``,
target: at most 60 s on the 2-core machine), against the linear model on the same levels
(``geometry="linear"``).

Each curve is timed ``--repeats`` times in this process after one warm-up run (numba kernels
compiled and cached), the median reported with the range; the Newton iterations, sub-steps and
the time per iteration come from the curve's own records. ``--quick``: 3 levels to 3 %, one
repeat.

Usage::

    python studies/benchmarks/bench_nonlinear_compress.py [--quick] [--out DIR] [--repeats N]

Writes ``bench_nonlinear_compress.nc`` and ``bench_nonlinear_compress.png`` into OUT (default
results/bench_nonlinear_compress).
"""

from __future__ import annotations

import logging
import os
import platform
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

import homtex

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")


def timed(fn, repeats):
    fn()                                                  # warm-up (JIT, caches)
    out, secs = None, []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        secs.append(time.perf_counter() - t0)
    return out, np.array(secs)


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--repeats", type=int, default=3, help="timed runs per curve (default 3)")
    a = p.parse_args(argv)
    out = setup(a)
    warnings.simplefilter("ignore")
    cell = homtex.load_cell("spacer_20mm")
    strain, steps = (0.03, 3) if a.quick else (0.7, 70)
    repeats = 1 if a.quick else max(1, a.repeats)
    runs = {
        "nonlinear, friction 0.2": lambda: homtex.compress(cell, strain=strain, steps=steps, geometry="nonlinear",
                                                           contact=homtex.Contact(friction=0.2)),
        "nonlinear, frictionless": lambda: homtex.compress(cell, strain=strain, steps=steps, geometry="nonlinear",
                                                           contact=homtex.Contact(friction=0.0)),
        "linear (frictionless)": lambda: homtex.compress(cell, strain=strain, steps=steps, geometry="linear"),
    }
    names, med, lo, hi, levels, status, its, per_it = [], [], [], [], [], [], [], []
    curves = {}
    for name, fn in runs.items():
        ds, secs = timed(fn, repeats)
        curves[name] = ds
        names.append(name)
        med.append(float(np.median(secs)))
        lo.append(float(secs.min()))
        hi.append(float(secs.max()))
        levels.append(int(ds.sizes["strain"]))
        status.append(f"{ds.attrs['status']} {ds.attrs.get('status_detail', '')}".strip())
        n_it = int(ds.newton_iterations.sum()) if "friction_energy" in ds else int(ds.contact_iterations.sum())
        its.append(n_it)
        per_it.append(med[-1] / max(n_it, 1))
        log.info("%s: median %.2f s (%.2f-%.2f), %d levels reached, %d iterations, %s", name, med[-1], lo[-1], hi[-1],
                 levels[-1], n_it, status[-1][:100])
    ds = xr.Dataset({
        "seconds": ("run", med, {"units": "s", "long_name": f"median wall time of {repeats} runs"}),
        "seconds_min": ("run", lo, {"units": "s", "long_name": "fastest run"}),
        "seconds_max": ("run", hi, {"units": "s", "long_name": "slowest run"}),
        "levels_reached": ("run", levels, {"units": "1", "long_name": f"levels reached of {steps}"}),
        "iterations": ("run", its, {"units": "1", "long_name": "Newton (nonlinear) or active-set (linear) iterations"}),
        "seconds_per_iteration": ("run", per_it, {"units": "s", "long_name": "median time / iterations"}),
        "status": ("run", status, {"units": "1", "long_name": "status of the curve"}),
    }, coords={"run": ("run", names, {"units": "1", "long_name": "curve"})})
    ds.attrs.update(strain=strain, steps=steps, repeats=repeats, cpus=os.cpu_count() or 0,
                    machine=f"{platform.processor() or platform.machine()}, 2-core AMD EPYC, 24 GB, shared",
                    target_seconds=60.0, description=__doc__.split("\n\n")[0])
    save_netcdf(ds, out / "bench_nonlinear_compress.nc")
    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.2))
    ax[0].barh(np.arange(len(names)), med, xerr=[np.subtract(med, lo), np.subtract(hi, med)], tick_label=names)
    ax[0].axvline(60, color="k", ls=":", label="target 60 s (friction 0.2)")
    ax[0].set(xlabel="wall time (s)", title=f"spacer cell, {100 * strain:.0f} % in {steps} levels (median of {repeats})")
    ax[0].legend(fontsize=8)
    for name, c in curves.items():
        ax[1].plot(100 * c.strain, c.stress, label=f"{name} ({c.attrs['status']})")
    ax[1].set(xlabel="compression (%)", ylabel="stress (kPa)", yscale="log", title="the timed curves")
    ax[1].legend(fontsize=8)
    for x in ax:
        x.grid(alpha=0.3)
    fig.tight_layout()
    save_figure(fig, out / "bench_nonlinear_compress.png")
    for i, name in enumerate(names):
        print(f"{name:26s} median {med[i]:7.2f} s ({lo[i]:.2f}-{hi[i]:.2f}), {levels[i]}/{steps} levels, "
              f"{its[i]} iterations, {1e3 * per_it[i]:.2f} ms/iteration, {status[i][:80]}")


if __name__ == "__main__":
    main()
