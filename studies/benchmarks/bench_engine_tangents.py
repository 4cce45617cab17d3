"""Tangent solvers on the large-motion engine: qdldl against PARDISO where contacts fill the factor.

The seamed spacer press is the engine's heaviest shipped job: the 43 mm seam cell (13 032 free
DOF) pressed to 70 % from its sewn state, legs and layers coming into contact until qdldl's LDL^T
costs 20-45 ms. The sewn state is computed first (cached in a temporary result cache, not timed),
then the press runs once per tangent solver ("ldl", and "pardiso" where pypardiso imports) in this
process, one thread. Recorded per solver: process CPU seconds, factorisations, their seconds, solves,
new contact patterns and the stress at each 10 % (the paths agree until the legs' buckling cascade,
whose path follows the factorisation's round-off). The machine and load are in the Dataset.

Usage::

    python studies/benchmarks/bench_engine_tangents.py [--out DIR] [--quick] [--distance D] [--strain S]

Default d = 43 mm to 70 % (about 10 + 8 minutes on the 2-core Xeon); ``--quick``: the unseamed spacer
cell to 2 % (seconds).
"""

from __future__ import annotations

import logging
import os
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np
import xarray as xr

import homtex
from homtex.linalg.tangent_backends import pardiso_available
from homtex.linalg.tangent_solver import TangentSolver

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402
from bench_core import machine  # noqa: E402

SOLVERS = ("ldl", "pardiso")
log = logging.getLogger("studies")
LEVELS = np.round(np.arange(0.1, 0.71, 0.1), 2)


def _counting(counts: Counter):
    """Count and time every factorisation and solve of every tangent solver the engine makes."""
    def wrap(name):
        real = getattr(TangentSolver, name)

        def f(self, *a, **k):
            t = time.perf_counter()
            try:
                return real(self, *a, **k)
            finally:
                counts[name] += 1
                counts[name + "_seconds"] += time.perf_counter() - t
        setattr(TangentSolver, name, f)
    for name in ("analyse", "factor", "solve"):
        wrap(name)


def run(quick: bool, distance: float, strain: float) -> tuple[list[dict], list]:
    counts: Counter = Counter()
    _counting(counts)
    cell = homtex.load_cell("spacer_20mm")
    if quick:
        levels = [0.005, 0.01, 0.02]

        def job():
            return homtex.compress(cell, strain=levels, geometry="nonlinear")
        job()                                                       # warm-up (loads the kernels), not timed
    else:
        levels = [lv for lv in LEVELS if lv <= strain + 1e-9]
        homtex.seam_profile(cell, seam_distance=distance)         # the sewn state, cached, not timed

        def job():
            return homtex.seam_compression(cell, seam_distance=distance, strain=strain)
    rows = []
    for name in SOLVERS:
        if name == "pardiso" and not pardiso_available():
            log.info("pardiso: pypardiso does not import (pip install 'homtex[pardiso]'); skipped")
            continue
        counts.clear()
        with homtex.set_options(tangent_solver=name):
            c0, t0 = time.process_time(), time.perf_counter()
            ds = job()
            cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        stress = [float(np.interp(lv, ds.strain.values, ds.stress.values)) for lv in levels]
        row = {"solver": name, "cpu": cpu, "wall": wall, "factorizations": counts["factor"],
               "factor_seconds": counts["factor_seconds"], "solves": counts["solve"],
               "solve_seconds": counts["solve_seconds"], "patterns": counts["analyse"],
               "stress": stress, "status": ds.attrs.get("status", "")}
        rows.append(row)
        log.info(f"{name:8s} {cpu:8.1f} s CPU {wall:8.1f} s wall, {row['factorizations']} factorisations "
                 f"({1e3 * row['factor_seconds'] / max(row['factorizations'], 1):.1f} ms each), {row['solves']} solves "
                 f"({1e3 * row['solve_seconds'] / max(row['solves'], 1):.2f} ms), {row['patterns']} patterns, "
                 f"stress {np.round(stress, 5)} kPa, {row['status']}")
    return rows, levels


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--distance", type=float, default=43.0, help="seam distance, mm")
    p.add_argument("--strain", type=float, default=0.7, help="final plate travel / 20 mm")
    a = p.parse_args(argv)
    out = setup(a)
    load0 = os.getloadavg()[0]
    log.info(f"{machine()}, load {load0:.2f}")
    before = os.environ.get("HOMTEX_CACHE_DIR")
    with tempfile.TemporaryDirectory() as cache:
        os.environ["HOMTEX_CACHE_DIR"] = cache          # a cold cache: the sewing is this run's own
        try:
            rows, levels = run(a.quick, a.distance, a.strain)
        finally:
            if before is None:
                del os.environ["HOMTEX_CACHE_DIR"]
            else:
                os.environ["HOMTEX_CACHE_DIR"] = before
    names = [r["solver"] for r in rows]
    units = {"cpu": "s", "wall": "s", "factor_seconds": "s", "solve_seconds": "s"}
    data = {k: (("solver",), np.array([r[k] for r in rows], float), {"units": units.get(k, "1")})
            for k in ("cpu", "wall", "factorizations", "factor_seconds", "solves", "solve_seconds", "patterns")}
    data["stress"] = (("solver", "strain"), np.array([r["stress"] for r in rows]), {"units": "kPa"})
    data["status"] = (("solver",), np.array([r["status"] for r in rows], dtype=object), {})
    case = "unseamed spacer cell to 2 %" if a.quick else f"{a.distance:g} mm seam cell pressed to {a.strain:.0%}"
    ds = xr.Dataset(data, coords={"solver": ("solver", names), "strain": ("strain", np.asarray(levels, float),
                                                                         {"units": "1"})},
                    attrs={"machine": machine(), "load_at_start": load0, "case": case, "threads": 1})
    path = save_netcdf(ds, out / "bench_engine_tangents.nc")
    plot(ds, out / "bench_engine_tangents.png")
    log.info(f"wrote {path} and {path.with_suffix('.png')}")


def plot(ds, path) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    names = [str(n) for n in ds.solver.values]
    x = np.arange(len(names))
    factor = ds.factor_seconds.values
    solve = ds.solve_seconds.values
    rest = ds.cpu.values - factor - solve
    ax.bar(x, factor, label="factorisations")
    ax.bar(x, solve, bottom=factor, label="solves")
    ax.bar(x, rest, bottom=factor + solve, label="everything else (elements, contacts, line search)")
    for i, n in enumerate(names):
        ax.text(i, ds.cpu.values[i], f"{ds.cpu.values[i]:.3g} s, {int(ds.factorizations.values[i])} factorisations",
                ha="center", va="bottom", fontsize=8)
    ax.set_xticks(x, [f"tangent_solver={n!r}" for n in names])
    ax.set_ylabel("process CPU, s")
    ax.set_ylim(0, 1.3 * float(ds.cpu.values.max()))
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title(f"{ds.attrs['case']}; {ds.attrs['machine']}, load {ds.attrs['load_at_start']:.2f}", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


if __name__ == "__main__":
    main()
