"""Optional PETSc backend (the ``petsc`` extra: petsc4py): one solve across MPI processes.

GAMG-preconditioned CG with the six rigid-body modes of 6-DOF beam nodes as near-null space
(PETSc's ``MatNullSpaceCreateRigidBody`` builds translations and rotations of 3-DOF nodes only;
here the modes come from :func:`homtex.linalg.nullspace.rigid_body_modes`: translations,
u = omega x (x - x0) with theta = omega, orthonormalised as PETSc requires). The matrix is a
AIJ matrix with block size 6 (GAMG aggregates nodes) distributed by node rows over the communicator; every process
passes the same global matrix (or its own node-row slice, ``local=True``) and gets the whole
solution back.

Run under MPI: ``mpiexec -n 2 python script.py``. Installable from the package index
(``pip install petsc petsc4py``, a long compile) or Debian's ``python3-petsc4py`` (for Debian's
Python and numpy). Without petsc4py :func:`petsc_available` is False and :func:`petsc_solve`
raises ImportError naming the extra.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

__all__ = ["petsc_available", "petsc_solve", "rigid_body_nullspace"]


def petsc_available() -> bool:
    try:
        import petsc4py  # noqa: F401
        from petsc4py import PETSc  # noqa: F401

        return True
    except Exception:
        return False


def _petsc():
    try:
        from petsc4py import PETSc
    except ImportError as err:
        raise ImportError("the PETSc backend needs petsc4py: pip install 'homtex[petsc]' "
                          "(or Debian's python3-petsc4py)") from err
    return PETSc


def rigid_body_nullspace(coords, rows: slice | None = None) -> np.ndarray:
    """(6n, 6) orthonormal rigid-body modes of 6-DOF beam nodes (global), or their ``rows`` slice."""
    from .nullspace import rigid_body_modes

    B = rigid_body_modes(coords)
    Q, _ = np.linalg.qr(B)
    return Q if rows is None else Q[rows]


def petsc_solve(A, b, coords, *, tol: float = 1e-8, maxiter: int = 2000, comm=None,
                options: dict | None = None) -> tuple[np.ndarray, dict]:
    """Solve A x = b (A SPD (6n, 6n), node-blocked; b (6n,)) with PETSc CG + GAMG over ``comm``
    (default: COMM_WORLD). Every process passes the global A, b and node coordinates (n, 3).

    Returns (x (6n,) on every process, report): iterations, residual (true, relative), setup and
    solve seconds (max over processes), processes, converged reason.
    """
    PETSc = _petsc()
    comm = comm or PETSc.COMM_WORLD
    size, rank = comm.getSize(), comm.getRank()
    A = sp.csr_matrix(A)
    n = A.shape[0]
    if n % 6:
        raise ValueError("the PETSc backend needs 6 DOFs per node (n divisible by 6)")
    nodes = n // 6
    # node-row ownership: contiguous ranges of nodes
    counts = np.full(size, nodes // size)
    counts[: nodes % size] += 1
    start = 6 * int(counts[:rank].sum())
    stop = start + 6 * int(counts[rank])
    t0 = time.perf_counter()
    loc = A[start:stop]
    M = PETSc.Mat().createAIJ(size=((stop - start, n), (stop - start, n)), bsize=6, comm=comm)
    M.setPreallocationCSR((loc.indptr.astype(PETSc.IntType), loc.indices.astype(PETSc.IntType)))
    M.setValuesCSR(loc.indptr.astype(PETSc.IntType), loc.indices.astype(PETSc.IntType), loc.data)
    M.assemble()
    Q = rigid_body_nullspace(coords)
    vecs = []
    for k in range(6):
        v = M.createVecLeft()
        v.setArray(Q[start:stop, k].copy())
        vecs.append(v)
    ns = PETSc.NullSpace().create(constant=False, vectors=vecs, comm=comm)
    M.setNearNullSpace(ns)
    ksp = PETSc.KSP().create(comm=comm)
    ksp.setOperators(M)
    ksp.setType("cg")
    ksp.setNormType(PETSc.KSP.NormType.UNPRECONDITIONED)   # rtol on the true residual, as homtex
    ksp.getPC().setType("gamg")
    ksp.setTolerances(rtol=tol, atol=0.0, max_it=maxiter)
    opts = PETSc.Options()
    for k, v in (options or {}).items():
        opts[k] = v
    ksp.setFromOptions()
    bv = M.createVecRight()
    bv.setArray(np.asarray(b, dtype=float)[start:stop].copy())
    xv = M.createVecLeft()
    ksp.setUp()
    t_setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    ksp.solve(bv, xv)
    t_solve = time.perf_counter() - t0
    # gather the solution on every process
    scat, xall = PETSc.Scatter.toAll(xv)
    scat.scatter(xv, xall, addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    x = xall.getArray().copy()
    res = float(np.linalg.norm(b - A @ x) / np.linalg.norm(b))
    mpi = comm.tompi4py() if hasattr(comm, "tompi4py") else None
    red = (lambda v: mpi.allreduce(v, op=__import__("mpi4py").MPI.MAX)) if mpi is not None else (lambda v: v)
    rep = {"iterations": int(ksp.getIterationNumber()), "residual": res, "setup_seconds": red(t_setup),
           "solve_seconds": red(t_solve), "processes": size, "reason": int(ksp.getConvergedReason())}
    for o in (ksp, M, ns, bv, xv, xall, scat, *vecs):
        o.destroy()
    return x, rep
