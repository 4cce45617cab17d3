"""The GPU path of AMG-CG (issue 24): one prepared device check, end to end, every second counted.

On the slender octet block of bench_core.py with R cells per edge (default 29: about 1e7 DOF):

1. a first solve of a new system to 1e-8: hierarchy built on the host (fast setup, numba threads),
   moved to the device (CSR levels, dense coarse inverse), V-cycle and CG there in float64, and
   again with a float32 hierarchy (``homtex.linalg.gpu.device_solve``): setup, transfer, solve,
   per-iteration and total seconds, iterations, true residual;
2. a re-solve of a changed matrix (every element's E scaled by 0.8-1.2) with the hierarchy reused;
3. the CPU CG phase at ``--cpu-repeat`` cells (default 17: about 2e6 DOF) on 1 thread and on all
   numba threads.

Without CuPy or a device it runs the same code on the CPU (``--device cpu``; what ``--quick``
does), so it is checked where no GPU is lent. The machine, the device and the load average at
the start are in the Dataset and on the chart (a table of the phases).

Usage::

    python studies/benchmarks/bench_gpu_amg.py [--out DIR] [--quick] [--repeat R] [--cpu-repeat R] [--device gpu|cpu]
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
from bench_core import build_problem, machine  # noqa: E402
from bench_parallel_amg import changed_matrix  # noqa: E402

TOL = 1e-8
PHASES = ("setup", "transfer", "solve", "per_iteration", "total", "iterations", "residual")


def device_name(device: str) -> str:
    if device != "gpu":
        return "cpu (numpy + scipy.sparse)"
    import cupy

    p = cupy.cuda.runtime.getDeviceProperties(0)
    return p["name"].decode() if isinstance(p["name"], bytes) else str(p["name"])


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--repeat", type=int, default=29, help="octet cells per edge of the device solve")
    p.add_argument("--cpu-repeat", type=int, default=17, help="cells per edge of the CPU thread comparison")
    p.add_argument("--device", choices=("gpu", "cpu"), default=None, help="default: gpu where CuPy sees one")
    a = p.parse_args(argv)
    out = setup(a)
    import numba
    import xarray as xr

    from homtex.fem.assembly import Assembler
    from homtex.linalg.gpu import device_solve, gpu_available
    from homtex.linalg.nullspace import rigid_body_modes
    from homtex.linalg.solvers import LinearSolver, ScaledAMG, constrain

    load0 = os.getloadavg()[0]
    device = a.device or ("gpu" if gpu_available() else "cpu")
    r, rc = (3, 3) if a.quick else (a.repeat, a.cpu_repeat)
    print(f"{machine()}, device {device_name(device)}, load {load0:.2f}", flush=True)
    f, mask, b = build_problem(r)
    A = constrain(Assembler(f).stiffness(), mask)
    B = rigid_body_modes(f.nodes)
    rows, labels = [], []
    for prec in ("float64", "float32"):
        t0 = time.perf_counter()
        x, rep = device_solve(A, b, B, tol=TOL, device=device, precision=prec)
        rep["total"] = time.perf_counter() - t0
        rows.append([rep[k] for k in PHASES])
        labels.append(f"first solve, {prec} hierarchy")
        print(f"  {labels[-1]}: " + ", ".join(f"{k} {rep[k]:.3g}" for k in PHASES), flush=True)
        h = rep["hierarchy"]
    A2 = changed_matrix(f, mask)
    t0 = time.perf_counter()
    x2, rep = device_solve(A2, b, B, tol=TOL, device=device, hierarchy=h)
    rep["total"] = time.perf_counter() - t0
    rows.append([rep[k] for k in PHASES])
    labels.append("re-solve, changed matrix, reused hierarchy")
    print(f"  {labels[-1]}: " + ", ".join(f"{k} {rep[k]:.3g}" for k in PHASES), flush=True)
    # CPU CG phase, 1 thread against all
    fc, mc, bc = build_problem(rc)
    Ac = constrain(Assembler(fc).stiffness(), mc)
    hc = ScaledAMG(Ac, rigid_body_modes(fc.nodes))
    cpu = {}
    import homtex

    for t in sorted({1, numba.config.NUMBA_NUM_THREADS}):
        numba.set_num_threads(t)
        with homtex.set_options(amg_threads=t):
            lin = LinearSolver(Ac, method="amg", tol=TOL, hierarchy=hc)
            lin.solve(bc)
            t0 = time.perf_counter()
            _, rp = lin.solve(bc)
            cpu[t] = time.perf_counter() - t0
        print(f"  CPU CG phase at {fc.ndof} DOF, {t} threads: {cpu[t]:.2f} s ({rp.iterations} iterations)", flush=True)
    ds = xr.Dataset(
        {"phase_value": (("case", "phase"), np.array(rows, float),
                         {"units": "s (iterations: 1, residual: 1)", "long_name": "phases of the device solve"}),
         "cpu_cg_seconds": (("threads",), np.array([cpu[t] for t in sorted(cpu)]),
                            {"units": "s", "long_name": f"CPU CG phase at {fc.ndof} DOF"})},
        coords={"case": labels, "phase": list(PHASES), "threads": sorted(cpu)},
        attrs={"machine": machine(), "device": device_name(device), "load_at_start": load0, "ndof": f.ndof,
               "cpu_ndof": fc.ndof, "tolerance": TOL})
    path = save_netcdf(ds, out / "bench_gpu_amg.nc")
    plot(ds, out / "bench_gpu_amg.png")
    print(f"wrote {path} and {path.with_suffix('.png')}")


def plot(ds, path) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(10, 2.8))
    ax.axis("off")
    cells = [[f"{v:.3g}" for v in row] for row in ds.phase_value.values]
    ax.table(cellText=cells, rowLabels=list(ds.case.values), colLabels=list(ds.phase.values), loc="center")
    thr = ", ".join(f"{int(t)} thr {s:.2f} s" for t, s in zip(ds.threads.values, ds.cpu_cg_seconds.values))
    ax.set_title(f"{ds.attrs['ndof']} DOF on {ds.attrs['device']}; {ds.attrs['machine']}; load "
                 f"{ds.attrs['load_at_start']:.2f}; CPU CG at {ds.attrs['cpu_ndof']} DOF: {thr}", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


if __name__ == "__main__":
    main()
