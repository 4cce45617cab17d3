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

from ..analysis.energy import ledger_check
from ..contact.engine import EngineStepper
from ..contact.incremental import IncrementalSolver, NonlinearSettings
from ..contact.ipc_system import serial_numba
from ..contact.lattice import Lattice
from ..contact.options import Contact
from ..errors import InputError, SolverError
from ..model.results import ENERGY_KEYS, ENERGY_LONG_NAMES, Status, set_status
from ..output.datasets import curve_dataset
from ..output.progress import Progress
from ..validate import check_choice, check_int, check_number
from .relax import RelaxedCell, cell_friction, knit_info, relax

log = logging.getLogger(__name__)

__all__ = ["DIRECTIONS", "tensile"]

DIRECTIONS = {"wale": 1, "course": 0}

META = {
    "force": ("N", "tensile force on the specimen (periodic cell: the force the cell carries across its boundary)"),
    "force_per_width": ("N/mm", "tensile force over the initial width"),
    "width": ("mm", "current width across the test direction"),
    "extension": ("mm", "extension of the gauge length"),
    "lateral_strain": ("1", "change of the width over the initial width"),
    **{k: ("N mm", ENERGY_LONG_NAMES[k] + ", from the yarns' rest state, total over the specimen")
       for k in ENERGY_KEYS},
    "contact_energy": ("N mm", "energy stored in the contacts (barrier and compressible shells)"),
    "friction_energy": ("N mm", "energy dissipated by friction since the start of the test"),
    "stabilization_energy": ("N mm", "energy taken out by the solver's pseudo-transient continuation since the start"),
    "external_work": ("N mm", "work of the grips / the macro stretch since the start of the test"),
    "energy_balance": ("1", "(external work - changes of strain and contact energy - friction - stabilisation) / the "
                            "largest of these magnitudes"),
    "max_filament_stress": ("MPa", "largest axial filament stress (tension)"),
    "max_fibre_stress": ("MPa", "largest filament stress, axial plus bending at the filament surface"),
    "max_axial_strain": ("1", "largest axial strain of any element"),
    "beyond_failure_stress": ("1", "a filament's axial stress is beyond the yarn's failure stress"),
    "active_contacts": ("1", "yarn-yarn segment pairs in contact"),
    "newton_iterations": ("1", "Newton iterations of the level"),
}


def filament_stresses(sol, info) -> tuple:
    """(axial stress (m,), axial + bending surface stress (m,)) of the filaments, MPa."""
    f = sol.frame
    F = sol.cor.forces
    axial = F[:, 6] / f.A
    EIy, EIz = f.E * f.Iy, f.E * f.Iz
    kap = np.maximum(np.hypot(F[:, 4] / EIy, F[:, 5] / EIz), np.hypot(F[:, 10] / EIy, F[:, 11] / EIz))
    return axial, axial + f.E * kap * info["yarn_model"]["filament_radius"]


class _Recorder:
    """Rows of a tensile test: one per reported level."""

    def __init__(self, sol, info, failure: float | None):
        self.sol, self.info, self.failure = sol, info, failure
        self.rows = {k: [] for k in META}
        self.rows["strain"] = []
        self.peak = []

    def add(self, strain, force, width, extension, width0, iters):
        sol, r = self.sol, self.rows
        L = sol.ledger
        E = sol.cor.energy
        ax, fib = filament_stresses(sol, self.info)
        vals = {"force": force, "force_per_width": force / width0, "width": width, "extension": extension,
                "lateral_strain": width / width0 - 1.0, **{k: float(E[:, j].sum()) for j, k in enumerate(ENERGY_KEYS)},
                "contact_energy": L["contact_energy"] + L["B0"], "friction_energy": L["dissipation"],
                "stabilization_energy": L["stabilization"], "external_work": L["external_work"],
                "energy_balance": sol.balance(), "max_filament_stress": float(ax.max()),
                "max_fibre_stress": float(fib.max()), "max_axial_strain": float(np.abs(ax / sol.frame.E).max()),
                "beyond_failure_stress": bool(self.failure is not None and ax.max() > self.failure),
                "active_contacts": int(sol.scene.pairs(sol._xc(sol.positions), hessian=False).n_active),
                "newton_iterations": int(iters)}
        r["strain"].append(strain)
        for k, v in vals.items():
            r[k].append(v)
        self.peak.append((int(np.argmax(ax)), float(ax.max())))

    def dataset(self, attrs) -> "object":
        n = len(self.rows["strain"])
        data = {k: ("strain", np.asarray(self.rows[k], dtype=bool if k == "beyond_failure_stress" else float)
                    .reshape(n), *META[k]) for k in META}
        coords = {"strain": (np.asarray(self.rows["strain"], dtype=float), "1", "extension over the gauge length")}
        return curve_dataset(data, coords, attrs)


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
    contact = Contact(friction=mu, compression=info["compression"])
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
    stepper = EngineStepper(sol, lambda lam: sol.solve(motion=lam, loads=1.0), max_cuts=10, refine=0.003)
    rec = _Recorder(sol, info, info["yarn_model"].get("failure_stress"))
    pos, ee, per = [], [], []
    rec.add(0.0, float(sol._react[sol.lat.rows[v], v]), width0, 0.0, width0, 0)
    if keep_positions:
        pos.append(sol.positions.copy())
        ee.append(sol.cor.energy.copy())
        per.append(sol.lat.periods.copy())
    bar = Progress(steps, "tensile levels", enabled=progress)
    status, detail = Status.OK, ""
    for k in range(1, steps + 1):
        try:
            stepper.advance(k / steps)
        except SolverError as err:
            status, detail = Status.FAILED, f"failed at strain {strain * k / steps:.4g} (step {k} of {steps}): {err}"
            log.warning("tensile: %s", detail)
            break
        tot = stepper.take_totals()
        react = sol._react
        P = sol.lat.periods
        rec.add(strain * k / steps, float(react[sol.lat.rows[v], v]), float(np.linalg.norm(P[w])),
                float(P[v, v] - L0), width0, tot["iterations"])
        if keep_positions:
            pos.append(sol.positions.copy())
            ee.append(sol.cor.energy.copy())
            per.append(sol.lat.periods.copy())
        bar.step()
    bar.close()
    attrs = _attrs(relaxed, info, "periodic cell, macro stretch with free lateral contraction", v, mu, L0, width0,
                   steps, sol, t0)
    attrs["take_down_released_Nmm"] = released
    ds = rec.dataset(attrs)
    if keep_positions:
        _positions(ds, pos, ee, per)
    return finish(ds, rec, status, detail, sol, info)


def settings(info, tol: float, **kw) -> NonlinearSettings:
    """Newton settings of the knit tests: compressible shells (many overlapping contacts) keep the
    exact Hessian where it is indefinite (``indefinite="shift"``)."""
    kw.setdefault("max_iter", 5000 if kw.get("stabilization") == "released" else 200)
    return NonlinearSettings(tol=tol, **kw)


def continue_from(relaxed: RelaxedCell, info, fixed, contact, lattice, tol: float = 1e-8, state=None
                  ) -> IncrementalSolver:
    """The engine on the cell's frame at the relaxed state (or ``state``, an EngineState of that
    frame: positions, rotations, lattice, the pairs touching at creation), the lattice's dead
    forces acting from the start, its ledger started afresh there."""
    sol = IncrementalSolver(relaxed.cell.frame, fixed, None, [], contact, rest=info["rest"], lattice=lattice,
                            settings=settings(info, tol), initial=relaxed.state if state is None else state)
    sol.delta = sol.s.delta0
    sol.load_scale = 1.0
    sol._start_ledger()
    return sol


def _let_go(relaxed: RelaxedCell, info, contact, free, tol) -> tuple:
    """(EngineState, energy released N mm): the relaxed cell with its take-down removed, the
    courses held at their relaxed length and the ``free`` lattice components free of force."""
    sol = IncrementalSolver(relaxed.cell.frame, {0: [0, 1, 2]}, None, [], contact, rest=info["rest"],
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


def _attrs(relaxed, info, what, v, mu, L0, width0, steps, sol, t0) -> dict:
    a = {"cell": relaxed.name, "specimen": what, "direction": "wale" if v == 1 else "course",
         "friction": mu, "gauge_length_mm": L0, "initial_width_mm": width0, "steps": int(steps),
         "loop_length_mm": relaxed.attrs["loop_length_mm"], "filaments": info["yarn_model"]["filaments"],
         "yarn_model": info["yarn_model"]["model"], "relax_protocol": relaxed.attrs["protocol"],
         "relax_status": relaxed.attrs["status"], "cpu_seconds": time.process_time() - t0,
         "energy_split": "strain energies per element of the co-rotational Timoshenko beam in its local frame: "
                         "bending_y about the section axis e2 (the yarn's material frame normal n1, parallel-"
                         "transported along it), bending_z about e3; shear is a term of its own (not complementary "
                         "to bending as in the paper's beams)"}
    fs = info["yarn_model"].get("failure_stress")
    if fs is not None:
        a["failure_stress_MPa"] = float(fs)
    return a


def _positions(ds, pos, ee, periods=None) -> None:
    """Node positions (strain, node, xyz), the energy split of every element (strain, element,
    mechanism) and (a periodic cell) the lattice vectors (strain, vector, xyz) into ds (in place)."""
    n = ds.sizes["strain"]
    if periods:
        ds["periods"] = (("strain", "vector", "xyz"), np.asarray(periods[:n]),
                         {"units": "mm", "long_name": "lattice vectors of the cell"})
    ds["x"] = (("strain", "node", "xyz"), np.asarray(pos[:n]), {"units": "mm", "long_name": "node positions"})
    ds["element_energy"] = (("strain", "element", "mechanism"), np.asarray(ee[:n]),
                            {"units": "N mm", "long_name": "strain energy of every element by mechanism"})
    ds.coords["xyz"] = ("xyz", np.array(["x", "y", "z"]), {"units": "1", "long_name": "coordinate"})
    ds.coords["mechanism"] = ("mechanism", np.array(ENERGY_KEYS), {"units": "1", "long_name": "energy term"})


def finish(ds, rec, status, detail, sol, info):
    """Status, the energy checks, the failure-stress strain and the peak's place; returns ds."""
    if status is Status.OK:
        check = ledger_check(ds.external_work.values, np.zeros(ds.sizes["strain"]), ds.stabilization_energy.values,
                             ds.energy_balance.values, ds.strain.values, level_name="strain", floor=sol.energy_floor)
        if check:
            status, detail = Status.FLAGGED, check
            log.warning("tensile: %s", check)
    set_status(ds, status, detail)
    beyond = np.flatnonzero(ds.beyond_failure_stress.values)
    ds.attrs["first_failure_strain"] = float(ds.strain[beyond[0]]) if len(beyond) else float("nan")
    k = int(np.argmax(ds.max_filament_stress.values))
    e, s = rec.peak[k]
    ds.attrs.update(peak_filament_stress_MPa=s, peak_strain=float(ds.strain[k]), peak_element=e,
                    peak_course=int(info["course"][e]), peak_filament=int(info["filament"][e]),
                    peak_axial_strain=float(s / float(sol.frame.E[e])))
    return ds
