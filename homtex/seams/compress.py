"""A seamed spacer fabric between two rigid plates at the yarn level (the paper's Fig. 11):
``seam_compression``.

By default the seam cell is sewn on the large-motion engine (:func:`homtex.seams.profile.sewn_seam`,
cached) and pressed from its sewn state (:func:`homtex.seams.press.press_sewn`): the plate starts
at the unseamed thickness, strain = plate travel / unseamed thickness, as in ``compress`` and
``macro_curve``. ``geometry="linear"`` runs the former small-rotation seam cell
(:func:`linear_seam_compression`: frictionless, contact re-linearised per step, strain from the
sewn thickness), kept for comparison."""

from __future__ import annotations

import logging
import time

import numpy as np
import xarray as xr

from ..analysis.static import element_state
from ..analysis.stepping import StepFailure, flag_force_drops, march
from ..api import compress
from ..cells import Cell
from ..contact.options import Contact
from ..contact.solver import ContactSolver
from ..errors import InputError, SolverError
from ..geometry.seam import seam_cell
from ..model.results import Status, set_status
from ..model.scene import Plate
from ..output.datasets import curve_dataset
from ..validate import check_choice, check_int, check_number
from .foundation import seam_table
from .measure import measure_profile
from .press import press_sewn
from .profile import sewn_seam
from .yarn import SeamSolver

__all__ = ["SlackThreads", "linear_seam_compression", "seam_compression", "strain_levels"]

log = logging.getLogger(__name__)

_META = {"plate_displacement": ("mm", "top plate displacement from first contact"),
         "force": ("N", "plate force on the seam cell"),
         "stress": ("kPa", "compression stress (force / cell area)"),
         "cushion_plate_contacts": ("1", "active contacts between fabric nodes and the top plate"),
         "cushions_touched": ("1", "wale bins of the cushion that touch the top plate"),
         "stitch_plate_contacts": ("1", "active contacts between the needle thread and the top plate"),
         "active_contacts": ("1", "active contacts (yarn-yarn and yarn-plate)"),
         "slack_stitch_elements": ("1", "stitch elements gone slack (tension-only thread)")}
_STRAIN = ("1", "compression strain (plate displacement / sewn thickness H0)")


def strain_levels(strain: float, steps: int) -> np.ndarray:
    """The plate positions of an engine curve to ``strain`` in ``steps`` equal steps (strain = travel /
    unseamed thickness), with the first step split in four (the unseamed pile buckles within the
    first per cent). To 70 % in 35 steps these are the levels of
    studies/experiments/spacer_engine_defaults.py; split in five, the unseamed spacer cell's curve
    failed to converge at 68 % (also with 400 iterations per step), a path the engine does not follow."""
    e = float(strain) * np.arange(1, int(steps) + 1) / int(steps)
    return np.unique(np.round(np.r_[e[0] * np.arange(1, 4) / 4.0, e], 12))


def seam_compression(cell: Cell, *, seam_distance: float | None, strain: float = 0.7, steps: int | None = None,
                     geometry: str = "nonlinear", prestrain: float | None = None, tension: float | None = None,
                     contact: Contact | None = None, ramp_steps: int | None = None, cache: bool = True,
                     **options) -> xr.Dataset:
    """Yarn-level compression of a seamed spacer fabric under the punch (the paper's Fig. 11).

    Parameters
    ----------
    cell : spacer Cell with [parameters.seam].
    seam_distance : d, mm (rounded to whole fabric repeats); None: the unseamed cell
        (``homtex.compress(cell, geometry="nonlinear")`` on the same plate positions).
    strain : final plate travel / unseamed thickness, in (0, 1) (the paper's test: 0.7).
    steps : plate steps (default 35, 2 % each, the first split in five); the engine halves a step
        that fails or whose energy ledger misses.
    geometry : "nonlinear" (the large-motion engine, friction from the cell file) or "linear" (the
        former small-rotation seam cell, :func:`linear_seam_compression`, which takes ``options``
        tension_only and whose strain counts from the sewn thickness).
    prestrain, tension : the stitch (see ``seam_profile``; None: the calibrated one).
    contact : homtex.Contact (default: the cell file's friction).
    ramp_steps : levels of the sewing ramp (default the cell file's ``ramp_steps``).
    cache : reuse a sewn state from the result cache (:mod:`homtex.cache`).

    Returns
    -------
    xarray.Dataset over ``strain`` (plate travel / unseamed thickness) with ``stress`` (kPa),
    ``force`` (N on the cell), ``plate_displacement`` (mm), plate and stitch contacts, the
    leg tension and the energy ledger; attrs status, thickness_mm (unseamed), sewn_thickness_mm,
    first_contact_mm, cushion_height_mm, area_mm2, seconds.
    """
    check_choice(geometry, "geometry", ("linear", "nonlinear"))
    strain = check_number(strain, "strain", gt=0.0, lt=1.0)
    if geometry == "linear":
        if tension is not None:
            raise InputError("seam_compression(geometry='linear') takes prestrain=, not tension=")
        return linear_seam_compression(cell, seam_distance=seam_distance, strain=strain,
                                       steps=30 if steps is None else steps, prestrain=prestrain, contact=contact,
                                       ramp_steps=4 if ramp_steps is None else ramp_steps, **options)
    if options:
        raise InputError(f"seam_compression(geometry='nonlinear'): unknown option(s) {sorted(options)}")
    steps = check_int(35 if steps is None else steps, "steps", ge=1, le=10_000)
    if contact is not None and not isinstance(contact, Contact):
        raise InputError(f"contact must be a homtex.Contact, got {type(contact).__name__}")
    levels = strain_levels(strain, steps)
    H0 = float(cell.info["thickness"])
    t0 = time.perf_counter()
    if seam_distance is None:
        ds = compress(cell, strain=levels, geometry="nonlinear", contact=contact)
        ds.attrs.update(seam_distance_mm="none", model="unseamed fabric cell (homtex.compress, large-motion engine)",
                        cushion_height_mm=H0, sewn_thickness_mm=H0, first_contact_mm=0.0)
        return ds
    check_number(seam_distance, "seam_distance", gt=0.0, le=1e4)
    sewn = sewn_seam(cell, seam_distance=seam_distance, prestrain=prestrain, tension=tension, contact=contact,
                     steps=ramp_steps, cache=cache)
    if sewn.status == "failed" and sewn.state is None:
        raise SolverError(f"seam_compression: the seam could not be sewn: {sewn.detail}")
    ds = press_sewn(sewn, levels, thickness=H0)
    ds.attrs.update(sewn_status=sewn.status, sewn_seconds=float(sewn.attrs.get("seconds", 0.0)),
                    seconds_total=time.perf_counter() - t0)
    if sewn.status != "ok":
        set_status(ds, Status.FAILED if sewn.status == "failed" else Status(ds.attrs["status"]),
                   f"the sewing ramp {sewn.status}: {sewn.detail}")
    return ds


def linear_seam_compression(cell: Cell, *, seam_distance: float | None, strain: float = 0.3, steps: int = 30,
                            prestrain: float | None = None, contact: Contact | None = None, ramp_steps: int = 4,
                            tension_only: bool = True) -> xr.Dataset:
    """Compression of the geometrically linear seam cell between two rigid plates (kept for comparison).

    The seam cell (:func:`homtex.geometry.seam.seam_cell`) is first brought to its sewn state (the
    stitch pre-strain ramped as in :func:`linear_profile`, plates far away); then both plates are
    moved onto the outermost yarn surfaces (stitch included) and the top plate descends by
    ``strain`` x H0 in ``steps`` equal steps, H0 = the sewn specimen's thickness (initial plate
    distance). Stitch pre-strain stays on. Contact geometry is re-linearised per step.

    Parameters
    ----------
    cell : spacer Cell with [parameters.seam].
    seam_distance : d, mm (rounded to whole fabric repeats); None: the unseamed fabric
        (``homtex.compress`` on the fabric cell with the same contact options).
    strain : final compression (plate displacement / H0), 0 < strain < 1.
    steps : plate steps. The contact geometry is re-linearised per step, so the curve depends on
        them: on the d = 24 mm cell to 30 % the default 30 steps are within 1 % of 60, 15 steps
        5 %, 8 steps 12 % - and slower, because too-large steps fail and are halved.
    prestrain : eps0 (None: ``[parameters.seam] prestrain``).
    tension_only : the stitch thread cannot carry compression (default): elements that would be
        shortened below their rest length go slack during the compression (see ``SlackThreads``).

    Returns
    -------
    xarray.Dataset over ``strain`` (plate displacement / H0): plate_displacement (mm), force (N on the
    cell), stress (kPa, force / cell area), cushion_plate_contacts (active top-plate contacts with
    fabric nodes), cushions_touched (wale bins of the cushion profile that touch the top plate),
    stitch_plate_contacts, active_contacts; attrs status (and status_detail), thickness_mm (H0), area_mm2,
    seam_distance_mm, cushion_height_mm (of the sewn state), seconds.
    """
    strain = check_number(strain, "strain", gt=0.0, lt=1.0)
    steps = check_int(steps, "steps", ge=1, le=10_000)
    ramp_steps = check_int(ramp_steps, "ramp_steps", ge=1, le=10_000)
    if seam_distance is not None:
        check_number(seam_distance, "seam_distance", gt=0.0, le=1e4)
    if prestrain is not None:
        check_number(prestrain, "prestrain", ge=0.0, lt=1.0)
    if not isinstance(tension_only, (bool, np.bool_)):
        raise InputError(f"tension_only must be True or False, got {tension_only!r}")
    if contact is not None and not isinstance(contact, Contact):
        raise InputError(f"contact must be a homtex.Contact, got {type(contact).__name__}")
    t0 = time.perf_counter()
    if seam_distance is None:
        ds = compress(cell, strain=strain, steps=steps, contact=Contact() if contact is None else contact,
                      geometry="linear")
        ds = ds.assign(cushion_plate_contacts=ds.active_yarn_plate.astype(float) * np.nan)
        ds.cushion_plate_contacts.attrs.update(units="1", long_name="not counted for the unseamed cell")
        ds.attrs.update(seam_distance_mm=float("nan"), model="unseamed fabric cell (homtex.compress)",
                        cushion_height_mm=float(cell.info["thickness"]))
        return ds
    seam = seam_table(cell)
    eps0 = float(seam.get("prestrain", 0.0)) if prestrain is None else float(prestrain)
    frame, info = seam_cell(cell, seam_distance=seam_distance, prestrain=eps0,
                            elements_per_mm=float(seam.get("elements_per_mm", 1.0)),
                            leg_elements=int(seam.get("leg_elements", 4)))
    rn = frame.node_radius
    z = frame.nodes[:, 2]
    far = 0.5 * float(info["thickness"])
    bottom = Plate(z=float((z - rn).min()) - far, normal=1, displacement=0.0, name="bottom")
    top = Plate(z=float((z + rn).max()) + far, normal=-1, displacement=0.0, name="top")
    ss = SeamSolver(frame, info, contact=contact, plates=[bottom, top])
    status, detail = Status.OK, ""
    rec = {k: [] for k in ("strain", *_META)}
    area = float(abs(np.cross(frame.periods[0], frame.periods[1])[2]))
    nb = int(round(float(info["seam_distance"]) / float(info["wale_spacing"])))
    H0 = float("nan")
    h_sewn = np.full(nb, np.nan)
    try:
        if eps0 > 0:
            ss.ramp(ramp_steps)
            u = ss.result.u
        else:
            u = np.zeros((frame.n_nodes, 6))
        _, h_sewn = measure_profile(frame, info, u)

        def touch(u):
            """Both plates onto the outermost yarn surfaces of state u; returns (H0, top displacement)."""
            x = frame.nodes + u[:, :3]
            z_lo = float((x[:, 2] - rn).min())
            z_hi = float((x[:, 2] + rn).max())
            ss.cs.set_plate(0, displacement=z_lo - bottom.z)
            ss.cs.set_plate(1, displacement=z_hi - top.z)
            return z_hi - z_lo, z_hi - top.z

        # the plates now hold the vertical position: free the interlock's uz (its reaction was zero,
        # the sewn state is self-equilibrated) so that plate loads on the stitch reach the fabric
        fix = dict(ss.fixed)
        fix[int(info["interlock_nodes"][0])] = [0, 1]
        ss.use_solver(ContactSolver(frame, fix, None, ss.contact, plates=[bottom, top], solver=ss.solver))
        slack = SlackThreads(frame, info, ss.cs)

        def solve_step():
            return ss.held(slack.solve(ss) if tension_only else ss.solve(1.0))

        H0, d_top0 = touch(u)
        # settle with both plates just touching: freeing the interlock lets a stitch loop that the
        # pin held give way (at eps0 = 0.4 the outermost loop sank 0.19 mm at zero force, so the
        # first plate step met nothing); H0 is the settled specimen's thickness
        res0 = solve_step()
        ss.accept(res0, 1.0)
        H0, d_top0 = touch(res0.u)

        def step(e):
            ss.cs.set_plate(1, displacement=d_top0 - e * H0)
            return solve_step()

        try:
            for st in march(step, [float(strain)], step=float(strain) / int(steps), max_cuts=3, grow="reset"):
                ss.accept(st.result, 1.0)
                _record(rec, st.level, st.result, frame, info, H0, area, int(slack.slack.sum()))
        except StepFailure as err:
            status, detail = Status.FAILED, f"failed at strain {err.level:.4g} after {err.cuts} step cuts: {err.last}"
    except SolverError as err:
        status, detail = Status.FAILED, f"failed in the seam pre-strain ramp: {err}"
    if status is not Status.OK:
        log.warning("seam_compression: %s", detail)
    data = {k: ("strain", np.asarray(v, float), *_META[k]) for k, v in rec.items() if k != "strain"}
    ds = curve_dataset(data, {"strain": (np.asarray(rec["strain"], float), *_STRAIN)})
    ds.attrs.update(model="yarn-level seam cell between rigid plates", thickness_mm=H0,
                    area_mm2=area, seam_distance_mm=float(info["seam_distance"]),
                    requested_seam_distance_mm=float(info["requested_seam_distance"]), prestrain=eps0,
                    cushion_height_mm=float(np.nanmax(h_sewn)), seam_height_mm=float(h_sewn[nb // 2]),
                    seconds=time.perf_counter() - t0, n_nodes=int(frame.n_nodes), tension_only=int(tension_only))
    set_status(ds, status, detail)
    return flag_force_drops(ds, what=f"seam_compression d = {float(info['seam_distance']):.4g} mm, eps0 = {eps0:g}")


def _record(rec, e, res, frame, info, H0, area, n_slack):
    """One accepted plate step of the seamed compression."""
    nf = int(info["fabric_nodes"])
    w = float(info["wale_spacing"])
    nb = int(round(float(info["seam_distance"]) / w))
    c = res.contacts
    act = c.plate_active & (c.plate == 1)
    pn = c.plate_node[act]
    fab = pn[pn < nf]
    xr_ = frame.nodes[fab, 0] + res.u[fab, 0] - float(info["seam_x"])
    bins = np.unique(np.mod(np.round(xr_ / w).astype(np.int64), nb))
    F = float(res.extra["plate_force"][1])
    rec["strain"].append(e)
    rec["plate_displacement"].append(e * H0)
    rec["force"].append(F)
    rec["stress"].append(F / area * 1e3)
    rec["cushion_plate_contacts"].append(len(fab))
    rec["cushions_touched"].append(len(bins))
    rec["stitch_plate_contacts"].append(int((pn >= nf).sum()))
    rec["active_contacts"].append(int(c.n_active))
    rec["slack_stitch_elements"].append(n_slack)


class SlackThreads:
    """Tension-only stitch thread for the linear seam cell: a stitch element whose axial force
    would be compressive (shorter than its rest length (1 - eps0) L0) goes slack - its axial
    stiffness drops by ``factor`` (it buckles; the thread's tiny bending stiffness stays) and so
    does its pre-strain load - and the step is solved again until the slack set settles.
    Without it the thread legs act as struts once the punch reaches the seam line."""

    def __init__(self, frame, info, cs: ContactSolver, factor: float = 1e-3):
        self.frame, self.cs, self.factor = frame, cs, float(factor)
        self.stitch = np.zeros(frame.n_elements, dtype=bool)
        self.stitch[int(info["fabric_elements"]):] = True
        self.slack = np.zeros(frame.n_elements, dtype=bool)

    def solve(self, ss, max_rounds: int = 12):
        """The seam solver's step at full pre-strain with the slack set settled."""
        seen = {self.slack.tobytes()}
        for _ in range(max_rounds):
            res = ss.solve(1.0)
            N = element_state(self.frame, res.u)[0][:, 6]       # with the full properties
            new = self.stitch & (N < 0.0)
            if np.array_equal(new, self.slack):
                res.forces[np.ix_(self.slack, [0, 6])] *= self.factor
                res.energy["axial"][self.slack] *= self.factor ** 2
                return res
            if new.tobytes() in seen:
                raise SolverError(f"tension-only stitch: the slack set cycles ({int(new.sum())} slack elements)")
            seen.add(new.tobytes())
            self.slack = new
            self.cs.set_axial_scale(np.where(self.slack, self.factor, 1.0))
        raise SolverError(f"tension-only stitch: the slack set did not settle in {max_rounds} rounds")
