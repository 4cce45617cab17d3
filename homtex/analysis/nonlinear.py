"""Geometrically nonlinear frames: co-rotational state and Newton's method.

:class:`Corotational` holds the large-displacement state of a frame (node translations and
nodal rotation matrices) and evaluates the exact internal forces and an approximate tangent
(kernels in :mod:`homtex.fem.corotational`). :func:`solve_nonlinear` solves a frame without
contact under loads ramped in steps; :func:`homtex.contact.nonlinear.newton_contact` does the
same with contact (each Newton step is a contact solve linearised at the current state).

Rotations of a node are stored as a rotation matrix Q (3, 3) and updated multiplicatively
(Q <- exp(spin) Q), so they may grow without limit; reported rotations are rotation vectors
log(Q) (rad). Strains stay small: each element is linear elastic in its co-rotated frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..config import option
from ..errors import InputError, SolverError
from ..fem.assembly import Assembler
from ..fem.corotational import add_geometric, corotational_response, gather_ends, log_nodes, rotate_nodes
from ..linalg.solvers import LinearSolver, constrain
from ..model.frame import Frame
from ..model.results import ENERGY_KEYS
from ..model.scene import check_held, parse_fixed, parse_loads

GEOMETRIC = ("tension", "full", "none")


class Corotational:
    """Large-rotation state of a frame.

    Parameters
    ----------
    frame : Frame (periodic frames keep their fixed image offsets: zero macro strain).
    geometric : axial-force geometric stiffness in the tangent: "tension" (default; compressed
        members add none, so the tangent stays positive definite and a Cholesky factor or AMG
        applies; Newton converges linearly past buckling instead of quadratically), "full"
        (exact for the axial part; may be indefinite after buckling) or "none".

    Attributes
    ----------
    ut : (n, 3) node translations, mm.  Q : (n, 3, 3) nodal rotations.
    Rr : (m, 3, 3) co-rotated element frames (rows) after the last :meth:`evaluate`.
    forces : (m, 12) local end forces; energy : (m, 5) energy split (as in the linear solve).
    """

    def __init__(self, frame: Frame, assembler: Assembler | None = None, *, geometric: str = "tension"):
        if geometric not in GEOMETRIC:
            raise InputError(f"geometric must be one of {GEOMETRIC}, got {geometric!r}")
        self.frame = frame
        self.geometric = geometric
        self.asm = assembler or Assembler(frame)
        n, m = frame.n_nodes, frame.n_elements
        self.ut = np.zeros((n, 3))
        self.Q = np.ascontiguousarray(np.broadcast_to(np.eye(3), (n, 3, 3)).copy())
        self.shift = np.ascontiguousarray(frame.shift, dtype=float)
        self.arrays = (frame.E * frame.A, frame.G * frame.J, frame.E * frame.Iy, frame.E * frame.Iz,
                       frame.k * frame.G * frame.A)
        self.fe = np.empty((m, 2, 6))
        self.Rr = np.empty((m, 3, 3))
        self.lcur = np.empty(m)
        self.theta = np.empty((m, 2, 3))
        self.forces = np.empty((m, 12))
        self.energy = np.empty((m, 5))
        self.fint = np.empty((n, 6))

    # -- state
    def copy_state(self):
        return self.ut.copy(), self.Q.copy()

    def set_state(self, state):
        self.ut[...] = state[0]
        self.Q[...] = state[1]

    def update(self, du: np.ndarray):
        """Add increments du (n, 6): translations add, rotations compose (spatial spin)."""
        du = np.asarray(du, dtype=float)
        self.ut += du[:, :3]
        rotate_nodes(self.Q, np.ascontiguousarray(du[:, 3:6]))

    @property
    def positions(self) -> np.ndarray:
        """(n, 3) current node positions, mm."""
        return self.frame.nodes + self.ut

    def u(self) -> np.ndarray:
        """(n, 6) translations (mm) and rotation vectors log(Q) (rad)."""
        rot = np.empty((len(self.Q), 3))
        log_nodes(self.Q, rot)
        return np.hstack([self.ut, rot])

    # -- forces and tangent
    def evaluate(self, prestrain_scale: float = 1.0) -> np.ndarray:
        """Internal force vector (n, 6) at the current state (N, N mm); the residual is f_ext - fint."""
        f = self.frame
        eps0 = np.ascontiguousarray(prestrain_scale * f.prestrain, dtype=float)
        corotational_response(np.ascontiguousarray(self.positions), self.Q, f.elements, self.shift, f.R, f.length,
                              *self.arrays, eps0, self.fe, self.Rr, self.lcur, self.theta, self.forces,
                              self.energy)
        if not np.all(np.isfinite(self.fe)):
            bad = int(np.flatnonzero(~np.all(np.isfinite(self.fe.reshape(len(self.fe), -1)), axis=1))[0])
            raise SolverError(f"co-rotational forces are not finite at element {bad} (collapsed to zero length "
                              "or an end rotation of pi)")
        p = self.asm.pattern
        gather_ends(p.node_ptr, p.inc_elem, p.inc_end, self.fe, self.fint)
        return self.fint

    def tangent(self):
        """Tangent stiffness (6n x 6n BSR) at the last evaluated state: the linear element in its
        co-rotated frame plus the axial-force geometric stiffness (``geometric``)."""
        f = self.frame
        K = self.asm.stiffness((self.Rr, f.length) + self.arrays)
        if self.geometric != "none":
            N = self.forces[:, 6]
            if self.geometric == "tension":
                N = np.maximum(N, 0.0)
            p = self.asm.pattern
            add_geometric(p.node_ptr, p.inc_elem, p.inc_end, p.slot_self, p.slot_other, self.Rr, self.lcur,
                          np.ascontiguousarray(N), K.data)
        return K

    def max_deformational_rotation(self) -> float:
        """Largest end rotation relative to the co-rotated frame (rad) at the last evaluation: the
        co-rotational beam's own accuracy limit (refine the mesh when it passes ~0.3)."""
        if not self.theta.size:
            return 0.0
        return float(np.sqrt((self.theta ** 2).sum(axis=-1)).max())


@dataclass
class NonlinearResult:
    """Result of :func:`solve_nonlinear`.

    Attributes
    ----------
    u : (n, 6) translations (mm) and rotation vectors (rad). x : (n, 3) deformed positions, mm.
    Q : (n, 3, 3) nodal rotation matrices. forces : (m, 12) local end forces (co-rotated frames).
    energy : dict of (m,) energies, N mm. reactions : (n, 6) support reactions.
    history : per load step (load factor, Newton iterations, final residual norm).
    """

    frame: Frame
    u: np.ndarray
    x: np.ndarray
    Q: np.ndarray
    forces: np.ndarray
    energy: dict
    reactions: np.ndarray
    history: list = field(default_factory=list)

    @property
    def axial_force(self) -> np.ndarray:
        return self.forces[:, 6]


def solve_nonlinear(frame: Frame, fixed=None, loads=None, *, steps: int = 10, tol: float = 1e-9,
                    max_iter: int = 40, geometric: str = "full", solver: str | None = None) -> NonlinearResult:
    """Large-rotation static solve of a frame without contact; loads (and prescribed
    translations) ramp linearly over ``steps`` equal load steps, Newton iterations in each.

    Parameters
    ----------
    fixed, loads : as :func:`homtex.static.solve_static` (prescribed rotations must be zero:
        a rotation vector is not additive). Loads keep their direction (dead loads; a moment is a
        moment about a fixed axis).
    steps : load steps. tol : convergence when the out-of-balance force on the free DOFs is below
        tol x (norm of the applied loads and reactions).
    geometric : tangent option of :class:`Corotational` ("full" by default here: without contact
        the exact axial geometric stiffness converges fastest).

    Raises
    ------
    SolverError when a step does not converge in ``max_iter`` iterations (with the step and the
    residual), or the state becomes non-finite.
    """
    if not isinstance(frame, Frame):
        raise InputError(f"frame must be a homtex.Frame, got {type(frame).__name__}")
    if int(steps) < 1:
        raise InputError(f"steps must be >= 1, got {steps!r}")
    solver = option("nonlinear_solver", solver)
    n = frame.n_nodes
    mask, up = parse_fixed(fixed, n)
    if np.any(up.reshape(n, 6)[:, 3:] != 0.0):
        raise InputError("solve_nonlinear: prescribed rotations must be zero (rotation vectors do not add up)")
    check_held(frame, mask)
    f_ext = parse_loads(loads, n)
    cor = Corotational(frame, geometric=geometric)
    # round-off floor of the internal forces: EA x machine epsilon x (coordinates / length)
    floor = 1e-13 * float(np.max(cor.arrays[0])) * np.sqrt(n)
    history = []
    for step in range(1, int(steps) + 1):
        lam = step / int(steps)
        fs = lam * f_ext
        target = lam * up.reshape(n, 6)[:, :3]
        res_norm = np.inf
        for it in range(1, max_iter + 1):
            fint = cor.evaluate().ravel()
            r = fs - fint
            ref = max(np.linalg.norm(fs), np.linalg.norm(fint), 1e-300)
            res_norm = float(np.linalg.norm(np.where(mask, 0.0, r)))
            presc = np.zeros((n, 6))
            presc[:, :3] = target - cor.ut
            presc = presc.ravel()
            if res_norm <= tol * ref + floor and np.abs(presc[mask]).max(initial=0.0) == 0.0:
                break
            K = cor.tangent()
            b = r - K @ np.where(mask, presc, 0.0)
            A = constrain(K, mask)
            b[mask] = A.diagonal()[mask] * presc[mask]
            lin = LinearSolver(A, method=solver, tol=1e-6)   # a Newton step needs no more
            du, _ = lin.solve(b)
            du[mask] = presc[mask]
            if not np.all(np.isfinite(du)):
                raise SolverError(f"Newton step {it} of load step {step} is not finite")
            cor.update(du.reshape(n, 6))
        else:
            raise SolverError(f"solve_nonlinear: load step {step}/{steps} (load factor {lam:.4g}) did not converge in "
                              f"{max_iter} Newton iterations (out-of-balance force {res_norm:.3e} N, "
                              f"tolerance {tol:g} x {ref:.3e} N); use more steps")
        history.append((lam, it - 1, res_norm))
    fint = cor.evaluate()
    reactions = np.where(mask.reshape(n, 6), fint - f_ext.reshape(n, 6), 0.0)
    return NonlinearResult(frame=frame, u=cor.u(), x=cor.positions, Q=cor.Q.copy(), forces=cor.forces.copy(),
                           energy=dict(zip(ENERGY_KEYS, cor.energy.T.copy())), reactions=reactions,
                           history=history)
