"""Lookup speed and accuracy: 10^5 queries of grid (tensor-product) and RBF (sample) lookups.

    python studies/benchmarks/bench_rom.py [--out DIR] [--queries N] [--quick | --full]

Fits lookups of a known function f(x, y) = sin(3x) cos(2y) + x y on grids of n^2 nodes and on
n Latin-hypercube samples, evaluates N queries (default 10^5, the issue's size) and records the
evaluation time (best of 3, after a warm-up call that compiles numba kernels), the true RMS
error at the queries and the reported hold-out error. Writes bench_rom.nc and bench_rom.png
into DIR (default results/bench_rom/). ``--full`` adds larger sizes; ``--quick``: 10^3 queries and
the two smallest training sets (seconds).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402


def f(x, y):
    return np.sin(3 * x) * np.cos(2 * y) + x * y


def timed(fn, q, repeat=3):
    fn(q)  # warm-up (numba compile / caches)
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn(q)
        best = min(best, time.perf_counter() - t)
    return best


def main(argv=None):
    from scipy.stats import qmc

    from homtex.lookup import Lookup

    ap = parser(__file__, __doc__)
    ap.add_argument("--queries", type=int, default=None, help="queries (default 10^5; --quick 10^3)")
    ap.add_argument("--full", action="store_true", help="larger training sets")
    args = ap.parse_args(argv)
    out = setup(args)
    args.queries = args.queries or (1_000 if args.quick else 100_000)

    rng = np.random.default_rng(0)
    q = rng.uniform([0, 0], [1, 2], (args.queries, 2))
    exact = f(q[:, 0], q[:, 1])
    sizes = [16, 64] if args.quick else [16, 64, 256, 1024] + ([4096] if args.full else [])
    rows = []
    for kind in ("grid-linear", "grid-cubic", "rbf"):
        for n in sizes:
            if kind == "rbf" and n > (2048 if args.full else 1024):
                continue
            t0 = time.perf_counter()
            if kind.startswith("grid"):
                m = int(round(np.sqrt(n)))
                x, y = np.linspace(0, 1, m), np.linspace(0, 2, m)
                X, Y = np.meshgrid(x, y, indexing="ij")
                lk = Lookup.from_grid({"x": x, "y": y}, f(X, Y), method=kind.split("-")[1])
                npts = m * m
            else:
                p = qmc.scale(qmc.LatinHypercube(2, rng=np.random.default_rng(1)).random(n), [0, 0], [1, 2])
                lk = Lookup.from_samples(["x", "y"], p, f(p[:, 0], p[:, 1]), bounds=[(0, 1), (0, 2)])
                npts = n
            fit = time.perf_counter() - t0
            sec = timed(lk, q)
            err = float(np.sqrt(np.mean((lk(q) - exact) ** 2)))
            rows.append((kind, npts, sec, fit, err, lk.holdout.get("rmse", np.nan)))
            print(f"{kind:12s} n={npts:5d}  eval {args.queries} queries {sec * 1e3:8.2f} ms   fit+holdout {fit:6.3f} s"
                  f"   rmse {err:.2e}   holdout rmse {lk.holdout.get('rmse', np.nan):.2e}")
    kinds = sorted({r[0] for r in rows})
    nmax = max(len([r for r in rows if r[0] == k]) for k in kinds)

    def table(col):
        a = np.full((len(kinds), nmax), np.nan)
        for i, k in enumerate(kinds):
            vals = [r[col] for r in rows if r[0] == k]
            a[i, :len(vals)] = vals
        return a

    ds = xr.Dataset(
        {"training_points": (("method", "level"), table(1), {"units": "1", "long_name": "training points (grid nodes or samples)"}),
         "eval_seconds": (("method", "level"), table(2), {"units": "s", "long_name": f"time to evaluate {args.queries} queries (best of 3)"}),
         "fit_seconds": (("method", "level"), table(3), {"units": "s", "long_name": "fit and hold-out time"}),
         "rmse": (("method", "level"), table(4), {"units": "1", "long_name": "true RMS error at the queries"}),
         "holdout_rmse": (("method", "level"), table(5), {"units": "1", "long_name": "reported hold-out RMS error"})},
        coords={"method": ("method", np.array(kinds, dtype=object), {"units": "1", "long_name": "lookup method"}),
                "level": ("level", np.arange(nmax), {"units": "1", "long_name": "training-set size level"})},
        attrs={"queries": args.queries, "function": "sin(3x) cos(2y) + x y on [0,1]x[0,2]"})
    save_netcdf(ds, out / "bench_rom.nc")
    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for i, k in enumerate(kinds):
        n = ds.training_points[i]
        ax[0].loglog(n, ds.rmse[i], "o-", label=f"{k} true")
        ax[0].loglog(n, ds.holdout_rmse[i], "x--", color=ax[0].lines[-1].get_color(), label=f"{k} hold-out")
        ax[1].loglog(n, ds.eval_seconds[i] * 1e3, "o-", label=k)
    ax[0].set(xlabel="training points", ylabel="RMS error", title="accuracy (reported hold-out dashed)")
    ax[1].axhline(1000, color="k", lw=0.8, ls=":")
    ax[1].set(xlabel="training points", ylabel=f"ms for {args.queries} queries", title="evaluation time")
    ax[0].legend(fontsize=7)
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out / "bench_rom.png")
    print(f"wrote {out / 'bench_rom.nc'} and {out / 'bench_rom.png'}")
    return ds


if __name__ == "__main__":
    main()
