"""Tensile tests of weft-knitted fabrics (``homtex.tensile``): the periodic cell under a macro
stretch with free lateral contraction, or a finite specimen between grips.

Both start from the relaxed cell (:func:`homtex.relax`; its protocol is in the result's attrs).
The periodic cell: the lattice vector along the test direction (wales: a2, y; courses: a1, x) is
stretched by ``strain`` x its relaxed length in ``steps`` levels, the other in-plane components
are free (zero average force: lateral contraction and shear), one node is held in translation.
Along the wales the relaxation's take-down stays with the stretched vector (the force starts at
it); along the courses the take-down is let go first (the wales then carry no force; the energy
that releases is ``take_down_released_Nmm`` in the attrs) and the gauge length is the cell's
length after that.
The force is the generalised force on the stretched component, the force the cell carries across
its boundary (N per cell); divided by the relaxed cell width it is the fabric's force per unit
width (N/mm). A finite specimen (:mod:`.specimen`) is pulled by its top grip.

The Dataset over ``strain`` (extension / gauge length): ``force`` (N), ``force_per_width`` (N/mm,
over the initial width), ``width`` (mm, current), ``extension`` (mm), the strain energy split
``axial``, ``torsion``, ``bending_y``, ``bending_z``, ``shear`` and ``contact_energy`` (N mm,
stored energies counted from the yarns' straight rest state and from no contact), the ledger from
the start of the test (``external_work``, ``friction_energy``, ``stabilization_energy``,
``energy_balance``: :mod:`homtex.analysis.energy`), ``max_filament_stress`` (MPa, the largest axial
filament stress, as the paper reports it) and ``max_fibre_stress`` (MPa, axial plus bending at the
filament's surface), with ``attrs["status"]``. Filament stresses beyond the yarn's failure stress
(``[parameters.yarn_model] failure_stress``) are flagged per level (``beyond_failure_stress``) and
the first such strain is in the attrs; the test goes on (the paper's model had no failure either).
"""

from __future__ import annotations

import logging
import time

import numpy as np

from ..contact.engine import EngineStepper
from ..contact.incremental import IncrementalSolver
from ..contact.ipc_system import serial_numba
from ..contact.lattice import Lattice
from ..errors import InputError, SolverError
from ..validate import check_choice, check_int, check_number
from .record import _attrs, _positions, _Recorder, finish, march, settings, stepping
from .relax import RelaxedCell, cell_friction, knit_contact, knit_info, relax

log = logging.getLogger(__name__)

__all__ = ["DIRECTIONS", "tensile"]

DIRECTIONS = {"wale": 1, "course": 0}


def tensile(cell, *, strain, direction: str = "wale", specimen="cell", steps: int | None = None, friction=None,
            progress: bool = False, keep_positions: bool = False, tol: float = 1e-8):
    """Tensile test of a weft-knit cell (see the module docstring).

    Parameters
    ----------
    cell : a weft-knit :class:`homtex.Cell` (relaxed first with :func:`homtex.relax`) or a
        :class:`~homtex.knits.relax.RelaxedCell`.
    strain : final extension over the gauge length (> 0, <= 2).
    direction : "wale" (along the wales, a2) or "course" (along the courses, a1).
    specimen : "cell" (the periodic cell, free lateral contraction) or (wales, courses) of a finite
        specimen between grips.
    steps : reported levels (default one per 1 % of strain, at least 10).
    friction : Coulomb coefficient between yarns (default the cell file's).
    keep_positions : also return node positions ``x`` (strain, node, xyz), the strain energy of
        every element ``element_energy`` (strain, element, mechanism) and, for the periodic cell, the
        lattice vectors ``periods`` (strain, vector, xyz) for pictures and VTK.
    tol : equilibrium tolerance, relative to the forces (Newton).

    Returns the Dataset described in the module docstring.
    """
    check_choice(direction, "direction", tuple(DIRECTIONS))
    strain = check_number(strain, "strain", gt=0.0, le=2.0)
    tol = check_number(tol, "tol", gt=0.0, lt=1.0)
    steps = max(10, int(np.ceil(strain / 0.01))) if steps is None else check_int(steps, "steps", ge=1, le=100_000)
    relaxed = cell if isinstance(cell, RelaxedCell) else relax(cell, friction=friction)
    info = knit_info(relaxed.cell)
    mu = cell_friction(relaxed.cell, friction)
    if isinstance(specimen, str):
        if specimen != "cell":
            raise InputError(f"specimen must be 'cell' or (wales, courses), got {specimen!r}")
        return _cell_test(relaxed, info, strain, DIRECTIONS[direction], steps, mu, progress, keep_positions, tol)
    try:
        wales, courses = (int(v) for v in specimen)
    except (TypeError, ValueError):
        raise InputError(f"specimen must be 'cell' or (wales, courses) of a finite specimen, got "
                         f"{specimen!r}") from None
    from .specimen import specimen_test

    return specimen_test(relaxed, info, wales, courses, strain, DIRECTIONS[direction], steps, mu, progress,
                         keep_positions, tol)


def _cell_test(relaxed: RelaxedCell, info, strain, v, steps, mu, progress, keep_positions, tol):
    t0 = time.process_time()
    w = 1 - v
    free = [(0, 0), (1, 0), (1, 1)]
    free.remove((v, v))
    contact = knit_contact(info, mu)
    # pulled along the wales, the stretch carries the relaxation's take-down (the force starts at
    # it); pulled along the courses, the wales carry no force: the take-down is let go first, the
    # courses held at their relaxed length (the energy that releases is counted in the attrs)
    state, released = relaxed.state, 0.0
    if v == 0 and relaxed.attrs["take_down_on_cell_N"] > 0:
        state, released = _let_go(relaxed, info, contact, ((0, 0), (1, 0), (1, 1)), tol)
    P0 = state.periods.copy()
    L0, width0 = float(P0[v, v]), float(np.linalg.norm(P0[w]))
    lat = Lattice(free=tuple(free), motion={(v, v): strain * L0})
    sol = continue_from(relaxed, info, {0: [0, 1, 2]}, contact, lat, tol, state=state)
    stepper = EngineStepper(sol, lambda lam: sol.solve(motion=lam, loads=1.0),
                            **stepping(info, sol.scene.has_friction))
    rec = _Recorder(sol, info, info["yarn_model"].get("failure_stress"))
    pos, ee, per = [], [], []
    rec.add(0.0, float(sol._react[sol.lat.rows[v], v]), width0, 0.0, width0, 0)
    if keep_positions:
        pos.append(sol.positions.copy())
        ee.append(sol.cor.energy.copy())
        per.append(sol.lat.periods.copy())
    def level(s, iters):
        P = sol.lat.periods
        rec.add(s, float(sol._react[sol.lat.rows[v], v]), float(np.linalg.norm(P[w])), float(P[v, v] - L0), width0,
                iters)
        if keep_positions:
            pos.append(sol.positions.copy())
            ee.append(sol.cor.energy.copy())
            per.append(sol.lat.periods.copy())

    status, detail = march(stepper, steps, strain, level, what="tensile", progress=progress)
    attrs = _attrs(relaxed, info, "periodic cell, macro stretch with free lateral contraction", v, mu, L0, width0,
                   steps, sol, t0)
    attrs["take_down_released_Nmm"] = released
    ds = rec.dataset(attrs)
    if keep_positions:
        _positions(ds, pos, ee, per)
    return finish(ds, rec, status, detail, sol, info)


def continue_from(relaxed: RelaxedCell, info, fixed, contact, lattice, tol: float = 1e-8, state=None
                  ) -> IncrementalSolver:
    """The engine on the cell's frame at the relaxed state (or ``state``, an EngineState of that
    frame: positions, rotations, lattice, the pairs touching at creation), the lattice's dead
    forces acting from the start, its ledger started afresh there."""
    sol = IncrementalSolver(relaxed.cell.frame, fixed, None, [], contact, rest=relaxed.rest_on_cell, lattice=lattice,
                            settings=settings(info, tol), initial=relaxed.state if state is None else state)
    sol.delta = sol.s.delta0
    sol.load_scale = 1.0
    sol._start_ledger()
    return sol


def _let_go(relaxed: RelaxedCell, info, contact, free, tol) -> tuple:
    """(EngineState, energy released N mm): the relaxed cell with its take-down removed, the
    courses held at their relaxed length and the ``free`` lattice components free of force."""
    sol = IncrementalSolver(relaxed.cell.frame, {0: [0, 1, 2]}, None, [], contact, rest=relaxed.rest_on_cell,
                            lattice=Lattice(free=free), settings=settings(info, tol, stabilization="released"),
                            initial=relaxed.state)
    before = float(sol.ledger["stabilization"])
    with serial_numba(sol.small):
        try:
            sol.solve(motion=0.0)
        except SolverError as err:
            raise SolverError(f"tensile {relaxed.name}: the relaxed cell did not settle without its take-down "
                              f"({err})") from None
    return sol.export_state(), float(sol.ledger["stabilization"]) - before


