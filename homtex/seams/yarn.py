"""The geometrically linear seam cell (``seam_profile(method="yarn", geometry="linear")``): the
seam cell sewn by ramping the stitch pre-strain with small-rotation beams and frictionless
contact re-linearised per load step. It cannot form cushions (its seam dip decays over about
2.6 mm; docs/seams.md); it is kept for comparison and for ``seam_compression(geometry="linear")``.
The default yarn-level seam model runs on the large-motion engine (:mod:`homtex.seams.sew`,
:mod:`homtex.seams.profile`).

The seam cell (:func:`homtex.geometry.seam.seam_cell`) is the fabric cell tiled over one seam
distance and one stitch length with a lock stitch 301 whose elements carry the pre-strain
eps0; :class:`SeamSolver` raises eps0 in load steps with yarn-yarn contact. The profile h(x) is
measured on the outer yarn surfaces (:func:`homtex.seams.measure.measure_profile`).
"""

from __future__ import annotations

import logging
import time

import numpy as np
import xarray as xr

from ..analysis.stepping import StepFailure, march
from ..cells import Cell
from ..config import option
from ..contact.options import Contact
from ..contact.solver import ContactSolver
from ..errors import InputError, SolverError
from ..geometry.seam import seam_cell
from ..model.results import Status, set_status
from ..model.scene import default_pins
from ..validate import check_int, check_number
from .foundation import SLACK_LONG_NAME, seam_table
from .measure import measure_profile, thread_escape

__all__ = ["SeamSolver", "linear_profile"]

log = logging.getLogger(__name__)


class SeamSolver:
    """Linear contact solve of a seam cell with the stitch pre-strain ramped in load steps.

    Parameters
    ----------
    frame, info : from :func:`homtex.geometry.seam.seam_cell` (frame.prestrain = full eps0).
    contact : homtex.Contact (default ``Contact()``: pdas, augmented Lagrangian).
    plates : optional list of :class:`homtex.Plate` (for compression after the seam).
    solver : linear solver (default: option ``compress_solver``).

    Supports: ux, uy of the fabric's lowest node (in-plane rigid translation of the periodic
    fabric); ux, uy, uz of the stitch's interlock node (rigid translation of the stitch) and ux of
    every stitch node (the thread stays on the seam line, held by the needle holes). The
    fabric's vertical position is held by its contacts with the stitch (no pin: the stitch and
    the fabric find their own relative height).
    """

    def __init__(self, frame, info, *, contact=None, plates=(), solver: str | None = None):
        self.frame, self.info = frame, info
        nf = int(info["fabric_nodes"])
        fix = {k: v for k, v in default_pins(frame).items() if k < nf}
        fix[int(info["interlock_nodes"][0])] = [0, 1, 2]
        # the stitch stays in its plane x = x_s: ux of every stitch node is held (the needle holes
        # and friction keep the thread on the seam line; without it the frictionless thread can
        # turn about y through the interlock or slide off the loop heads)
        for k in range(nf, frame.n_nodes):
            fix.setdefault(k, [0])
        self.fixed = fix
        self.contact = Contact() if contact is None else contact
        self.solver = option("compress_solver", solver)
        self.cs = ContactSolver(frame, fix, None, self.contact, plates=list(plates), solver=self.solver)
        self.alpha = 0.0
        self.u_ref = None
        self.warm = None
        self.result = None
        self.history = []
        self.retries = 0

    def use_solver(self, cs: ContactSolver) -> None:
        """Continue with another contact solver of the same frame (e.g. other supports); the
        accepted state and its contacts carry over."""
        self.cs = cs

    def solve(self, alpha: float):
        """Contact solve at pre-strain factor alpha from the accepted state; a cycling active set
        is retried once from a cold start (active set from the gaps instead of the previous
        step's contacts)."""
        def run(warm):
            self.cs.set_prestrain_scale(alpha)
            return self.cs.solve(u_ref=self.u_ref, warm_keys=warm)
        try:
            return run(self.warm)
        except SolverError:
            if self.warm is None:
                raise
            self.retries += 1
            return run(None)

    def held(self, res):
        """``res`` if the stitch still holds the fabric between its threads, else SolverError
        (:func:`thread_escape`): the caller treats the step as failed and cuts it."""
        escape = thread_escape(self.frame, self.info, res.u)
        if escape:
            raise SolverError(escape)
        return res

    def accept(self, res, alpha: float) -> None:
        """Make ``res`` (at pre-strain factor alpha) the state later steps start from."""
        self.alpha = alpha
        self.u_ref = res.extra["u_ext"]
        self.warm = res.extra["active_keys"]
        self.result = res

    def ramp(self, steps: int = 4, max_cuts: int = 4, time_limit: float | None = None):
        """Raise the pre-strain factor from the current value to 1 in ``steps`` equal steps; a step
        whose contact solve fails, or ends with a thread slipped through its layer
        (:func:`thread_escape`), is halved (at most ``max_cuts`` times in a row; the increment grows
        back after a success). ``time_limit`` (s): stop with a SolverError once it is exceeded
        (the accepted steps are kept). Returns the list of (alpha, contact iterations, active
        contacts) of the accepted steps."""
        steps = check_int(steps, "steps", ge=1, le=10_000)
        max_cuts = check_int(max_cuts, "max_cuts", ge=0, le=20)
        if time_limit is not None:
            check_number(time_limit, "time_limit", gt=0.0)
        if self.alpha >= 1.0 - 1e-12:
            return self.history
        try:
            for st in march(lambda a: self.held(self.solve(a)), [1.0], start=self.alpha,
                            step=(1.0 - self.alpha) / int(steps), max_cuts=max_cuts, grow="double",
                            time_limit=time_limit):
                res = st.result
                self.accept(res, st.level)
                self.history.append((st.level, int(res.extra["contact_iterations"]), int(res.contacts.n_active)))
        except StepFailure as err:
            if err.last is None:
                raise SolverError(f"seam pre-strain ramp: time limit {time_limit:g} s reached at "
                                  f"{self.alpha:.4g} x eps0") from err
            raise SolverError(f"seam pre-strain ramp failed at {err.level:.4g} x eps0 after {err.cuts} step cuts: "
                              f"{err.last}") from err
        return self.history


def linear_profile(cell: Cell, *, seam_distance: float, prestrain: float | None = None, steps: int = 4,
                   stitches: int = 1, exact: bool = False, contact=None, elements_per_mm: float | None = None,
                   leg_elements: int | None = None, max_cuts: int = 4) -> xr.Dataset:
    """Cushion profile from the geometrically linear seam cell (``seam_profile(method="yarn",
    geometry="linear")``).

    Parameters
    ----------
    cell : spacer Cell with a [parameters.seam] table (stitch_length, prestrain, yarn,
        optional elements_per_mm, leg_elements) and the stitch yarn type.
    seam_distance : d, mm; rounded to a whole number of fabric repeats across the wales
        (``exact=True``: InputError instead); the effective d is returned.
    prestrain : eps0 (None: the calibrated ``[parameters.seam] prestrain``).
    steps : load steps of the pre-strain ramp (a failing step is halved, at most ``max_cuts`` times
        in a row). The contact geometry is re-linearised per step, so the answer depends somewhat on
        the steps (see the report); compare cells on the same step path.
    stitches : stitches along y in the cell (2: a 2-stitch supercell, same answer expected).

    Returns
    -------
    xarray.Dataset: ``height`` (mm) over ``x`` (mm, (2 n_x wales,), 0 = seam line), scalars
    ``cushion_height`` (max height, mm), ``seam_height`` (height at x = 0, mm), ``stitch_force``
    (axial force of one stitch leg = two thread strands, N), ``prestrain``, ``seam_distance``
    (effective, mm); attrs status ("ok" or the failure), timings, sizes, contact statistics.
    """
    seam = seam_table(cell)
    check_number(seam_distance, "seam_distance", gt=0.0, le=1e4)
    eps0 = check_number(seam.get("prestrain", 0.0) if prestrain is None else prestrain, "prestrain", ge=0.0, lt=1.0)
    steps = check_int(steps, "steps", ge=1, le=10_000)
    stitches = check_int(stitches, "stitches", ge=1, le=100)
    if not isinstance(exact, (bool, np.bool_)):
        raise InputError(f"exact must be True or False, got {exact!r}")
    max_cuts = check_int(max_cuts, "max_cuts", ge=0, le=20)
    if contact is not None and not isinstance(contact, Contact):
        raise InputError(f"contact must be a homtex.Contact, got {type(contact).__name__}")
    epm = check_number(seam.get("elements_per_mm", 1.0) if elements_per_mm is None else elements_per_mm,
                       "elements_per_mm", gt=0.0, le=100.0)
    nl = check_int(seam.get("leg_elements", 4) if leg_elements is None else leg_elements, "leg_elements",
                   ge=1, le=1000)
    t0 = time.perf_counter()
    frame, info = seam_cell(cell, seam_distance=seam_distance, prestrain=eps0, stitches=stitches, exact=exact,
                            elements_per_mm=epm, leg_elements=nl)
    t_build = time.perf_counter() - t0
    status, detail = Status.OK, ""
    u = None
    N_leg = 0.0
    slack = 0.0
    hist = []
    iters = 0
    if eps0 > 0.0:
        try:
            ss = SeamSolver(frame, info, contact=contact)
            hist = ss.ramp(steps, max_cuts=max_cuts)
            res = ss.result
            u = res.u
            N_leg = float(np.mean(res.forces[info["legs"], 6]))
            # the top and bottom legs of a stitch are in series between the needle and bobbin threads:
            # pushing the seam line down by delta shortens them by delta; slack after N L / EA_leg
            xyz = frame.nodes + np.asarray(u)[:frame.n_nodes, :3]
            el = frame.elements[info["legs"]]
            L_legs = float(np.linalg.norm(xyz[el[:, 1]] - xyz[el[:, 0]], axis=1).sum()) / max(int(stitches), 1)
            slack = max(N_leg, 0.0) * L_legs / (2.0 * float(info["stitch_EA"]))
            iters = sum(h[1] for h in hist)
        except SolverError as err:
            status, detail = Status.FAILED, f"failed: {err}"
            log.warning("seam profile d = %g mm: %s", float(info["seam_distance"]), detail)
    x, h = measure_profile(frame, info, u)
    if u is None and eps0 > 0.0:
        h = np.full_like(h, np.nan)
    seconds = time.perf_counter() - t0
    i0 = int(np.argmin(np.abs(x)))
    d_eff = float(info["seam_distance"])
    ds = xr.Dataset(
        {"height": ("x", h, {"units": "mm", "long_name": "cushion height (outer yarn surfaces, per wale bin)"}),
         "cushion_height": ((), float(np.max(h)),
                            {"units": "mm", "long_name": "cushion height (max height between seams)"}),
         "seam_height": ((), float(h[i0]), {"units": "mm", "long_name": "height at the seam line"}),
         "stitch_force": ((), N_leg, {"units": "N", "long_name": "axial force of a stitch leg (two thread strands)"}),
         "slack_travel": ((), slack, {"units": "mm", "long_name": SLACK_LONG_NAME}),
         "prestrain": ((), eps0, {"units": "1", "long_name": "stitch-yarn pre-strain eps0"}),
         "seam_distance": ((), d_eff, {"units": "mm", "long_name": "effective seam distance (whole fabric repeats)"})},
        coords={"x": ("x", x, {"units": "mm", "long_name": "position across the seam (0 = seam line)"})})
    ds.attrs.update(
        model="yarn", method="yarn", geometry="linear",
        validity="the yarn-level seam dips only locally (decay length ~2.6 mm): the cushion stays near the "
        "fabric thickness and does NOT reproduce measured cushion heights; eps0 is a nominal value, not "
        "calibrated (docs/seams.md)",
        description="yarn-level seam cell (lock stitch 301, pre-strained stitch yarn, yarn-yarn contact; "
        "geometrically linear beams, contact re-linearised per load step)",
        requested_seam_distance_mm=float(info["requested_seam_distance"]), effective_seam_distance_mm=d_eff,
        stitch_length_mm=float(info["stitch_length"]), stitches=int(stitches), thickness_mm=float(info["thickness"]),
        n_nodes=int(frame.n_nodes), n_elements=int(frame.n_elements), repeats_x=int(info["n_x"]),
        repeats_y=int(info["n_y"]), ramp_steps=len(hist), contact_iterations=int(iters),
        leg_clearance_mm=float(info["leg_clearance"]), seconds=seconds, build_seconds=t_build,
        stitch_elements_per_mm=epm, leg_elements=nl)
    return set_status(ds, status, detail)

