"""AMG for contact systems (issue 24): CG iterations with contact against the contact-free count,
and AMG against the direct solver, on woven-like grids of crossing beams and on the spacer cell.

Grids: ``homtex.contact.examples.beam_grid`` (2n simply supported crossing beams, contact at the
n^2 crossings, random loads), n = 8, 24, 64 (1.5e4 to 1.0e5 DOF). For each grid it solves

* without contact (``solve_static``, AMG): the contact-free CG iterations;
* with contact (``solve_static(..., contact=Contact())``), AMG with aggregation along the beam
  elements (option ``contact_aggregation="elements"``, the default), AMG with aggregation by the
  strength of the whole operator (``"strength"``, the former behaviour), and the direct solver:
  wall and CPU seconds, linear solves, the median and largest CG iterations of a solve with a
  fresh hierarchy, and the largest displacement difference from the direct answer;

and the spacer cell compressed to 30 % in 10 steps with ``solver="amg"`` and ``"direct"``.
The machine and the load average at the start are on the chart and in the Dataset.

Usage::

    python studies/benchmarks/bench_contact_amg.py [--out DIR] [--quick]

``--quick``: n = 4 and the spacer cell to 5 % in 1 step (seconds).
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

METHODS = ("amg_elements", "amg_strength", "direct")


class _Log:
    """Records (method, iterations, reused) of every LinearSolver.solve while active."""

    def __enter__(self):
        from homtex.linalg import solvers

        self.entries = []
        self._orig = orig = solvers.LinearSolver.solve
        log = self.entries

        def solve(lin, b, x0=None):
            x, rep = orig(lin, b, x0)
            log.append((rep.method, rep.iterations, rep.reused_setup))
            return x, rep

        solvers.LinearSolver.solve = solve
        return self

    def __exit__(self, *a):
        from homtex.linalg import solvers

        solvers.LinearSolver.solve = self._orig
        return False


def run_grid(n: int) -> dict:
    import homtex
    from homtex.contact.examples import beam_grid

    n_el = 2 * (n + 1)
    frame, fixed, loads = beam_grid(n, n_el, L=4.0 * (n + 1), load=0.02)
    out = {"ndof": frame.ndof, "crossings": n * n}
    with _Log() as lg:
        free = homtex.solve_static(frame, fixed, loads, solver="amg", tol=1e-10)
    out["free_iterations"] = free.report.iterations
    ref = None
    for meth in ("direct", "amg_elements", "amg_strength"):
        agg = "strength" if meth.endswith("strength") else "elements"
        with homtex.set_options(contact_aggregation=agg), _Log() as lg:
            t0, c0 = time.perf_counter(), time.process_time()
            res = homtex.solve_static(frame, fixed, loads, contact=homtex.Contact(), solver=meth.split("_")[0],
                                      tol=1e-10)
            out[f"{meth}_seconds"], out[f"{meth}_cpu"] = time.perf_counter() - t0, time.process_time() - c0
        its = [e[1] for e in lg.entries if e[0] == "amg" and not e[2]]
        out[f"{meth}_solves"] = len(lg.entries)
        if its:
            out[f"{meth}_median_iterations"] = float(np.median(its))
            out[f"{meth}_max_iterations"] = float(max(its))
        u = res.u[:, :3]
        if ref is None:
            ref = u
        out[f"{meth}_difference"] = float(np.abs(u - ref).max() / np.abs(ref).max())
        print(f"  n={n} ({frame.ndof} DOF) {meth:13s} {out[f'{meth}_seconds']:7.2f} s  solves {len(lg.entries):3d}  "
              f"CG it (fresh) median {out.get(f'{meth}_median_iterations', 0):.0f} max "
              f"{out.get(f'{meth}_max_iterations', 0):.0f} (contact-free {out['free_iterations']})  "
              f"diff {out[f'{meth}_difference']:.1e}", flush=True)
    return out


def run_spacer(strain: float, steps: int) -> dict:
    import homtex

    cell = homtex.load_cell("spacer_20mm")
    out = {}
    for meth in ("direct", "amg"):
        t0, c0 = time.perf_counter(), time.process_time()
        cur = homtex.compress(cell, strain=strain, steps=steps, solver=meth, geometry="linear")
        out[f"spacer_{meth}_seconds"], out[f"spacer_{meth}_cpu"] = time.perf_counter() - t0, time.process_time() - c0
        out[f"spacer_{meth}_ok"] = float(cur.attrs.get("status") == "ok")
        out[f"spacer_{meth}_stress"] = float(cur.stress.values[-1])
        print(f"  spacer {meth}: {out[f'spacer_{meth}_seconds']:.2f} s ({cur.attrs.get('status')}), "
              f"final stress {out[f'spacer_{meth}_stress']:.6g} kPa", flush=True)
    return out


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    a = p.parse_args(argv)
    out = setup(a)
    import xarray as xr

    load0 = os.getloadavg()[0]
    print(f"{machine()}, load {load0:.2f}", flush=True)
    sizes = (4,) if a.quick else (8, 24, 64)
    rows = [run_grid(n) for n in sizes]
    sp_ = run_spacer(0.05, 1) if a.quick else run_spacer(0.3, 10)
    keys = sorted({k for r in rows for k in r})
    ds = xr.Dataset({k: (("size",), np.array([r.get(k, np.nan) for r in rows], float),
                         {"units": "s" if k.endswith(("seconds", "cpu")) else "1", "long_name": k.replace("_", " ")})
                     for k in keys},
                    coords={"size": ("size", np.asarray(sizes), {"units": "1", "long_name": "beams per direction"})},
                    attrs={"machine": machine(), "load_at_start": load0, "tolerance": 1e-10, **sp_})
    path = save_netcdf(ds, out / "bench_contact_amg.nc")
    plot(ds, out / "bench_contact_amg.png")
    print(f"wrote {path} and {path.with_suffix('.png')}")


def plot(ds, path) -> None:
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    n = ds.ndof.values
    a1.semilogx(n, ds.free_iterations.values, "ko-", label="contact-free")
    for m in ("amg_elements", "amg_strength"):
        k = f"{m}_median_iterations"
        if k in ds:
            a1.semilogx(n, ds[k].values, "o-", label=f"with contact, {m.split('_')[1]} aggregation")
    a1.set_xlabel("DOF")
    a1.set_ylabel("CG iterations (fresh hierarchy, median)")
    a1.legend(fontsize=7)
    for m in METHODS:
        a2.loglog(n, ds[f"{m}_seconds"].values, "s-", label=m)
    a2.set_xlabel("DOF")
    a2.set_ylabel("solve_static with contact, s (wall)")
    a2.legend(fontsize=7)
    fig.suptitle(f"crossing-beam grids; {ds.attrs['machine']}; load at start {ds.attrs['load_at_start']:.2f}",
                 fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


if __name__ == "__main__":
    main()
