"""The parallel AMG-CG phase, the fast setup, the tangent backends and the array-module GPU path
(checked on the CPU), against direct solves and pyamg's own preconditioner."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import homtex
from homtex.errors import SolverError
from homtex.fem.assembly import Assembler
from homtex.geometry.lattices import lattice_frame
from homtex.linalg import kernels as K
from homtex.linalg.nullspace import rigid_body_modes
from homtex.linalg.parallel_amg import BSROperator, VCycle, pcg, spectral_radius
from homtex.linalg.solvers import LinearSolver, ScaledAMG, constrain


@pytest.fixture(scope="module")
def block():
    f = lattice_frame("octet", radius=0.02, E=1000.0, nu=0.3, elements_per_strut=2, repeat=(3, 3, 3),
                      periodic=False)
    z = f.nodes[:, 2]
    mask = np.zeros((f.n_nodes, 6), dtype=bool)
    mask[z < 1e-9] = True
    b = np.zeros((f.n_nodes, 6))
    b[z > z.max() - 1e-9, 0] = 1e-3
    A = constrain(Assembler(f).stiffness(), mask.ravel())
    return f, A, b.ravel(), mask.ravel()


@pytest.mark.parametrize("parallel", [True, False])
def test_bsr_kernels_match_scipy(parallel):
    rng = np.random.default_rng(0)
    M = sp.random(600, 480, density=0.02, random_state=rng, format="csr")
    for bs in ((6, 6), (6, 3), (1, 1)):
        B = sp.bsr_matrix(sp.random(600, 480, density=0.02, random_state=rng), blocksize=bs) if bs != (1, 1) else M
        op = BSROperator(B, parallel=parallel)
        op._k = K._TABLE["bsr66" if op.blocks66 else "bsr"][0 if parallel else 1]
        x = rng.normal(size=480)
        z = rng.normal(size=600)
        y = np.empty(600)
        op.apply(x, y, alpha=0.5, z=z, s=-2.0)
        assert np.allclose(y, 0.5 * z - 2.0 * (B @ x), rtol=1e-12, atol=1e-12)
    S = sp.bsr_matrix(sp.random(120, 120, density=0.1, random_state=rng) + sp.eye(120), blocksize=(6, 6))
    op = BSROperator(S, parallel=parallel)
    x = rng.normal(size=120)
    y = np.empty(120)
    assert np.isclose(op.dot_apply(x, y), x @ (S @ x))
    assert np.allclose(y, S @ x)


def test_vector_kernels():
    rng = np.random.default_rng(1)
    n = 50_000
    x, r, p, ap = (rng.normal(size=n) for _ in range(4))
    for par in (True, False):
        xx, rr = x.copy(), r.copy()
        nr2 = K._TABLE["cg_update"][0 if par else 1](xx, rr, p, ap, 0.3)
        assert np.allclose(xx, x + 0.3 * p) and np.allclose(rr, r - 0.3 * ap) and np.isclose(nr2, rr @ rr)
        assert np.isclose(K._TABLE["dot"][0 if par else 1](x, r), x @ r)
    assert K.stream_triad(100_000, repeats=1) > 0


def test_spectral_radius_against_eigsh(block):
    _, A, _, _ = block
    d = A.diagonal()
    s = sp.diags(1 / np.sqrt(d))
    As = sp.bsr_matrix(s @ A @ s, blocksize=(6, 6))
    ref = spla.eigsh(sp.csr_matrix(As), k=1, which="LA", return_eigenvectors=False)[0]
    est = spectral_radius(As, steps=30)
    assert ref * 0.97 <= est <= ref * 1.05


def test_vcycle_equals_pyamg_preconditioner(block):
    f, A, b, _ = block
    h = ScaledAMG(A, rigid_body_modes(f.nodes), max_coarse=300, setup="pyamg")
    assert len(h.ml.levels) >= 3
    V = VCycle(h)
    r = np.random.default_rng(2).normal(size=A.shape[0])
    ref = h.aspreconditioner() @ r
    z = np.empty_like(r)
    rz = V.apply(r, z)
    assert np.abs(z - ref).max() <= 1e-12 * np.abs(ref).max()
    assert np.isclose(rz, r @ ref)


@pytest.mark.parametrize("setup,precision", [("fast", "float64"), ("pyamg", "float64"), ("fast", "float32")])
def test_amg_cg_agrees_with_direct(block, setup, precision):
    f, A, b, _ = block
    x_ref = spla.spsolve(sp.csc_matrix(A), b)
    with homtex.set_options(amg_setup=setup, amg_precision=precision):
        lin = LinearSolver(A, method="amg", B=rigid_body_modes(f.nodes), tol=1e-10)
        x, rep = lin.solve(b)
    assert rep.residual <= 1e-9
    assert np.abs(x - x_ref).max() <= 1e-6 * np.abs(x_ref).max()
    ref_lin = LinearSolver(A, method="amg", B=rigid_body_modes(f.nodes), tol=1e-10, cycle="pyamg")
    _, ref_rep = ref_lin.solve(b)
    # the numba cycle with the same hierarchy runs the same recurrence
    assert abs(rep.iterations - ref_rep.iterations) <= max(3, ref_rep.iterations // 5)


def test_two_threads_same_answer(block):
    f, A, b, _ = block
    old = numba.get_num_threads()
    out = []
    try:
        for t in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            numba.set_num_threads(t)
            with homtex.set_options(amg_setup="fast"):
                lin = LinearSolver(A, method="amg", B=rigid_body_modes(f.nodes), tol=1e-10)
                out.append(lin.solve(b))
    finally:
        numba.set_num_threads(old)
    (x1, r1), (x2, r2) = out
    assert abs(r1.iterations - r2.iterations) <= 1
    assert np.abs(x1 - x2).max() <= 1e-8 * np.abs(x1).max()


def test_cg_detects_indefinite(block):
    f, A, b, _ = block
    h = ScaledAMG(A, rigid_body_modes(f.nodes))
    V = VCycle(h)
    Aneg = sp.bsr_matrix(-A, blocksize=(6, 6))
    with pytest.raises(SolverError, match="non-positive curvature"):
        pcg(BSROperator(Aneg), b, V, tol=1e-10, maxiter=50)


def test_device_path_on_cpu_matches_vcycle(block):
    from homtex.linalg.gpu import DeviceAMG, device_solve

    f, A, b, _ = block
    h = ScaledAMG(A, rigid_body_modes(f.nodes), max_coarse=300)
    dev = DeviceAMG(h, A, device="cpu")
    r = np.random.default_rng(3).normal(size=A.shape[0])
    z_ref = VCycle(h)(r)
    z = dev.precondition(r)
    # the coarse grid: dense inverse on the device, LU on the host
    assert np.abs(z - z_ref).max() <= 1e-8 * np.abs(z_ref).max()
    x, rep = device_solve(A, b, None, device="cpu", hierarchy=h, tol=1e-10)
    assert rep["residual"] <= 1e-9
    x32, rep32 = device_solve(A, b, None, device="cpu", hierarchy=h, tol=1e-10, precision="float32")
    assert rep32["residual"] <= 1e-9 and np.abs(x32 - x).max() <= 1e-6 * np.abs(x).max()


def test_gpu_solve_on_a_device(block):
    from homtex.linalg.gpu import device_solve, gpu_available

    if not gpu_available():
        pytest.skip("no CuPy or no CUDA device")
    f, A, b, _ = block
    x, rep = device_solve(A, b, rigid_body_modes(f.nodes), tol=1e-10)
    assert rep["residual"] <= 1e-9


def test_gpu_cycle_option_without_cupy(block):
    from homtex.linalg.gpu import gpu_available

    if gpu_available():
        pytest.skip("a device is present")
    f, A, b, _ = block
    with pytest.raises(ImportError, match="CuPy"):
        LinearSolver(A, method="amg", B=rigid_body_modes(f.nodes), cycle="gpu").solve(b)


# ----------------------------------------------------------------------------- tangent backends
def _net_system(nx=9, shift=0.0):

    xs = np.linspace(0, 10, nx)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    nodes = np.c_[X.ravel(), Y.ravel(), 0.3 * np.sin(X.ravel())]
    idx = np.arange(nx * nx).reshape(nx, nx)
    els = np.r_[np.c_[idx[:-1].ravel(), idx[1:].ravel()], np.c_[idx[:, :-1].ravel(), idx[:, 1:].ravel()]]
    frame = homtex.Frame(nodes, els, radius=0.2, E=1000.0, nu=0.3)
    mask = np.zeros((nx * nx, 6), dtype=bool)
    mask[idx[0]] = True
    mask[idx[-1]] = True
    mask = mask.ravel()
    Kf = Assembler(frame).stiffness().toarray()[np.ix_(~mask, ~mask)]
    Kf = Kf + shift * np.diag(np.abs(np.diag(Kf)))
    return frame, mask, Kf


def _fill(sys_, Kf):
    A = sys_.A
    cols = np.repeat(np.arange(sys_.nf), np.diff(A.indptr))
    A.data[:] = Kf[A.indices, cols]


def test_amg_tangent_solves_and_reuses_its_hierarchy():
    from homtex.analysis.tangent import FreeSystem

    frame, mask, Kf = _net_system()
    with homtex.set_options(tangent_solver="amg"):
        s = FreeSystem(frame, mask)
    assert s.solver.name == "amg"
    _fill(s, Kf)
    s.factor(inertia=True)
    assert s.negative == 0
    b = np.random.default_rng(4).normal(size=s.nf)
    x = s.solve(b)
    assert np.linalg.norm(Kf @ x - b) <= 1e-8 * np.linalg.norm(b)
    s.add_diagonal(0.05 * np.abs(np.diag(Kf)))       # a changed (PTC-shifted) tangent: hierarchy reused
    s.factor(inertia=True)
    x2 = s.solve(b)
    assert s.solver.builds == 1
    assert np.linalg.norm(s.symmetric() @ x2 - b) <= 1e-8 * np.linalg.norm(b)
    _fill(s, -Kf)                                        # indefinite: the Krylov probe sees it
    s.factor(inertia=True)
    assert s.negative != 0 and s.solver.positive_definite is False


def test_reuse_rule():
    from homtex.linalg.tangent_backends import ReuseRule

    r = ReuseRule()
    r.reset(1.0)                       # 1 s setup
    r.record(20, 0.2)                  # n0 = 20, 10 ms per iteration
    assert not r.rebuild()
    for _ in range(9):
        r.record(30, 0.3)              # 10 lost iterations each: 90 x 10 ms = 0.9 s < 1 s
    assert not r.rebuild()
    r.record(35, 0.35)                 # 105 lost: 1.05 s > 1 s setup: rebuild pays
    assert r.rebuild()
    r.reset(1.0)
    r.record(10, 0.1)
    r.record(31, 0.31)                 # more than 3x the fresh count
    assert r.rebuild()
    assert ReuseRule().rebuild(diag_change=0.6)


def test_cholmod_tangent():
    from homtex.analysis.tangent import FreeSystem
    from homtex.linalg.tangent_backends import cholmod_available

    if not cholmod_available():
        pytest.skip("scikit-sparse (CHOLMOD) not installed")
    frame, mask, Kf = _net_system()
    s = FreeSystem(frame, mask, tangent_solver="cholmod")
    _fill(s, Kf)
    s.factor(inertia=True)
    assert s.negative == 0
    b = np.ones(s.nf)
    assert np.allclose(Kf @ s.solve(b), b)
    _fill(s, Kf - 1.5 * np.diag(np.diag(Kf)))
    s.factor(inertia=True)
    ev = np.linalg.eigvalsh(s.symmetric().toarray())
    assert s.negative == int(np.sum(ev < 0)) > 0


def test_auto_rule_small_systems_use_ldl():
    from homtex.analysis.tangent import FreeSystem

    frame, mask, _ = _net_system()
    with homtex.set_options(tangent_solver="auto", tangent_auto_dof=10**6):
        assert FreeSystem(frame, mask).solver.name == "ldl"
    from homtex.linalg.tangent_backends import cholmod_available

    with homtex.set_options(tangent_solver="auto", tangent_auto_dof=10):
        assert FreeSystem(frame, mask).solver.name == ("cholmod" if cholmod_available() else "ldl")


def test_options_are_validated():
    with pytest.raises(homtex.InputError):
        homtex.set_options(tangent_solver="magic")
    with pytest.raises(homtex.InputError):
        homtex.set_options(amg_precision="float16")


# ----------------------------------------------------------------------------- PETSc under MPI
def _petsc_python():
    """A Python that imports petsc4py (this one, or HOMTEX_PETSC_PYTHON), or None."""
    cand = [os.environ.get("HOMTEX_PETSC_PYTHON"), sys.executable]
    for py in filter(None, cand):
        r = subprocess.run([py, "-c", "from petsc4py import PETSc"], capture_output=True)
        if r.returncode == 0:
            return py
    return None


@pytest.mark.parametrize("procs", [1, 2])
def test_petsc_gamg_matches_homtex_amg(procs):
    py = _petsc_python()
    mpiexec = shutil.which("mpiexec")
    if py is None or mpiexec is None:
        pytest.skip("petsc4py or mpiexec not available (set HOMTEX_PETSC_PYTHON to a Python with petsc4py)")
    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(root), OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
    env.setdefault("NUMBA_CACHE_DIR", "/tmp/homtex-petsc-numba")
    cmd = [mpiexec, "-n", str(procs), py, str(root / "studies/benchmarks/_petsc_worker.py"), "2",
           "1e-10"]
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
    line = [x for x in r.stdout.splitlines() if x.startswith("PETSC_RESULT ")]
    assert r.returncode == 0 and line, r.stdout[-2000:] + r.stderr[-2000:]
    import json

    rep = json.loads(line[0].split(" ", 1)[1])
    assert rep["processes"] == procs and rep["reason"] > 0
    assert rep["residual"] <= 1e-9 and rep["difference"] <= 1e-6


def test_hierarchy_cache_reuses_on_a_changed_matrix(block):
    from homtex.linalg.reuse import CACHE, pattern_key

    f, A, b, mask = block
    CACHE.clear()
    A2 = A.copy()
    A2.data *= 1.1                                     # same pattern, new values
    assert pattern_key(A) == pattern_key(A2)
    with homtex.set_options(amg_reuse=True):
        x1, r1 = LinearSolver(A, method="amg", B=rigid_body_modes(f.nodes), tol=1e-10).solve(b)
        lin2 = LinearSolver(A2, method="amg", B=rigid_body_modes(f.nodes), tol=1e-10)
        x2, r2 = lin2.solve(b)
    assert not r1.reused_setup and r2.reused_setup and CACHE.builds == 1 and CACHE.reuses == 1
    assert np.abs(1.1 * x2 - x1).max() <= 1e-7 * np.abs(x1).max()   # (1.1 A) x2 = b
    CACHE.clear()
