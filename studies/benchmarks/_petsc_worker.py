"""One PETSc solve of a slender octet block under MPI, against homtex's own AMG-CG (rank 0).

Not a study of its own: ``bench_parallel_amg.py --petsc PYTHON`` and tests/test_petsc_backend.py
run it as ``mpiexec -n P PYTHON studies/benchmarks/_petsc_worker.py R TOL`` (R octet cells per edge)
and read the JSON line rank 0 prints: PETSc's iterations, setup and solve seconds, and the
largest difference from homtex's AMG-CG answer relative to its largest displacement.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    r = int(argv[0]) if argv else 2
    tol = float(argv[1]) if len(argv) > 1 else 1e-8
    from bench_core import build_problem
    from petsc4py import PETSc

    from homtex.fem.assembly import Assembler
    from homtex.linalg.nullspace import rigid_body_modes
    from homtex.linalg.petsc_backend import petsc_solve
    from homtex.linalg.solvers import LinearSolver, constrain

    comm = PETSc.COMM_WORLD
    f, mask, b = build_problem(r)
    A = constrain(Assembler(f).stiffness(), mask)
    x, rep = petsc_solve(A, b, f.nodes, tol=tol, comm=comm)
    if comm.getRank() == 0:
        t0 = time.perf_counter()
        lin = LinearSolver(A, method="amg", B=rigid_body_modes(f.nodes), tol=tol)
        xh, hrep = lin.solve(b)
        rep.update(ndof=int(f.ndof), homtex_seconds=time.perf_counter() - t0, homtex_iterations=hrep.iterations,
                   homtex_residual=hrep.residual,
                   difference=float(np.abs(x - xh).max() / np.abs(xh).max()),
                   load=os.getloadavg()[0])
        print("PETSC_RESULT " + json.dumps(rep), flush=True)


if __name__ == "__main__":
    main()
