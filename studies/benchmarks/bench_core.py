"""Benchmark of the beam-frame core (issue 2): assembly, AMG-CG, Jacobi-CG, direct solvers.

Slender 3D octet-truss blocks (strut length / radius = 35, 4 Timoshenko elements per
strut, clamped at z = 0, a lateral and vertical load on the top face) from ~1e4 DOF up.
For every size it measures

* assembly throughput (elements/s, best of repeated warm calls of ``Assembler.stiffness``)
  and, at small sizes, the plain-numpy reference assembly on the same input;
* AMG-CG (the default solver): setup s, solve s, iterations, operator complexity;
* Jacobi-CG: iterations until convergence or the iteration cap (stall, reported);
* the direct solver (CHOLMOD when scikit-sparse imports, else SuperLU) while it is
  predicted to finish within the time limit;
* peak resident memory during each method (psutil sampler thread, MiB);
* optionally OpenSeesPy (``--opensees``) on one size, same frame, displacements compared.

Numba JIT compile time of the assembly kernel is measured cold (a subprocess with an
empty ``NUMBA_CACHE_DIR``) and cached (a second subprocess reusing that directory).

Threads: numba gets ``--threads`` (default: all cores, 2 on the reference machine); BLAS
is limited to 1 thread inside the solvers (homtex.solvers does that).

Usage::

    python studies/benchmarks/bench_core.py [--out DIR] [--quick | --full] [--opensees] [--threads N]

Default sizes 8.7e3 .. 4.1e5 DOF (about 45 s here); ``--full`` up to 2.1e6 DOF (4-5 min);
``--quick``: 2 and 3 cells per edge, a small stall case and no JIT subprocesses (seconds).
Writes ``DIR/bench_core.nc`` (dims: size, method) and ``DIR/bench_core.png``
(default DIR = results/bench_core).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

DEFAULT_REPEATS = (3, 5, 8, 10)  # 8.7e3 .. 4.1e5 DOF, about 45 s here
FULL_REPEATS = (3, 5, 8, 10, 12, 14, 17)  # up to 2.1e6 DOF, about 4-5 min here
QUICK_REPEATS = (2, 3)
NEL = 4
RADIUS = 0.02  # mm; strut length a / sqrt(2) = 0.707 mm -> L / r = 35
E_MOD, NU = 1000.0, 0.3  # MPa


class PeakRSS:
    """Context manager sampling the process RSS every ``dt`` s; ``.peak`` in MiB."""

    def __init__(self, dt: float = 0.005):
        import psutil

        self.proc = psutil.Process()
        self.dt = dt
        self.peak = 0.0
        self.start = 0.0

    def _run(self):
        while not self._stop.is_set():
            self.peak = max(self.peak, self.proc.memory_info().rss / 2**20)
            time.sleep(self.dt)

    def __enter__(self):
        self.start = self.proc.memory_info().rss / 2**20
        self.peak = self.start
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()
        return self

    def __exit__(self, *a):
        self._stop.set()
        self._t.join()
        self.peak = max(self.peak, self.proc.memory_info().rss / 2**20)
        return False


def build_problem(r: int, nel: int = NEL):
    """Octet block of r^3 cells (edge 1 mm), clamped at z = 0, loaded on the top face.

    Returns (frame, mask (6n,) bool, b (6n,) load vector N / N mm).
    """
    from homtex.geometry.lattices import lattice_frame

    f = lattice_frame("octet", radius=RADIUS, E=E_MOD, nu=NU, elements_per_strut=nel,
                      repeat=(r, r, r), periodic=False)
    z = f.nodes[:, 2]
    mask = np.zeros((f.n_nodes, 6), dtype=bool)
    mask[z < 1e-9] = True
    top = np.flatnonzero(z > z.max() - 1e-9)
    b = np.zeros((f.n_nodes, 6))
    b[top, 0] = 1e-3
    b[top, 2] = -1e-3
    return f, mask.ravel(), b.ravel()


def time_assembly(asm, min_seconds: float = 0.3) -> float:
    """Best wall time (s) of warm ``asm.stiffness()`` calls (at least 3, >= min_seconds)."""
    asm.stiffness()
    best, spent, k = np.inf, 0.0, 0
    while k < 3 or spent < min_seconds:
        t0 = time.perf_counter()
        asm.stiffness()
        dt = time.perf_counter() - t0
        best, spent, k = min(best, dt), spent + dt, k + 1
    return best


JIT_SNIPPET = r"""
import json, time
t0 = time.perf_counter()
import numpy as np
from homtex.geometry.lattices import lattice_frame
from homtex.fem.assembly import Assembler
import homtex
t_import = time.perf_counter() - t0
f = lattice_frame("octet", radius=0.02, E=1000.0, nu=0.3, elements_per_strut=2, repeat=(2, 2, 2), periodic=False)
asm = Assembler(f)
t0 = time.perf_counter(); asm.stiffness(); t_first = time.perf_counter() - t0
t0 = time.perf_counter(); asm.stiffness(); t_second = time.perf_counter() - t0
z = f.nodes[:, 2]
fixed = {int(i): "all" for i in np.flatnonzero(z < 1e-9)}
t0 = time.perf_counter()
homtex.solve_static(f, fixed, {int(np.argmax(z)): (1e-3, 0, 0, 0, 0, 0)})
t_static = time.perf_counter() - t0
print(json.dumps({"import": t_import, "assembly_first": t_first, "assembly_second": t_second,
                  "static_first": t_static}))
"""


def jit_times(threads: int) -> dict:
    """Cold (empty numba cache) and cached first-call times, s, from two subprocesses."""
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, NUMBA_NUM_THREADS=str(threads))
        for label in ("cold", "cached"):
            res = subprocess.run([sys.executable, "-c", JIT_SNIPPET], env=env, capture_output=True,
                                 text=True, check=True)
            out[label] = json.loads(res.stdout.strip().splitlines()[-1])
    return out


def opensees_solve(frame, mask, b):
    """Same frame in OpenSeesPy (ElasticTimoshenkoBeam, same k G A): (u (n, 6), build s, solve s)."""
    import openseespy.opensees as ops

    t0 = time.perf_counter()
    ops.wipe()
    ops.model("basic", "-ndm", 3, "-ndf", 6)
    for i, x in enumerate(frame.nodes):
        ops.node(i + 1, *map(float, x))
    m6 = mask.reshape(-1, 6)
    for i in np.flatnonzero(m6.any(axis=1)):
        ops.fix(int(i) + 1, *[int(v) for v in m6[i]])
    # one transformation per distinct local e3 (vecxz); octet blocks have a handful
    e3 = np.round(frame.R[:, 2], 12)
    uniq, tag = np.unique(e3, axis=0, return_inverse=True)
    for t, v in enumerate(uniq):
        ops.geomTransf("Linear", t + 1, *map(float, v))
    A, G, J, Iy, Iz, k = frame.A, frame.G, frame.J, frame.Iy, frame.Iz, frame.k
    for e, (i, j) in enumerate(frame.elements):
        ops.element("ElasticTimoshenkoBeam", e + 1, int(i) + 1, int(j) + 1, float(frame.E[e]),
                    float(G[e]), float(A[e]), float(J[e]), float(Iy[e]), float(Iz[e]),
                    float(k[e] * A[e]), float(k[e] * A[e]), int(tag[e]) + 1)
    ops.timeSeries("Linear", 1)
    ops.pattern("Plain", 1, 1)
    b6 = b.reshape(-1, 6)
    for i in np.flatnonzero(np.any(b6 != 0, axis=1)):
        ops.load(int(i) + 1, *map(float, b6[i]))
    ops.constraints("Plain")
    ops.numberer("RCM")
    ops.system("UmfPack")
    ops.test("NormUnbalance", 1e-12, 1)
    ops.algorithm("Linear")
    ops.integrator("LoadControl", 1.0)
    ops.analysis("Static")
    t_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    ok = ops.analyze(1)
    t_solve = time.perf_counter() - t0
    if ok != 0:
        raise RuntimeError(f"OpenSees analyze returned {ok}")
    u = np.array([ops.nodeDisp(i + 1) for i in range(frame.n_nodes)])
    ops.wipe()
    return u, t_build, t_solve


STALL_NDOF = [0]


def stall_case(direct_name: str, r: int = 6, nel: int = 8, maxiter: int = 3000) -> dict:
    """Bending-dominated BCC block (strut L / r = 87) where Jacobi-CG stalls: per method a dict
    of iterations, seconds, residual, converged (the stall is raised as SolverError)."""
    from homtex.errors import SolverError
    from homtex.fem.assembly import Assembler
    from homtex.geometry.lattices import lattice_frame
    from homtex.linalg.nullspace import rigid_body_modes
    from homtex.linalg.solvers import LinearSolver, constrain

    f = lattice_frame("bcc", radius=0.01, E=E_MOD, nu=NU, elements_per_strut=nel, repeat=(r, r, r),
                      periodic=False)
    STALL_NDOF[0] = f.ndof
    z = f.nodes[:, 2]
    mask = np.zeros((f.n_nodes, 6), dtype=bool)
    mask[z < 1e-9] = True
    b = np.zeros((f.n_nodes, 6))
    b[z > z.max() - 1e-9, 0] = 1e-3
    A = constrain(Assembler(f).stiffness(), mask.ravel())
    out = {}
    for name, kind in (("amg", "amg"), ("cg_jacobi", "cg"), (direct_name, "direct")):
        t0 = time.perf_counter()
        try:
            lin = LinearSolver(A, method=kind, B=rigid_body_modes(f.nodes) if kind == "amg" else None,
                               tol=1e-8, maxiter=maxiter if kind == "cg" else None)
            _, rep = lin.solve(b.ravel())
            ok = 1.0
        except SolverError as err:
            rep, ok = err.report, 0.0
            print(f"   stall case {name}: SolverError raised: {str(err)[:200]}")
        out[name] = dict(iterations=rep.iterations, seconds=time.perf_counter() - t0,
                         residual=rep.residual, converged=ok)
        print(f"   stall case (BCC, {f.ndof} DOF) {name:15s} it {rep.iterations:5d} "
              f"res {rep.residual:.1e} {out[name]['seconds']:.2f} s converged={bool(ok)}", flush=True)
    return out


def run(out: Path, repeats, *, threads: int, direct_limit: float, jacobi_maxiter: int,
        jacobi_max_dof: int, reference_max_elements: int, opensees_repeat: int | None,
        jit: bool = True, stall: tuple = (6, 8)) -> Path:
    import xarray as xr

    from homtex.errors import SolverError
    from homtex.fem.assembly import Assembler, assemble_reference
    from homtex.linalg.nullspace import rigid_body_modes
    from homtex.linalg.solvers import LinearSolver, _cholmod, constrain

    direct_name = "direct_cholmod" if _cholmod is not None else "direct_superlu"
    methods = ["amg", "cg_jacobi", direct_name, "opensees"]
    ns, nm = len(repeats), len(methods)
    nan = lambda: np.full((ns, nm), np.nan)  # noqa: E731
    setup, solve, iters, resid, opc, peak, peak_inc, conv = (nan() for _ in range(8))
    ndof, nelem, asm_s, asm_rate, ref_s, ref_err = (np.full(ns, np.nan) for _ in range(6))
    os_err = np.full(ns, np.nan)
    direct_prev = None  # (ndof, seconds) of the last direct run
    if jit:
        print(f"JIT timings (subprocesses, NUMBA_NUM_THREADS={threads}) ...", flush=True)
        jit = jit_times(threads)
        print(json.dumps(jit, indent=1), flush=True)
    else:
        jit = {}
        print("JIT timings skipped", flush=True)
    for s, r in enumerate(repeats):
        frame, mask, b = build_problem(r)
        ndof[s], nelem[s] = frame.ndof, frame.n_elements
        asm = Assembler(frame)
        asm_s[s] = time_assembly(asm)
        asm_rate[s] = frame.n_elements / asm_s[s]
        K = asm.stiffness().copy()
        line = f"r={r:2d} ndof={frame.ndof:8d} elements={frame.n_elements:8d} assembly {asm_rate[s]:.3g} el/s"
        if frame.n_elements <= reference_max_elements:
            t0 = time.perf_counter()
            Kr = assemble_reference(frame)
            ref_s[s] = time.perf_counter() - t0
            ref_err[s] = abs(Kr - K.tocsr()).max() / abs(Kr).max()
            line += f", numpy reference {ref_s[s] / asm_s[s]:.0f}x slower (max rel diff {ref_err[s]:.1e})"
        print(line, flush=True)
        A = constrain(K, mask)
        B = rigid_body_modes(frame.nodes)
        for mi, meth in enumerate(methods):
            if meth == "opensees":
                continue
            if meth == "cg_jacobi" and frame.ndof > jacobi_max_dof:
                continue
            if meth.startswith("direct") and direct_prev is not None:
                guess = direct_prev[1] * (frame.ndof / direct_prev[0]) ** 1.5
                if guess > direct_limit:
                    print(f"   {meth}: skipped (predicted {guess:.0f} s > {direct_limit:.0f} s)")
                    continue
            kind = {"amg": "amg", "cg_jacobi": "cg"}.get(meth, "direct")
            with PeakRSS() as mem:
                try:
                    lin = LinearSolver(A, method=kind, B=B if kind == "amg" else None, tol=1e-8,
                                       maxiter=jacobi_maxiter if kind == "cg" else None)
                    x, rep = lin.solve(b)
                    conv[s, mi] = 1.0
                except SolverError as err:
                    rep = err.report
                    conv[s, mi] = 0.0
                    print(f"   {meth}: SolverError (detected, not returned): {str(err)[:160]}")
            setup[s, mi], solve[s, mi] = rep.setup_seconds, rep.solve_seconds
            iters[s, mi], resid[s, mi] = rep.iterations, rep.residual
            opc[s, mi] = rep.operator_complexity
            peak[s, mi], peak_inc[s, mi] = mem.peak, mem.peak - mem.start
            if kind == "direct":
                direct_prev = (frame.ndof, rep.setup_seconds + rep.solve_seconds)
            if conv[s, mi] == 1.0 and kind in ("amg", "direct"):
                x_ref = x  # the direct solution wins when both ran (it comes later)
            print(f"   {meth:15s} setup {rep.setup_seconds:8.3f} s  solve {rep.solve_seconds:8.3f} s  "
                  f"it {rep.iterations:5d}  res {rep.residual:.1e}  opc {rep.operator_complexity:.2f}  "
                  f"peak +{mem.peak - mem.start:.0f} MiB", flush=True)
        if opensees_repeat == r:
            mi = methods.index("opensees")
            try:
                with PeakRSS() as mem:
                    u_os, tb, ts = opensees_solve(frame, mask, b)
                setup[s, mi], solve[s, mi] = tb, ts
                peak[s, mi], peak_inc[s, mi] = mem.peak, mem.peak - mem.start
                ref = x_ref.reshape(-1, 6)
                os_err[s] = np.abs(u_os - ref).max() / np.abs(ref).max()
                conv[s, mi] = 1.0
                print(f"   opensees        build {tb:8.3f} s  solve {ts:8.3f} s  max |u_os - u| / "
                      f"max |u| = {os_err[s]:.1e}", flush=True)
            except Exception as err:  # optional comparison
                print(f"   opensees: skipped ({type(err).__name__}: {err})")
    stall = stall_case(direct_name, r=stall[0], nel=stall[1])
    dims = ("size", "method")
    ds = xr.Dataset(
        {
            "ndof": (("size",), ndof, {"units": "1", "long_name": "degrees of freedom"}),
            "n_elements": (("size",), nelem, {"units": "1", "long_name": "beam elements"}),
            "assembly_seconds": (("size",), asm_s, {"units": "s", "long_name": "warm assembly time (best of repeats)"}),
            "assembly_rate": (("size",), asm_rate, {"units": "1/s", "long_name": "assembly throughput, elements per second (warm)"}),
            "reference_assembly_seconds": (("size",), ref_s, {"units": "s", "long_name": "plain-numpy reference assembly time"}),
            "reference_ratio": (("size",), ref_s / asm_s, {"units": "1", "long_name": "numpy reference time / numba assembly time"}),
            "reference_difference": (("size",), ref_err, {"units": "1", "long_name": "max |K_ref - K| / max |K_ref|"}),
            "setup_seconds": (dims, setup, {"units": "s", "long_name": "solver setup (AMG hierarchy, factorisation; model build for opensees)"}),
            "solve_seconds": (dims, solve, {"units": "s", "long_name": "solve time"}),
            "total_seconds": (dims, setup + solve, {"units": "s", "long_name": "setup plus solve"}),
            "iterations": (dims, iters, {"units": "1", "long_name": "CG iterations (0 for direct)"}),
            "residual": (dims, resid, {"units": "1", "long_name": "true relative residual ||b - A x|| / ||b||"}),
            "operator_complexity": (dims, opc, {"units": "1", "long_name": "AMG operator complexity (1 for non-AMG)"}),
            "converged": (dims, conv, {"units": "1", "long_name": "1 converged, 0 failure detected and raised, NaN not run"}),
            "peak_rss": (dims, peak, {"units": "MiB", "long_name": "peak resident memory of the process during the method"}),
            "peak_rss_increase": (dims, peak_inc, {"units": "MiB", "long_name": "peak resident memory above the level at the method's start"}),
            "opensees_difference": (("size",), os_err, {"units": "1", "long_name": "max |u_opensees - u_amg| / max |u_amg|"}),
        },
        coords={"stall_method": ("stall_method", list(stall),
                                 {"units": "1", "long_name": "solver on the bending-dominated BCC block"}),
                "size": ("size", np.asarray(repeats), {"units": "1", "long_name": "cells per edge of the octet block"}),
                "method": ("method", methods, {"units": "1", "long_name": "solver"})},
        attrs={"lattice": f"octet block, {NEL} elements per strut, strut L/r = 35, clamped at z=0",
               "tolerance": 1e-8, "numba_threads": threads, "blas_threads_in_solver": 1,
               "jit_timings": "measured" if jit else "skipped",
               "machine": machine(),
               **{f"jit_{k}_{q}_seconds": v for k, d in jit.items() for q, v in d.items()}},
    )
    for key, unit, long in (("iterations", "1", "CG iterations"), ("seconds", "s", "setup plus solve"),
                            ("residual", "1", "true relative residual"),
                            ("converged", "1", "1 converged, 0 failure detected and raised")):
        ds[f"stall_{key}"] = (("stall_method",), np.array([v[key] for v in stall.values()], float),
                              {"units": unit, "long_name": f"{long}, bending-dominated BCC block "
                                                          f"(L/r = 87, 8 elements per strut)"})
    ds.attrs["stall_ndof"] = STALL_NDOF[0]
    path = save_netcdf(ds, out / "bench_core.nc")
    plot(ds, out / "bench_core.png")
    return path


def machine() -> str:
    import platform

    name = platform.processor() or platform.machine()
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                name = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{os.cpu_count()} cores, {name}"


def plot(ds, path: Path) -> None:
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    n = ds.ndof.values
    for meth in ds.method.values:
        t = ds.total_seconds.sel({"method": meth}).values
        ok = np.isfinite(t)
        if not ok.any():
            continue
        a1.loglog(n[ok], t[ok], "o-", label=str(meth))
        it = ds.iterations.sel({"method": meth}).values
        if meth in ("amg", "cg_jacobi") and np.isfinite(it).any():
            conv = ds.converged.sel({"method": meth}).values
            a2.semilogx(n[ok], it[ok], "o-", label=str(meth))
            bad = ok & (conv == 0)
            a2.semilogx(n[bad], it[bad], "rx", ms=10, label="stalled (raised)" if bad.any() else None)
    a1.loglog(n, ds.assembly_seconds.values, "s--", label="assembly (warm)")
    ref = ds.total_seconds.sel({"method": "amg"}).values
    i0 = int(np.nanargmin(n))
    a1.loglog(n, ref[i0] * n / n[i0], "k:", label="O(n)")
    a1.set_xlabel("DOF")
    a1.set_ylabel("setup + solve, s")
    a1.set_title("octet block, tol 1e-8")
    a1.legend(fontsize=8)
    a2.set_xlabel("DOF")
    a2.set_ylabel("CG iterations")
    a2.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--full", action="store_true", help="sizes up to ~2e6 DOF")
    p.add_argument("--threads", type=int, default=os.cpu_count())
    p.add_argument("--opensees", action="store_true", help="compare OpenSeesPy at ~5e4 DOF")
    p.add_argument("--repeats", type=int, nargs="+", help="octet cells per edge (overrides sizes)")
    p.add_argument("--direct-limit", type=float, default=None,
                   help="skip the direct solver when predicted slower than this, s")
    a = p.parse_args(argv)
    out = setup(a)
    os.environ["NUMBA_NUM_THREADS"] = str(a.threads)
    import numba

    numba.set_num_threads(min(a.threads, numba.config.NUMBA_NUM_THREADS))
    sizes = QUICK_REPEATS if a.quick else (FULL_REPEATS if a.full else DEFAULT_REPEATS)
    repeats = tuple(a.repeats) if a.repeats else sizes
    limit = a.direct_limit or (300.0 if a.full else 40.0)
    path = run(out, repeats, threads=a.threads, direct_limit=limit,
               jacobi_maxiter=3000, jacobi_max_dof=250_000, reference_max_elements=12_000,
               opensees_repeat=(repeats[-1] if a.quick else 5) if a.opensees else None,
               jit=not a.quick, stall=(2, 2) if a.quick else (6, 8))
    print(f"wrote {path} and {path.with_suffix('.png')}")


if __name__ == "__main__":
    main()
