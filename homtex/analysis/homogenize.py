"""Effective stiffness of periodic frames (``homogenize``).

The effective stiffness follows from the strain energy of the equilibrium states of
the unit cases (one per Voigt component, one operator setup for all of them):

    C_ij = (1/V) sum_e f_e(j) . d_e(i),

with f_e(j) the local end forces of element e in case j and d_e(i) its local end
displacements (fluctuation plus jump) in case i. This is the energy form
(a_i + B w_i)^T K_e (a_j + B w_j): symmetric by construction and second-order
accurate in the solve error. The macro stress of each case is also computed from
the virial sum (1/V) sum_e f2_e (x) d_e (force acting at the second end times the
element vector); its difference from C is reported as ``consistency``.
Strain bookkeeping (Voigt order, units) is in :mod:`homtex.analysis.periodic`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numba import get_num_threads

from ..config import option
from ..errors import InputError, SolverError
from ..fem.periodic import pair_work_kernel
from ..linalg.multirhs import solve_many
from ..model.frame import Frame
from ..validate import check_choice, check_int
from .periodic import UNITS, _component_index, _forces, _Operator, cell_measure, unit_strains, voigt_components

__all__ = ["Homogenization", "homogenize"]


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


def homogenize(frame: Frame, *, solver: str | None = None, tol: float | None = None, free=None,
               maxiter: int | None = None, nullspace: str = "rigid",
               batched: bool = True) -> Homogenization:
    """Effective stiffness of a periodic frame (one operator setup for all load cases).

    Parameters
    ----------
    frame : periodic Frame (k = 1, 2 or 3 lattice vectors; k = 2 in the x-y plane).
    solver : "amg", "direct" or "cg" (default: option ``homogenize_solver``, "amg"); set up once,
        used for every unit case.
    tol : relative residual of the iterative solves (default: option ``tol``).
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
    solver = option("homogenize_solver", solver)
    tol = option("tol", tol)
    check_choice(nullspace, "nullspace", ("rigid", "translations"))
    if not isinstance(batched, (bool, np.bool_)):
        raise InputError(f"batched must be True or False, got {batched!r}")
    if maxiter is not None:
        check_int(maxiter, "maxiter", ge=1)
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
        C[:, j] = pair_work_kernel(frame.elements, frame.R, dvec, H, U, forces, nchunk) / V
        f2 = np.einsum("eab,ea->eb", frame.R, forces[:, 6:9])
        sig = f2.T @ dvec / V  # sum f2 (x) d
        stress[j] = np.einsum("ab,qab->q", sig, H)
        energy[j] = en.sum(axis=0)
    return 0.5 * (C + C.T), stress, energy
