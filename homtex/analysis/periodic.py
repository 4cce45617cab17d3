"""Periodic frames: macro strain bookkeeping and the fluctuation operator.

A periodic :class:`~homtex.Frame` has k lattice vectors ``periods`` (k, 3) and an
integer image offset per element: element e joins node i to node j shifted by
``images[e] @ periods``. Displacements are split as

    u(x) = H x + w(x),

with H the (symmetric) macro displacement gradient and w, together with the nodal
rotations, periodic. Each element then sees its end translations through w plus
the relative macro motion ``H d_e`` of its second end (d_e the element vector, mm),
so a macro strain enters the fluctuation problem ``K w = b(H)`` as a right-hand side
(the equivalent nodal load of an end *jump*, :func:`jump_load`). Rigid translations of
w are removed by pinning one node per connected part
(:func:`homtex.model.scene.periodic_pins`).

Voigt order (engineering shear strains):

* k = 3: (11, 22, 33, 23, 13, 12), C in MPa over the cell volume V = |det P| (mm^3);
* k = 2 (lattice vectors in the x-y plane): (11, 22, 12), the membrane stiffness in
  N/mm (force per unit length) over the cell area (mm^2);
* k = 1: (11) along the lattice vector, the axial stiffness in N over the period (mm).
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from ..errors import InputError
from ..fem.assembly import Assembler, element_arrays
from ..fem.beam import element_response
from ..fem.periodic import jump_load_kernel
from ..linalg.nullspace import rigid_body_modes
from ..linalg.solvers import METHODS, LinearSolver, constrain
from ..model.frame import Frame
from ..model.scene import periodic_pins

__all__ = ["VOIGT", "UNITS", "cell_measure", "jump_load", "rotate_stiffness", "unit_strains", "voigt_components"]

VOIGT = {3: ("11", "22", "33", "23", "13", "12"), 2: ("11", "22", "12"), 1: ("11",)}
_PAIRS = {"11": (0, 0), "22": (1, 1), "33": (2, 2), "23": (1, 2), "13": (0, 2), "12": (0, 1)}
UNITS = {3: "MPa", 2: "N/mm", 1: "N"}


def jump_load(frame: Frame, H: np.ndarray, pattern=None) -> np.ndarray:
    """Equivalent nodal loads (nc, n, 6) of macro gradients H (nc, 3, 3) (or (3, 3)).

    Each element's second end is moved by ``H @ d_e`` relative to the first (d_e the
    element vector, mm); the returned load is the right-hand side of K w = b for the
    periodic fluctuation w (N, N mm).
    """
    H = np.ascontiguousarray(np.asarray(H, dtype=float).reshape(-1, 3, 3))
    if pattern is None:
        pattern = Assembler(frame).pattern
    out = np.empty((len(H), frame.n_nodes, 6))
    R, L, EA, GJ, EIy, EIz, kGA = element_arrays(frame)
    jump_load_kernel(pattern.node_ptr, pattern.inc_elem, pattern.inc_end, R, L, EA, GJ, EIy,
                      EIz, kGA, np.ascontiguousarray(frame.element_vectors), H, out)
    return out


def _forces(frame, u, jump):
    """Local end forces (m, 12) and energies (m, 5) without prestrain (linear part only)."""
    m = frame.n_elements
    forces = np.empty((m, 12))
    energy = np.empty((m, 5))
    R, L, EA, GJ, EIy, EIz, kGA = element_arrays(frame)
    element_response(np.ascontiguousarray(u), frame.elements, np.ascontiguousarray(jump), R, L,
                     EA, GJ, EIy, EIz, kGA, np.zeros(m), forces, energy)
    return forces, energy


# ----------------------------------------------------------------------------------
# macro strain bookkeeping
def voigt_components(frame: Frame) -> tuple:
    """Voigt component names of a periodic frame: see the module docstring."""
    k = frame.dim_periodic
    if k == 0:
        raise InputError("homogenisation needs a periodic frame (periods and images), "
                         "got a frame without lattice vectors")
    if k == 2:
        P = frame.periods
        scale = np.abs(P).max()
        if np.abs(P[:, 2]).max() > 1e-9 * scale:
            raise InputError(f"periods: a 2-periodic frame is homogenised as a membrane in the x-y "
                             f"plane; its lattice vectors {P.tolist()} must have zero z components")
    return VOIGT[k]


def cell_measure(frame: Frame) -> float:
    """Cell volume (k=3, mm^3), area (k=2, mm^2) or length (k=1, mm)."""
    P = frame.periods
    k = len(P)
    if k == 3:
        return float(abs(np.linalg.det(P)))
    if k == 2:
        return float(np.linalg.norm(np.cross(P[0], P[1])))
    if k == 1:
        return float(np.linalg.norm(P[0]))
    raise InputError("frame is not periodic")


def unit_strains(frame: Frame) -> np.ndarray:
    """(ncomp, 3, 3) macro displacement gradients of the unit Voigt strain cases.

    Normal components: H_ii = 1; shear components (engineering): H_ij = H_ji = 1/2.
    For k = 1 the single case is the axial strain t t^T along the unit lattice vector t.
    """
    comps = voigt_components(frame)
    if frame.dim_periodic == 1:
        t = frame.periods[0] / np.linalg.norm(frame.periods[0])
        return np.outer(t, t)[None]
    H = np.zeros((len(comps), 3, 3))
    for c, name in enumerate(comps):
        i, j = _PAIRS[name]
        if i == j:
            H[c, i, i] = 1.0
        else:
            H[c, i, j] = H[c, j, i] = 0.5
    return H


def _component_index(frame, names, what="free") -> list:
    comps = voigt_components(frame)
    out = []
    if names is not None and not isinstance(names, (list, tuple, np.ndarray, str)):
        raise InputError(f"{what} must be a list of strain components (names such as '22' or indices), got {names!r}")
    for x in ([] if names is None else [names] if isinstance(names, str) else list(names)):
        if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, np.integer, str)):
            raise InputError(f"{what}: strain components are names such as '22' or indices, got {x!r}")
        if isinstance(x, (int, np.integer)):
            if not 0 <= int(x) < len(comps):
                raise InputError(f"{what}: component index {x} is outside 0..{len(comps) - 1} "
                                 f"(components {comps})")
            out.append(int(x))
        else:
            s = str(x).lstrip("eE").lstrip("_")
            if s not in comps:
                raise InputError(f"{what}: unknown strain component {x!r}; this "
                                 f"{frame.dim_periodic}-periodic frame has {comps}")
            out.append(comps.index(s))
    if len(set(out)) != len(out):
        raise InputError(f"{what}: repeated components {names}")
    return out


class _Operator:
    """The periodic fluctuation operator with its pins and one solver setup."""

    def __init__(self, frame, solver, tol, maxiter, nullspace="rigid"):
        if solver not in METHODS:
            raise InputError(f"solver must be one of {METHODS}, got {solver!r}")
        t0 = time.perf_counter()
        self.frame = frame
        self.asm = Assembler(frame)
        self.K = self.asm.stiffness()
        self.mask = periodic_pins(frame)
        self.A = constrain(self.K, self.mask)
        self.assembly_seconds = time.perf_counter() - t0
        B = None
        if solver == "amg":
            if nullspace == "rigid":
                B = rigid_body_modes(frame.nodes)
            elif nullspace == "translations":
                B = rigid_body_modes(frame.nodes)[:, :3]
            else:
                raise InputError(f"nullspace must be 'rigid' or 'translations', got {nullspace!r}")
            B = np.ascontiguousarray(B)
        with warnings.catch_warnings():
            # pyamg warns when B has fewer columns than the block size ("translations")
            warnings.filterwarnings("ignore", message="Having less target vectors")
            self.lin = LinearSolver(self.A, method=solver, B=B, tol=tol, maxiter=maxiter)
        self.setup_seconds = self.lin.setup_seconds

    def rhs(self, H):
        b = jump_load(self.frame, H, self.asm.pattern).reshape(len(H), -1)
        b[:, self.mask] = 0.0
        return b

    def solve(self, b):
        x, rep = self.lin.solve(b)
        x[self.mask] = 0.0
        return x, rep


# ----------------------------------------------------------------------------------
def _bond(Q: np.ndarray, comps: tuple) -> np.ndarray:
    """Voigt strain transformation T (engineering shear): e' = T e for x' = Q x."""
    nc = len(comps)
    T = np.zeros((nc, nc))
    for a, ca in enumerate(comps):
        i, j = _PAIRS[ca]
        for b, cb in enumerate(comps):
            k, l = _PAIRS[cb]
            # eps'_ij = Q_ik Q_jl eps_kl; eps_kl = e_b (normal) or e_b/2 (shear, both kl and lk)
            if k == l:
                v = Q[i, k] * Q[j, l]
            else:
                v = 0.5 * (Q[i, k] * Q[j, l] + Q[i, l] * Q[j, k])
            T[a, b] = v if i == j else 2.0 * v
    return T


def rotate_stiffness(C: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Stiffness of the lattice rotated by Q (x' = Q x), as a fourth-order tensor.

    C : (6, 6) Voigt (11, 22, 33, 23, 13, 12) or (3, 3) membrane (11, 22, 12); engineering
    shear. Q : (3, 3) rotation (for a membrane: a rotation about z, or a (2, 2) rotation).
    Returns T^-T C T^-1 with T the Voigt strain transformation.
    """
    C = np.asarray(C, dtype=float)
    Q = np.asarray(Q, dtype=float)
    if C.shape == (6, 6):
        comps = VOIGT[3]
    elif C.shape == (3, 3):
        comps = VOIGT[2]
        if Q.shape == (2, 2):
            Q3 = np.eye(3)
            Q3[:2, :2] = Q
            Q = Q3
    else:
        raise InputError(f"C must be 6x6 or 3x3, got {C.shape}")
    T = _bond(Q, comps)
    Ti = np.linalg.inv(T)
    return Ti.T @ C @ Ti


