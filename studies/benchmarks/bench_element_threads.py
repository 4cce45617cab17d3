"""The co-rotational element loops on one thread and on all: where threading pays.

A frame of wavy yarns (elements 0.25 mm, radius 0.1 mm, E 3 GPa) in a deformed state (random
translations of 0.05 mm and rotations of 0.05 rad) is evaluated with the consistent tangent and
with the forces alone, over 64 .. 16384 elements, three ways:

- ``plain``: the one-thread loop (``corotational_tangent_serial`` / ``..._response_serial``);
- ``prange_1``: the threaded kernel on one numba thread;
- ``prange_all``: the threaded kernel on all numba threads.

The three give bitwise the same forces and tangents (checked here). ``homtex`` runs the threaded
kernel wherever numba has one thread (it is the faster loop there), and on all threads from
``PARALLEL_ELEMENTS`` elements (4000; a shared machine's busy core makes a threaded call wait).

Usage::

    python studies/benchmarks/bench_element_threads.py [--out DIR] [--quick]

Writes ``OUT/bench_element_threads.nc`` and ``.png`` (default OUT = results/bench_element_threads).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numba
import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

import homtex
from homtex.analysis.corotational import PARALLEL_ELEMENTS, Corotational
from homtex.fem import corotational as K

EL, R = 0.25, 0.1
MODES = ("plain", "prange_1", "prange_all")


def wavy_frame(n_elements: int, per_yarn: int = 64) -> homtex.Frame:
    """Yarns of ``per_yarn`` elements along x, 1 mm apart, each a sine of amplitude 0.2 mm."""
    n_yarns = max(1, n_elements // per_yarn)
    s = np.arange(per_yarn + 1) * EL
    X, el, yarn = [], [], []
    for k in range(n_yarns):
        X.append(np.column_stack([s, np.full_like(s, float(k)), 0.2 * np.sin(2 * np.pi * s / 4.0)]))
        b = k * (per_yarn + 1)
        el.append(np.column_stack([b + np.arange(per_yarn), b + np.arange(1, per_yarn + 1)]))
        yarn.append(np.full(per_yarn, k))
    return homtex.Frame(np.vstack(X), np.vstack(el), radius=R, E=3000.0, nu=0.3, yarn=np.concatenate(yarn))


def kernel_args(cor: Corotational, tangent: bool):
    a = (np.ascontiguousarray(cor.positions), cor.Q, cor.frame.elements, cor.shift, cor.E0, cor.L0, *cor.arrays,
         cor._prestrain(1.0))
    outs = (cor.fe, cor.Ke, cor.Rr, cor.lcur, cor.theta, cor.forces, cor.energy) if tangent else (
        cor.fe, cor.Rr, cor.lcur, cor.theta, cor.forces, cor.energy)
    return a + outs


def best_of(fn, repeat: int) -> float:
    fn()
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def run(out: Path, sizes, repeat: int) -> xr.Dataset:
    threads = numba.get_num_threads()
    T = np.full((len(sizes), 2, len(MODES)), np.nan)
    m_el = np.zeros(len(sizes), dtype=np.int64)
    for i, n in enumerate(sizes):
        fr = wavy_frame(n)
        m_el[i] = fr.n_elements
        cor = Corotational(fr, geometric="consistent")
        rng = np.random.default_rng(1)
        cor.ut[...] = rng.normal(scale=0.05, size=cor.ut.shape)
        cor.Ke = np.zeros((fr.n_elements, 12, 12))
        results = []
        for j, kind in enumerate(("tangent", "response")):
            tangent = kind == "tangent"
            plain = K.corotational_tangent_serial if tangent else K.corotational_response_serial
            par = K.corotational_tangent if tangent else K.corotational_response
            args = kernel_args(cor, tangent)
            for k, (fn, nt) in enumerate(((plain, threads), (par, 1), (par, threads))):
                numba.set_num_threads(nt)
                try:
                    T[i, j, k] = best_of(lambda: fn(*args), repeat)
                    results.append((cor.fe.copy(), cor.Ke.copy()))
                finally:
                    numba.set_num_threads(threads)
        same = all(np.array_equal(results[0][0], r[0]) for r in results) and all(
            np.array_equal(results[0][1], r[1]) for r in results[:3])
        if not same:
            raise AssertionError(f"{m_el[i]} elements: the threaded and plain loops differ")
        print(f"{m_el[i]:6d} elements: tangent " + " / ".join(f"{T[i, 0, k] * 1e3:.3f}" for k in range(3))
              + " ms; forces " + " / ".join(f"{T[i, 1, k] * 1e3:.3f}" for k in range(3))
              + f" ms (plain / prange 1 thread / prange {threads} threads)")
    ds = xr.Dataset(
        {"seconds": (("elements", "evaluation", "mode"), T, {"units": "s", "long_name": "best wall time of one call"})},
        coords={"elements": ("elements", m_el, {"units": "1", "long_name": "beam elements of the frame"}),
                "evaluation": ("evaluation", ["tangent", "forces"],
                               {"units": "1", "long_name": "forces and consistent tangent, or forces alone"}),
                "mode": ("mode", list(MODES), {"units": "1", "long_name": "plain loop, threaded kernel on one "
                                                "thread, threaded kernel on all threads"})},
        attrs={"threads": threads, "element_length_mm": EL, "radius_mm": R, "repeat": repeat,
               "parallel_elements": PARALLEL_ELEMENTS,
               "machine": "the run's machine; see docs/performance.md for the quoted one"})
    save_netcdf(ds, out / "bench_element_threads.nc")
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for j, ev in enumerate(("tangent", "forces")):
        for k, (mode, ls) in enumerate(zip(MODES, ("-", "--", ":"))):
            ax.plot(m_el, T[:, j, k] / m_el * 1e6, ls, marker="o" if j == 0 else "s",
                    label=f"{ev}: {mode.replace('_all', f' {threads} threads').replace('_1', ' 1 thread')}")
    ax.axvline(PARALLEL_ELEMENTS, color="0.3", lw=0.8)
    ax.text(PARALLEL_ELEMENTS, 0.97 * ax.get_ylim()[1], "engine threads from here (PARALLEL_ELEMENTS) ", fontsize=7,
            va="top", ha="right")
    ax.set(xscale="log", xlabel="beam elements, 1", ylabel="time per element, us",
           title="co-rotational element loops: one thread against all")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    save_figure(fig, out / "bench_element_threads.png")
    return ds


def main(argv=None) -> None:
    a = parser(__file__, __doc__).parse_args(argv)
    run(setup(a), (64, 256) if a.quick else (64, 128, 256, 512, 1024, 2048, 4096, 16384), 3 if a.quick else 20)


if __name__ == "__main__":
    main()
