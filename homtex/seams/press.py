"""A sewn seam cell under the punch on the large-motion engine (the paper's Fig. 11 at yarn level).

The cell starts in its sewn state (:class:`~homtex.seams.sew.SewnSeam`): the thread is locked at
its sewn length (no more thread is fed once the seam is sewn: a tension-controlled stitch keeps
the tension it was sewn with until the punch slackens it) and cannot push (``slack_thread``: its
axial stiffness becomes a tension-only term, :func:`slack_stitch`; a leg the punch shortens goes
slack instead of buckling as a strut), two rigid plates are added to the
state, the bottom one under the lowest yarn surface and the top one at the UNSEAMED thickness
H0 above it (as the paper's curves and the macro layer start: one strain is one plate position,
strain = plate travel / H0), and the top plate descends through the given strain levels with the
engine's adaptive steps (:class:`~homtex.contact.engine.EngineStepper`). The sewn specimen's own
thickness is reported in attrs (``sewn_thickness_mm``): the plate meets it after
``first_contact_mm`` of travel.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import xarray as xr

from ..analysis.energy import LEDGER_META, ledger_check
from ..analysis.stepping import flag_force_drops
from ..contact.engine import PATH_STEPPING, EngineStepper
from ..contact.incremental import IncrementalSolver, NonlinearSettings
from ..contact.tension import TensionOnly
from ..errors import SolverError
from ..model.results import Status, set_status
from ..model.scene import Plate
from ..output.datasets import curve_dataset
from .sew import SEW_ITERATIONS, SOFT_AXIAL, SewnSeam, seam_supports

__all__ = ["press_sewn"]

log = logging.getLogger(__name__)

_META = {
    "plate_displacement": ("mm", "top plate travel from the unseamed thickness (20 mm for the shipped fabric)"),
    "force": ("N", "force of the cell on the top plate"),
    "stress": ("kPa", "compressive stress (force / cell area)"),
    "cushion_plate_contacts": ("1", "fabric nodes within the barrier's activation gap of the top plate"),
    "cushions_touched": ("1", "wale bins of the cushion that touch the top plate"),
    "stitch_plate_contacts": ("1", "stitch nodes within the barrier's activation gap of the top plate"),
    "active_yarn_yarn": ("1", "yarn-yarn segment pairs within the barrier's activation gap"),
    "leg_tension": ("N", "mean axial force of a stitch leg (two thread strands)"),
    "substeps": ("1", "engine steps the level needed (1: none; more after halving)"),
    **{k: LEDGER_META[k] for k in ("external_work", "strain_energy", "contact_energy", "friction_energy",
                                   "stabilization_energy", "energy_balance")},
}
_STRAIN = ("1", "compression strain: plate travel / unseamed thickness")


def slack_stitch(sol: IncrementalSolver, frame, info) -> TensionOnly:
    """Make the stitch of a sewn state a thread that cannot push: its elements' axial stiffness is
    handed to a :class:`~homtex.contact.tension.TensionOnly` term whose free lengths keep every
    element's present tension (an element in compression, or without force, gets its present
    length); their bending and torsion stay. Returns the term (added to ``sol``)."""
    m0 = int(info["fabric_elements"])
    el = np.arange(m0, frame.n_elements)
    x = sol.positions
    N = np.maximum(np.asarray(sol.cor.forces[el, 6], dtype=float), 0.0)
    EA = np.asarray(frame.EA, dtype=float)[el]
    v = x[frame.elements[el, 1]] + frame.shift[el] - x[frame.elements[el, 0]]
    term = TensionOnly(frame, el, EA, np.linalg.norm(v, axis=1) / (1.0 + N / EA))
    term.soften(sol.cor, SOFT_AXIAL)
    sol.add_term(term)
    return term


def press_sewn(sewn: SewnSeam, levels, *, thickness: float, max_cuts: int = 6, refine: float = 0.01,
               slack_thread: bool = True) -> xr.Dataset:
    """Press ``sewn`` between rigid plates through the strain ``levels`` (plate travel / ``thickness``
    H0, increasing, < 1; see the module docstring).

    Returns
    -------
    xarray.Dataset over ``strain`` (:data:`_META`: plate displacement, force, stress, plate contacts,
    cushions touched, stitch contacts, leg tension, the energy ledger); attrs status ("failed" with
    the levels before the failure kept; "flagged" when the ledger check fails), sewn_thickness_mm,
    first_contact_mm, area_mm2, cushion_height_mm, seconds, cpu_seconds.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    H0 = float(thickness)
    frame = sewn.locked_frame()
    info = sewn.info
    ut, Q = sewn.state_arrays()
    x = frame.nodes + ut
    rn = frame.node_radius
    z_lo = float((x[:, 2] - rn).min())
    z_hi = float((x[:, 2] + rn).max())
    ghat = sewn.contact.barrier_gap * float(frame.contact_radius.min())
    z_top0 = z_lo + max(H0, z_hi - z_lo) + ghat
    plates = [Plate(z=z_lo - ghat, normal=1, displacement=0.0, name="bottom"),
              Plate(z=z_top0, normal=-1, displacement=0.0, name="top")]
    fixed = seam_supports(frame, info)
    for k in np.atleast_1d(info["interlock_nodes"]):
        fixed[int(k)] = [0, 1]           # the plates hold the height now
    sol = IncrementalSolver(frame, fixed, None, plates, sewn.contact, friction_spec=sewn.friction_spec,
                            settings=NonlinearSettings(max_iter=SEW_ITERATIONS))
    sol.restart_at(ut, Q)
    if slack_thread:
        thread = slack_stitch(sol, frame, info)
    z_ref = z_lo + H0 + ghat            # the plate position of zero strain

    def solve(level):
        return sol.solve(plate_z={1: min(z_top0, z_ref - level * H0)})

    # measured on d = 18 mm to 70 %: the same stresses to 4 digits as without PATH_STEPPING, 22 % less
    # CPU, and no coarse tries at first contact whose rolled-back work left the ledger check
    # comparing a missing energy with the near-zero work done so far
    stepper = EngineStepper(sol, solve, max_cuts=max_cuts, refine=refine, **PATH_STEPPING)
    area = float(abs(np.cross(frame.periods[0], frame.periods[1])[2]))
    nf = int(info["fabric_nodes"])
    w = float(info["wale_spacing"])
    nb = int(round(float(info["seam_distance"]) * int(info.get("seams", 1)) / w))   # wale bins over the x period
    legs = np.asarray(info["legs"], dtype=bool)
    rows = {k: [] for k in ("strain", *_META)}
    status, detail = Status.OK, ""
    # until the top plate meets the specimen nothing loads it (no force, the state unchanged); a
    # solve there would face the specimen floating between the plates (held in z by nothing)
    free_until = max(0.0, H0 - (z_hi - z_lo)) / H0
    def leg_force() -> float:
        """Mean axial force of the legs (the thread term's where the stitch is slack-capable), N."""
        if not legs.any():
            return 0.0
        N = np.asarray(sol.cor.forces[:, 6], dtype=float).copy()
        if slack_thread:
            N[thread.elements] += thread.forces(sol.positions)
        return float(np.mean(N[legs]))

    legs_N = leg_force()
    yy = sewn.path.get("yarn_yarn_contacts")
    sewn_pairs = float(yy.values[-1]) if yy is not None and yy.size else np.nan
    for k, lv in enumerate(np.asarray(levels, dtype=float)):
        if lv <= free_until:
            vals = dict.fromkeys(_META, 0.0)
            vals.update(strain=float(lv), plate_displacement=float(lv) * H0, leg_tension=legs_N, substeps=0.0,
                        active_yarn_yarn=sewn_pairs)
            for key, v in vals.items():
                rows[key].append(v)
            continue
        if stepper.level < free_until:
            # the plate reaches the specimen's top without a solve (no force acts before), so no
            # step of the path is taken with the specimen floating
            sol.plates.z[1] = min(z_top0, z_ref - free_until * H0)
            stepper.level = free_until
        try:
            step = stepper.advance(float(lv))
        except SolverError as err:
            status = Status.FAILED
            detail = f"failed at strain {lv:.4g} (step {k + 1}, after {max_cuts} halvings): {err}"
            log.warning("seam_compression d = %g mm: %s", float(info["seam_distance"]), detail)
            break
        tot = stepper.take_totals()
        ev = step.extra["ev"]
        pl = ev["plates"]
        act = pl["active"][sol.scene.plate_index[pl["active"]] == 1]
        pn = sol.scene.plate_nodes[act]
        fab = pn[pn < nf]
        xr_ = sol.positions[fab, 0] - float(info["seam_x"])
        F = -float(pl["grad_plate"][1])
        L = sol.ledger
        vals = {"strain": float(lv), "plate_displacement": float(lv) * H0, "force": F, "stress": F / area * 1e3,
                "cushion_plate_contacts": len(fab),
                "cushions_touched": len(np.unique(np.mod(np.round(xr_ / w).astype(np.int64), nb))),
                "stitch_plate_contacts": int((pn >= nf).sum()), "active_yarn_yarn": ev["pairs"].n_active,
                "leg_tension": leg_force(), "substeps": tot["substeps"],
                "external_work": L["external_work"], "strain_energy": L["strain_energy"],
                "contact_energy": L["contact_energy"], "friction_energy": L["dissipation"],
                "stabilization_energy": L["stabilization"], "energy_balance": sol.balance()}
        for key, v in vals.items():
            rows[key].append(v)
        log.info("seam_compression d = %.4g mm: strain %.4g, force %.4g N (%.3g kPa), %d cushion bins touched, "
                 "%d sub-steps", float(info["seam_distance"]), float(lv), F, F / area * 1e3, vals["cushions_touched"],
                 tot["substeps"])
    data = {k: ("strain", np.asarray(v, dtype=float), *_META[k]) for k, v in rows.items() if k != "strain"}
    ds = curve_dataset(data, {"strain": (np.asarray(rows["strain"], dtype=float), *_STRAIN)})
    x_s, h_s = sewn.profile()
    ds.attrs.update(model="sewn seam cell between rigid plates (large-motion engine)", geometry="nonlinear",
                    thickness_mm=H0, sewn_thickness_mm=z_hi - z_lo, first_contact_mm=max(0.0, H0 - (z_hi - z_lo)),
                    area_mm2=area, seam_distance_mm=float(info["seam_distance"]),
                    cushion_height_mm=float(h_s.max()), seam_height_mm=float(h_s[int(np.argmin(np.abs(x_s)))]),
                    stitch=sewn.stitch, prestrain=float(sewn.prestrain), tension_N=float(sewn.tension),
                    seconds=time.perf_counter() - t0, cpu_seconds=time.process_time() - c0,
                    branch_switches=np.array(stepper.events, dtype=float).reshape(-1), n_nodes=int(frame.n_nodes))
    if status is Status.OK and len(rows["strain"]):
        check = ledger_check(ds.external_work.values, np.zeros(ds.sizes["strain"]), ds.stabilization_energy.values,
                             ds.energy_balance.values, ds.strain.values, level_name="strain", floor=sol.energy_floor,
                             friction_energy=ds.friction_energy.values)
        if check:
            status, detail = Status.FLAGGED, check
            log.warning("seam_compression: %s", check)
    set_status(ds, status, detail)
    return flag_force_drops(ds, what=f"seam_compression d = {float(info['seam_distance']):.4g} mm")
