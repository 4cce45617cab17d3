"""What a knit tensile test records (shared by the periodic cell and the finite specimen): the
variables and their units, the per-level recorder, the filament stresses, the Newton settings,
the Dataset's attributes and its final checks."""

from __future__ import annotations

import logging
import time

import numpy as np

from ..analysis.energy import ledger_check
from ..contact.engine import FRICTION_STEPPING, PATH_STEPPING
from ..contact.incremental import NonlinearSettings
from ..errors import SolverError
from ..model.results import ENERGY_KEYS, ENERGY_LONG_NAMES, Status, set_status
from ..output.datasets import curve_dataset
from ..output.progress import Progress
from .relax import FILAMENT_EXACT_RETRY, FILAMENT_PATTERN_REACH, is_filament_bundle

__all__ = ["META", "filament_stresses", "finish", "settings"]

log = logging.getLogger("homtex.knits.tensile")


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


def settings(info, tol: float, **kw) -> NonlinearSettings:
    """Newton settings of the knit tests: compressible shells (many overlapping contacts) keep the
    exact Hessian where it is indefinite (``indefinite="shift"``)."""
    # a bundle of filaments rearranges in snaps under load (each filament settling on its neighbours):
    # the 3-filament jersey's wale steps took 250-770 iterations and with 200 it failed at 4 %, with
    # 1000 it reaches 12 %, where the loops lock up (docs/knits.md)
    iters = 1000 if info["yarn_model"]["model"] == "filaments" else 200
    kw.setdefault("max_iter", 5000 if kw.get("stabilization") == "released" else iters)
    if is_filament_bundle(info):
        kw.setdefault("pattern_reach", FILAMENT_PATTERN_REACH)
        kw.setdefault("exact_retry", FILAMENT_EXACT_RETRY)
    return NonlinearSettings(tol=tol, **kw)


def stepping(info, friction: bool) -> dict:
    """Keyword arguments of the knit tests' :class:`~homtex.contact.engine.EngineStepper`: halvings
    for failures and for accuracy (a step whose stabilisation or imbalance exceeds 0.3 % of its
    work is redone in halves). Yarns of filaments get no halving for accuracy: a bundle settles in
    snaps of single filaments at every step size (with five halvings allowed the 20-filament rib's
    first 2 % level was not finished after 15 minutes of CPU, kept whole it passes in 92 s), so
    each level is kept once it converges and the energy its snaps release goes to the ledger, which
    flags the curve past 1 % of the work (docs/knits.md)."""
    kw = {"max_cuts": 10, "refine": 0.003, **(FRICTION_STEPPING if friction else PATH_STEPPING)}
    if is_filament_bundle(info):
        kw["max_refine"] = 0
    return kw


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
                             ds.energy_balance.values, ds.strain.values, level_name="strain", floor=sol.energy_floor,
                             friction_energy=ds.friction_energy.values)
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


def march(stepper, steps: int, strain: float, on_level, *, what: str, progress: bool) -> tuple:
    """Advance ``stepper`` through ``steps`` equal levels to ``strain``, calling
    ``on_level(strain_k, newton_iterations)`` after each; (Status, detail): FAILED with the level
    where a step failed at every size (the levels before it are recorded)."""
    bar = Progress(steps, f"{what} levels", enabled=progress)
    status, detail = Status.OK, ""
    for k in range(1, steps + 1):
        try:
            stepper.advance(k / steps)
        except SolverError as err:
            status, detail = Status.FAILED, f"failed at strain {strain * k / steps:.4g} (step {k} of {steps}): {err}"
            log.warning("%s: %s", what, detail)
            break
        on_level(strain * k / steps, stepper.take_totals()["iterations"])
        bar.step()
    bar.close()
    return status, detail
