"""Benchmark of the parallel AMG-CG phase (issue 24) on the slender octet blocks of bench_core.py.

For every size (octet cells per edge) it measures, in one run, to a relative residual of 1e-8:

* the STREAM-like triad a = b + s c on 1 and 2 numba threads (GB/s): the memory bandwidth that
  bounds a bandwidth-bound CG phase, and the bound of its 2-thread speed-up;
* the AMG setup: homtex's fast setup (Lanczos bounds on numba products) and pyamg's own;
* the CG phase with the V-cycle applied directly (numba kernels) on 1 and 2 threads, with the
  level matrices in float64 and float32, and pyamg's preconditioner with scipy products (1 thread):
  wall and process CPU seconds, iterations, seconds per iteration, and the bytes one iteration
  reads (level matrices, R, P and the CG operator; vectors not counted) with the time that read
  takes at the triad bandwidth (the memory-traffic bound);
* hierarchy reuse on a changed matrix (every element's E scaled by a random factor 0.8-1.2, and
  the PTC-like diagonal shift): iterations and CG seconds with the old hierarchy, against a
  rebuild;
* CHOLMOD (scikit-sparse, BLAS threads) where it imports: analysis + factorisation + solve
  (fresh), numeric refactorisation with the symbolic analysis reused + solve (changed matrix);
* optionally (``--petsc PYTHON``) PETSc CG + GAMG with the six rigid-body modes on 1 and 2 MPI
  processes (_petsc_worker.py under mpiexec, PYTHON a Python with petsc4py).

The machine (CPU model, cores) and the load average at the start of the run and of every size are
stored with the data and printed on the chart. On a shared machine the wall-clock ratios of 1 and
2 threads mean little; the process CPU seconds and same-run ratios are reported beside them.

Usage::

    python studies/benchmarks/bench_parallel_amg.py [--out DIR] [--quick] [--repeats R ...] [--petsc PYTHON]

Default sizes: 6, 10, 13 cells per edge (9.3e4, 4.1e5, 9.1e5 DOF); ``--quick``: 3 cells (seconds).
Writes DIR/bench_parallel_amg.nc and DIR/bench_parallel_amg.png (default DIR results/bench_parallel_amg).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402
from bench_core import build_problem, machine  # noqa: E402

DEFAULT = (6, 10, 13)
QUICK = (3,)
TOL = 1e-8
CASES = ("numba_t1", "numba_t2", "numba_f32_t1", "numba_f32_t2", "pyamg_t1")


class Clock:
    """Wall and process-CPU seconds of a block."""

    def __enter__(self):
        self.w, self.c = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *a):
        self.wall, self.cpu = time.perf_counter() - self.w, time.process_time() - self.c
        return False


def changed_matrix(frame, mask, seed=1):
    """The block's stiffness with every element's E scaled by a random factor in [0.8, 1.2]."""
    from homtex.fem.assembly import Assembler
    from homtex.linalg.solvers import constrain

    asm = Assembler(frame)
    R, L, EA, GJ, EIy, EIz, kGA = asm.element_arrays()
    s = np.random.default_rng(seed).uniform(0.8, 1.2, len(EA))
    return constrain(asm.stiffness((R, L, EA * s, GJ * s, EIy * s, EIz * s, kGA * s)), mask)


def cg_phase(lin, b, threads: int | None):
    """Warm solve, then the timed one; ``threads`` forced (None: the solver's load-average rule)."""
    import numba

    import homtex

    old = numba.get_num_threads()
    numba.set_num_threads(min(threads or 2, numba.config.NUMBA_NUM_THREADS))
    try:
        with homtex.set_options(amg_threads=threads):  # forced unless None
            lin.solve(b)                               # warm (first calls, page faults)
            with Clock() as c:
                x, rep = lin.solve(b)
    finally:
        numba.set_num_threads(old)
    return x, rep, c


def bytes_per_iteration(vc, Aop) -> float:
    """Bytes of matrix data one PCG iteration reads: 2 x degree products with each level matrix,
    R and P once, the CG product once (indices included; vectors not counted)."""
    deg = len(vc.levels[0]["coef"]) if len(vc.levels) > 1 else 0
    tot = Aop.nbytes
    for L in vc.levels[:-1]:
        tot += 2 * deg * L["A"].nbytes + L["R"].nbytes + L["P"].nbytes
    return float(tot)


def run_size(r: int, bw1: float, bw2: float, petsc: str | None) -> dict:
    import numba

    from homtex.fem.assembly import Assembler
    from homtex.linalg.nullspace import rigid_body_modes
    from homtex.linalg.parallel_amg import BSROperator
    from homtex.linalg.solvers import LinearSolver, ScaledAMG, _cholmod, constrain

    out = {"load_avg": os.getloadavg()[0]}
    f, mask, b = build_problem(r)
    A = constrain(Assembler(f).stiffness(), mask)
    B = rigid_body_modes(f.nodes)
    out["ndof"] = f.ndof
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))
    with Clock() as c:
        h = ScaledAMG(A, B, setup="fast")
    out["setup_fast"], out["setup_fast_cpu"] = c.wall, c.cpu
    if f.ndof <= 500_000:
        with Clock() as c:
            ScaledAMG(A, B, setup="pyamg")
        out["setup_pyamg"], out["setup_pyamg_cpu"] = c.wall, c.cpu
    x_ref = None
    for case in CASES:
        cyc = "pyamg" if case.startswith("pyamg") else "numba"
        prec = "float32" if "f32" in case else "float64"
        t = int(case[-1])
        lin = LinearSolver(A, method="amg", tol=TOL, hierarchy=h, cycle=cyc, precision=prec)
        x, rep, c = cg_phase(lin, b, t)
        out[f"cg_{case}"], out[f"cg_cpu_{case}"], out[f"it_{case}"] = c.wall, c.cpu, rep.iterations
        out[f"res_{case}"] = rep.residual
        if case == "numba_t1":
            x_ref = x
            out["bytes_it"] = bytes_per_iteration(lin.vcycle, BSROperator(A))
            out["bytes_it_f32"] = bytes_per_iteration(
                LinearSolver(A, method="amg", tol=TOL, hierarchy=h, precision="float32").vcycle, BSROperator(A))
        out[f"diff_{case}"] = float(np.abs(x - x_ref).max() / np.abs(x_ref).max())
        print(f"   {case:14s} CG {c.wall:7.2f} s wall {c.cpu:7.2f} s cpu  it {rep.iterations:4d}  "
              f"res {rep.residual:.1e}", flush=True)
    out["bound_t1"] = out["it_numba_t1"] * out["bytes_it"] / (bw1 * 1e9)
    out["bound_t2"] = out["it_numba_t2"] * out["bytes_it"] / (bw2 * 1e9)
    # reuse on a changed matrix
    A2 = changed_matrix(f, mask)
    lin = LinearSolver(A2, method="amg", tol=TOL, hierarchy=h)
    _, rep, c = cg_phase(lin, b, None)
    out["reuse_cg"], out["reuse_cg_cpu"], out["reuse_it"] = c.wall, c.cpu, rep.iterations
    with Clock() as c:
        lin2 = LinearSolver(A2, method="amg", B=B, tol=TOL)
    out["rebuild_setup"] = c.wall
    _, rep2, c2 = cg_phase(lin2, b, None)
    out["rebuild_cg"], out["rebuild_it"] = c2.wall, rep2.iterations
    print(f"   reuse: {out['reuse_it']} it {out['reuse_cg']:.2f} s; rebuild: setup {out['rebuild_setup']:.2f} s + "
          f"{out['rebuild_it']} it {out['rebuild_cg']:.2f} s", flush=True)
    if _cholmod is not None:
        import scipy.sparse as sp
        from sksparse.cholmod import analyze

        with Clock() as c:
            F = analyze(sp.csc_matrix(A), mode="supernodal")
            F.cholesky_inplace(sp.csc_matrix(A))
            xc = F(b)
        out["cholmod_fresh"], out["cholmod_fresh_cpu"] = c.wall, c.cpu
        with Clock() as c:
            F.cholesky_inplace(sp.csc_matrix(A2))
            F(b)
        out["cholmod_refactor"], out["cholmod_refactor_cpu"] = c.wall, c.cpu
        with Clock() as c:
            F(b)
        out["cholmod_resolve"] = c.wall
        out["cholmod_diff"] = float(np.abs(xc - x_ref).max() / np.abs(x_ref).max())
        print(f"   cholmod fresh {out['cholmod_fresh']:.2f} s, refactor+solve {out['cholmod_refactor']:.2f} s, "
              f"re-solve {out['cholmod_resolve']:.3f} s", flush=True)
    if petsc:
        for p in (1, 2):
            rep = petsc_run(petsc, r, p)
            if rep:
                out[f"petsc_p{p}"] = rep["setup_seconds"] + rep["solve_seconds"]
                out[f"petsc_it_p{p}"] = rep["iterations"]
                out[f"petsc_diff_p{p}"] = rep["difference"]
                print(f"   petsc {p} proc: setup {rep['setup_seconds']:.2f} s solve {rep['solve_seconds']:.2f} s "
                      f"it {rep['iterations']} diff {rep['difference']:.1e}", flush=True)
    return out


def petsc_run(python: str, r: int, procs: int) -> dict | None:
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, PYTHONPATH=str(root), OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1", NUMBA_CACHE_DIR="/tmp/homtex-petsc-numba")
    cmd = [shutil.which("mpiexec") or "mpiexec", "-n", str(procs), python,
           str(Path(__file__).resolve().parent / "_petsc_worker.py"), str(r), str(TOL)]
    res = subprocess.run(cmd, capture_output=True, text=True, env=env)
    line = [x for x in res.stdout.splitlines() if x.startswith("PETSC_RESULT ")]
    if not line:
        print(f"   petsc {procs} proc failed: {res.stderr[-400:]}")
        return None
    return json.loads(line[0].split(" ", 1)[1])


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--repeats", type=int, nargs="+", help="octet cells per edge (overrides sizes)")
    p.add_argument("--petsc", default=None, help="a Python with petsc4py: also run PETSc on 1 and 2 processes")
    a = p.parse_args(argv)
    out = setup(a)
    import numba
    import xarray as xr

    from homtex.linalg.kernels import stream_triad

    load0 = os.getloadavg()
    sizes = tuple(a.repeats) if a.repeats else (QUICK if a.quick else DEFAULT)
    nthr = numba.config.NUMBA_NUM_THREADS
    numba.set_num_threads(1)
    bw1 = stream_triad(2_000_000 if a.quick else 20_000_000)
    numba.set_num_threads(min(2, nthr))
    bw2 = stream_triad(2_000_000 if a.quick else 20_000_000)
    print(f"{machine()}, load {load0[0]:.2f}; triad 1 thread {bw1:.1f} GB/s, 2 threads {bw2:.1f} GB/s "
          f"({bw2 / bw1:.2f}x)", flush=True)
    rows = []
    for r in sizes:
        print(f"r = {r}", flush=True)
        rows.append(run_size(r, bw1, bw2, a.petsc))
    keys = sorted({k for row in rows for k in row})
    data = {k: ("size", np.array([row.get(k, np.nan) for row in rows], dtype=float)) for k in keys}
    units = {k: ("s" if any(k.startswith(s) for s in ("cg", "setup", "reuse", "rebuild", "cholmod_f", "cholmod_r",
                                                       "bound", "petsc_p")) else "1") for k in keys}
    units.update(bytes_it="B", bytes_it_f32="B", ndof="1", load_avg="1")
    ds = xr.Dataset({k: (v[0], v[1], {"units": units[k], "long_name": k.replace("_", " ")}) for k, v in data.items()},
                    coords={"size": ("size", np.asarray(sizes), {"units": "1", "long_name": "octet cells per edge"})},
                    attrs={"machine": machine(), "load_at_start": float(load0[0]), "tolerance": TOL,
                           "triad_GBs_1_thread": bw1, "triad_GBs_2_threads": bw2,
                           "lattice": "octet block, 4 elements per strut, L/r = 35 (bench_core.py)"})
    path = save_netcdf(ds, out / "bench_parallel_amg.nc")
    plot(ds, out / "bench_parallel_amg.png")
    print(f"wrote {path} and {path.with_suffix('.png')}")


def plot(ds, path) -> None:
    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.6))
    n = ds.ndof.values
    for k, lab in (("cg_numba_t1", "CG numba, 1 thread"), ("cg_numba_t2", "CG numba, 2 threads"),
                   ("cg_numba_f32_t2", "CG numba fp32 hierarchy, 2 thr."), ("cg_pyamg_t1", "CG pyamg/scipy"),
                   ("setup_fast", "setup, fast"), ("setup_pyamg", "setup, pyamg"),
                   ("bound_t2", "CG bound: bytes / triad (2 thr.)")):
        if k in ds and np.isfinite(ds[k].values).any():
            a1.loglog(n, ds[k].values, "o-" if "bound" not in k else "k^--", label=lab)
    a1.set_xlabel("DOF")
    a1.set_ylabel("seconds (wall)")
    a1.set_title("octet block to 1e-8: CG phase and setup", fontsize=9)
    a1.legend(fontsize=7)
    for k, lab in (("cholmod_fresh", "CHOLMOD fresh"), ("cholmod_refactor", "CHOLMOD refactor + solve"),
                   ("reuse_cg", "AMG-CG, reused hierarchy, changed matrix"), ("petsc_p1", "PETSc GAMG 1 proc"),
                   ("petsc_p2", "PETSc GAMG 2 proc")):
        if k in ds and np.isfinite(ds[k].values).any():
            a2.loglog(n, ds[k].values, "s-", label=lab)
    if "setup_fast" in ds:
        a2.loglog(n, ds.setup_fast.values + ds.cg_numba_t2.values, "o-", label="AMG-CG fresh (setup + CG, 2 thr.)")
    a2.set_xlabel("DOF")
    a2.set_ylabel("seconds (wall)")
    a2.set_title("against CHOLMOD and PETSc", fontsize=9)
    a2.legend(fontsize=7)
    loads = ", ".join(f"{v:.1f}" for v in ds.load_avg.values)
    fig.suptitle(f"{ds.attrs['machine']}; load at start {ds.attrs['load_at_start']:.2f} (per size: {loads}); "
                 f"triad {ds.attrs['triad_GBs_1_thread']:.1f} / {ds.attrs['triad_GBs_2_threads']:.1f} GB/s "
                 f"(1 / 2 threads)", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


if __name__ == "__main__":
    main()
