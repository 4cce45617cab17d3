"""Relaxation of a weft-knit cell (``homtex.relax``): the generated loops of straight yarn let go.

Protocol (stated, because dry friction gives a set of possible rest shapes and the relaxation
path picks one): the cell of :mod:`homtex.geometry.knit_cell` starts from its generated geometry
with the yarns straight at rest; the large-motion engine minimises the yarns' bending, twist and
stretch with frictionless contact (compressible shells where the cell gives them: dry friction
would freeze an arbitrary intermediate of the generated geometry), then lets the relaxed state
settle with Coulomb friction (``friction``, default the cell file's), while the lattice is free in
the fabric plane (course and wale spacing and shear; a1 stays along x and the fabric in the xy plane) and a take-down
tension pulls along the wales: the paper's ``take_down`` (N, on its 5-needle specimen) per 5
needles of the cell. One node is held in translation (the cell floats
otherwise). The take-down acts from the start (a dead force on the wale lattice vector, as the
knitting machine's take-down holds the fabric while it forms), and the generated loops let go in
one quasi-static step: the energy the relaxation releases is what the solver takes out, and the
ledger counts it exactly (:class:`~homtex.contact.incremental.NonlinearSettings`
``stabilization="released"``: external work F x extension = released + stored changes).

A yarn of N filaments (``yarn_model.model = "filaments"``) first relaxes as its equivalent yarn
(one beam per course with the bundle's stiffness) whose contact radius holds the packed filaments
with room to spare (:func:`~homtex.geometry.knit_cell.bundle_axis`), frictionless with the same
lattice and take-down; the filaments are then laid around those relaxed axes at their generated
places in the section (:func:`~homtex.geometry.knit_cell.lay_bundles`) and released as above. The
ledger of the filament stage counts from the laid state (``start_*`` attrs; ``axis_*`` for the
axis stage).

The result is a :class:`RelaxedCell`: the relaxed frame (nodes at their relaxed positions, the
relaxed lattice, the rest state carried along), and ``attrs`` with the relaxed loop length, wale
and course spacing, loop height and width against the input, the protocol and the solve's figures:
``released_energy_Nmm`` (what the solver took out) equals the generated state's stored energy
minus the relaxed one's (``strain_energy_Nmm``, ``contact_energy_Nmm``, the generated contact
energy ``generated_contact_energy_Nmm``) plus the take-down's work ``take_down_work_Nmm``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from ..cache import cached
from ..contact.incremental import IncrementalSolver, NonlinearSettings
from ..contact.ipc_system import serial_numba
from ..contact.lattice import Lattice
from ..contact.options import Contact
from ..errors import InputError, SolverError
from ..geometry.knit_cell import bundle_axis, creation_overlaps, lay_bundles
from ..model.frame import Frame
from ..model.rest import RestState, straight_rest
from ..validate import check_int, check_number
from .stored import relaxed_dataset, relaxed_from_dataset

log = logging.getLogger(__name__)

__all__ = ["RelaxedCell", "relax"]

#: needles of the paper's specimen, over which its take-down tension acts
PAPER_NEEDLES = 5
#: NonlinearSettings.pattern_reach of a yarn of filaments: they settle into new contacts at nearly
#: every Newton iteration (the 20-filament rib: 589 pattern rebuilds in 700 iterations, 183 with 3)
FILAMENT_PATTERN_REACH = 3.0
#: NonlinearSettings.exact_retry of a yarn of filaments under test: a bundle's exact Hessian stays
#: indefinite over most iterations (filaments buckling on each other), so trying it first at each
#: wasted a factorisation (1.86 -> 1.12 per Newton iteration). Tests only: the relaxation gains
#: nothing by it and would settle in another state of its soft set (docs/knits.md)
FILAMENT_EXACT_RETRY = 8
#: Contact.parallel_sagitta of a yarn of filaments: two filaments of a bundle that cross at a small
#: angle are held apart by at most about kappa ghat / parallel_sagitta where the nodal form looks at
#: their elements' ends; at the lock-up the loops press them together harder than the default 0.3
#: allows and Newton stalls at the collision check (the 3-filament jersey at 14 %, the 20-filament
#: rib at 38 %); 0.02 and 0.005 give the same curve within 0.02 % (docs/knits.md)
FILAMENT_SAGITTA = 0.01


@dataclass
class RelaxedCell:
    """A relaxed weft-knit cell: ``cell`` (the source :class:`homtex.Cell`), ``frame`` (relaxed
    nodes and lattice, for pictures and VTK), ``rest`` (the yarns' rest state seen from it),
    ``state`` (the engine state on the cell's own frame that tests continue from: positions,
    rotations, lattice, the pairs touching at creation), ``attrs`` (loop length, wale and course
    spacing, loop height and width: relaxed and as generated, mm; the protocol), ``cell_rest``
    (the rest state on the cell's own frame that ``state`` belongs to: for laid filaments the one
    with their laid lengths; None: the cell's)."""

    cell: object
    frame: Frame
    rest: object
    state: object = None
    attrs: dict = field(default_factory=dict)
    cell_rest: object = None

    @classmethod
    def from_state(cls, cell, state, attrs: dict, cell_rest=None) -> "RelaxedCell":
        """The relaxed cell of ``cell`` at the engine ``state`` (on the cell's own frame, the rest
        state ``cell_rest`` or the cell's): its frame at the state's positions and lattice, the rest
        state seen from there."""
        frame = cell.frame
        base = cell.info["rest"] if cell_rest is None else cell_rest
        new = Frame(frame.nodes + state.ut, frame.elements, periods=state.periods.copy(), images=frame.images,
                    **frame.element_fields())
        return cls(cell=cell, frame=new, rest=base.moved(state.Q, frame.elements), state=state, attrs=attrs,
                   cell_rest=cell_rest)

    @property
    def rest_on_cell(self):
        """The yarns' rest state on the cell's own frame (:attr:`cell_rest`, else the cell's)."""
        return self.cell.info["rest"] if self.cell_rest is None else self.cell_rest

    @property
    def info(self) -> dict:
        return self.cell.info

    @property
    def name(self) -> str:
        return self.cell.name

    def cell_attrs(self) -> dict:
        return self.cell.attrs()


def knit_info(cell) -> dict:
    """The knit cell's info (InputError for cells of another generator)."""
    info = getattr(cell, "info", None)
    if not isinstance(info, dict) or "rest" not in info or "pattern" not in info:
        raise InputError(f"{getattr(cell, 'name', cell)!r} is not a weft-knit cell (generator 'weft_knit'); relax and "
                         "tensile take the cells of homtex.load_cell('cells/rib_1x1_eglass.toml') and the like")
    return info


def cell_friction(cell, friction) -> float:
    """The friction coefficient: ``friction``, else the cell file's [contact] friction, else 0."""
    if friction is not None:
        return check_number(friction, "friction", ge=0.0, le=10.0)
    return float(getattr(cell, "contact", {}).get("friction", 0.0))


def loop_measures(frame: Frame, x: np.ndarray, periods: np.ndarray, info: dict) -> dict:
    """Loop length (yarn length per stitch), wale spacing (between wales of one bed), course
    spacing, and the mean loop height and width (y and x extent of each knitted loop's yarn), mm."""
    pat = info["pattern"]
    rep = info["repeat"]
    course = info["course"]
    fil = info["filament"]
    el = frame.elements
    vec = x[el[:, 1]] + frame.images @ periods - x[el[:, 0]]
    L = np.linalg.norm(vec, axis=1)
    centre = fil == 0                  # the equivalent yarn, or the first (central) filament
    loop = float(L[centre].sum() / info["stitches"])
    beds = 2 if (np.any(pat.bed > 0) and np.any(pat.bed < 0)) else 1
    wales_per_bed = max(1, pat.n_needles * rep[0] // beds)
    hts, wds = [], []
    N = pat.n_needles * rep[0]
    for c in np.unique(course):
        e = np.flatnonzero((course == c) & centre)
        n = len(e)
        j = int(c) % pat.n_courses
        pts = x[el[e, 0]]
        # unwrap the chain so that a loop crossing the cell boundary stays whole
        steps = np.vstack([np.zeros(3), np.cumsum(vec[e][:-1], axis=0)])
        pts = pts[0] + steps
        for i in range(N):
            if pat.action[j, i % pat.n_needles] != "knit":
                continue
            seg = pts[int(i * n / N):int((i + 1) * n / N)]
            hts.append(np.ptp(seg[:, 1]))
            wds.append(np.ptp(seg[:, 0]))
    return {"loop_length": loop, "wale_spacing": float(np.linalg.norm(periods[0]) / wales_per_bed),
            "course_spacing": float(np.linalg.norm(periods[1]) / (pat.n_courses * rep[1])),
            "loop_height": float(np.mean(hts)), "loop_width": float(np.mean(wds))}


def relax(cell, *, friction=None, take_down: float = 0.06, max_iter: int = 5000, tol: float = 1e-8,
          cache: bool = True) -> RelaxedCell:
    """Relax a weft-knit cell (see the module docstring).

    Parameters
    ----------
    cell : a weft-knit :class:`homtex.Cell` (``homtex.load_cell("cells/rib_1x1_eglass.toml")``).
    friction : Coulomb coefficient between yarns (default: the cell file's ``[contact] friction``).
    take_down : take-down tension on the paper's 5-needle specimen, N (0.06 N in the paper), applied
        per 5 needles of the cell along the wales.
    max_iter : Newton iterations of the relaxation (it takes the generated loops far).
    tol : equilibrium tolerance, relative to the forces.
    cache : take the relaxed cell from the result cache (:mod:`homtex.cache`) where the same cell
        content was relaxed with the same arguments by the same homtex version, and store it there
        (False: always compute). ``attrs["cpu_seconds"]`` is the CPU of the computation that made it,
        ``attrs["from_cache"]`` says whether this call took it from the cache.

    Returns a :class:`RelaxedCell`; SolverError if the relaxation fails at every step size.
    """
    if isinstance(cell, RelaxedCell):
        return cell
    info = knit_info(cell)
    take_down = check_number(take_down, "take_down (N)", ge=0.0, le=1e6)
    mu = cell_friction(cell, friction)
    max_iter = check_int(max_iter, "max_iter", ge=1)
    tol = check_number(tol, "tol", gt=0.0, lt=1.0)
    if not cache:
        return _relax(cell, info, mu, take_down, max_iter, tol)
    box = {}

    def compute():
        box["relaxed"] = _relax(cell, info, mu, take_down, max_iter, tol)
        return relaxed_dataset(box["relaxed"])

    # the module's bundle settings are part of what determines the result
    params = {"friction": mu, "take_down": take_down, "max_iter": max_iter, "tol": tol,
              "filament_sagitta": FILAMENT_SAGITTA, "filament_pattern_reach": FILAMENT_PATTERN_REACH}
    ds = cached("relaxed", cell, params, compute)
    out = box["relaxed"] if "relaxed" in box else RelaxedCell.from_state(cell, *relaxed_from_dataset(cell, ds))
    out.attrs["from_cache"] = "relaxed" not in box
    return out


def _relax(cell, info, mu: float, take_down: float, max_iter: int, tol: float) -> RelaxedCell:
    """The relaxation of :func:`relax` (arguments checked)."""
    t0 = time.process_time()
    frame = cell.frame
    force = take_down * info["needles"] / PAPER_NEEDLES
    lat = Lattice(free=((0, 0), (1, 0), (1, 1)), force={(1, 1): force} if force > 0 else {})
    settings = NonlinearSettings(stabilization="released", max_iter=max_iter, tol=tol)
    # frictionless release (dry friction would freeze an arbitrary intermediate of the generated
    # geometry), then the state settles with the cell's friction (its contacts stick where they are)
    start, axis, rest0 = None, {}, info["rest"]
    if is_filament_bundle(info):
        settings.pattern_reach = FILAMENT_PATTERN_REACH
        start, rest0, axis = _axis_start(cell, frame, info, lat, settings)
    info = dict(info, rest=rest0)
    sol = _release(cell, frame, info, lat, settings, knit_contact(info, 0.0), start, restart=start is not None)
    iters = sol.info.iterations + axis.get("axis_newton_iterations", 0)
    stable = bool(sol.info.negative_eigenvalues == 0)
    if mu > 0:
        sol = _release(cell, frame, info, lat, settings, knit_contact(info, mu), sol.export_state())
        iters += sol.info.iterations
    x, P = sol.positions.copy(), sol.lat.periods.copy()
    energy = float(sol.cor.energy.sum())
    before = loop_measures(frame, frame.nodes, frame.periods, info)
    x0 = frame.nodes if start is None else frame.nodes + start.ut
    begun = loop_measures(frame, x0, frame.periods if start is None else start.periods, info)
    after = loop_measures(frame, x, P, info)
    attrs = {f"relaxed_{k}_mm": v for k, v in after.items()}
    attrs.update({f"generated_{k}_mm": v for k, v in before.items()})
    attrs.update({f"start_{k}_mm": v for k, v in begun.items()})
    attrs.update(axis)
    attrs.update(loop_length_mm=after["loop_length"], wale_spacing_mm=after["wale_spacing"],
                 course_spacing_mm=after["course_spacing"], input_loop_length_mm=float(info["loop_length"]),
                 friction=mu, take_down_N=float(take_down), take_down_on_cell_N=float(force),
                 protocol=(("filaments laid around the axes of their yarns relaxed as equivalent yarns of the "
                            "bundle's outer radius (frictionless, the same lattice and take-down), then "
                            if start is not None else "") +
                           "generated loops of straight yarn released frictionless with contact"
                           f"{' (compressible shells)' if info['compression'] is not None else ''}, lattice free in "
                           f"the fabric plane, take-down {take_down:g} N per {PAPER_NEEDLES} needles acting along "
                           f"the wales from the start, one node held; then settled with friction {mu:g}"),
                 status="ok" if abs(sol.balance()) <= 0.01 else "flagged",
                 released_energy_Nmm=float(sol.ledger["stabilization"]), energy_balance=float(sol.balance()),
                 take_down_work_Nmm=float(sol.ledger["external_work"]), newton_iterations=int(iters),
                 cpu_seconds=time.process_time() - t0, strain_energy_Nmm=energy,
                 contact_energy_Nmm=float(sol.ledger["contact_energy"] + sol.ledger["B0"]),
                 generated_contact_energy_Nmm=float(sol.ledger["B0"]) if start is None else float("nan"),
                 start_strain_energy_Nmm=float(sol.ledger["U0"]), start_contact_energy_Nmm=float(sol.ledger["B0"]),
                 stable=stable)
    log.info("relax %s: loop length %.4g mm (input %.4g), wale spacing %.4g mm, course spacing %.4g mm, %d Newton "
             "iterations, %.1f s CPU", cell.name, after["loop_length"], info["loop_length"], after["wale_spacing"],
             after["course_spacing"], attrs["newton_iterations"], attrs["cpu_seconds"])
    return RelaxedCell.from_state(cell, sol.export_state(), attrs, None if start is None else rest0)


def knit_contact(info, friction: float | None) -> Contact:
    """Contact options of a knit cell's engine runs: the cell's compressible shells, Coulomb
    ``friction`` and, for a yarn of filaments, the nodal form's crossing error cut to
    :data:`FILAMENT_SAGITTA`."""
    sag = FILAMENT_SAGITTA if is_filament_bundle(info) else Contact.parallel_sagitta
    return Contact(friction=friction, compression=info["compression"], parallel_sagitta=sag)


def is_filament_bundle(info) -> bool:
    """The cell's yarn is a bundle of more than one filament."""
    return info["yarn_model"]["model"] == "filaments" and info["yarn_model"]["filaments"] > 1


def _axis_start(cell, frame, info, lat, settings) -> tuple:
    """A filament cell's start: its yarns relaxed first as equivalent beams whose contact radius
    holds the packed filaments (cheap, and their bundles cannot interpenetrate), then every filament
    laid around its relaxed axis (:func:`~homtex.geometry.knit_cell.lay_bundles`). Releasing 20
    filaments per yarn straight from the generated loops ran out of 5000 Newton iterations (a soft
    mode of filaments settling on each other as the loops close); from relaxed axes they only settle
    into the crossings. Returns (EngineState on ``frame``, the filaments' RestState on ``frame``,
    attrs of the axis stage)."""
    yarn = cell.yarns[info["yarn_type"][int(frame.yarn[0])]]
    axis, nodes = bundle_axis(frame, info, yarn)
    sol = _release(cell, axis, dict(info, rest=straight_rest(axis)), lat, settings, Contact(friction=0.0), None)
    x, Q = lay_bundles(frame, info, axis, nodes, sol.positions, sol.lat.periods)
    laid = Frame(x, frame.elements, periods=sol.lat.periods, images=frame.images, **frame.element_fields())
    ov = creation_overlaps(laid)
    if ov["count"]:
        raise SolverError(f"relax {cell.name}: the filaments laid around the relaxed yarn axes overlap "
                          f"({ov['summary']}); the axes bend too sharply for their elements: use shorter "
                          "elements ([resolution] element_length)")
    # each filament axially unstrained where it is laid (rest length = laid length, as the generated
    # cell's rest lengths are its generated ones): a bundle laid as a solid section would carry
    # strains of curvature x offset (16 % on the outer filaments of a 20-filament rib's loops), which
    # real filaments shed by sliding along each other
    rest = RestState(length=laid.length.copy(), frames=info["rest"].frames.copy()).check(frame)
    template = IncrementalSolver(frame, {0: [0, 1, 2]}, None, [], Contact(friction=0.0), rest=rest,
                                 lattice=lat, settings=settings)
    start = template.export_state()
    start.ut, start.Q, start.periods = x - frame.nodes, Q, sol.lat.periods.copy()
    attrs = {"axis_contact_radius_mm": float(axis.contact_radius[0]),
             "axis_newton_iterations": int(sol.info.iterations),
             "axis_released_energy_Nmm": float(sol.ledger["stabilization"])}
    return start, rest, attrs


def _release(cell, frame, info, lat, settings, contact, initial, restart: bool = False) -> IncrementalSolver:
    """One quasi-static step from the generated (or an earlier) state to equilibrium with the
    take-down acting throughout; the ledger counts the energy released (continued: added to it;
    ``restart``: counted from ``initial``)."""
    sol = IncrementalSolver(frame, {0: [0, 1, 2]}, None, [], contact, rest=info["rest"], lattice=lat,
                            settings=settings, initial=initial)
    sol.load_scale = 1.0            # the take-down acts from the start: its work is F x the cell's extension
    if initial is None or restart:
        sol._start_ledger()
    else:
        sol._react = sol._reactions(sol._evaluate(sol.positions, [], hessian=False))
    with serial_numba(sol.small):
        try:
            sol.solve(loads=1.0)
        except SolverError as err:
            raise SolverError(f"relax {cell.name}: the generated loops did not reach equilibrium ({err})") from None
    return sol
