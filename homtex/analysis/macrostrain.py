"""One macro strain case with some components free (zero macro stress): ``solve_macro``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from numba import get_num_threads

from ..config import option
from ..errors import InputError
from ..fem.periodic import pair_work_kernel
from ..linalg.solvers import LinearSolver
from ..model.frame import Frame
from .periodic import _component_index, _forces, _Operator, cell_measure, unit_strains, voigt_components

__all__ = ["MacroState", "solve_macro"]


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


def solve_macro(frame: Frame, strain, *, free=None, solver: str | None = None, tol: float | None = None,
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
    solver = option("homogenize_solver", solver)
    tol = option("tol", tol)
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
            A[:, j] = pair_work_kernel(frame.elements, frame.R, dvec, Hall, Z, forces,
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
