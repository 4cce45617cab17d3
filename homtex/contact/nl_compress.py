"""Compression curves with large rotations, large-motion contact and friction
(``homtex.compress(..., geometry="nonlinear")``).

The cell lies between two rigid plates (:class:`~homtex.contact.compress.CompressionTest`),
both set back by the barrier's activation gap ghat so that the undeformed cell touches them at
zero force; the top plate moves down (displacement control) or carries a pressure (force
control: its height is an unknown). Every load level is reached by
:class:`~homtex.contact.incremental.IncrementalSolver` steps; a step whose pseudo-transient
stabilisation absorbs more than ``refine`` of the work done on it (a buckling or snap inside
the step), whose energy balance misses by more than ``refine`` of that work (too coarse for the
trapezoidal work) or that fails is redone as two half steps, recursively up to ``max_cuts`` levels. A
step that still fails ends the curve (status "failed", the levels before it kept); a curve
whose stabilisation absorbed more than 1 % of the external work, or whose energy balance is off
by more than 1 %, is complete but "flagged" (``attrs["status_detail"]`` says where).

The Dataset has the variables of the linear curve (stress, force, contacts, energies, ...)
and the energy bookkeeping of the large-motion engine: ``external_work``, ``strain_energy``,
``contact_energy``, ``friction_energy`` (dissipated), ``stabilization_energy`` (absorbed) and
``energy_balance``; ``attrs["first_buckling_strain"]`` is where the most compressed pile
element (group "pile", else any element) has lost half of its initial axial stiffness
(:func:`first_buckling_strain`).
"""

from __future__ import annotations

import logging
import time

import numpy as np
import xarray as xr

from ..analysis.energy import CHECK_LIMIT, LEDGER_META, ledger_check
from ..analysis.stepping import flag_force_drops
from ..errors import SolverError
from ..model.results import ENERGY_KEYS, ENERGY_LONG_NAMES, Status, set_status
from ..model.scene import Plate
from ..output.datasets import curve_dataset
from ..output.progress import Progress
from .engine import EngineStepper
from .incremental import IncrementalSolver, NonlinearSettings
from .options import Contact

__all__ = ["CHECK_LIMIT", "first_buckling_strain", "run_nonlinear_compression"]

log = logging.getLogger(__name__)

META = {
    "stress": ("kPa", "nominal compressive stress (top plate force / area)"),
    "force": ("N", "compressive force on the top plate"),
    "plate_displacement": ("mm", "downward displacement of the top plate"),
    "pressure": ("kPa", "applied pressure (force control) or measured stress"),
    "bottom_force": ("N", "compressive force on the bottom plate"),
    "active_contacts": ("1", "active contacts (yarn-yarn pairs + yarn-plate nodes) within the barrier gap"),
    "active_yarn_yarn": ("1", "yarn-yarn segment pairs within the barrier's activation gap"),
    "active_yarn_plate": ("1", "nodes within the barrier's activation gap of a plate"),
    "max_penetration": ("mm", "largest overlap (0: the barrier keeps every gap positive)"),
    "min_gap": ("mm", "smallest yarn-yarn or yarn-plate gap (surface to surface)"),
    "contact_iterations": ("1", "Newton iterations of the level (all its sub-steps and friction rounds)"),
    "linear_solves": ("1", "factorisations of the tangent at the level"),
    "substeps": ("1", "steps the level needed (1: none; more after halving)"),
    "newton_iterations": ("1", "Newton iterations of the level"),
    "friction_rounds": ("1", "friction lag rounds of the last step of the level"),
    "stabilization_force": ("N", "viscous force left in the converged state (0: the continuation term "
                                 "vanishes at equilibrium)"),
    "negative_eigenvalues": ("1", "negative eigenvalues of the Hessian of the total potential (0: stable)"),
    "pile_force": ("N", "largest compressive axial force of a pile element (group 'pile', else any element)"),
    "contact_energy": ("N mm", "barrier energy of the contacts (yarn-yarn and yarn-plate)"),
    "strain_energy": ("N mm", "strain energy of the beams minus its initial value"),
    "external_work": ("N mm", "work of the plates (and loads) on the cell, trapezoidal sum of force x motion"),
    "friction_energy": ("N mm", "energy dissipated by friction since the start"),
    "stabilization_energy": ("N mm", "energy absorbed by the pseudo-transient continuation since the start "
                                     "(sum du M du / delta)"),
    "prestrain_work": LEDGER_META["prestrain_work"],
    "energy_balance": LEDGER_META["energy_balance"],
    **{k: ("N mm", v) for k, v in ENERGY_LONG_NAMES.items()},
}
_STRAIN = ("1", "compression strain (plate displacement / initial plate distance)")


def first_buckling_strain(strain, pile_force, drop: float = 0.5) -> float:
    """Strain where the compressive force of the most loaded pile element has lost ``drop`` of
    its initial stiffness: d F / d strain <= (1 - drop) x its value over the first level (a
    straight strut loses all of it at its bifurcation; a bowed one softens gradually and halving
    marks its knee). Linear interpolation between levels; NaN if not reached."""
    e = np.r_[0.0, np.asarray(strain, dtype=float)]
    f = np.r_[0.0, np.asarray(pile_force, dtype=float)]
    if len(e) < 3 or not np.all(np.isfinite(f)):
        return float("nan")
    k = np.diff(f) / np.maximum(np.diff(e), 1e-300)
    k0 = k[0]
    if not k0 > 0:
        return float("nan")
    ratio = k / k0
    below = np.flatnonzero(ratio <= 1.0 - drop)
    if not below.size:
        return float("nan")
    i = int(below[0])
    if i == 0:
        return float(e[1])
    # slopes belong to interval midpoints: interpolate the crossing between them
    m0, m1 = 0.5 * (e[i - 1] + e[i]), 0.5 * (e[i] + e[i + 1])
    r0, r1 = ratio[i - 1], ratio[i]
    t = (r0 - (1.0 - drop)) / max(r0 - r1, 1e-300)
    return float(m0 + t * (m1 - m0))


class _Curve:
    """The solver, the top plate's control and the recorded levels of one curve."""

    def __init__(self, test, contact: Contact, control: str, friction_spec, settings, refine: float,
                 max_cuts: int):
        self.test, self.control, self.refine = test, control, refine
        frame = test.frame
        self.ghat = contact.barrier_gap * float(frame.contact_radius.min())
        self.z0 = test.z_lo + test.H0 + self.ghat
        top = (Plate(z=self.z0, normal=-1, force=0.0, name="top") if control == "force"
               else Plate(z=self.z0, normal=-1, displacement=0.0, name="top"))
        plates = [Plate(z=test.z_lo - self.ghat, normal=1, displacement=0.0, name="bottom"), top]
        self.sol = IncrementalSolver(frame, test.fixed, None, plates, contact, friction_spec=friction_spec,
                                     settings=settings)
        groups = test.groups
        self.pile = np.asarray(groups["pile"], dtype=bool) if "pile" in groups else np.ones(frame.n_elements, bool)
        self.masks = [np.asarray(m, dtype=bool) for m in groups.values()]
        self.names = list(groups)
        self.rows = {k: [] for k in ("strain", *META, "group_energy")}
        self.stepper = EngineStepper(self.sol, self._solve, max_cuts=max_cuts, refine=refine,
                                     on_accept=self._accepted)

    def _solve(self, level: float):
        if self.control == "displacement":
            return self.sol.solve(plate_z={1: self.z0 - level * self.test.H0})
        return self.sol.solve(plate_force={1: level * self.test.area * 1e-3})

    def _accepted(self, info):
        N = self.sol.cor.forces[:, 6]
        return self.sol.plates.z[1], float(max(0.0, -N[self.pile].min())) if self.pile.any() else 0.0

    @property
    def history(self):
        """(top plate height, pile force) of every accepted step."""
        return self.stepper.accepted

    def advance(self, level: float, depth: int, max_cuts: int):
        """Reach ``level`` (see :class:`~homtex.contact.engine.EngineStepper`)."""
        return self.stepper.advance(level, depth)

    def record(self, info, target: float):
        sol, test, r = self.sol, self.test, self.rows
        ev = info.extra["ev"]
        gp = ev["plates"]["grad_plate"]
        F_top, F_bot = -float(gp[1]), float(gp[0])
        w = self.z0 - float(sol.plates.z[1])
        r["strain"].append(w / test.H0)
        r["plate_displacement"].append(w)
        r["force"].append(F_top)
        r["stress"].append(F_top / test.area * 1e3)
        r["pressure"].append(target if self.control == "force" else F_top / test.area * 1e3)
        r["bottom_force"].append(F_bot)
        nyy = ev["pairs"].n_active
        nyp = len(ev["plates"]["active"])
        r["active_contacts"].append(nyy + nyp)
        r["active_yarn_yarn"].append(nyy)
        r["active_yarn_plate"].append(nyp)
        gaps = np.r_[ev["pairs"].gap, ev["plates"]["gap"]]
        r["min_gap"].append(float(gaps.min()) if gaps.size else np.inf)
        r["max_penetration"].append(max(0.0, -r["min_gap"][-1]))
        acc = self.stepper.take_totals()
        for key, name in (("iterations", "contact_iterations"), ("iterations", "newton_iterations"),
                          ("factorisations", "linear_solves"), ("substeps", "substeps")):
            r[name].append(acc[key])
        r["friction_rounds"].append(info.friction_rounds)
        r["stabilization_force"].append(0.0)
        r["negative_eigenvalues"].append(info.negative_eigenvalues)
        N = sol.cor.forces[:, 6]
        r["pile_force"].append(float(max(0.0, -N[self.pile].min())) if self.pile.any() else 0.0)
        L = sol.ledger
        r["contact_energy"].append(L["contact_energy"])
        r["strain_energy"].append(L["strain_energy"])
        r["external_work"].append(L["external_work"])
        r["prestrain_work"].append(L["prestrain_work"])
        r["friction_energy"].append(L["dissipation"])
        r["stabilization_energy"].append(L["stabilization"])
        r["energy_balance"].append(sol.balance())
        E = sol.cor.energy
        for j, k in enumerate(ENERGY_KEYS):
            r[k].append(float(E[:, j].sum()))
        tot = E.sum(axis=1)
        r["group_energy"].append([float(tot[mk].sum()) for mk in self.masks])


def _buckling(cv, test) -> float:
    """First buckling strain from every accepted step (finer than the reported levels)."""
    if not cv.history:
        return float("nan")
    h = np.array(cv.history)
    return first_buckling_strain((cv.z0 - h[:, 0]) / test.H0, h[:, 1])


def _checks(ds, floor: float = 0.0) -> str:
    """'' if the curve passes the energy checks, else what fails (and where)."""
    return ledger_check(ds["external_work"].values, ds["prestrain_work"].values, ds["stabilization_energy"].values,
                        ds["energy_balance"].values, ds["strain"].values, level_name="strain", floor=floor,
                        friction_energy=ds["friction_energy"].values if "friction_energy" in ds else None)


def run_nonlinear_compression(test, targets, *, control: str, contact: Contact, friction_spec: dict | None = None,
                              max_cuts: int = 4, progress: bool = False, settings: NonlinearSettings | None = None,
                              refine: float = 0.01, keep_positions: bool = False) -> xr.Dataset:
    """The compression curve of ``test`` (:class:`~homtex.contact.compress.CompressionTest`) through
    the levels ``targets`` (strains, or kPa under force control) with the large-motion engine.

    ``refine``: a step is redone in halves while its stabilisation absorbs more than this share
    of the work done on it (up to ``max_cuts`` levels). ``keep_positions``: also return the node
    positions ``x`` (strain, node, xyz; mm), the plate heights ``plate_z`` and the strain energy
    of every element ``element_energy`` (strain, element; N mm) at every level (pictures, VTK).
    Returns the Dataset described in the module docstring.
    """
    t0 = time.perf_counter()
    cv = _Curve(test, contact, control, friction_spec, settings, refine, max_cuts)
    bar = Progress(len(targets), "compression steps", enabled=progress)
    status, detail = Status.OK, ""
    for k, target in enumerate(targets):
        try:
            info = cv.advance(float(target), 0, max_cuts)
        except SolverError as err:
            label = f"strain {target:.4g}" if control == "displacement" else f"pressure {target:.4g} kPa"
            status = Status.FAILED
            detail = f"failed at step {k + 1} ({label}, also after halving the step {max_cuts} times): {err}"
            log.warning("compress: %s", detail)
            break
        cv.record(info, float(target))
        if keep_positions:
            cv.rows.setdefault("x", []).append(cv.sol.positions.copy())
            cv.rows.setdefault("plate_z", []).append(cv.sol.plates.z.copy())
            cv.rows.setdefault("element_energy", []).append(cv.sol.cor.energy.sum(axis=1))
        bar.step(f"{cv.rows['substeps'][-1]} sub-steps" if cv.rows["substeps"][-1] > 1 else "")
    bar.close()
    rows = cv.rows
    n = len(rows["strain"])
    data = {k: ("strain", np.asarray(rows[k], dtype=float), *META[k]) for k in META}
    coords = {"strain": (np.asarray(rows["strain"], dtype=float), *_STRAIN)}
    if cv.names:
        ge = np.asarray(rows["group_energy"], dtype=float).reshape(n, len(cv.names))
        data["group_energy"] = (("strain", "group"), ge, "N mm", "strain energy per element group")
        coords["group"] = (np.array(cv.names, dtype=str), "1", "element group")
    if keep_positions:
        m = test.frame.n_elements
        data["x"] = (("strain", "node", "xyz"), np.asarray(rows.get("x", []), dtype=float).reshape(n, -1, 3), "mm",
                     "node positions")
        data["plate_z"] = (("strain", "plate"), np.asarray(rows.get("plate_z", []), dtype=float).reshape(n, 2), "mm",
                           "plate heights (bottom, top)")
        data["element_energy"] = (("strain", "element"), np.asarray(rows.get("element_energy", []),
                                                                    dtype=float).reshape(n, m), "N mm",
                                  "strain energy of every element")
        coords["xyz"] = (np.array(["x", "y", "z"]), "1", "coordinate")
    ds = curve_dataset(data, coords)
    sol = cv.sol
    ds.attrs.update(
        control=control, geometry="nonlinear", engine="large-motion contact (IPC barrier, lagged friction, PTC)",
        thickness_mm=test.H0, area_mm2=test.area, area_source=test.area_source, bottom_plate_z_mm=test.z_lo - cv.ghat,
        top_plate_z_mm=cv.z0, barrier_gap_mm=sol.ghat, barrier_stiffness_N_per_mm=sol.kappa,
        friction_slip_mm=sol.eps_v, friction_max=float(max(sol.scene.mu_table.max(initial=0.0),
                                                            sol.scene.mu_plate.max(initial=0.0))),
        friction_source=("Contact(friction=...)" if contact.friction is not None or friction_spec is None
                         else "cell file [contact] table"),
        initial_touching_pairs=sol.scene.initial_touching, supports=str(test.fixed),
        steps_requested=int(len(targets)), refine=float(refine), max_cuts=int(max_cuts),
        first_buckling_strain=_buckling(cv, test),
        first_buckling_criterion="the most compressed pile element's axial force has lost half of its initial "
                                 "stiffness (d F / d strain <= 0.5 x its first value)",
        seconds=time.perf_counter() - t0, searches=int(sol.scene.searches))
    if status is Status.OK:
        check = _checks(ds, sol.energy_floor)
        if check:
            status, detail = Status.FLAGGED, check
            log.warning("compress: %s", check)
    set_status(ds, status, detail)
    ds.attrs["steps_done"] = int(n)
    if control == "displacement":
        flag_force_drops(ds, what="compress", model="nonlinear")
    return ds
