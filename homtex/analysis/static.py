"""Linear static analysis of a beam frame: ``solve_static``."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, SolverError
from ..fem.assembly import Assembler
from ..fem.beam import element_response, prestrain_forces
from ..model.frame import Frame
from ..linalg.solvers import LinearSolver, SolveReport, constrain, rigid_body_modes
from ..model.scene import check_held, parse_fixed, parse_loads

ENERGY_KEYS = ("axial", "torsion", "bending_y", "bending_z", "shear")


def element_state(frame: Frame, u: np.ndarray, jump=None):
    """Local end forces (m, 12) and energy split (m, 5) for displacements u (n, 6)."""
    m = frame.n_elements
    forces = np.empty((m, 12))
    energy = np.empty((m, 5))
    if jump is None:
        jump = np.zeros((m, 3))
    element_response(np.ascontiguousarray(u), frame.elements, np.ascontiguousarray(jump), frame.R,
                     frame.length, frame.E * frame.A, frame.G * frame.J, frame.E * frame.Iy,
                     frame.E * frame.Iz, frame.k * frame.G * frame.A, frame.prestrain, forces, energy)
    return forces, energy


def prestrain_load(frame: Frame, EA=None) -> np.ndarray:
    """(6n,) equivalent nodal loads of the frame's initial strains (``EA`` (m,): axial
    stiffnesses to use instead of the frame's, e.g. with slack elements)."""
    f = np.zeros((frame.n_nodes, 6))
    if not np.any(frame.prestrain):
        return f.ravel()
    EA = frame.E * frame.A if EA is None else np.ascontiguousarray(EA, dtype=float)
    pe = np.empty((frame.n_elements, 2, 3))
    prestrain_forces(frame.elements, frame.R, EA, frame.prestrain, pe)
    np.add.at(f[:, :3], frame.elements[:, 0], pe[:, 0])
    np.add.at(f[:, :3], frame.elements[:, 1], pe[:, 1])
    return f.ravel()


@dataclass
class StaticResult:
    """Result of a static solve.

    Attributes
    ----------
    u : (n, 6) displacements (mm) and rotations (rad) per node.
    report : SolveReport of the linear solve.
    forces : (m, 12) local end forces on each element [N, Vy, Vz, T, My, Mz] x 2 ends (N, N mm).
    energy : dict of (m,) strain energies (N mm): axial, torsion, bending_y, bending_z, shear.
    reactions : (n, 6) support reactions (zero where nothing is constrained).
    """

    frame: Frame
    u: np.ndarray
    report: SolveReport
    forces: np.ndarray
    energy: dict
    reactions: np.ndarray
    contacts: object = None
    extra: dict = field(default_factory=dict)

    @property
    def axial_force(self) -> np.ndarray:
        """(m,) axial force, tension positive, N."""
        return self.forces[:, 6]

    @property
    def total_energy(self) -> float:
        return float(sum(v.sum() for v in self.energy.values()))


def solve_static(frame: Frame, fixed=None, loads=None, *, solver: str = "amg", tol: float = 1e-10,
                 maxiter: int | None = None, contact=None, assembler: Assembler | None = None,
                 **contact_options) -> StaticResult:
    """Solve K u = f for a (non-periodic) frame with supports and loads.

    Parameters
    ----------
    frame : Frame
    fixed : dict node -> "all" | [DOFs 0..5] | {DOF: value}
        Supports; listed DOFs are held at zero, dict values are prescribed (mm, rad).
    loads : dict node -> (Fx, Fy, Fz, Mx, My, Mz), N and N mm.
    solver : "amg" (default), "direct" or "cg".
    tol : relative residual of iterative solvers.
    contact : homtex.Contact or None
        With contact, yarns cannot interpenetrate (see :mod:`homtex.contact`).

    Raises
    ------
    InputError for bad supports/loads; SolverError for unheld parts or a failed solve.
    """
    if not isinstance(frame, Frame):
        raise InputError(f"frame must be a homtex.Frame, got {type(frame).__name__}")
    if contact is not None:
        from ..contact.solve import solve_contact

        return solve_contact(frame, fixed, loads, contact=contact, solver=solver, tol=tol,
                             maxiter=maxiter, assembler=assembler, **contact_options)
    if contact_options:
        raise InputError(f"unknown options {sorted(contact_options)}")
    n = frame.n_nodes
    mask, up = parse_fixed(fixed, n)
    f = parse_loads(loads, n) + prestrain_load(frame)
    check_held(frame, mask)
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
    return StaticResult(frame=frame, u=u, report=rep, forces=forces,
                        energy=dict(zip(ENERGY_KEYS, energy.T.copy())), reactions=reactions)
