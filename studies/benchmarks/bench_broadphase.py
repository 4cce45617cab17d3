"""Broad phase benchmark (issue 4): uniform grid in numba vs scipy cKDTree, up to 1e6 segments.

Random segments (length 0.5 mm, contact radius 0.05 mm, random directions) fill a cube at a
fixed density (1 segment per mm^3), so the number of candidate pairs grows like n; the box
is periodic in x and y (as for a fabric cell) for the grid (``find_pairs`` with periods) and
cKDTree (``boxsize``). For every size: best-of-``repeats`` wall time of each method (numba
compiled beforehand), candidate pairs found, and a check that both find the same set.

Usage::

    python studies/benchmarks/bench_broadphase.py [--out DIR] [--quick | --full] [--threads N] [--repeats R]

Default sizes 1e3..2e5 segments (< 1 min here); ``--full`` goes to 1e6 (target: <= 1 s);
``--quick``: 1e3 and 3e3 segments, one repeat (seconds). Writes ``DIR/bench_broadphase.nc``
(dims: size, method) and ``DIR/bench_broadphase.png`` (default DIR = results/bench_broadphase).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

DEFAULT_SIZES = (1_000, 3_000, 10_000, 30_000, 100_000, 200_000)
FULL_SIZES = DEFAULT_SIZES + (500_000, 1_000_000)
QUICK_SIZES = (1_000, 3_000)
LENGTH, RADIUS, MARGIN = 0.5, 0.05, 0.02


def segments(n: int, seed: int = 0):
    """(p0 (n, 3), d (n, 3), r (n,), box (3,)): random segments at 1 per mm^3, mm."""
    rng = np.random.default_rng(seed)
    side = float(n) ** (1.0 / 3.0)
    box = np.array([side, side, side])
    mid = rng.uniform(0.0, 1.0, (n, 3)) * box
    v = rng.normal(size=(n, 3))
    v *= LENGTH / np.linalg.norm(v, axis=1)[:, None]
    return mid - 0.5 * v, v, np.full(n, RADIUS), box


def _time(fn, repeats):
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _pairset(res):
    """Unordered segment pairs (a, b) found (periodic images not compared)."""
    a, b = res["a"], res["b"]
    return {(int(x), int(y)) if x < y else (int(y), int(x)) for x, y in zip(a, b)}


def run(out: Path, sizes, repeats: int = 3, threads: int | None = None, kdtree_max: int = 10 ** 7):
    import xarray as xr

    from homtex.contact.broad import find_pairs, find_pairs_kdtree

    out.mkdir(parents=True, exist_ok=True)
    # compile the numba kernels on a small problem
    p0, d, r, box = segments(200)
    find_pairs(p0, d, r, MARGIN, np.diag(box)[:2])
    methods = ("grid", "kdtree")
    t = np.full((len(sizes), 2), np.nan)
    npairs = np.zeros((len(sizes), 2), dtype=np.int64)
    agree = np.zeros(len(sizes), dtype=bool)
    for i, n in enumerate(sizes):
        p0, d, r, box = segments(n, seed=i)
        periods = np.diag(box)[:2]                       # periodic in x and y
        t[i, 0], g = _time(lambda: find_pairs(p0, d, r, MARGIN, periods), repeats)
        npairs[i, 0] = len(g["a"])
        if n <= kdtree_max:
            kbox = np.array([box[0], box[1], np.inf])
            t[i, 1], q = _time(lambda: find_pairs_kdtree(p0, d, r, MARGIN, box=kbox), repeats)
            npairs[i, 1] = len(q["a"])
            agree[i] = _pairset(g) == _pairset(q)
        print(f"n = {n:>9,d}: grid {t[i, 0]:.3f} s, cKDTree {t[i, 1]:.3f} s, pairs {npairs[i].tolist()}, "
              f"same set: {agree[i]}", flush=True)
    ds = xr.Dataset(
        {"seconds": (("size", "method"), t, {"units": "s", "long_name": f"best-of-{repeats} wall time of the broad phase (incl. narrow-phase distances)"}),
         "pairs": (("size", "method"), npairs, {"units": "1", "long_name": "candidate pairs found"}),
         "same_pairs": (("size",), agree, {"units": "1", "long_name": "grid and cKDTree find the same pair set"}),
         "seconds_per_segment": (("size", "method"), t / np.asarray(sizes)[:, None],
                                 {"units": "s", "long_name": "wall time per segment"})},
        coords={"size": ("size", np.asarray(sizes), {"units": "1", "long_name": "number of segments"}),
                "method": ("method", np.array(methods), {"units": "1", "long_name": "broad-phase method"})},
        attrs={"segment_length_mm": LENGTH, "contact_radius_mm": RADIUS, "margin_mm": MARGIN,
               "density_per_mm3": 1.0, "periodic": "x and y", "threads": int(threads or 0),
               "target": "1e6 segments in <= 1 s"})
    path = save_netcdf(ds, out / "bench_broadphase.nc")
    chart(ds, path.with_suffix(".png"))
    return path


def chart(ds, path):
    plt = pyplot()
    n = ds["size"].values
    fig, ax = plt.subplots(figsize=(6, 4.5))
    for j, m in enumerate(ds["method"].values):
        ax.loglog(n, ds["seconds"].values[:, j], "o-", label=str(m))
    ref = ds["seconds"].values[-1, 0] * n / n[-1]
    ax.loglog(n, ref, "k--", lw=0.8, label="O(n)")
    ax.axhline(1.0, color="grey", lw=0.8, ls=":")
    ax.axvline(1e6, color="grey", lw=0.8, ls=":")
    ax.set_xlabel("segments")
    ax.set_ylabel("wall time, s")
    ax.set_title("broad phase: uniform grid (numba) vs cKDTree, 2-periodic box")
    ax.legend()
    fig.tight_layout()
    save_figure(fig, path)


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--full", action="store_true", help="sizes up to 1e6 segments")
    p.add_argument("--threads", type=int, default=os.cpu_count())
    p.add_argument("--repeats", type=int, default=None, help="timing repeats (default 3; --quick: 1)")
    a = p.parse_args(argv)
    out = setup(a)
    import numba

    numba.set_num_threads(min(a.threads, numba.config.NUMBA_NUM_THREADS))
    sizes = QUICK_SIZES if a.quick else (FULL_SIZES if a.full else DEFAULT_SIZES)
    repeats = a.repeats or (1 if a.quick else 3)
    path = run(out, sizes, repeats=repeats, threads=a.threads)
    print(f"wrote {path} and {path.with_suffix('.png')}")


if __name__ == "__main__":
    main()
