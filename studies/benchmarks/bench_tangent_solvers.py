"""Tangent solvers of the nonlinear solvers (issue 24): qdldl LDL^T, CHOLMOD and AMG-PCG.

``solve_nonlinear`` on a square net of nx x nx nodes (crossing yarns, 100 mm, r = 0.1 mm, clamped
edges, a centre load of 0.2 N out of the plane: large deflection, 5 load steps; the net of
bench_corotational.py), once per ``tangent_solver`` option ("ldl", "cholmod" where scikit-sparse
imports, "amg"). It records wall and process CPU seconds, Newton iterations, seconds per Newton
iteration and the largest difference of the loaded node's displacement from the "ldl" answer.
The machine and the load average at the start are in the Dataset and on the chart.

Usage::

    python studies/benchmarks/bench_tangent_solvers.py [--out DIR] [--quick] [--nx N ...]

Default nx = 60, 130 (2.2e4, 1.0e5 DOF; the 1e5 qdldl run takes several minutes); ``--quick``:
nx = 10 (seconds).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402
from bench_core import machine  # noqa: E402
from bench_corotational import homtex_frame, net_model  # noqa: E402

METHODS = ("ldl", "cholmod", "amg")


def run(nx: int) -> dict:
    import homtex
    from homtex.linalg.tangent_backends import cholmod_available

    m = net_model(nx)
    fr = homtex_frame(m)
    fixed = {int(i): "all" for i in m["clamped"]}
    loads = {m["load_node"]: m["load"]}
    out = {"ndof": fr.ndof, "load_avg": os.getloadavg()[0]}
    ref = None
    for meth in METHODS:
        if meth == "cholmod" and not cholmod_available():
            continue
        with homtex.set_options(tangent_solver=meth):
            t0, c0 = time.perf_counter(), time.process_time()
            res = homtex.solve_nonlinear(fr, fixed, loads, steps=m["steps"], max_iter=50)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        its = int(res.path.iterations.values.sum())
        u = res.u[m["load_node"], :3]
        ref = u if ref is None else ref
        out.update({f"{meth}_seconds": wall, f"{meth}_cpu": cpu, f"{meth}_iterations": its,
                    f"{meth}_per_iteration": wall / its, f"{meth}_cpu_per_iteration": cpu / its,
                    f"{meth}_difference": float(np.abs(u - ref).max() / np.abs(ref).max())})
        print(f"  nx={nx} ({fr.ndof} DOF) {meth:8s} {wall:8.2f} s wall {cpu:8.2f} s cpu  {its} Newton iterations  "
              f"{wall / its:.3f} s / iteration  diff {out[f'{meth}_difference']:.1e}", flush=True)
    return out


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--nx", type=int, nargs="+", help="net sizes (nodes per side)")
    a = p.parse_args(argv)
    out = setup(a)
    import xarray as xr

    load0 = os.getloadavg()[0]
    print(f"{machine()}, load {load0:.2f}", flush=True)
    sizes = tuple(a.nx) if a.nx else ((10,) if a.quick else (60, 130))
    rows = [run(n) for n in sizes]
    keys = sorted({k for r in rows for k in r})
    ds = xr.Dataset({k: (("size",), np.array([r.get(k, np.nan) for r in rows], float),
                         {"units": "s" if ("seconds" in k or "cpu" in k or "per_iteration" in k) else "1",
                          "long_name": k.replace("_", " ")}) for k in keys},
                    coords={"size": ("size", np.asarray(sizes), {"units": "1", "long_name": "net nodes per side"})},
                    attrs={"machine": machine(), "load_at_start": load0,
                           "model": "square net, clamped edges, centre load 0.2 N, 5 steps (bench_corotational.py)"})
    path = save_netcdf(ds, out / "bench_tangent_solvers.nc")
    plot(ds, out / "bench_tangent_solvers.png")
    print(f"wrote {path} and {path.with_suffix('.png')}")


def plot(ds, path) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    n = ds.ndof.values
    for m in METHODS:
        for k, style, lab in ((f"{m}_per_iteration", "o-", "wall"), (f"{m}_cpu_per_iteration", "s--", "CPU")):
            if k in ds and np.isfinite(ds[k].values).any():
                ax.loglog(n, ds[k].values, style, label=f"{m} ({lab})")
    ax.set_xlabel("DOF")
    ax.set_ylabel("seconds per Newton iteration")
    ax.legend(fontsize=7)
    loads = ", ".join(f"{v:.1f}" for v in ds.load_avg.values)
    ax.set_title(f"{ds.attrs['machine']}; load {ds.attrs['load_at_start']:.2f} (per size {loads})", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


if __name__ == "__main__":
    main()
