"""Linear static analysis of a beam frame without contact (``solve_static`` dispatches here),
and the element response every linear solve reports: end forces, energy split, pre-strain loads.
"""

from __future__ import annotations

import numpy as np

from ..config import option
from ..errors import InputError, SolverError
from ..fem.assembly import Assembler, element_arrays
from ..fem.beam import element_response, prestrain_forces
from ..linalg.nullspace import rigid_body_modes
from ..linalg.solvers import LinearSolver, constrain
from ..model.frame import Frame
from ..model.results import ENERGY_KEYS, StaticResult
from ..model.scene import Scene

__all__ = ["check_finite", "element_state", "prestrain_load", "solve_linear"]


def element_state(frame: Frame, u: np.ndarray, jump=None, prestrain=None) -> tuple[np.ndarray, np.ndarray]:
    """Local end forces (m, 12) and energy split (m, 5) for displacements u (n, 6).

    ``jump`` (m, 3): extra translation of each element's second end (periodic macro strain);
    ``prestrain`` (m,): the pre-strain the elements carry now (default the frame's: a ramp
    passes its current value so that forces match the load it applied).
    """
    m = frame.n_elements
    forces = np.empty((m, 12))
    energy = np.empty((m, 5))
    if jump is None:
        jump = np.zeros((m, 3))
    eps0 = frame.prestrain if prestrain is None else np.ascontiguousarray(prestrain, dtype=float)
    element_response(np.ascontiguousarray(u), frame.elements, np.ascontiguousarray(jump),
                     *element_arrays(frame), eps0, forces, energy)
    return forces, energy


def prestrain_load(frame: Frame, EA=None, prestrain=None) -> np.ndarray:
    """(6n,) equivalent nodal loads of the frame's initial strains.

    ``EA`` (m,): axial stiffnesses to use instead of the frame's (e.g. with slack elements);
    ``prestrain`` (m,): the pre-strain to use instead of the frame's (a ramp's current value).
    """
    f = np.zeros((frame.n_nodes, 6))
    eps0 = frame.prestrain if prestrain is None else np.ascontiguousarray(prestrain, dtype=float)
    if not np.any(eps0):
        return f.ravel()
    EA = frame.E * frame.A if EA is None else np.ascontiguousarray(EA, dtype=float)
    pe = np.empty((frame.n_elements, 2, 3))
    prestrain_forces(frame.elements, frame.R, EA, eps0, pe)
    np.add.at(f[:, :3], frame.elements[:, 0], pe[:, 0])
    np.add.at(f[:, :3], frame.elements[:, 1], pe[:, 1])
    return f.ravel()


def check_finite(**arrays) -> None:
    """SolverError naming the first result array with a non-finite value (an answer beyond
    double precision: loads or pre-strains far outside any physical range)."""
    for name, a in arrays.items():
        with np.errstate(over="ignore", invalid="ignore"):
            ok = np.all(np.isfinite(a))
        if not ok:
            raise SolverError(f"the {name} of the solution overflow double precision (non-finite values): "
                              "loads, prescribed motions or pre-strains far outside a physical range")


def solve_linear(frame: Frame, fixed=None, loads=None, *, solver: str | None = None, tol: float | None = None,
                 maxiter: int | None = None, assembler: Assembler | None = None) -> StaticResult:
    """Solve K u = f for a frame with supports and loads (no contact; see ``homtex.solve_static``).

    ``solver`` and ``tol`` default to the options ``static_solver`` and ``tol`` (:mod:`homtex.config`).
    """
    if not isinstance(frame, Frame):
        raise InputError(f"frame must be a homtex.Frame, got {type(frame).__name__}")
    solver = option("static_solver", solver)
    tol = option("tol", tol)
    scene = Scene.build(frame, fixed, loads)
    n = frame.n_nodes
    mask, up = scene.mask, scene.values
    f = scene.loads + prestrain_load(frame)
    scene.check_held()
    asm = assembler or Assembler(frame)
    K = asm.stiffness()
    b = f - K @ up
    A = constrain(K, mask)
    b[mask] = A.diagonal()[mask] * up[mask]
    lin = LinearSolver(A, method=solver, B=rigid_body_modes(frame.nodes), tol=tol, maxiter=maxiter)
    x, rep = lin.solve(b)
    x[mask] = up[mask]
    if not np.all(np.isfinite(x)):
        raise SolverError("solve produced non-finite displacements", report=rep)
    u = x.reshape(n, 6)
    forces, energy = element_state(frame, u)
    reactions = np.where(mask, K @ x - f, 0.0).reshape(n, 6)
    check_finite(u=u, forces=forces, energy=energy, reactions=reactions)
    return StaticResult(frame=frame, u=u, report=rep, forces=forces,
                        energy=dict(zip(ENERGY_KEYS, energy.T.copy())), reactions=reactions)
