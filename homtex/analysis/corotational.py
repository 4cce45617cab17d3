"""The large-rotation state of a frame (:class:`Corotational`): translations and nodal rotation
matrices, the exact internal forces and the tangents of the co-rotational beam.

Kernels are in :mod:`homtex.fem.corotational`. Rotations of a node are stored as a rotation matrix
Q (3, 3) and updated multiplicatively (Q <- exp(spin) Q), so they may grow without limit; reported
rotations are rotation vectors log(Q) (rad). Strains stay small: each element is linear elastic in
its co-rotated frame (see :meth:`Corotational.strains` for the monitor of that assumption).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import InputError, SolverError
from ..fem.assembly import Assembler
from ..fem.corotational import (
    corotational_response,
    corotational_response_serial,
    corotational_tangent,
    corotational_tangent_serial,
)
from ..fem.corotational_system import (
    add_geometric,
    gather_ends,
    gather_ends_serial,
    log_nodes,
    rotate_nodes,
    scatter_bsr,
)
from ..model.frame import Frame
from ..model.rest import RestState, start_rest

#: tangent options: "consistent" (= "full": exact derivative of the forces), "tension" (linear
#: element in the current frame plus the geometric stiffness of tensile members only: positive
#: definite, for contact), "none" (linear element in the current frame)
GEOMETRIC = ("tension", "full", "none", "consistent")

#: elements from which the element loop runs on all threads by default (below it one thread is
#: faster on a shared machine: measured 8 ms thread start-up per call on the 2-core machine for 32
#: elements when another process held the second core)
PARALLEL_ELEMENTS = 4000


def element_loop_serial(n_elements: int) -> bool:
    """Whether a frame of ``n_elements`` runs its element loops (and the engine its contact
    search) on one thread: below :data:`PARALLEL_ELEMENTS`. The option ``threads`` does not lower
    it: with ``threads=2`` (numba and BLAS) the 43 mm seam cell (2416 elements) pressed to 70 % on
    the idle 2-core machine took 870 s against 555 s with both on one thread, although its element
    loops alone ran 2.1x faster on two (``studies/benchmarks/bench_element_threads.py``; docs/performance.md)."""
    return int(n_elements) < PARALLEL_ELEMENTS


def _threaded_kernels(n_elements: int) -> bool:
    """The prange element kernels: where the loop is threaded, and on one numba thread (there they
    are 3-35 % faster than the plain loop, bitwise the same results; a threaded small frame keeps
    the plain loop, which waits for no partner thread on a busy machine)."""
    import numba

    return not element_loop_serial(n_elements) or numba.get_num_threads() == 1


class Corotational:
    """Large-rotation state of a frame.

    Parameters
    ----------
    frame : Frame (periodic frames keep their fixed image offsets: zero macro strain).
    assembler : an Assembler of the frame to share (its block pattern is reused).
    rest : a :class:`~homtex.model.rest.RestState` (rest lengths and per-end rest frames): the
        stress-free shape when it is not the start geometry (default: the start geometry).
    geometric : tangent returned by :meth:`tangent`: "full" or "consistent" (the exact derivative
        of the internal forces; nonsymmetric away from equilibrium, indefinite after buckling),
        "tension" (default; the linear element in the current frame plus the axial-force
        geometric stiffness of members in tension only, so the tangent stays positive definite
        and a Cholesky factor or AMG applies; Newton converges linearly) or "none".

    Attributes
    ----------
    ut : (n, 3) node translations, mm.  Q : (n, 3, 3) nodal rotations.
    Rr : (m, 3, 3) co-rotated element frames (rows) after the last :meth:`evaluate`.
    forces : (m, 12) local end forces; energy : (m, 5) energy split (as in the linear solve), N mm.
    fint : (n, 6) internal forces and moments at the nodes, N, N mm. Ke : (m, 12, 12) element
    tangents after :meth:`evaluate_tangent` (spatial spins).
    """

    def __init__(self, frame: Frame, assembler: Assembler | None = None, *, geometric: str = "tension",
                 rest: RestState | None = None):
        if geometric not in GEOMETRIC:
            raise InputError(f"geometric must be one of {GEOMETRIC}, got {geometric!r}")
        self.frame = frame
        rest = start_rest(frame) if rest is None else rest.check(frame)
        self.rest = rest
        self.E0, self.L0 = rest.frames, rest.length
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
        self.theta = np.zeros((m, 2, 3))
        self.forces = np.empty((m, 12))
        self.energy = np.empty((m, 5))
        self.fint = np.empty((n, 6))
        self.Ke = None
        self._eps0 = (None, None)

    # -- state
    def copy_state(self):
        """(ut, Q) copies: the state to hand back to :meth:`set_state`."""
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
    def _prestrain(self, scale: float) -> np.ndarray:
        if self._eps0[0] != scale:
            self._eps0 = (scale, np.ascontiguousarray(scale * self.frame.prestrain, dtype=float))
        return self._eps0[1]

    def _check(self):
        if not np.all(np.isfinite(self.fe)):
            bad = int(np.flatnonzero(~np.all(np.isfinite(self.fe.reshape(len(self.fe), -1)), axis=1))[0])
            raise SolverError(f"co-rotational forces are not finite at element {bad} (collapsed to zero length "
                              "or an end rotation of pi)")

    def evaluate(self, prestrain_scale: float = 1.0) -> np.ndarray:
        """Internal force vector (n, 6) at the current state (N, N mm); the residual is f_ext - fint."""
        f = self.frame
        big = _threaded_kernels(f.n_elements)
        kernel = corotational_response if big else corotational_response_serial
        kernel(np.ascontiguousarray(self.positions), self.Q, f.elements, self.shift, self.E0, self.L0,
               *self.arrays, self._prestrain(prestrain_scale), self.fe, self.Rr, self.lcur,
               self.theta, self.forces, self.energy)
        self._check()
        p = self.asm.pattern
        (gather_ends if big else gather_ends_serial)(p.node_ptr, p.inc_elem, p.inc_end, self.fe, self.fint)
        return self.fint

    def evaluate_tangent(self, prestrain_scale: float = 1.0) -> np.ndarray:
        """As :meth:`evaluate`, and the element tangents ``Ke`` (m, 12, 12) of the consistent tangent."""
        f = self.frame
        if self.Ke is None:
            self.Ke = np.zeros((f.n_elements, 12, 12))
        big = _threaded_kernels(f.n_elements)
        kernel = corotational_tangent if big else corotational_tangent_serial
        kernel(np.ascontiguousarray(self.positions), self.Q, f.elements, self.shift, self.E0, self.L0, *self.arrays,
               self._prestrain(prestrain_scale), self.fe, self.Ke, self.Rr, self.lcur, self.theta, self.forces,
               self.energy)
        self._check()
        p = self.asm.pattern
        (gather_ends if big else gather_ends_serial)(p.node_ptr, p.inc_elem, p.inc_end, self.fe, self.fint)
        return self.fint

    def tangent(self, prestrain_scale: float = 1.0, *, symmetric: bool = False) -> sp.bsr_matrix:
        """Tangent stiffness (6n x 6n BSR, 6x6 blocks) at the current state.

        ``geometric`` "full"/"consistent": the exact derivative of :meth:`evaluate` with respect to
        translations and spatial spins (``symmetric``: its symmetric part, the Hessian of the
        strain energy). "tension"/"none": the linear element in its co-rotated frame (at the last
        :meth:`evaluate`) plus the axial-force geometric stiffness of tensile members / none.
        """
        p = self.asm.pattern
        if self.geometric in ("full", "consistent"):
            self.evaluate_tangent(prestrain_scale)
            K = self.asm.stiffness()     # the reused BSR pattern (overwritten below)
            scatter_bsr(p.node_ptr, p.inc_elem, p.inc_end, p.slot_self, p.slot_other, self.Ke, K.data,
                        bool(symmetric))
            return K
        K = self.asm.stiffness((self.Rr, self.L0) + self.arrays)
        if self.geometric == "tension":
            N = np.ascontiguousarray(np.maximum(self.forces[:, 6], 0.0))
            add_geometric(p.node_ptr, p.inc_elem, p.inc_end, p.slot_self, p.slot_other, self.Rr, self.lcur, N, K.data)
        return K

    def max_deformational_rotation(self) -> float:
        """Largest end rotation relative to the co-rotated frame (rad) at the last evaluation: the
        co-rotational beam's own accuracy limit (refine the mesh when it passes ~0.3)."""
        if not self.theta.size:
            return 0.0
        return float(np.sqrt((self.theta ** 2).sum(axis=-1)).max())

    def strains(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Generalised strains of every element at the last evaluation, each (m,):

        axial strain N / EA (mechanical, pre-strain included), shear strain
        sqrt(Vy^2 + Vz^2) / (k G A) and the largest bending fibre strain
        max over the ends of |M_y| b / EI_y + |M_z| a / EI_z (a, b: semi-axes, mm).
        """
        f = self.frame
        EA, _, EIy, EIz, kGA = self.arrays
        F = self.forces
        axial = F[:, 6] / EA
        shear = np.hypot(F[:, 1], F[:, 2]) / kGA
        bend = np.maximum(np.abs(F[:, 4]) * f.b / EIy + np.abs(F[:, 5]) * f.a / EIz,
                          np.abs(F[:, 10]) * f.b / EIy + np.abs(F[:, 11]) * f.a / EIz)
        return axial, shear, bend
