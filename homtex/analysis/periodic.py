"""Periodic frames: macro strain, homogenisation, periodisation and a compression scene.

A periodic :class:`~homtex.Frame` has k lattice vectors ``periods`` (k, 3) and an
integer image offset per element: element e joins node i to node j shifted by
``images[e] @ periods``. Displacements are split as

    u(x) = H x + w(x),

with H the (symmetric) macro displacement gradient and w, together with the nodal
rotations, periodic. Each element then sees its end translations through w plus
the relative macro motion ``H d_e`` of its second end (d_e the element vector, mm),
so a macro strain enters the fluctuation problem ``K w = b(H)`` as a right-hand side
(the equivalent nodal load of an end *jump*, :func:`jump_load`). Rigid translations of
w are removed by pinning one node per connected part.

The effective stiffness follows from the strain energy of the equilibrium states of
the unit cases (one per Voigt component, one operator setup for all of them):

    C_ij = (1/V) sum_e f_e(j) . d_e(i),

with f_e(j) the local end forces of element e in case j and d_e(i) its local end
displacements (fluctuation plus jump) in case i. This is the energy form
(a_i + B w_i)^T K_e (a_j + B w_j): symmetric by construction and second-order
accurate in the solve error. The macro stress of each case is also computed from
the virial sum (1/V) sum_e f2_e (x) d_e (force acting at the second end times the
element vector); its difference from C is reported as ``consistency``.

Voigt order (engineering shear strains):

* k = 3: (11, 22, 33, 23, 13, 12), C in MPa over the cell volume V = |det P| (mm^3);
* k = 2 (lattice vectors in the x-y plane): (11, 22, 12), the membrane stiffness in
  N/mm (force per unit length) over the cell area (mm^2);
* k = 1: (11) along the lattice vector, the axial stiffness in N over the period (mm).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numba import get_num_threads, njit, prange

from ..errors import InputError, SolverError
from ..fem.assembly import Assembler
from ..fem.beam import coefficients, element_response
from ..model.frame import Frame
from ..linalg.solvers import METHODS, LinearSolver, SolveReport, constrain, rigid_body_modes
from ..model.scene import check_held, components

__all__ = ["homogenize", "Homogenization", "solve_macro", "MacroState", "periodize",
           "compression_modulus", "CompressionResult", "rotate_stiffness", "voigt_components",
           "unit_strains", "jump_load"]

VOIGT = {3: ("11", "22", "33", "23", "13", "12"), 2: ("11", "22", "12"), 1: ("11",)}
_PAIRS = {"11": (0, 0), "22": (1, 1), "33": (2, 2), "23": (1, 2), "13": (0, 2), "12": (0, 1)}
UNITS = {3: "MPa", 2: "N/mm", 1: "N"}
ENERGY_KEYS = ("axial", "torsion", "bending_y", "bending_z", "shear")


# ----------------------------------------------------------------------------------
# kernels
@njit(cache=True, parallel=True)
def _jump_load_kernel(node_ptr, inc_elem, inc_end, R, L, EA, GJ, EIy, EIz, kGA, dvec, H, out):
    """Equivalent nodal loads of the jumps ``H[q] @ dvec[e]`` of every element's second end.

    out (nc, n, 6) is overwritten: out[q, a] = -(sum over the element ends at node a of
    the global end force that the jump alone produces), i.e. b = -B^T K_e a(H).
    Parallel over nodes (each node owns its row), no atomics.
    """
    nc = H.shape[0]
    n = node_ptr.size - 1
    for a in prange(n):
        for q in range(nc):
            for c in range(6):
                out[q, a, c] = 0.0
        for p in range(node_ptr[a], node_ptr[a + 1]):
            e = inc_elem[p]
            s = inc_end[p]
            ax, tor, a_y, b_y, c_y, d_y, a_z, b_z, c_z, d_z = coefficients(
                L[e], EA[e], GJ[e], EIy[e], EIz[e], kGA[e])
            Re = R[e]
            for q in range(nc):
                # global jump, then local
                jg0 = H[q, 0, 0] * dvec[e, 0] + H[q, 0, 1] * dvec[e, 1] + H[q, 0, 2] * dvec[e, 2]
                jg1 = H[q, 1, 0] * dvec[e, 0] + H[q, 1, 1] * dvec[e, 1] + H[q, 1, 2] * dvec[e, 2]
                jg2 = H[q, 2, 0] * dvec[e, 0] + H[q, 2, 1] * dvec[e, 1] + H[q, 2, 2] * dvec[e, 2]
                j0 = Re[0, 0] * jg0 + Re[0, 1] * jg1 + Re[0, 2] * jg2
                j1 = Re[1, 0] * jg0 + Re[1, 1] * jg1 + Re[1, 2] * jg2
                j2 = Re[2, 0] * jg0 + Re[2, 1] * jg1 + Re[2, 2] * jg2
                # local end forces on the element of d = (0, 0, 0, 0, 0, 0, j0, j1, j2, 0, 0, 0)
                N = ax * j0
                dv = -j1
                dw = -j2
                if s == 0:
                    ft0 = -N
                    ft1 = a_y * dv
                    ft2 = a_z * dw
                    fm1 = -b_z * dw
                    fm2 = b_y * dv
                else:
                    ft0 = N
                    ft1 = -a_y * dv
                    ft2 = -a_z * dw
                    fm1 = -b_z * dw
                    fm2 = b_y * dv
                # global, with the minus sign of the load
                for c in range(3):
                    out[q, a, c] -= Re[0, c] * ft0 + Re[1, c] * ft1 + Re[2, c] * ft2
                    out[q, a, 3 + c] -= Re[1, c] * fm1 + Re[2, c] * fm2


@njit(cache=True, parallel=True)
def _pair_work_kernel(elements, R, dvec, H, U, forces, nchunk):
    """out[q] = sum_e forces[e] . d_e(q) with d_e(q) the local end displacements of case q.

    U (nc, n, 6) fluctuations; H (nc, 3, 3) macro gradients; forces (m, 12) local end
    forces of one case. Returns (nc,) work, N mm.
    """
    m = elements.shape[0]
    nc = U.shape[0]
    part = np.zeros((nchunk, nc))
    size = (m + nchunk - 1) // nchunk
    for c in prange(nchunk):
        stop = min(m, (c + 1) * size)
        for e in range(c * size, stop):
            i = elements[e, 0]
            j = elements[e, 1]
            Re = R[e]
            f = forces[e]
            for q in range(nc):
                s = 0.0
                for r in range(3):
                    jr = H[q, r, 0] * dvec[e, 0] + H[q, r, 1] * dvec[e, 1] + H[q, r, 2] * dvec[e, 2]
                    # jump in global axis r contributes to every local component
                    for a in range(3):
                        Rar = Re[a, r]
                        s += Rar * (f[a] * U[q, i, r] + f[3 + a] * U[q, i, 3 + r]
                                    + f[6 + a] * (U[q, j, r] + jr) + f[9 + a] * U[q, j, 3 + r])
                part[c, q] += s
    return part.sum(axis=0)


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
    R, L, EA, GJ, EIy, EIz, kGA = _element_arrays(frame)
    _jump_load_kernel(pattern.node_ptr, pattern.inc_elem, pattern.inc_end, R, L, EA, GJ, EIy,
                      EIz, kGA, np.ascontiguousarray(frame.element_vectors), H, out)
    return out


def _element_arrays(frame):
    return (frame.R, frame.length, frame.E * frame.A, frame.G * frame.J, frame.E * frame.Iy,
            frame.E * frame.Iz, frame.k * frame.G * frame.A)


def _forces(frame, u, jump):
    """Local end forces (m, 12) and energies (m, 5) without prestrain (linear part only)."""
    m = frame.n_elements
    forces = np.empty((m, 12))
    energy = np.empty((m, 5))
    R, L, EA, GJ, EIy, EIz, kGA = _element_arrays(frame)
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
    for x in ([] if names is None else list(names)):
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


def _pin_mask(frame: Frame) -> np.ndarray:
    """Pin the translations of one node per connected part (and, for k = 1 along a
    coordinate axis, the rotation about that axis)."""
    n = frame.n_nodes
    label, _ = components(n, frame.elements, frame.images)
    _, first = np.unique(label, return_index=True)
    mask = np.zeros((n, 6), dtype=bool)
    mask[first, :3] = True
    if frame.dim_periodic == 1:
        t = np.abs(frame.periods[0]) / np.linalg.norm(frame.periods[0])
        ax = int(np.argmax(t))
        if t[ax] > 1 - 1e-12:
            mask[first, 3 + ax] = True
    mask = mask.ravel()
    check_held(frame, mask)
    return mask


class _Operator:
    """The periodic fluctuation operator with its pins and one solver setup."""

    def __init__(self, frame, solver, tol, maxiter, nullspace="rigid"):
        if solver not in METHODS:
            raise InputError(f"solver must be one of {METHODS}, got {solver!r}")
        t0 = time.perf_counter()
        self.frame = frame
        self.asm = Assembler(frame)
        self.K = self.asm.stiffness()
        self.mask = _pin_mask(frame)
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
@dataclass
class Homogenization:
    """Effective stiffness of a periodic frame.

    Attributes
    ----------
    C : (p, p) effective stiffness over the prescribed components ``components``
        (all Voigt components unless some were left free): MPa for k = 3, N/mm for
        k = 2 (membrane, force per unit length), N for k = 1. Engineering shear strains.
    C_full : (ncomp, ncomp) the stiffness over all Voigt components.
    components : names of the rows/columns of C; ``all_components`` those of C_full.
    free : names of the components left free (zero macro stress) in every case.
    measure : cell volume (mm^3), area (mm^2) or length (mm).
    strain : (n_cases, ncomp) macro strain of each case (prescribed unit value plus
        the free components' response).
    fluctuation : (n_cases, n, 6) periodic fluctuation w (mm) and rotations (rad) of each case.
    stress : (n_cases, ncomp) macro stress of each case from the virial of the end forces
        (units of C).
    energy : (n_cases, 5) strain energy per cell split into axial, torsion, bending_y,
        bending_z and shear, N mm.
    reports : one SolveReport per unit case.
    consistency : max |C_virial - C_energy| / max |C| over the unit cases (solve accuracy).
    """

    frame: Frame
    C: np.ndarray
    C_full: np.ndarray
    components: tuple
    all_components: tuple
    free: tuple
    measure: float
    units: str
    strain: np.ndarray
    fluctuation: np.ndarray
    stress: np.ndarray
    energy: np.ndarray
    reports: list
    consistency: float
    assembly_seconds: float = 0.0
    setup_seconds: float = 0.0
    solve_seconds: float = 0.0
    post_seconds: float = 0.0
    total_seconds: float = 0.0
    info: dict = field(default_factory=dict)

    @property
    def dim(self) -> int:
        return self.frame.dim_periodic

    @property
    def n_cases(self) -> int:
        return len(self.fluctuation)

    @property
    def S(self) -> np.ndarray:
        """Compliance inv(C_full) (1/units of C)."""
        return np.linalg.inv(self.C_full)

    def engineering_constants(self) -> dict:
        """E_i, nu_ij, G_ij from the full compliance S = inv(C_full).

        E_i = 1/S_ii, nu_ij = -S_ji / S_ii (contraction in j under uniaxial stress in i),
        G_ij = 1/S_kk for the shear component ij. Units: MPa (k = 3), N/mm (k = 2,
        membrane moduli), N (k = 1); Poisson's ratios dimensionless.
        """
        S = self.S
        comps = self.all_components
        out = {}
        normal = [c for c in comps if c[0] == c[1]]
        for c in normal:
            i = comps.index(c)
            out[f"E{c[0]}"] = 1.0 / S[i, i]
        for a in normal:
            for b in normal:
                if a != b:
                    i, j = comps.index(a), comps.index(b)
                    out[f"nu{a[0]}{b[0]}"] = -S[j, i] / S[i, i]
        for c in comps:
            if c[0] != c[1]:
                i = comps.index(c)
                out[f"G{c}"] = 1.0 / S[i, i]
        return out

    @property
    def constants(self) -> dict:
        return self.engineering_constants()

    def per_volume(self, thickness: float) -> np.ndarray:
        """k = 2 only: the membrane stiffness divided by a thickness (mm): MPa."""
        if self.dim != 2:
            raise InputError("per_volume(thickness) applies to 2-periodic (membrane) cells")
        if not thickness > 0:
            raise InputError(f"thickness must be > 0, got {thickness}")
        return self.C / float(thickness)

    @property
    def symmetry_error(self) -> float:
        return float(np.abs(self.C_full - self.C_full.T).max() / np.abs(self.C_full).max())

    def to_dataset(self):
        """xarray Dataset with C, C_full, the engineering constants and the solve reports."""
        import xarray as xr

        u = self.units
        ds = xr.Dataset(
            {"C": (("row", "col"), self.C, {"units": u, "long_name": "effective stiffness (Voigt, engineering shear)"}),
             "C_full": (("row_full", "col_full"), self.C_full,
                        {"units": u, "long_name": "effective stiffness over all components"}),
             "iterations": (("case",), np.array([r.iterations for r in self.reports]),
                            {"units": "1", "long_name": "solver iterations per unit case"}),
             "residual": (("case",), np.array([r.residual for r in self.reports]),
                          {"units": "1", "long_name": "true relative residual per unit case"}),
             "solve_seconds": (("case",), np.array([r.solve_seconds for r in self.reports]),
                               {"units": "s", "long_name": "solve time per unit case"})},
            coords={"row": list(self.components), "col": list(self.components),
                    "row_full": list(self.all_components), "col_full": list(self.all_components),
                    "case": list(self.all_components)},
            attrs={"measure": self.measure, "dim_periodic": self.dim,
                   "free": ",".join(self.free), "setup_seconds": self.setup_seconds,
                   "consistency": self.consistency})
        for key, val in self.engineering_constants().items():
            unit = "1" if key.startswith("nu") else u
            ds[key] = ((), val, {"units": unit, "long_name": f"effective {key}"})
        return ds


def homogenize(frame: Frame, *, solver: str = "amg", tol: float = 1e-10, free=None,
               maxiter: int | None = None, nullspace: str = "rigid",
               batched: bool = True) -> Homogenization:
    """Effective stiffness of a periodic frame (one operator setup for all load cases).

    Parameters
    ----------
    frame : periodic Frame (k = 1, 2 or 3 lattice vectors; k = 2 in the x-y plane).
    solver : "amg" (default), "direct" or "cg"; set up once, used for every unit case.
    tol : relative residual of the iterative solves.
    free : Voigt components (names such as "22" or indices) left free with zero macro
        stress in every case; ``C`` is then the condensed stiffness over the others.
    nullspace : AMG near-null space: "rigid" (6 rigid-body modes; the rotations are only
        approximate on a periodic cell) or "translations".
    batched : with solver="amg", solve the unit cases together (lockstep block CG and a
        block V-cycle, :func:`homtex.krylov.solve_many`: the matrices are read once for all
        cases); False solves them one after another.

    Returns
    -------
    Homogenization (see its attributes); ``C`` in MPa (k = 3), N/mm (k = 2), N (k = 1).

    Raises
    ------
    InputError for non-periodic frames or bad ``free``; SolverError for parts that
    nothing connects to the lattice (e.g. a floating strut) or a failed solve.
    """
    if not isinstance(frame, Frame):
        raise InputError(f"frame must be a homtex.Frame, got {type(frame).__name__}")
    t_start = time.perf_counter()
    comps = voigt_components(frame)
    free_idx = _component_index(frame, free)
    if len(free_idx) == len(comps):
        raise InputError(f"free: at least one strain component must be prescribed, got all of {comps}")
    H = unit_strains(frame)
    op = _Operator(frame, solver, tol, maxiter, nullspace)
    b = op.rhs(H)
    t0 = time.perf_counter()
    W = np.empty_like(b)
    reports = []
    if solver == "amg" and batched and len(H) > 1:
        from ..linalg.krylov import solve_many

        W, reports = solve_many(op.lin, b, names=[f"unit case {c}" for c in comps])
        W[:, op.mask] = 0.0
    else:
        for q in range(len(H)):
            W[q], rep = op.solve(b[q])
            reports.append(rep)
    t_solve = time.perf_counter() - t0
    t0 = time.perf_counter()
    n = frame.n_nodes
    U = np.ascontiguousarray(W.reshape(len(H), n, 6))
    C_full, stress, energy = _post(frame, H, U)
    t_post = time.perf_counter() - t0
    scale = np.abs(C_full).max()
    consistency = float(np.abs(stress.T - C_full).max() / scale) if scale > 0 else 0.0
    if not np.all(np.isfinite(C_full)) or scale == 0:
        raise SolverError("homogenisation produced a zero or non-finite stiffness")
    pre = [i for i in range(len(comps)) if i not in free_idx]
    strain = np.eye(len(comps))
    C = C_full
    if free_idx:
        Cff = C_full[np.ix_(free_idx, free_idx)]
        Cfp = C_full[np.ix_(free_idx, pre)]
        Ef = -np.linalg.solve(Cff, Cfp)  # (nf, np)
        C = C_full[np.ix_(pre, pre)] + C_full[np.ix_(pre, free_idx)] @ Ef
        C = 0.5 * (C + C.T)
        strain = np.zeros((len(pre), len(comps)))
        strain[np.arange(len(pre)), pre] = 1.0
        strain[:, free_idx] = Ef.T
        U = np.ascontiguousarray(np.einsum("pc,cnk->pnk", strain, U))
        stress = strain @ stress
        dvec = np.ascontiguousarray(frame.element_vectors)
        Hc = np.einsum("pc,cab->pab", strain, H)
        energy = np.array([_forces(frame, U[q], dvec @ Hc[q].T)[1].sum(axis=0)
                           for q in range(len(pre))])
    return Homogenization(
        frame=frame, C=C, C_full=C_full, components=tuple(comps[i] for i in pre),
        all_components=comps, free=tuple(comps[i] for i in free_idx), measure=cell_measure(frame),
        units=UNITS[frame.dim_periodic], strain=strain, fluctuation=U, stress=stress,
        energy=energy, reports=reports, consistency=consistency,
        assembly_seconds=op.assembly_seconds, setup_seconds=op.setup_seconds,
        solve_seconds=t_solve, post_seconds=t_post, total_seconds=time.perf_counter() - t_start,
        info={"solver": solver, "nullspace": nullspace, "ndof": frame.ndof,
              "batched": bool(solver == "amg" and batched and len(H) > 1)})


def _post(frame, H, U):
    """C (energy form), virial stresses (nc, ncomp) and energy splits (nc, 5)."""
    nc = len(H)
    V = cell_measure(frame)
    dvec = np.ascontiguousarray(frame.element_vectors)
    nchunk = 4 * get_num_threads()
    C = np.empty((nc, nc))
    stress = np.empty((nc, nc))
    energy = np.empty((nc, 5))
    for j in range(nc):
        forces, en = _forces(frame, U[j], dvec @ H[j].T)
        C[:, j] = _pair_work_kernel(frame.elements, frame.R, dvec, H, U, forces, nchunk) / V
        f2 = np.einsum("eab,ea->eb", frame.R, forces[:, 6:9])
        sig = f2.T @ dvec / V  # sum f2 (x) d
        stress[j] = np.einsum("ab,qab->q", sig, H)
        energy[j] = en.sum(axis=0)
    return 0.5 * (C + C.T), stress, energy


# ----------------------------------------------------------------------------------
@dataclass
class MacroState:
    """One macro strain case with prescribed and free components.

    strain : (ncomp,) full macro strain (prescribed values and the free components'
        response); stress : (ncomp,) macro stress (units of C; zero on free components
        up to the solve accuracy); fluctuation : (n, 6); reports : solve reports.
    """

    frame: Frame
    components: tuple
    strain: np.ndarray
    stress: np.ndarray
    fluctuation: np.ndarray
    free: tuple
    reports: list
    energy: float


def solve_macro(frame: Frame, strain, *, free=None, solver: str = "amg", tol: float = 1e-10,
                maxiter: int | None = None) -> MacroState:
    """Solve one macro strain case with some components free (zero macro stress).

    The free components are extra unknowns beside the fluctuation w: the bordered
    system [[K, G_f], [G_f^T, A_ff]] [w; E_f] = -[G_p E_p; A_fp E_p] (the Hessian of
    the cell energy, symmetric positive definite). ``solver="direct"`` factors the
    bordered matrix as it is; the iterative solvers eliminate the extra unknowns
    (Schur complement on E_f, one operator setup, 1 + n_free solves).

    Parameters
    ----------
    strain : (ncomp,) macro strain in Voigt order (engineering shear); the values of
        free components are ignored. Or a dict {component name: value}.
    free : names or indices of the free components.

    Returns
    -------
    MacroState.
    """
    comps = voigt_components(frame)
    if isinstance(strain, dict):
        E = np.zeros(len(comps))
        for key, v in strain.items():
            E[_component_index(frame, [key], "strain")[0]] = float(v)
    else:
        E = np.asarray(strain, dtype=float).ravel()
        if E.shape != (len(comps),):
            raise InputError(f"strain must have {len(comps)} components {comps}, got shape {E.shape}")
    if not np.isfinite(E).all():
        raise InputError(f"strain is not finite: {E.tolist()}")
    fi = _component_index(frame, free)
    pi = [i for i in range(len(comps)) if i not in fi]
    Hunit = unit_strains(frame)
    E[fi] = 0.0
    Hp = np.einsum("c,cab->ab", E, Hunit)[None]
    Hf = Hunit[fi]
    op = _Operator(frame, solver, tol, maxiter)
    n = frame.n_nodes
    bp = op.rhs(Hp)[0]
    reports = []
    if fi:
        bf = op.rhs(Hf)  # (nf, 6n) = -G_f
        zero = np.zeros((1, n, 6))
        # A_ff and A_fp: jump-only work a_i^T K a_j
        Hall = np.concatenate([Hf, Hp])
        Z = np.zeros((len(Hall), n, 6))
        dvec = np.ascontiguousarray(frame.element_vectors)
        A = np.empty((len(Hall), len(Hall)))
        for j in range(len(Hall)):
            forces, _ = _forces(frame, zero[0], dvec @ Hall[j].T)
            A[:, j] = _pair_work_kernel(frame.elements, frame.R, dvec, Hall, Z, forces,
                                            4 * get_num_threads())
        nf = len(fi)
        Aff, Afp = A[:nf, :nf], A[:nf, nf]
        if solver == "direct":
            G = -bf.T  # (6n, nf)
            keep = ~op.mask
            Kb = sp.bmat([[sp.csr_matrix(op.A), sp.csr_matrix(np.where(keep[:, None], G, 0.0))],
                          [sp.csr_matrix(np.where(keep[None, :], G.T, 0.0)), sp.csr_matrix(Aff)]],
                         format="csc")
            rhs = np.concatenate([bp, -Afp])
            lin = LinearSolver(Kb, method="direct", tol=tol)
            x, rep = lin.solve(rhs)
            reports.append(rep)
            w = x[:6 * n]
            w[op.mask] = 0.0
            Ef = x[6 * n:]
        else:
            Wf = np.empty_like(bf)
            for q in range(nf):
                Wf[q], rep = op.solve(bf[q])
                reports.append(rep)
            wp, rep = op.solve(bp)
            reports.append(rep)
            # Schur complement: (A_ff - G_f^T K^-1 G_f) E_f = -(A_fp - G_f^T K^-1 G_p E_p)
            # with b = -G: K^-1 G_f = -Wf^T, so A_ff - G_f^T K^-1 G_f = A_ff - bf Wf^T
            S = Aff - bf @ Wf.T
            S = 0.5 * (S + S.T)
            r = -Afp + bf @ wp
            Ef = np.linalg.solve(S, r)
            w = wp + Ef @ Wf
        E[fi] = Ef
    else:
        w, rep = op.solve(bp)
        reports.append(rep)
    U = w.reshape(n, 6)
    H = np.einsum("c,cab->ab", E, Hunit)
    dvec = np.ascontiguousarray(frame.element_vectors)
    forces, en = _forces(frame, U, dvec @ H.T)
    f2 = np.einsum("eab,ea->eb", frame.R, forces[:, 6:9])
    sig = f2.T @ dvec / cell_measure(frame)
    stress = np.einsum("ab,qab->q", sig, Hunit)
    return MacroState(frame=frame, components=comps, strain=E, stress=stress, fluctuation=U,
                      free=tuple(comps[i] for i in fi), reports=reports, energy=float(en.sum()))


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


# ----------------------------------------------------------------------------------
def periodize(frame: Frame, box, *, axes=None, tol: float = 1e-6) -> Frame:
    """A periodic Frame from a frame drawn in an axis-aligned box.

    Nodes on an upper face of the box (coordinate = hi within ``tol`` along a periodic
    axis) are merged with their partners on the lower face (coordinate = lo, the other
    coordinates equal within ``tol``, modulo the other periods for edges and corners);
    elements that reached an upper-face node get the matching image offset. Elements
    that become duplicates (struts drawn on both opposite faces) are kept once.

    Parameters
    ----------
    frame : Frame (non-periodic), mm.
    box : (2, 3) array [lo, hi] of the box corners, mm.
    axes : periodic axes (subset of 0, 1, 2); default every axis with hi > lo.
    tol : pairing tolerance, mm.

    Returns
    -------
    Frame with ``periods`` = diag(hi - lo) rows of the periodic axes; the nodes of the
    upper faces are removed and the rest renumbered in order.

    Raises
    ------
    InputError listing the boundary nodes without a partner on the opposite face.
    """
    from scipy.spatial import cKDTree

    if frame.dim_periodic:
        raise InputError("periodize: the frame is already periodic")
    box = np.asarray(box, dtype=float)
    if box.shape != (2, 3) or not np.isfinite(box).all():
        raise InputError(f"box must be a (2, 3) array [lo, hi], got shape {box.shape}")
    lo, hi = box
    if axes is None:
        axes = [a for a in range(3) if hi[a] - lo[a] > tol]
    axes = sorted(int(a) for a in axes)
    if not axes or any(a not in (0, 1, 2) for a in axes):
        raise InputError(f"periodize: periodic axes must be a non-empty subset of 0, 1, 2, got {axes}")
    for a in axes:
        if not hi[a] - lo[a] > tol:
            raise InputError(f"periodize: box extent along axis {a} is {hi[a] - lo[a]}, must be > tol")
    x = frame.nodes
    outside = np.any((x < lo - tol) | (x > hi + tol), axis=1)
    if outside.any():
        bad = np.flatnonzero(outside)
        raise InputError(f"periodize: {len(bad)} nodes lie outside the box, e.g. node {bad[0]} at "
                         f"{x[bad[0]].tolist()}; nodes {bad[:20].tolist()}")
    Lp = hi - lo
    k = len(axes)
    on_hi = np.column_stack([np.abs(x[:, a] - hi[a]) <= tol for a in axes])
    on_lo = np.column_stack([np.abs(x[:, a] - lo[a]) <= tol for a in axes])
    img = on_hi.astype(np.int64)  # (n, k)
    canon = x.copy()
    for c, a in enumerate(axes):
        canon[:, a] -= img[:, c] * Lp[a]
    master = ~on_hi.any(axis=1)
    midx = np.flatnonzero(master)
    tree = cKDTree(canon[midx])
    dist, nearest = tree.query(canon, distance_upper_bound=tol * np.sqrt(3) * 1.0001)
    found = np.isfinite(dist)
    target = np.where(found, midx[np.minimum(nearest, len(midx) - 1)], -1)
    target[master] = midx
    unpaired_hi = np.flatnonzero(~master & ~found)
    # a lower-face node needs a partner on the upper face
    slaves = np.flatnonzero(~master & found)
    need = np.zeros((len(x), k), dtype=bool)
    for c in range(k):
        sel = slaves[on_hi[slaves, c]]
        need[target[sel], c] = True
    unpaired_lo = np.flatnonzero((on_lo & ~need & master[:, None]).any(axis=1))
    if len(unpaired_hi) or len(unpaired_lo):
        lines = []
        for i in unpaired_hi[:20]:
            lines.append(f"  node {i} at {x[i].tolist()} (upper face) has no partner on the lower face")
        for i in unpaired_lo[:20]:
            faces = [axes[c] for c in range(k) if on_lo[i, c] and not need[i, c]]
            lines.append(f"  node {i} at {x[i].tolist()} (lower face, axis {faces}) has no "
                         f"partner on the upper face")
        total = len(unpaired_hi) + len(unpaired_lo)
        raise InputError(f"periodize: {total} boundary node(s) without a partner within tol={tol} mm:\n"
                         + "\n".join(lines))
    new_id = -np.ones(len(x), dtype=np.int64)
    new_id[midx] = np.arange(len(midx))
    el = frame.elements
    a_, b_ = el[:, 0], el[:, 1]
    eimg = img[b_] - img[a_]
    elements = np.column_stack([new_id[target[a_]], new_id[target[b_]]])
    # duplicates (struts drawn on both opposite faces) are kept once
    swap = elements[:, 0] > elements[:, 1]
    lo_e = np.where(swap, elements[:, 1], elements[:, 0])
    hi_e = np.where(swap, elements[:, 0], elements[:, 1])
    im_c = np.where(swap[:, None], -eimg, eimg)
    same = lo_e == hi_e
    if same.any():
        first = np.zeros(len(el), dtype=np.int64)
        for c in range(k - 1, -1, -1):
            first = np.where(im_c[:, c] != 0, im_c[:, c], first)
        im_c = np.where((same & (first < 0))[:, None], -im_c, im_c)
    _, keep = np.unique(np.column_stack([lo_e, hi_e, im_c]), axis=0, return_index=True)
    keep = np.sort(keep)
    periods = np.zeros((k, 3))
    for c, a in enumerate(axes):
        periods[c, a] = Lp[a]
    return Frame(canon[midx], elements[keep], semi_axes=np.column_stack([frame.a, frame.b])[keep],
                 E=frame.E[keep], nu=frame.nu[keep], yarn=frame.yarn[keep], ref=frame.R[keep, 1],
                 periods=periods, images=eimg[keep], contact_radius=frame.contact_radius[keep],
                 prestrain=frame.prestrain[keep], bending_factor=frame.bending_factor[keep],
                 torsion_factor=frame.torsion_factor[keep])


# ----------------------------------------------------------------------------------
@dataclass
class CompressionResult:
    """A 2-periodic cell compressed between two rigid planes (nodes tied to them).

    modulus : effective compression modulus, MPa (force per area / (compression / thickness)).
    stiffness : force per compression displacement, N/mm.
    force_per_area : compressive stress at the imposed ``strain``, MPa.
    strain : imposed compression (plate approach / thickness), 1.
    thickness : plate distance, mm; area : cell area, mm^2.
    bottom, top : indices of the nodes tied to the planes.
    u : (n, 6) displacement; report : SolveReport.
    """

    modulus: float
    stiffness: float
    force_per_area: float
    strain: float
    thickness: float
    area: float
    bottom: np.ndarray
    top: np.ndarray
    planes: tuple
    u: np.ndarray
    report: SolveReport


def compression_modulus(frame: Frame, *, solver: str = "amg", tol: float = 1e-10,
                        tie: str = "xyz", strain: float = 1e-3, plane_tol: float | None = None,
                        maxiter: int | None = None) -> CompressionResult:
    """Effective compression modulus of a 2-periodic cell between two rigid planes in z.

    The planes touch the cell: the bottom plane at min(z - r_c), the top plane at
    max(z + r_c) over the nodes (r_c: the largest contact radius of the elements at a
    node). Nodes within ``plane_tol`` (default 1e-6 times the thickness) of a plane are
    tied to it: all translations (``tie="xyz"``, bonded) or only uz (``tie="z"``,
    frictionless; then one node's in-plane translations are pinned). The top plane
    moves down by ``strain`` times the thickness; the in-plane macro strain is zero
    (periodic fluctuations). Linear: the modulus does not depend on ``strain``.
    Real contact (nodes leaving or reaching a plane) is done by :mod:`homtex.contact`.

    Returns
    -------
    CompressionResult with the modulus (MPa) and the force per area (MPa).
    """
    if not isinstance(frame, Frame):
        raise InputError(f"frame must be a homtex.Frame, got {type(frame).__name__}")
    if frame.dim_periodic != 2 or np.abs(frame.periods[:, 2]).max() > 1e-9 * np.abs(frame.periods).max():
        raise InputError("compression_modulus needs a 2-periodic frame with lattice vectors in the "
                         "x-y plane")
    if tie not in ("xyz", "z"):
        raise InputError(f"tie must be 'xyz' or 'z', got {tie!r}")
    if not (np.isfinite(strain) and 0 < strain < 1):
        raise InputError(f"strain must be in (0, 1), got {strain}")
    n = frame.n_nodes
    rc = np.zeros(n)
    np.maximum.at(rc, frame.elements[:, 0], frame.contact_radius)
    np.maximum.at(rc, frame.elements[:, 1], frame.contact_radius)
    z = frame.nodes[:, 2]
    zb = float(np.min(z - rc))
    zt = float(np.max(z + rc))
    thick = zt - zb
    ptol = 1e-6 * thick if plane_tol is None else float(plane_tol)
    bottom = np.flatnonzero(z - rc <= zb + ptol)
    top = np.flatnonzero(z + rc >= zt - ptol)
    if np.intersect1d(bottom, top).size:
        raise InputError(f"compression_modulus: nodes {np.intersect1d(bottom, top)[:10].tolist()} touch "
                         f"both planes (the cell is flat)")
    mask = np.zeros((n, 6), dtype=bool)
    vals = np.zeros((n, 6))
    delta = strain * thick
    if tie == "xyz":
        mask[bottom, :3] = True
        mask[top, :3] = True
    else:
        mask[bottom, 2] = True
        mask[top, 2] = True
        mask[bottom[0], :2] = True
    vals[top, 2] = -delta
    mask = mask.ravel()
    vals = vals.ravel()
    check_held(frame, mask)
    asm = Assembler(frame)
    K = asm.stiffness()
    b = -(K @ vals)
    A = constrain(K, mask)
    b[mask] = A.diagonal()[mask] * vals[mask]
    B = rigid_body_modes(frame.nodes) if solver == "amg" else None
    lin = LinearSolver(A, method=solver, B=B, tol=tol, maxiter=maxiter)
    x, rep = lin.solve(b)
    x[mask] = vals[mask]
    react = (K @ x).reshape(n, 6)
    force = -float(react[top, 2].sum())  # compressive force on the top plane, N
    area = cell_measure(frame)
    return CompressionResult(modulus=force / area / strain, stiffness=force / delta,
                             force_per_area=force / area, strain=strain, thickness=thick,
                             area=area, bottom=bottom, top=top, planes=(zb, zt),
                             u=x.reshape(n, 6), report=rep)
