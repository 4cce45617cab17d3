"""The public entry points that dispatch to a stage: ``solve_static`` (with or without contact),
``solve_nonlinear`` (large rotations; with contact the large-motion engine) and ``compress``
(the large-motion engine by default; the linear small-rotation model by name). They check their
arguments, read the defaults of :mod:`homtex.config` and hand over; the work is done in the
stage's room."""

from __future__ import annotations

import numpy as np
import xarray as xr

from .analysis.nonlinear import CONTROLS, NonlinearResult
from .analysis.nonlinear import solve_nonlinear as _solve_frame
from .analysis.static import solve_linear
from .config import option, threads_for
from .contact.compress import CompressionTest, run_compression
from .contact.engine import run_engine
from .contact.incremental import NonlinearSettings
from .contact.lattice import Lattice
from .contact.options import Contact
from .contact.solver import solve_contact
from .errors import InputError, SolverError
from .fem.assembly import Assembler
from .linalg.solvers import SINGULAR
from .model.arrays import as_real
from .model.frame import Frame
from .model.rest import RestState
from .model.results import StaticResult
from .model.scene import Scene
from .model.topology import singular_diagnosis
from .validate import check_choice, check_int, check_number

__all__ = ["compress", "solve_nonlinear", "solve_static"]

GEOMETRIES = ("linear", "nonlinear")


def solve_static(frame: Frame, fixed=None, loads=None, *, solver: str | None = None, tol: float | None = None,
                 maxiter: int | None = None, contact: Contact | None = None, assembler: Assembler | None = None,
                 **contact_options) -> StaticResult:
    """Solve K u = f for a (non-periodic) frame with supports and loads.

    Parameters
    ----------
    frame : Frame
    fixed : dict node -> "all" | [DOFs 0..5] | {DOF: value}
        Supports; listed DOFs are held at zero, dict values are prescribed (mm, rad).
    loads : dict node -> (Fx, Fy, Fz, Mx, My, Mz), N and N mm.
    solver : "amg", "direct" or "cg" (default: option ``static_solver``, "amg").
    tol : relative residual of iterative solvers (default: option ``tol``, 1e-10).
    contact : homtex.Contact or None
        With contact, yarns cannot interpenetrate (see :mod:`homtex.contact`); then
        ``plates`` (rigid planes) and ``u_ref`` (linearisation point) are accepted too.

    Raises
    ------
    InputError for bad supports/loads; SolverError for unheld parts or a failed solve; a singular
    stiffness matrix (from any solver, AMG's coarse grid included) names the parts nothing holds
    and the elements of almost no stiffness.
    """
    if not isinstance(frame, Frame):
        raise InputError(f"frame must be a homtex.Frame, got {type(frame).__name__}")
    if contact_options and contact is None:
        raise InputError(f"unknown options {sorted(contact_options)}")
    try:
        with threads_for(frame.ndof):     # one numba thread for a small frame (homtex.config)
            if contact is not None:
                return solve_contact(frame, fixed, loads, contact=contact, solver=solver, tol=tol,
                                     maxiter=maxiter, assembler=assembler, **contact_options)
            return solve_linear(frame, fixed, loads, solver=solver, tol=tol, maxiter=maxiter, assembler=assembler)
    except SolverError as err:
        if not any(w in str(err) for w in (SINGULAR, "singular", "not positive definite")):
            raise
        hint = _singular_hint(frame, None if contact is not None else fixed, loads)
        if not hint:
            raise
        raise SolverError(f"{err}\nIn this frame:\n{hint}", history=err.history, report=err.report) from err


def _singular_hint(frame, fixed, loads) -> str:
    """The frame's diagnosis of a singular stiffness matrix (:func:`homtex.model.topology.singular_diagnosis`):
    unheld parts (without contact: the supports alone must hold every part) and elements of almost
    no stiffness."""
    mask = None
    if fixed is not None:
        try:
            mask = Scene.build(frame, fixed, loads).mask
        except InputError:
            mask = None
    return singular_diagnosis(frame, mask)


def _frame_of(obj):
    if isinstance(obj, Frame):
        return obj, None, {"validity": {}}, None
    fr = getattr(obj, "frame", None)
    if not isinstance(fr, Frame):
        raise InputError(f"compress needs a homtex.Frame or an object with a .frame (a homtex Cell), "
                         f"got {type(obj).__name__}")
    groups = getattr(obj, "groups", None)
    info = getattr(obj, "info", None) or {}
    spec = getattr(obj, "friction_spec", None)
    validity = dict(getattr(obj, "validity", None) or {})
    if validity.get("mesh_cell") and hasattr(obj, "fabric_fingerprint"):
        validity["mesh_matches"] = obj.fabric_fingerprint() == validity["mesh_cell"]
    info = dict(info, validity=validity)
    return fr, groups, info, spec


def _refuse_linear_options(*, solver, tol, contact: Contact) -> None:
    """InputError for an option of the linear model given to the engine (``compress``'s default),
    which would otherwise ignore it: say to name ``geometry="linear"`` or leave the option out."""
    given = [f"{name}={value!r}" for name, value in (("solver", solver), ("tol", tol)) if value is not None]
    given += [f"Contact({name}={value!r})" for name, value in contact.linear_only().items()]
    if given:
        raise InputError(f"compress: {', '.join(given)} {'is an option' if len(given) == 1 else 'are options'} of "
                         "the linear model, which compress runs only when named: add geometry=\"linear\" for it "
                         "(small rotations, frictionless; valid to the cell's [validity] linear_strain_limit), or "
                         "leave the option out for the large-motion engine (geometry=\"nonlinear\", the default), "
                         "which has its own solver and tolerances")


def _targets(v, steps, name):
    arr = np.atleast_1d(as_real(v, name))
    if arr.ndim != 1 or arr.size > 100_000:
        raise InputError(f"{name} must be a number or a 1-D array of at most 100000 levels, got shape {arr.shape}")
    if arr.size == 0:
        raise InputError(f"{name} must be a number or a non-empty array of levels, got an empty array (a curve "
                         "needs at least one level)")
    if arr.size == 1:
        if not (np.isfinite(arr[0]) and arr[0] > 0):
            raise InputError(f"{name} must be positive, got {v!r}")
        return arr[0] * np.arange(1, int(steps) + 1) / int(steps)
    if not (np.all(np.isfinite(arr)) and np.all(arr > 0) and np.all(np.diff(arr) > 0)):
        raise InputError(f"{name} values must be positive and increasing")
    return arr


def compress(cell_or_frame, *, strain=None, steps: int = 20, control: str = "displacement",
             contact: Contact | None = None, pressure=None, fixed=None, thickness: float | None = None,
             area: float | None = None, solver: str | None = None, tol: float | None = None,
             maxiter: int | None = None, max_cuts: int = 4, progress: bool | None = None, geometry: str = "nonlinear",
             stabilize: float = 0.0) -> xr.Dataset:
    """Compression curve of a cell between two rigid plates: by default on the large-motion engine
    (``geometry="nonlinear"``, with the cell file's ``[contact]`` friction); the linear
    small-rotation model only when named (``geometry="linear"``).

    Parameters
    ----------
    cell_or_frame : homtex.Frame, or an object with ``.frame`` (a homtex Cell; its ``.groups``
        {name: (m,) bool element mask} give per-group energies, ``.info["thickness"]`` the
        plate distance, its ``[contact]`` table the friction of the engine).
    strain : final compression strain (plate displacement / initial plate distance, > 0), or
        an increasing array of strains (displacement control).
    steps : number of equal steps up to ``strain`` (or ``pressure``).
    control : "displacement" (the top plate moves) or "force" (uniform ``pressure`` on it).
    pressure : final pressure (kPa) or an increasing array (force control).
    contact : Contact options. Engine (default): the barrier, friction and search options
        (``friction``, ``plate_friction``, ``barrier_gap``, ``barrier_stiffness``, ``friction_slip``,
        ``compression``, ``margin``), e.g. ``Contact(friction=0.3)``; default ``Contact()``, the
        friction of the cell file's ``[contact]`` table (else 0). ``geometry="linear"``: the
        active-set and enforcement options (``strategy``, ``enforcement``, ``penalty``, ``gap_tol``,
        ...; default pdas, augmented Lagrangian); frictionless, solid yarns only. An option of the
        other model set away from its default is refused (InputError), not ignored.
    fixed : extra supports (dict as in ``solve_static``); default pins the in-plane rigid
        motions that frictionless plates leave free (ux, uy of the lowest node for a 2-periodic
        frame; plus one in-plane DOF against rotation about z for a finite frame).
    thickness : plate distance, mm (default ``info["thickness"]``, else the yarns' extent
        (z_max + r) - (z_min - r)); the bottom plate touches the lowest yarn surface.
    area : nominal area for the stress, mm^2 (default |p1 x p2| of a 2-periodic frame in x-y,
        else the x-y bounding box of the yarns).
    solver, tol : linear solver and tolerance of the linear model (``geometry="linear"`` only;
        default: options ``compress_solver`` ("direct") and ``tol``). The engine has its own
        factorisation and equilibrium tolerance: passing either without ``geometry="linear"`` is
        an InputError that says so.
    maxiter : iteration limit, an integer >= 1: with ``geometry="nonlinear"`` the large-motion
        engine's Newton iterations per friction round of a step (default 80;
        :class:`homtex.contact.incremental.NonlinearSettings` ``max_iter``); with
        ``geometry="linear"`` of the iterative linear solves (``solver="amg"`` or ``"cg"``; default
        1000 and 5000).
    max_cuts : a step that fails (linear: cycling active set, penetration, solver failure; engine:
        no convergence, or a step whose stabilisation takes more than 1 % of its work) is retried
        as two half steps, recursively up to ``max_cuts`` times (down to 1/2**max_cuts of the
        step); only then the curve ends. 0 disables the retries.
    progress : show a progress bar (default: option ``progress``).
    geometry : "nonlinear" (default: the large-motion engine, :mod:`homtex.contact.nl_compress`:
        co-rotational beams, IPC barrier contact that no yarn passes through, lagged Coulomb
        friction from ``contact.friction`` or the cell file's ``[contact]`` table, pseudo-transient
        continuation through buckling; yarns may rotate, buckle and slide) or "linear" (the
        small-rotation model, kept by name: linear beams, frictionless contact re-linearised per
        step; fast, and valid only for small motions: a curve that goes beyond the cell file's
        ``[validity] linear_strain_limit`` (where its stress leaves 10 % of the engine's; 0.18 %
        on spacer_20mm), or whose nodes turn by more than 0.1 rad, is "flagged").
    stabilize : must be 0 (the viscous stabilisation of the former co-rotational contact solve;
        the large-motion engine stabilises itself and records what that absorbs).

    Returns
    -------
    xarray.Dataset over ``strain`` (compression positive) with stress (kPa), force (N),
    plate_displacement (mm), active contacts (total, yarn-yarn, yarn-plate), max penetration
    (mm), contact iterations, linear solves, energies (N mm) and, with groups, ``group_energy``;
    with ``geometry="nonlinear"`` also ``external_work``, ``strain_energy``, ``contact_energy``,
    ``friction_energy``, ``stabilization_energy`` (N mm), ``energy_balance``, ``min_gap``,
    ``pile_force`` and ``attrs["first_buckling_strain"]``; ``attrs["geometry"]`` names the model.
    A failing step ends the curve: the steps before it are kept, ``attrs["status"]`` is
    "failed" and ``attrs["status_detail"]`` says why ("ok" otherwise; "flagged" for a complete
    nonlinear curve whose stabilisation or energy balance exceeds 1 % of the external work, or a
    linear curve beyond the linear model's validity).
    """
    frame, groups, info, spec = _frame_of(cell_or_frame)
    check_choice(control, "control", ("displacement", "force"))
    contact = Contact() if contact is None else contact
    if not isinstance(contact, Contact):
        raise InputError(f"contact must be a homtex.Contact, got {type(contact).__name__}")
    steps = check_int(steps, "steps", ge=1, le=100_000)
    check_choice(geometry, "geometry", GEOMETRIES)
    stabilize = check_number(stabilize, "stabilize", ge=0.0, lt=1.0)
    if stabilize != 0.0:
        raise InputError(f"stabilize = {stabilize!r}: the viscous stabilisation of the former co-rotational contact "
                         "solve is gone; geometry='nonlinear' stabilises itself (pseudo-transient continuation, its "
                         "absorbed energy recorded) - leave stabilize at 0")
    friction_spec = None
    if geometry == "linear":
        contact.require_frictionless("compress(geometry='linear')")
    else:
        _refuse_linear_options(solver=solver, tol=tol, contact=contact)
        if callable(spec) and contact.friction is None:
            friction_spec = spec()
    max_cuts = check_int(max_cuts, "max_cuts", ge=0, le=30)
    if maxiter is not None:
        maxiter = check_int(maxiter, "maxiter", ge=1, le=10 ** 6)
    if progress is not None and not isinstance(progress, (bool, np.bool_)):
        raise InputError(f"progress must be True or False, got {progress!r}")
    if thickness is not None:
        thickness = check_number(thickness, "thickness", gt=0.0, le=1e6)
    if area is not None:
        area = check_number(area, "area", gt=0.0, le=1e12)
    if fixed is not None and not isinstance(fixed, dict):
        raise InputError("fixed must be a dict node -> 'all' | [dofs] | {dof: value}")
    test = CompressionTest.build(frame, thickness=thickness, area=area, fixed=fixed, groups=groups, info=info)
    if control == "displacement":
        if pressure is not None:
            raise InputError("compress: 'pressure' is for control='force'; displacement control takes 'strain'")
        if strain is None:
            raise InputError("compress: 'strain' (final compression strain) is required for displacement control")
        targets = _targets(strain, steps, "strain")
        if np.any(targets >= 1.0):
            raise InputError(f"strain must stay below 1 (plates would meet), got max {targets.max()}")
    else:
        if pressure is None:
            raise InputError("compress: 'pressure' (kPa) is required for control='force'")
        if strain is not None:
            raise InputError("compress: 'strain' is for control='displacement'; force control takes 'pressure'")
        targets = _targets(pressure, steps, "pressure")
    ds = run_compression(test, targets, control=control, contact=contact, solver=option("compress_solver", solver),
                           tol=option("tol", tol), maxiter=maxiter, max_cuts=int(max_cuts),
                           progress=option("progress", progress), geometry=geometry, friction_spec=friction_spec,
                           validity=info.get("validity"))
    v = info.get("validity") or {}
    ds.attrs["mesh_convergence"] = (
        v["mesh_convergence"] if v.get("mesh_matches") else
        "not shown for this cell: its resolution or fabric differs from the one the cell file's mesh convergence "
        "was shown on" if v.get("mesh_cell") else "not shown for this cell (no [validity] mesh_convergence)")
    return ds


def solve_nonlinear(frame, fixed=None, loads=None, *, contact: Contact | None = None, plates=None,
                    prestrain: float | None = None, initial: NonlinearResult | None = None, control: str = "load",
                    steps: int = 10, tol: float | None = None, atol: float | None = None, max_iter: int | None = None,
                    max_cuts: int | None = None, geometric: str = "full", solver: str | None = None,
                    perturbation: float = 1e-2, arc_length: float | None = None, monitor=None,
                    progress: bool | None = None, rest=None, lattice=None) -> NonlinearResult:
    """Large-rotation static solve of a frame, following the load path; with ``contact`` the
    large-motion engine (yarns that touch, slide with friction and never pass through each other).

    The load factor lambda goes from 0 to 1 and scales the drivers of the path: the dead loads
    ``loads``, the prescribed motions of ``fixed``, the plates' motions and forces and (with the
    engine) the pre-strain ramp ``prestrain``.

    Parameters
    ----------
    frame : homtex.Frame, or a homtex Cell (its frame, and its ``[contact]`` friction table when
        ``contact.friction`` is None).
    fixed : supports: node -> "all" | [DOFs] (held) | {DOF: value} (prescribed at lambda = 1: mm, or
        rad as a spin about the fixed axis). With ``initial``, motions count from the initial state
        and held DOFs stay where it left them.
    loads : node -> (Fx, Fy, Fz, Mx, My, Mz), N and N mm (dead loads at lambda = 1). With ``initial``
        they are added to the loads acting in the initial state.
    contact : homtex.Contact: run the large-motion engine (co-rotational beams + IPC barrier between
        yarn surfaces and against the plates + lagged Coulomb friction + pseudo-transient
        continuation; every state intersection-free). None: frames without contact (the
        path-following solver with limit points, bifurcations and arc length).
    plates : homtex.Plate list (rigid planes normal to z): ``z`` the start height, ``displacement``
        its motion at lambda = 1 (mm) or ``force`` pressing it on the yarns at lambda = 1 (N). Needs
        the engine (``contact``; ``Contact()`` when plates are given alone). With ``initial`` and
        ``plates=None`` the initial state's plates stay where they are.
    prestrain : scale of the frame's pre-strain at lambda = 1 (engine): ramped from its current value
        (0 on a fresh solve when given; without it a fresh solve has the pre-strain acting in full
        from the start, and a continued one keeps its scale).
    initial : a NonlinearResult of an earlier engine solve on the same frame: continue from its state
        (positions, rotations, pre-strain scale, loads, plates, touching pairs, energy ledger); supports,
        loads and plates may be added or changed. Sewing then pressing is two calls.
    control : "load" (default) / "displacement": lambda in ``steps`` equal steps, cut and regrown
        as needed; "arclength" (frames without contact): Crisfield's arc length through limit points.
    steps : requested steps (>= 1); the engine halves a step that fails, or whose energy ledger does
        not close within 1 % of its work, up to ``max_cuts`` times.
    tol : equilibrium tolerance relative to the forces (default 1e-9 without contact, 1e-8 for the
        engine). atol : absolute tolerance (frames without contact). max_iter : Newton iterations
        per step (default 15; engine 80). max_cuts : halvings of a step (default 10).
    geometric, solver, perturbation, arc_length : see :func:`homtex.analysis.nonlinear.solve_nonlinear`
        (frames without contact).
    monitor : node indices whose displacements and forces the path records (default: the loaded
        nodes and those with prescribed motions).
    progress : progress reports of the engine (default: option ``progress``).
    rest : a :class:`homtex.RestState` (engine): the yarns' stress-free shape when it is not the
        frame's geometry, e.g. ``homtex.model.rest.straight_rest(frame)`` for knitted loops of a
        straight yarn; strain energies and their split count from it.
    lattice : a :class:`homtex.Lattice` (engine, periodic frames): lattice vectors as unknowns,
        held, prescribed (``motion``, mm at lambda = 1: a macro stretch) or free (zero average
        force: free lateral contraction, a cell relaxing to its own size), with dead forces on
        free components (``force``, N); the path records ``periods`` and ``lattice_force``.

    Returns
    -------
    NonlinearResult: ``u`` (n, 6), ``x`` (n, 3), ``reactions``, ``path`` (xarray Dataset over
    ``step``; with the engine also ``contact_energy``, ``friction_energy``, ``stabilization_energy``,
    ``external_work``, ``prestrain_work``, ``energy_balance``, ``plate_z`` and ``plate_force`` per
    plate, contacts; ``attrs["status"]`` "ok", or "flagged" with ``status_detail`` when the energy
    ledger is off by more than 1 % or the stabilisation took more than 1 % of the driven work) and,
    with the engine, ``state`` to continue from.

    Raises
    ------
    InputError for bad arguments or options the chosen solver does not have; SolverError for a step
    that fails at every size (with the engine its ``result`` attribute holds the path up to it).
    """
    cell = None if isinstance(frame, Frame) else frame
    fr = frame if cell is None else getattr(frame, "frame", None)
    if not isinstance(fr, Frame):
        raise InputError(f"frame must be a homtex.Frame or a homtex Cell, got {type(frame).__name__}")
    if initial is not None and not isinstance(initial, NonlinearResult):
        raise InputError(f"initial must be the NonlinearResult of an earlier solve, got {type(initial).__name__}")
    engine = contact is not None or plates is not None or prestrain is not None or rest is not None or \
        lattice is not None or (initial is not None and initial.state is not None)
    if not engine:
        if initial is not None:
            raise InputError("initial: this result comes from a solve without contact, which cannot be continued; "
                             "continue solves of the large-motion engine (contact=homtex.Contact())")
        with threads_for(fr.ndof):
            return _solve_frame(fr, fixed, loads, control=control, steps=steps, tol=1e-9 if tol is None else tol,
                                atol=atol, max_iter=15 if max_iter is None else max_iter,
                                max_cuts=10 if max_cuts is None else max_cuts, geometric=geometric, solver=solver,
                                perturbation=perturbation, arc_length=arc_length, monitor=monitor)
    contact = Contact() if contact is None else contact
    if not isinstance(contact, Contact):
        raise InputError(f"contact must be a homtex.Contact, got {type(contact).__name__}")
    check_choice(control, "control", CONTROLS)
    for name, value, what in (("control", control if control == "arclength" else None, "arc length"),
                              ("atol", atol, "an absolute tolerance"), ("arc_length", arc_length, "an arc length"),
                              ("solver", solver, "a choice of factorisation")):
        if value is not None:
            raise InputError(f"{name}={value!r}: the large-motion engine (contact) has no {what}; it steps the load "
                             "factor with control='load' or 'displacement' (leave the option out)")
    if geometric not in ("full", "consistent"):
        raise InputError(f"geometric must be 'full' for the large-motion engine, got {geometric!r}")
    if initial is not None and initial.state is None:
        raise InputError("initial: this result comes from a solve without contact; only engine solves continue")
    steps = check_int(steps, "steps", ge=1, le=100_000)
    settings = NonlinearSettings()
    if tol is not None:
        settings.tol = check_number(tol, "tol", gt=0.0, lt=1.0)
    if max_iter is not None:
        settings.max_iter = check_int(max_iter, "max_iter", ge=1, le=10_000)
    max_cuts = 10 if max_cuts is None else check_int(max_cuts, "max_cuts", ge=0, le=30)
    if prestrain is not None:
        prestrain = check_number(prestrain, "prestrain (scale of the frame's pre-strain)", ge=0.0, le=10.0)
        if not np.any(fr.prestrain != 0.0):
            raise InputError("prestrain: the frame has no pre-strain to scale (give the frame's elements a prestrain)")
    if monitor is not None:
        monitor = np.atleast_1d(np.asarray(monitor))
        if not np.issubdtype(monitor.dtype, np.integer) or monitor.ndim != 1 or \
                np.any((monitor < 0) | (monitor >= fr.n_nodes)):
            raise InputError(f"monitor must be node indices in 0..{fr.n_nodes - 1}, got {monitor!r}")
    spec = getattr(cell, "friction_spec", None) if cell is not None else None
    friction_spec = spec() if callable(spec) and contact.friction is None else None
    if lattice is not None and not isinstance(lattice, Lattice):
        raise InputError(f"lattice must be a homtex.Lattice, got {type(lattice).__name__}")
    if rest is not None and not isinstance(rest, RestState):
        raise InputError(f"rest must be a homtex.RestState, got {type(rest).__name__}")
    with threads_for(fr.ndof):
        return run_engine(fr, fixed, loads, contact=contact, plates=plates, steps=steps, prestrain=prestrain,
                          initial=None if initial is None else initial.state, friction_spec=friction_spec,
                          max_cuts=max_cuts, settings=settings, monitor=monitor,
                          progress=option("progress", progress), rest=rest, lattice=lattice)
