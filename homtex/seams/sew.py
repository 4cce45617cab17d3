"""Sewing a seam cell on the large-motion engine: the lock stitch 301 pulled tight through the
spacer fabric with co-rotational beams, barrier contact that no yarn passes through, Coulomb
friction and the pile free to buckle.

Two stitch models, both ramped by the engine's pre-strain scale s from 0 to 1 in load steps:

* ``stitch="length"`` (length-controlled): every stitch element carries the pre-strain eps0 (it
  wants to be shorter by eps0: the thread consumed per stitch is (1 - eps0) of its sewn-in length);
  the threads along the seam cannot shorten (the cell is periodic along the seam), so only the
  legs pull, and they go slack once they have shortened by eps0.
* ``stitch="tension"`` (tension-controlled, the sewing machine's view): the thread is fed at the
  tension T (N) and slides through the needle holes: every thread strand carries T whatever its
  length (:class:`homtex.contact.tension.ConstantTension`; a leg is two strands, 2 T), the thread
  consumed per stitch follows from the equilibrium (reported as ``thread_per_stitch``).

Bifurcations: the pile legs next to the seam buckle under the stitch's pull. The engine's
stepper (:class:`homtex.contact.engine.EngineStepper`) leaves a buckling state along its critical
mode by ``perturbation`` (mm; default half the thinnest contact radius) and records it
(``branch_switches``); ``imperfection`` (mm) and ``seed`` add a seeded random lateral offset to
the pile's interior nodes in the reference geometry (an imperfect fabric: the path then needs no
perturbation), so the effect of the seed on the cushion can be measured.

:func:`sew` returns a :class:`SewnSeam`: the frame, the state to continue from (a punch pressing
the sewn cell starts there, :mod:`homtex.seams.compress`), the path over the ramp and the
measured cushion profile.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from ..cells import Cell
from ..contact.engine import EngineStepper
from ..contact.incremental import EngineState, IncrementalSolver, NonlinearSettings
from ..contact.options import Contact
from ..contact.tension import ConstantTension
from ..errors import InputError, SolverError
from ..fem.corotational_system import log_nodes
from ..geometry.seam import seam_cell
from ..model.results import Status, set_status
from ..model.scene import default_pins
from ..output.datasets import curve_dataset
from ..validate import check_choice, check_int, check_number
from .measure import leg_shortening, measure_profile, pile_legs, thread_escape

__all__ = ["STITCHES", "SewnSeam", "seam_frame", "sew"]

log = logging.getLogger(__name__)

STITCHES = ("length", "tension")

#: Newton iterations per ramp step: once the pile next to the seam has buckled, the cushion
#: settles by a snap whose pseudo-transient descent takes 100-200 iterations (the engine's default
#: of 80 stalled d = 18 mm at level 0.5 of the ramp at every step size, with and without a seeded
#: imperfection; 400 passes it in one to three sub-steps)
SEW_ITERATIONS = 400

#: a tension-controlled thread's own axial stiffness is scaled by this: the tension comes from
#: the constant-force term (a leg shortened by 60 % then differs from 2 T by 1e-4 EA x 0.6, under
#: 0.02 N for the shipped thread)
SOFT_AXIAL = 1e-4

_PATH = {
    "prestrain_scale": ("1", "ramp level: factor on the stitch's pre-strain (length) or tension (tension)"),
    "cushion_height": ("mm", "cushion height (max height between seams)"),
    "seam_height": ("mm", "height at the seam line"),
    "leg_tension": ("N", "mean axial force of a stitch leg (two thread strands)"),
    "stitch_fabric_contacts": ("1", "stitch-fabric segment pairs within the barrier's activation gap"),
    "yarn_yarn_contacts": ("1", "yarn-yarn segment pairs within the barrier's activation gap"),
    "buckled_legs": ("1", "pile legs whose end-to-end length shortened by more than 5 %"),
    "buckled_reach": ("mm", "largest distance from the seam line of a pile leg shortened by more than 5 %"),
    "negative_eigenvalues": ("1", "negative eigenvalues of the Hessian of the sewn state (0: stable)"),
    "substeps": ("1", "engine steps the level needed (1: none; more after halving)"),
    "iterations": ("1", "Newton iterations of the level"),
    "energy_balance": ("1", "energy balance of the ramp (homtex.analysis.energy)"),
    "stabilization_energy": ("N mm", "energy the pseudo-transient continuation absorbed since the start"),
    "prestrain_work": ("N mm", "work of the ramp (pre-strain or thread tension)"),
    "friction_energy": ("N mm", "energy dissipated by friction since the start"),
}


def seam_frame(cell: Cell, *, seam_distance: float, prestrain, stitches: int = 1, exact: bool = False,
               elements_per_mm: float | None = None, leg_elements: int | None = None, seams: int = 1):
    """(frame, info) of the seam cell with the cell file's stitch resolution (see
    :func:`homtex.geometry.seam.seam_cell`)."""
    seam = (cell.parameters or {}).get("seam") or {}
    epm = float(seam.get("elements_per_mm", 1.0)) if elements_per_mm is None else float(elements_per_mm)
    nl = int(seam.get("leg_elements", 4)) if leg_elements is None else int(leg_elements)
    return seam_cell(cell, seam_distance=seam_distance, prestrain=prestrain, stitches=stitches, exact=exact,
                     elements_per_mm=epm, leg_elements=nl, seams=seams)


def seam_supports(frame, info) -> dict:
    """Supports of a seam cell: the fabric's in-plane rigid motion (ux, uy of its lowest node),
    the stitch's interlock node (ux, uy, uz: the stitch's rigid translation; the fabric's height
    is held by its contacts with the stitch) and ux of every stitch node (the needle holes keep the
    thread on the seam line)."""
    nf = int(info["fabric_nodes"])
    fix = {k: v for k, v in default_pins(frame).items() if k < nf}
    for k in np.atleast_1d(info["interlock_nodes"]):
        fix[int(k)] = [0, 1, 2]
    for k in range(nf, frame.n_nodes):
        fix.setdefault(k, [0])
    return fix


def seam_friction(cell: Cell, frame, info) -> dict | None:
    """The cell file's ``[contact]`` friction mapped onto the seam cell's elements (fabric elements
    take their source element's yarn type, the stitch the seam table's yarn); None without one."""
    spec = cell.friction_spec() if callable(getattr(cell, "friction_spec", None)) else None
    if spec is None:
        return None
    src = np.asarray(info["element_source"], dtype=np.int64)
    yname = ((cell.parameters or {}).get("seam") or {}).get("yarn", "stitch")
    ms = frame.n_elements - len(src)
    types = np.r_[np.asarray(spec["types"])[src], np.full(ms, spec["names"].index(yname))]
    return {**spec, "types": types}


def imperfect(frame, info, amplitude: float, seed) -> object:
    """The frame with a seeded random lateral offset (x and y, normal with standard deviation
    ``amplitude`` mm) on the interior nodes of the pile legs (their ends in the layers stay)."""
    if amplitude <= 0.0:
        return frame
    rng = np.random.default_rng(seed)
    legs = pile_legs(frame, info)
    nodes = frame.nodes.copy()
    for e in legs:
        nd = np.unique(frame.elements[e].ravel())
        z = frame.nodes[nd, 2]
        inner = nd[(z > z.min() + 1e-9) & (z < z.max() - 1e-9)]
        nodes[inner, :2] += amplitude * rng.standard_normal((len(inner), 2))
    return frame.replace(nodes=nodes)


@dataclass
class SewnSeam:
    """A seam cell sewn on the large-motion engine.

    frame, info : the seam cell (:func:`homtex.geometry.seam.seam_cell`); state : the engine's
    sewn state (:class:`~homtex.contact.incremental.EngineState`) to continue from; u (n, 6) mm/rad;
    path : Dataset over the ramp levels (:data:`_PATH`); stitch, prestrain, tension (N per strand):
    the stitch model; contact, friction_spec : the contact options it was sewn with; status, detail;
    attrs : run time, branch switches, sizes.
    """

    frame: object
    info: dict
    state: EngineState | None
    u: np.ndarray
    path: xr.Dataset
    stitch: str
    prestrain: float
    tension: float
    contact: Contact
    friction_spec: dict | None
    status: str = "ok"
    detail: str = ""
    attrs: dict = field(default_factory=dict)

    def to_dataset(self) -> xr.Dataset:
        """The sewn state as a Dataset (translations ``ut`` and rotations ``Q`` of every node, the
        ramp's path variables over ``step``, the stitch model in attrs): what the result cache
        stores; :meth:`from_dataset` rebuilds the SewnSeam from it and the cell."""
        ds = self.path.copy()
        ds["ut"] = (("node", "xyz"), np.asarray(self.state_arrays()[0]),
                    {"units": "mm", "long_name": "node translation of the sewn state"})
        ds["Q"] = (("node", "i", "j"), np.asarray(self.state_arrays()[1]),
                   {"units": "1", "long_name": "nodal rotation matrix of the sewn state"})
        for k in ("node", "xyz", "i", "j"):
            ds[k] = (k, np.arange(ds.sizes[k]), {"units": "1", "long_name": k})
        ds.attrs.update({k: v for k, v in self.attrs.items()})
        ds.attrs.update(stitch=self.stitch, prestrain=float(self.prestrain), tension_N=float(self.tension),
                        sewn_status=self.status, sewn_detail=self.detail,
                        seam_distance_mm=float(self.info["seam_distance"]))
        return ds

    def state_arrays(self):
        """(ut (n, 3) mm, Q (n, 3, 3)) of the sewn state."""
        if self.state is not None:
            return self.state.ut, self.state.Q
        n = self.frame.n_nodes
        return np.zeros((n, 3)), np.broadcast_to(np.eye(3), (n, 3, 3)).copy()

    @classmethod
    def from_dataset(cls, cell: Cell, ds: xr.Dataset, *, contact: Contact | None = None, **seam_kw) -> "SewnSeam":
        """The SewnSeam stored by :meth:`to_dataset` for ``cell`` (the frame is rebuilt from the cell:
        ``seam_kw`` the same seam-cell arguments as when it was sewn)."""
        stitch = str(ds.attrs["stitch"])
        eps0 = float(ds.attrs["prestrain"])
        per_seam = _events(ds.attrs.get("seam_prestrains", [eps0]))
        frame, info = seam_frame(cell, seam_distance=float(ds.attrs.get("requested_seam_distance_mm",
                                                                         ds.attrs["seam_distance_mm"])),
                                 prestrain=per_seam if per_seam.size > 1 else eps0, **seam_kw)
        frame = imperfect(frame, info, float(ds.attrs.get("imperfection_mm", 0.0)),
                          None if str(ds.attrs.get("seed", "none")) == "none" else int(ds.attrs["seed"]))
        ut = np.asarray(ds["ut"].values, dtype=float)
        Q = np.asarray(ds["Q"].values, dtype=float)
        if ut.shape != (frame.n_nodes, 3):
            raise InputError(f"a stored sewn state of {ut.shape[0]} nodes does not belong to this seam cell "
                             f"({frame.n_nodes} nodes)")
        rot = np.empty((frame.n_nodes, 3))
        log_nodes(np.ascontiguousarray(Q), rot)
        contact = Contact() if contact is None else contact
        spec = seam_friction(cell, frame, info) if contact.friction is None else None
        state = EngineState(n_nodes=frame.n_nodes, n_elements=frame.n_elements, ut=ut, Q=Q, prestrain_scale=1.0,
                            loads=np.zeros((frame.n_nodes, 6)), plate_z=np.zeros(0), plate_normal=np.zeros(0, int),
                            plate_force=np.zeros(0), touch=None, ledger={})
        path = ds.drop_vars([v for v in ("ut", "Q", "node", "xyz", "i", "j") if v in ds.variables])
        attrs = {k: v for k, v in ds.attrs.items()}
        attrs["branch_switches"] = _events(attrs.get("branch_switches", []))
        return cls(frame=frame, info=info, state=state, u=np.hstack([ut, rot]), path=path, stitch=stitch,
                   prestrain=eps0, tension=float(ds.attrs["tension_N"]), contact=contact, friction_spec=spec,
                   status=str(ds.attrs.get("sewn_status", "ok")), detail=str(ds.attrs.get("sewn_detail", "")),
                   attrs=attrs)

    def profile(self):
        """(x (k,) mm, 0 = seam line; h (k,) mm) of the sewn state (:func:`measure_profile`)."""
        return measure_profile(self.frame, self.info, self.u)

    def tension_term(self) -> ConstantTension | None:
        """The constant-tension thread of a tension-controlled stitch (None for a length-controlled one)."""
        if self.stitch != "tension":
            return None
        return stitch_tension(self.frame, self.info, self.tension)

    def locked_frame(self):
        """The frame with the thread locked at its sewn length: after sewing no more thread is fed,
        so a punch that pushes the seam line down slackens it. Length-controlled: the frame itself;
        tension-controlled: every stitch element gets the pre-strain that makes its elastic force
        (full EA) equal its sewn tension at the sewn length."""
        if self.stitch != "tension":
            return self.frame
        f = self.frame
        x = f.nodes + self.u[:, :3]
        v = x[f.elements[:, 1]] + f.shift - x[f.elements[:, 0]]
        eps = np.linalg.norm(v, axis=1) / f.length - 1.0
        term = self.tension_term()
        pre = np.asarray(f.prestrain, dtype=float).copy()
        pre[term.elements] = term.force / f.EA[term.elements] - eps[term.elements]
        return f.replace(prestrain=np.clip(pre, -0.999, 0.999))


def _events(v) -> np.ndarray:
    """Branch-switch records as a flat float array (a netCDF file gives an empty one back as '[]')."""
    if isinstance(v, str):
        v = [float(t) for t in v.strip().strip("[]").replace(",", " ").split()]
    return np.asarray(v, dtype=float).reshape(-1)


def stitch_tension(frame, info, tension: float) -> ConstantTension:
    """The constant-tension term of a stitch fed at ``tension`` N per strand (legs: two strands)."""
    m0 = int(info["fabric_elements"])
    el = np.arange(m0, frame.n_elements)
    strands = np.where(np.asarray(info["legs"], dtype=bool)[el], 2.0, 1.0)
    return ConstantTension(frame, el, float(tension) * strands)


def _stitch_contacts(pairs, stencil, m0: int) -> int:
    """Active yarn-yarn pairs with one stitch element (index >= m0) and one fabric element."""
    if stencil is None or not len(stencil) or not pairs.n_active:
        return 0
    a, b = stencil.a[pairs.active], stencil.b[pairs.active]
    return int(np.sum((a >= m0) != (b >= m0)))


def sew(cell: Cell, *, seam_distance: float, stitch: str | None = None, prestrain: float | None = None,
        tension: float | None = None, contact: Contact | None = None, steps: int | None = None,
        max_cuts: int = 6, refine: float = 0.01, perturbation: float | None = None, imperfection: float = 0.0,
        seed=None, stitches: int = 1, exact: bool = False, elements_per_mm: float | None = None,
        leg_elements: int | None = None, progress_log: bool = True, stop=None, seams: int = 1) -> SewnSeam:
    """Sew the seam cell of ``cell`` on the large-motion engine (see the module docstring).

    Parameters
    ----------
    cell : spacer Cell with a [parameters.seam] table.
    seam_distance : d, mm (rounded to whole fabric repeats across the wales unless ``exact``).
    stitch : "length" or "tension" (default: ``[parameters.seam] stitch``, else "length").
    prestrain : eps0 of a length-controlled stitch (default ``[parameters.seam] prestrain``); with
        ``seams`` > 1 one per seam may be given.
    tension : needle-thread tension of a tension-controlled stitch, N per strand (default
        ``[parameters.seam] tension``).
    contact : homtex.Contact (default: ``Contact()`` with the cell file's [contact] friction).
    steps : ramp levels (default ``[parameters.seam] ramp_steps``, else 10); a level that fails, or whose
        energy ledger misses ``refine`` of its work, is halved, up to ``max_cuts`` times.
    perturbation : amplitude (mm) by which a buckling state is left along its critical mode
        (default: half the thinnest contact radius).
    imperfection, seed : standard deviation (mm) of a seeded random lateral offset of the pile's
        interior nodes (default 0: a perfect fabric).
    seams : seams in the cell, ``seam_distance`` apart (a strip of cushions, :mod:`homtex.seams.strip`).
    stop : ``stop(row) -> bool`` called with every accepted level's path row (a dict of
        :data:`_PATH`); True ends the ramp there (status "ok", ``ramp_done`` below 1: a calibration
        that only needs the ramp until the cushion passes its target).

    Returns
    -------
    SewnSeam (its ``status`` "failed" with ``detail`` when a level fails at every step size: the
    levels before it are kept in ``path``, ``u`` is the last accepted state).
    """
    seam = (cell.parameters or {}).get("seam")
    if not isinstance(seam, dict):
        raise InputError(f"cell {getattr(cell, 'name', '?')!r}: no [parameters.seam] table")
    stitch = check_choice(seam.get("stitch", "length") if stitch is None else stitch, "stitch", STITCHES)
    check_number(seam_distance, "seam_distance", gt=0.0, le=1e4)
    eps0, T = 0.0, 0.0
    seams = check_int(seams, "seams", ge=1, le=100)
    per_seam = None
    if stitch == "length":
        if tension is not None:
            raise InputError("tension= is for stitch='tension'; a length-controlled stitch takes prestrain=")
        if prestrain is not None and np.ndim(prestrain) == 1:
            if len(prestrain) != seams:
                raise InputError(f"prestrain: {len(prestrain)} values for {seams} seams (one per seam, or one)")
            per_seam = np.array([check_number(e, f"prestrain of seam {i + 1}", ge=0.0, lt=1.0)
                                 for i, e in enumerate(prestrain)])
            eps0 = float(per_seam.mean())
        else:
            eps0 = check_number(seam.get("prestrain", 0.0) if prestrain is None else prestrain, "prestrain",
                                ge=0.0, lt=1.0)
    else:
        if prestrain is not None:
            raise InputError("prestrain= is for stitch='length'; a tension-controlled stitch takes tension= (N)")
        if tension is None and "tension" not in seam:
            raise InputError("stitch='tension' needs tension= (N per thread strand) or [parameters.seam] tension")
        T = check_number(seam["tension"] if tension is None else tension, "tension (N)", ge=0.0, le=1e4)
    steps = check_int(seam.get("ramp_steps", 10) if steps is None else steps, "steps", ge=1, le=10_000)
    max_cuts = check_int(max_cuts, "max_cuts", ge=0, le=30)
    imperfection = check_number(imperfection, "imperfection (mm)", ge=0.0, le=10.0)
    if contact is not None and not isinstance(contact, Contact):
        raise InputError(f"contact must be a homtex.Contact, got {type(contact).__name__}")
    contact = Contact() if contact is None else contact
    t0, c0 = time.perf_counter(), time.process_time()
    frame, info = seam_frame(cell, seam_distance=seam_distance, prestrain=eps0 if per_seam is None else per_seam,
                             stitches=stitches, exact=exact, elements_per_mm=elements_per_mm,
                             leg_elements=leg_elements, seams=seams)
    frame = imperfect(frame, info, imperfection, seed)
    fixed = seam_supports(frame, info)
    spec = seam_friction(cell, frame, info) if contact.friction is None else None
    sol = IncrementalSolver(frame, fixed, None, [], contact, friction_spec=spec, prestrain_scale=0.0,
                            settings=NonlinearSettings(max_iter=SEW_ITERATIONS))
    term = None
    if stitch == "tension":
        term = stitch_tension(frame, info, T)
        term.soften(sol.cor, SOFT_AXIAL)
        sol.add_term(term)
    stepper = EngineStepper(sol, lambda lv: sol.solve(prestrain_scale=lv), max_cuts=max_cuts, refine=refine)
    if perturbation is not None:
        stepper.perturbation = check_number(perturbation, "perturbation (mm)", gt=0.0, le=10.0)
    legs = pile_legs(frame, info)
    m0 = int(info["fabric_elements"])
    rows = []
    status, detail = Status.OK, ""
    done = 0.0
    if eps0 > 0.0 or T > 0.0:
        for k in range(1, steps + 1):
            lam = k / steps
            try:
                info_k = stepper.advance(lam)
                escape = thread_escape(frame, info, sol.cor.u())
                if escape:
                    raise SolverError(escape)
            except SolverError as err:
                status = Status.FAILED
                detail = f"sewing failed at level {lam:.4g} of the ramp (after {max_cuts} halvings): {err}"
                log.warning("sew d = %g mm: %s", float(info["seam_distance"]), detail)
                break
            done = lam
            rows.append(_row(sol, frame, info, info_k, stepper.take_totals(), legs, m0, term))
            if progress_log:
                log.info("sew d = %.4g mm (%s): level %.3g, cushion %.2f mm, seam line %.2f mm, legs %.3g N",
                         float(info["seam_distance"]), stitch, lam, rows[-1]["cushion_height"],
                         rows[-1]["seam_height"], rows[-1]["leg_tension"])
            if stop is not None and stop(rows[-1]):
                break
    u = sol.cor.u()
    n = len(rows)
    data = {k: ("step", np.array([r[k] for r in rows], dtype=float).reshape(n), *meta) for k, meta in _PATH.items()}
    path = curve_dataset(data, {"step": (np.arange(1, n + 1), "1", "ramp level")})
    attrs = {"requested_seam_distance_mm": float(seam_distance), "seconds": time.perf_counter() - t0,
             "cpu_seconds": time.process_time() - c0, "ramp_steps": steps,
             "ramp_done": done, "branch_switches": np.array(stepper.events, dtype=float).reshape(-1),
             "perturbation_mm": float(stepper.perturbation), "imperfection_mm": imperfection,
             "seed": "none" if seed is None else int(seed), "n_nodes": int(frame.n_nodes), "seams": seams,
             "seam_prestrains": np.full(seams, eps0) if per_seam is None else per_seam,
             "n_elements": int(frame.n_elements), "friction_max": float(max(sol.scene.mu_table.max(initial=0.0),
                                                                             sol.scene.mu_plate.max(initial=0.0)))}
    set_status(path, status, detail)
    return SewnSeam(frame=frame, info=info, state=sol.export_state() if rows or eps0 == T == 0.0 else None, u=u,
                    path=path, stitch=stitch, prestrain=eps0, tension=T, contact=contact, friction_spec=spec,
                    status=status.value, detail=detail, attrs=attrs)


def _row(sol, frame, info, step, totals, legs, m0, term) -> dict:
    """One accepted ramp level."""
    u = sol.cor.u()
    x, h = measure_profile(frame, info, u)
    i0 = int(np.argmin(np.abs(x)))
    legs_el = np.asarray(info["legs"], dtype=bool)
    N = sol.cor.forces[:, 6]
    if term is not None:
        N = N.copy()
        N[term.elements] += sol.prestrain_scale * term.force
    xc, loss = leg_shortening(frame, info, u, legs)
    buck = loss > 0.05
    ev = step.extra["ev"]
    L = sol.ledger
    return {"prestrain_scale": sol.prestrain_scale, "cushion_height": float(h.max()), "seam_height": float(h[i0]),
            "leg_tension": float(np.mean(N[legs_el])),
            "stitch_fabric_contacts": _stitch_contacts(ev["pairs"], sol.scene.stencil, m0),
            "yarn_yarn_contacts": ev["pairs"].n_active, "buckled_legs": int(buck.sum()),
            "buckled_reach": float(np.abs(xc[buck]).max(initial=0.0)),
            "negative_eigenvalues": step.negative_eigenvalues, "substeps": totals["substeps"],
            "iterations": totals["iterations"], "energy_balance": sol.balance(),
            "stabilization_energy": L["stabilization"], "prestrain_work": L["prestrain_work"],
            "friction_energy": L["dissipation"]}
