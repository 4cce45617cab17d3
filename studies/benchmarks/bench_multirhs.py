"""Batched (multi-right-hand-side) homogenisation versus one solve (issue 3 must-show).

A wavy periodic octet supercell (r^3 cells of edge 1 mm, struts of radius 0.02 mm, 4
Timoshenko elements per strut, struts bowed by 0.1 of their length) is homogenised with the
6 unit macro-strain cases solved

- one after another (``homogenize(batched=False)``: 6 PCG solves with pyamg's V-cycle), and
- together (``homogenize(batched=True)``, the default: lockstep block PCG and a block
  V-cycle, :mod:`homtex.krylov`, which read every matrix once for all 6 cases).

The reference "one solve" is the same periodic operator built, set up and solved for one load
case (the shear case 23, the one that needs most iterations) with the one-vector path:

    one_solve = assembly + pins + AMG setup + right-hand side + 1 PCG solve (pyamg V-cycle)

The issue's target is ``homogenize / one_solve <= 2.5`` at 1e6 DOF. Also timed: the block
path with one column (``one_solve_block``), to show what the block kernels give per vector.

Usage::

    python studies/benchmarks/bench_multirhs.py [--out DIR] [--quick | --full] [--repeats R ...] [--runs N]
        [--no-sequential]

Default: r = 6 (~1e5 DOF); ``--full``: r = 13 (~1e6 DOF); ``--quick``: r = 2, warm-up on r = 1
(seconds). Numba threads: NUMBA_NUM_THREADS (recorded). Writes ``DIR/bench_multirhs.nc`` (dim:
size) and ``DIR/bench_multirhs.png`` (default DIR = results/bench_multirhs).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

NEL = 4
RADIUS = 0.02
E_MOD, NU = 1000.0, 0.3
CASES = ("11", "22", "33", "23", "13", "12")


def measure(r: int, tol: float, sequential: bool = True, waviness: float = 0.1) -> dict:
    """Timings (s), iterations and C of the r^3 supercell: one solve, sequential, batched."""
    import homtex
    from homtex.analysis.periodic import _Operator, unit_strains
    from homtex.geometry.lattices import lattice_frame
    from homtex.linalg.multirhs import solve_many

    frame = lattice_frame("octet", radius=RADIUS, E=E_MOD, nu=NU, elements_per_strut=NEL,
                          repeat=(r, r, r), periodic=True, waviness=waviness)
    H = unit_strains(frame)
    # one solve of the shear case 23 (index 3), one-vector path
    t0 = time.perf_counter()
    op = _Operator(frame, "amg", tol, None)
    b = op.rhs(H[3:4])
    _, rep = op.solve(b[0])
    one = time.perf_counter() - t0
    t_op = op.assembly_seconds + op.setup_seconds
    # the same case through the block path with one column (setup reused)
    t0 = time.perf_counter()
    _, reps1 = solve_many(op.lin, b)
    one_block_cg = time.perf_counter() - t0
    del op
    out = dict(r=r, ndof=frame.ndof, one_solve=one, one_setup=t_op, one_cg=rep.solve_seconds,
               one_iterations=rep.iterations, one_block_cg=one_block_cg,
               one_block_iterations=reps1[0].iterations)
    hb = homtex.homogenize(frame, tol=tol)
    out.update(batched=hb.total_seconds, batched_solve=hb.solve_seconds,
               batched_iterations=[q.iterations for q in hb.reports], C=hb.C,
               assembly=hb.assembly_seconds, setup=hb.setup_seconds, post=hb.post_seconds)
    if sequential:
        hs = homtex.homogenize(frame, tol=tol, batched=False)
        out.update(sequential=hs.total_seconds, sequential_solve=hs.solve_seconds,
                   sequential_iterations=[q.iterations for q in hs.reports],
                   C_difference=float(np.abs(hs.C - hb.C).max() / np.abs(hs.C).max()))
    else:
        out.update(sequential=np.nan, sequential_solve=np.nan, sequential_iterations=[np.nan] * 6,
                   C_difference=np.nan)
    return out


TIMING_KEYS = ("one_solve", "one_setup", "one_cg", "one_block_cg", "batched", "batched_solve",
               "assembly", "setup", "post", "sequential", "sequential_solve")


def run(out: Path, repeats, tol: float = 1e-10, runs: int = 1, sequential: bool = True,
        waviness: float = 0.1, warmup: int = 2) -> Path:
    import numba
    import xarray as xr

    measure(warmup, tol, True, waviness)  # warm-up: numba cache loads, first calls
    rows = []
    for r in repeats:
        ms = [measure(r, tol, sequential, waviness) for _ in range(runs)]
        m = dict(ms[0])
        for k in TIMING_KEYS:
            m[k] = min(x[k] for x in ms)
        rows.append(m)
        print(f"r={r:2d} ndof={m['ndof']:8d}: one solve {m['one_solve']:.2f} s (setup "
              f"{m['one_setup']:.2f}, PCG {m['one_cg']:.2f} s, {m['one_iterations']} it; block path "
              f"1 column {m['one_block_cg']:.2f} s); homogenize batched {m['batched']:.2f} s (solve "
              f"{m['batched_solve']:.2f} s, ratio {m['batched'] / m['one_solve']:.2f}), sequential "
              f"{m['sequential']:.2f} s (solve {m['sequential_solve']:.2f} s, ratio "
              f"{m['sequential'] / m['one_solve']:.2f}); iterations {m['batched_iterations']} vs "
              f"{m['sequential_iterations']}; C difference {m['C_difference']:.1e}", flush=True)
    size, case = ("size",), ("size", "case")
    g = lambda k: np.array([m[k] for m in rows], dtype=float)  # noqa: E731
    ds = xr.Dataset(
        {
            "ndof": (size, g("ndof"), {"units": "1", "long_name": "degrees of freedom"}),
            "one_solve_seconds": (size, g("one_solve"), {"units": "s", "long_name": "one solve of case 23: assembly + pins + AMG setup + rhs + 1 PCG solve"}),
            "one_setup_seconds": (size, g("one_setup"), {"units": "s", "long_name": "assembly + pins + AMG setup"}),
            "one_cg_seconds": (size, g("one_cg"), {"units": "s", "long_name": "PCG time of the single solve (pyamg V-cycle)"}),
            "one_iterations": (size, g("one_iterations"), {"units": "1", "long_name": "PCG iterations of the single solve"}),
            "one_block_cg_seconds": (size, g("one_block_cg"), {"units": "s", "long_name": "PCG time of case 23 alone through the block path"}),
            "batched_seconds": (size, g("batched"), {"units": "s", "long_name": "homogenize(batched=True) end to end (6 cases)"}),
            "batched_solve_seconds": (size, g("batched_solve"), {"units": "s", "long_name": "block PCG of the 6 cases"}),
            "sequential_seconds": (size, g("sequential"), {"units": "s", "long_name": "homogenize(batched=False) end to end (6 cases)"}),
            "sequential_solve_seconds": (size, g("sequential_solve"), {"units": "s", "long_name": "6 PCG solves one after another"}),
            "assembly_seconds": (size, g("assembly"), {"units": "s", "long_name": "assembly and pins (homogenize)"}),
            "setup_seconds": (size, g("setup"), {"units": "s", "long_name": "AMG setup (homogenize)"}),
            "post_seconds": (size, g("post"), {"units": "s", "long_name": "post-processing (homogenize)"}),
            "ratio_batched": (size, g("batched") / g("one_solve"), {"units": "1", "long_name": "batched homogenize / one solve (target <= 2.5)"}),
            "ratio_sequential": (size, g("sequential") / g("one_solve"), {"units": "1", "long_name": "sequential homogenize / one solve"}),
            "C_difference": (size, g("C_difference"), {"units": "1", "long_name": "max |C_batched - C_sequential| / max |C|"}),
            "batched_iterations": (case, np.array([m["batched_iterations"] for m in rows], float), {"units": "1", "long_name": "PCG iterations per case, batched"}),
            "sequential_iterations": (case, np.array([m["sequential_iterations"] for m in rows], float), {"units": "1", "long_name": "PCG iterations per case, sequential"}),
            "C": (("size", "i", "j"), np.array([m["C"] for m in rows]), {"units": "MPa", "long_name": "effective Voigt stiffness (batched)"}),
        },
        coords={"size": ("size", np.asarray(repeats), {"units": "1", "long_name": "cells per edge of the periodic supercell"}),
                "case": ("case", list(CASES), {"units": "1", "long_name": "unit macro strain (Voigt)"}),
                "i": ("i", list(CASES), {"units": "1", "long_name": "Voigt row"}),
                "j": ("j", list(CASES), {"units": "1", "long_name": "Voigt column"})},
        attrs={"lattice": f"periodic octet supercell, {NEL} elements per strut, L/r = 35, "
                          f"waviness {waviness}", "tol": tol, "timing": f"minimum over {runs} runs",
               "numba_threads": int(numba.get_num_threads()),
               "block_solve_threads": 1, "nullspace": "rigid",
               "one_solve_block_note": "one_block_cg_seconds: case 23 alone through solve_many"},
    )
    path = save_netcdf(ds, out / "bench_multirhs.nc")
    plot(ds, out / "bench_multirhs.png")
    return path


def plot(ds, path: Path) -> None:
    plt = pyplot()
    n = ds.ndof.values
    x = np.arange(len(n))
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    w = 0.25
    ax.bar(x - w, ds.one_solve_seconds, w, label="one solve (setup + 1 case)")
    ax.bar(x, ds.sequential_seconds, w, label="homogenize, 6 cases one by one")
    ax.bar(x + w, ds.batched_seconds, w, label="homogenize, 6 cases batched")
    ax.hlines(2.5 * ds.one_solve_seconds.values, x - 1.5 * w, x + 1.5 * w, colors="k",
              linestyles="--", label="2.5 x one solve (target)")
    for i in range(len(n)):
        for dx, key in ((0, "ratio_sequential"), (w, "ratio_batched")):
            v = float(ds[key][i])
            if np.isfinite(v):
                top = float(ds["sequential_seconds" if dx == 0 else "batched_seconds"][i])
                ax.text(x[i] + dx, top, f"{v:.2f}x", ha="center", va="bottom", fontsize=8)
    ax.set_xticks(x, [f"{v:.2g} DOF" for v in n])
    ax.set_ylabel("wall time, s")
    ax.set_title(f"wavy periodic octet; block solve on {int(ds.attrs['block_solve_threads'])} "
                 f"numba thread(s)")
    ax.set_ylim(0, 1.3 * float(np.nanmax(ds.sequential_seconds.values.tolist()
                                         + ds.batched_seconds.values.tolist())))
    ax.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    save_figure(fig, path)


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--full", action="store_true", help="the ~1e6 DOF supercell (r = 13)")
    p.add_argument("--repeats", type=int, nargs="+", help="cells per edge (overrides sizes)")
    p.add_argument("--tol", type=float, default=1e-10, help="PCG relative residual")
    p.add_argument("--runs", type=int, default=1, help="timing runs per size (minimum kept)")
    p.add_argument("--no-sequential", action="store_true", help="skip homogenize(batched=False)")
    p.add_argument("--waviness", type=float, default=0.1, help="strut bow / length")
    a = p.parse_args(argv)
    out = setup(a)
    sizes = (2,) if a.quick else ((13,) if a.full else (6,))
    repeats = tuple(a.repeats) if a.repeats else sizes
    path = run(out, repeats, a.tol, a.runs, not a.no_sequential, a.waviness, warmup=1 if a.quick else 2)
    print(f"wrote {path} and {path.with_suffix('.png')}")


if __name__ == "__main__":
    main()
