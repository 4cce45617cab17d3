"""Geometrically nonlinear frames: :func:`solve_nonlinear` (path following with stability).

The co-rotational state and its consistent tangent are :class:`~homtex.analysis.corotational.Corotational`
(re-exported here); the controls are in :mod:`homtex.analysis.path`, the stability checks in
:mod:`homtex.analysis.stability`, what is recorded in :mod:`homtex.analysis.records`.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from ..config import option
from ..errors import InputError
from ..model.frame import Frame
from ..model.scene import parse_fixed, parse_loads
from ..model.topology import check_held
from ..validate import check_choice, check_int, check_number, check_tol
from .corotational import GEOMETRIC, Corotational
from .equilibrium import Equilibrium, Settings
from .path import follow_arclength, follow_lambda
from .records import ENERGY_NAMES, PathRecorder

__all__ = ["CONTROLS", "GEOMETRIC", "Corotational", "NonlinearResult", "solve_nonlinear"]

log = logging.getLogger(__name__)

CONTROLS = ("load", "displacement", "arclength")


@dataclass
class NonlinearResult:
    """Result of :func:`solve_nonlinear`: the last converged state and the path to it.

    Attributes
    ----------
    u : (n, 6) translations (mm) and rotation vectors log Q (rad). x : (n, 3) deformed positions, mm.
    Q : (n, 3, 3) nodal rotation matrices. forces : (m, 12) local end forces (co-rotated frames).
    energy : dict of (m,) energies per element (axial, torsion, bending_y, bending_z, shear), N mm.
    reactions : (n, 6) support reactions (N, N mm), zero on free DOFs.
    path : xarray Dataset over ``step`` (see :mod:`homtex.analysis.records`).
    load_factor : lambda of the last state. stable : whether it is stable; negative_eigenvalues.
    critical_load_factor : first bifurcation or limit point met (nan if none).
    history : per state (load factor, Newton iterations, residual), as before the path existed.
    state : the large-motion engine's state to continue from (``initial=`` of a later solve; None
        without contact). plate_z : (P,) plate heights at the end (mm; empty without plates).
    """

    frame: Frame
    u: np.ndarray
    x: np.ndarray
    Q: np.ndarray
    forces: np.ndarray
    energy: dict
    reactions: np.ndarray
    path: xr.Dataset
    load_factor: float = 1.0
    stable: bool = True
    negative_eigenvalues: int = 0
    critical_load_factor: float = float("nan")
    history: list = field(default_factory=list)
    state: object = None
    plate_z: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def axial_force(self) -> np.ndarray:
        """(m,) axial force of every element (tension positive), N."""
        return self.forces[:, 6]


def solve_nonlinear(frame: Frame, fixed=None, loads=None, *, control: str = "load", steps: int = 10,
                    tol: float = 1e-9, atol: float | None = None, max_iter: int = 15, max_cuts: int = 10,
                    geometric: str = "full", solver: str | None = None, perturbation: float = 1e-2,
                    arc_length: float | None = None, monitor=None) -> NonlinearResult:
    """Large-rotation static solve of a frame without contact, following the load path.

    The load factor lambda scales the loads and the prescribed motions together (dead loads; a
    moment keeps its axis; a prescribed rotation vector turns its node about that fixed axis by
    lambda times its length).

    Parameters
    ----------
    frame : Frame (n nodes, m elements).
    fixed : supports, as :func:`homtex.static.solve_static`: node -> "all" | [DOFs] (held) |
        {DOF: value} (prescribed translation, mm, or rotation, rad; DOFs 0..5 = ux uy uz rx ry rz).
    loads : node -> (Fx, Fy, Fz, Mx, My, Mz), N and N mm (the reference load).
    control : "load" (lambda = k / steps, the default), "displacement" (the same ramp, driven by
        non-zero prescribed translations or rotations in ``fixed``; past a turning point of the
        prescribed motion it raises) or "arclength" (Crisfield's arc length with the loads and
        prescribed motions as the reference: the path is followed through limit points until
        lambda reaches 1 or ``steps`` increments are spent). Under "load" and "displacement" a
        converged state that is unstable is never returned: the critical point is located and
        recorded and the stable branch is taken along the critical mode; a limit point raises
        :class:`~homtex.errors.SolverError` naming it and the remedy (control="arclength").
    steps : requested load steps (cut and regrown automatically) or arc-length increments (>= 1).
    tol : equilibrium when the out-of-balance force on the free DOFs is below tol x max(|lambda f|,
        |f_int|) (+ a round-off floor), in (0, 1). atol : an absolute tolerance (N, N mm) used
        instead when given (as OpenSees' NormUnbalance test).
    max_iter : Newton iterations per step (>= 1). max_cuts : halvings of a step before giving up.
    geometric : "full" (or "consistent"): the consistent tangent (the only option here).
    solver : "auto" (the default of option ``nonlinear_solver``: "lu" where moments are applied to free
        rotations, else "ldl"), "ldl"
        (qdldl LDL^T of the symmetric part, symbolic analysis reused; "direct" is an alias) or "lu"
        (SuperLU on the full nonsymmetric tangent). The skew part of the consistent tangent is
        -1/2 [m]x per node (m its internal moment): without applied moments it is the residual and
        LDL^T of the symmetric part converges quadratically (measured: the same iterations as LU on
        the bend); applied moments out of their plane of rotation need the full tangent (a helix by
        two end moments: LDL^T converges linearly and stalls).
    perturbation : size of the perturbation along a critical mode (branch switching), as a
        fraction of the structure size, in (0, 1).
    arc_length : first arc length (weighted mm; default: the linear response to the reference load
        divided by ``steps``).
    monitor : node indices whose displacements and forces are recorded along the path (``path.u``,
        ``path.force``, (step, node, dof)); default: the loaded nodes and those with prescribed motions.

    Returns
    -------
    NonlinearResult with ``u`` (n, 6), ``x`` (n, 3), ``reactions`` (n, 6) and ``path`` (xarray
    Dataset over ``step``: load_factor, stable, negative_eigenvalues, iterations, residual, the
    energy split, external_work, energy_balance, strains; attributes critical_load_factor, check,
    status). Never a non-converged state.

    Raises
    ------
    InputError for bad arguments (naming the argument and its range); SolverError for limit points
    under load control, turning points under displacement control and steps that do not converge.
    """
    if not isinstance(frame, Frame):
        raise InputError(f"frame must be a homtex.Frame, got {type(frame).__name__}")
    check_choice(control, "control", CONTROLS)
    steps = check_int(steps, "steps", ge=1, le=10 ** 6)
    settings = Settings(tol=check_tol(tol), atol=None if atol is None else check_number(atol, "atol", gt=0.0),
                        max_iter=check_int(max_iter, "max_iter", ge=1, le=10000),
                        max_cuts=check_int(max_cuts, "max_cuts", ge=0, le=40),
                        perturbation=check_number(perturbation, "perturbation", gt=0.0, lt=1.0))
    arc_length = None if arc_length is None else check_number(arc_length, "arc_length", gt=0.0)
    solver = option("nonlinear_solver", solver)
    if geometric not in ("full", "consistent"):
        raise InputError(f"geometric must be 'full' or 'consistent' for solve_nonlinear (the approximate tangents "
                         f"{GEOMETRIC} are for contact), got {geometric!r}")
    n = frame.n_nodes
    mask, ubar = parse_fixed(fixed, n)
    f = parse_loads(loads, n)
    moments = np.zeros((n, 6), dtype=bool)
    moments[:, 3:] = True
    used = solver
    if solver == "auto":
        used = "lu" if np.any(f[moments.ravel() & ~mask] != 0.0) else "ldl"
    settings.solver = "lu" if used == "lu" else "ldl"
    if control == "displacement" and not np.any(ubar[mask] != 0.0):
        raise InputError("control='displacement' needs a non-zero prescribed translation or rotation in fixed "
                         "(node -> {dof: value})")
    if control == "arclength" and not (np.any(f[~mask] != 0.0) or np.any(ubar[mask] != 0.0)):
        raise InputError("control='arclength' needs a reference load on a free DOF (loads) or a non-zero "
                         "prescribed motion (fixed)")
    check_held(frame, mask)
    eq = Equilibrium(frame, mask, f, ubar, settings)
    if monitor is None:
        monitor = np.flatnonzero(np.any((f != 0.0).reshape(n, 6) | (ubar != 0.0).reshape(n, 6), axis=1))
    else:
        monitor = np.atleast_1d(np.asarray(monitor))
        if not np.issubdtype(monitor.dtype, np.integer) or monitor.ndim != 1 or \
                np.any((monitor < 0) | (monitor >= n)):
            raise InputError(f"monitor must be node indices in 0..{n - 1}, got {monitor!r}")
    rec = PathRecorder(control, steps, monitor)
    try:
        if control == "arclength":
            follow_arclength(eq, rec, steps, arc_length)
        else:
            follow_lambda(eq, rec, steps, control)
    finally:
        rec.finish()
    return _result(eq, rec, solver)


def _result(eq: Equilibrium, rec: PathRecorder, solver: str) -> NonlinearResult:
    cor = eq.cor
    n = eq.n
    fint = eq.fint.reshape(n, 6)
    reactions = np.where(eq.mask.reshape(n, 6), fint - eq.lam * eq.f.reshape(n, 6), 0.0)
    path = rec.dataset({"tol": eq.s.tol, "atol": -1.0 if eq.s.atol is None else eq.s.atol, "solver": solver,
                        "factorisation": "SuperLU of the full tangent" if eq.s.solver == "lu" else
                        "qdldl LDL^T of the symmetric part",
                        "evaluations": eq.evaluations, "factorisations": eq.factorisations,
                        "ldl_refinements": eq.sys.refinements, "ldl_fallbacks": eq.sys.fallbacks})
    neg = -1 if eq.negative is None else int(eq.negative)
    if neg > 0:          # arc length only: load and displacement control never accept one
        msg = (f"solve_nonlinear returns an unstable state (load factor {eq.lam:.6g}, {neg} negative eigenvalue(s)): "
               "arc length follows the path it is on and does not switch branches")
        log.warning(msg)
        warnings.warn(msg, RuntimeWarning, stacklevel=3)
    history = [(float(a), int(b), float(c)) for a, b, c in zip(path.load_factor.values, path.iterations.values,
                                                                   path.residual.values)]
    return NonlinearResult(frame=eq.frame, u=cor.u(), x=cor.positions, Q=cor.Q.copy(), forces=cor.forces.copy(),
                           energy=dict(zip(ENERGY_NAMES, cor.energy.T.copy())), reactions=reactions, path=path,
                           load_factor=float(eq.lam), stable=neg == 0, negative_eigenvalues=neg,
                           critical_load_factor=rec.critical_load_factor(), history=history)
