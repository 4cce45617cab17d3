"""Timings of the large-motion contact kernels on a grid of crossing yarns (issue 18).

A square grid of straight yarns (x-yarns at z = 0, y-yarns at z = 2r + a random gap in
[0, 2 ghat], r = 0.1 mm, elements 0.3 mm, yarn spacing 0.5 mm) gives ~4 candidate pairs per
crossing from the broad phase (margin ghat). For ~1e3 and ~1e5 candidate pairs it times, serial
and parallel (numba threads): the gaps of all candidates, the barrier potential with gradient and
PSD-projected Hessian blocks, the friction lag and potential, and the additive CCD bound for a
random step of 0.02 mm.

Measured here (2 cores shared with other work, 2026-11-24; ms per call, serial / 2 threads):

    pairs (all active)   gaps         potential+PSD Hessian   friction lag   friction     CCD
    968                  0.05 / 0.04  9.5 / 5.0               0.37           0.42 / 0.35  0.61 / 0.34
    93537                4.3 / 2.5    904 / 465               41             56 / 31      61 / 31

i.e. ~10 us per active pair for energy, gradient and projected Hessian (1.2 us without the
projection, 0.5 us without the Hessian), ~0.6 us per pair for friction and the CCD. When the
other core is busy a parallel call can cost a scheduler tick (4-8 ms) more than the serial one,
hence the size thresholds of ``homtex.contact.potential.PARALLEL_MIN``.

Usage::

    python studies/benchmarks/bench_contact_kernels.py [OUT] [--quick]

Writes ``OUT/bench_contact_kernels.nc`` (default OUT = results/contact_enforcement).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

import homtex
from homtex.contact import potential as pot
from homtex.contact.broad import BroadPhase
from homtex.contact.ccd import pair_step_bound
from homtex.contact.friction import friction_potential, pair_friction_lag
from homtex.contact.potential import Enforcement, pair_gaps, pair_potential
from homtex.contact.stencil import frame_stencil
from homtex.model.exclusions import arc_exclusions

R, GHAT, SPACING, EL_LEN = 0.1, 0.01, 0.5, 0.3


def grid(n_yarns, seed=0):
    rng = np.random.default_rng(seed)
    L = n_yarns * SPACING
    ne = int(round(L / EL_LEN))
    s = np.linspace(0, L, ne + 1)
    X, el, yarn = [], [], []
    for k in range(2 * n_yarns):
        c = (k % n_yarns + 0.5) * SPACING
        if k < n_yarns:
            X.append(np.column_stack([s, np.full(ne + 1, c), np.zeros(ne + 1)]))
        else:
            X.append(np.column_stack([np.full(ne + 1, c), s, 2 * R + rng.uniform(0, 2 * GHAT, ne + 1)]))
        base = k * (ne + 1)
        el.append(np.column_stack([base + np.arange(ne), base + np.arange(1, ne + 1)]))
        yarn.append(np.full(ne, k))
    return homtex.Frame(np.vstack(X), np.vstack(el), radius=R, E=3000.0, nu=0.3, yarn=np.concatenate(yarn))


def timed(fn, repeat):
    fn()
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def run(out: Path, sizes, repeat=3):
    import xarray as xr
    out.mkdir(parents=True, exist_ok=True)
    enf = Enforcement("barrier", ghat=GHAT, kappa=1.0)
    kernels = ("gaps", "potential", "friction_lag", "friction", "ccd")
    T = np.full((len(sizes), 2, len(kernels)), np.nan)
    n_pairs = np.zeros(len(sizes), dtype=np.int64)
    n_active = np.zeros(len(sizes), dtype=np.int64)
    saved = dict(pot.PARALLEL_MIN)
    for i, ny in enumerate(sizes):
        fr = grid(ny)
        bp = BroadPhase(fr.elements, fr.contact_radius, exclusions=arc_exclusions(fr))
        st = frame_stencil(fr, bp.pairs(fr.nodes, GHAT))
        x = fr.nodes
        rng = np.random.default_rng(1)
        dx = rng.normal(scale=0.02, size=x.shape)
        x1 = x + 0.1 * dx
        n_pairs[i] = len(st)
        n_active[i] = pair_potential(x, st, enf, hessian=False).n_active
        lag = pair_friction_lag(x, st, enf, mu=0.3)
        for p, par in enumerate((False, True)):
            for key in pot.PARALLEL_MIN:
                pot.PARALLEL_MIN[key] = 0 if par else 1 << 62
            fns = (lambda: pair_gaps(x, st), lambda: pair_potential(x, st, enf),
                   lambda: pair_friction_lag(x, st, enf, mu=0.3), lambda: friction_potential(lag, x1, x, 1e-3),
                   lambda: pair_step_bound(x, dx, st))
            for k, fn in enumerate(fns):
                T[i, p, k] = timed(fn, repeat)
        pot.PARALLEL_MIN.update(saved)
        print(f"{n_pairs[i]} pairs ({n_active[i]} active): " + ", ".join(
            f"{k} {T[i, 0, j] * 1e3:.2f}/{T[i, 1, j] * 1e3:.2f} ms" for j, k in enumerate(kernels)))
    ds = xr.Dataset(
        {"seconds": (("size", "mode", "kernel"), T, {"units": "s", "long_name": "best wall time of one call"}),
         "pairs": ("size", n_pairs, {"units": "1", "long_name": "candidate pairs"}),
         "active": ("size", n_active, {"units": "1", "long_name": "pairs with gap < ghat"})},
        coords={"size": ("size", np.asarray(sizes), {"units": "1", "long_name": "yarns per direction of the grid"}),
                "mode": ("mode", ["serial", "parallel"], {"units": "1", "long_name": "numba threads: one or all"}),
                "kernel": ("kernel", list(kernels), {"units": "1", "long_name": "contact kernel"})},
        attrs={"threads": int(pot.numba.get_num_threads()), "ghat_mm": GHAT, "radius_mm": R,
               "homtex_version": homtex.__version__ if hasattr(homtex, "__version__") else "",
               "note": "serial/parallel: numba kernels forced to one or all threads"})
    save_netcdf(ds, out / "bench_contact_kernels.nc")
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for k, name in enumerate(kernels):
        for p, (mode, ls) in enumerate((("serial", "-"), ("parallel", "--"))):
            ax.plot(n_pairs, T[:, p, k] * 1e3, ls, marker="o", label=f"{name}, {mode}")
    ax.set(xscale="log", yscale="log", xlabel="candidate pairs, 1", ylabel="time per call, ms",
           title="large-motion contact kernels (2-core machine)")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    save_figure(fig, out / "bench_contact_kernels.png")
    return ds


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    a = p.parse_args(argv)
    run(setup(a), (36,) if a.quick else (36, 360))


if __name__ == "__main__":
    main()
