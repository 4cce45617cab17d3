"""Compression test between two rigid plates: the scene, the step solvers and the curve.

The cell (or frame) lies between a fixed bottom plate and a top plate that moves down
(displacement control) or carries a uniform pressure (force control, as in the paper).
With ``geometry="linear"`` each step is a linear-beam contact solve whose gaps are
linearised about the previous step's deformed state (contacts are searched again at every
step), so new contacts appear as the fabric compresses while every step stays a convex
problem; with ``geometry="nonlinear"`` the large-motion engine takes over
(:mod:`homtex.contact.nl_compress`: co-rotational beams, barrier contact, friction,
pseudo-transient continuation). ``homtex.compress`` is the public entry.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..analysis.stepping import StepFailure, flag_force_drops, march
from ..config import threads_for
from ..errors import InputError
from ..model.frame import Frame
from ..model.results import ENERGY_KEYS, ENERGY_LONG_NAMES, Status, set_status
from ..model.scene import Plate, default_pins
from ..output.datasets import curve_dataset
from ..output.progress import Progress
from .options import Contact
from .solver import ContactSolver

__all__ = ["CompressionTest", "compression_summary", "run_compression"]

log = logging.getLogger(__name__)

_META = {
    "stress": ("kPa", "nominal compressive stress (top plate force / area)"),
    "force": ("N", "compressive force on the top plate"),
    "plate_displacement": ("mm", "downward displacement of the top plate"),
    "pressure": ("kPa", "applied pressure (force control) or measured stress"),
    "bottom_force": ("N", "compressive force on the bottom plate"),
    "active_contacts": ("1", "active contacts (yarn-yarn + yarn-plate)"),
    "active_yarn_yarn": ("1", "active yarn-yarn contacts"),
    "active_yarn_plate": ("1", "active yarn-plate contacts"),
    "max_penetration": ("mm", "largest overlap of the linearised contact gaps"),
    "contact_iterations": ("1", "active-set iterations of the step (last sub-step)"),
    "linear_solves": ("1", "linear solves of the step (last sub-step)"),
    "substeps": ("1", "sub-steps the step needed (1: none; more after halving a failed step)"),
    "contact_energy": ("N mm", "energy stored in the contact penalty springs"),
    "newton_iterations": ("1", "Newton iterations of the step (0: the linear model has none)"),
    "stabilization_force": ("N", "stabilisation force (0: the linear model has none)"),
    **{k: ("N mm", v) for k, v in ENERGY_LONG_NAMES.items()},
}
_STRAIN = ("1", "compression strain (plate displacement / initial plate distance)")


@dataclass
class CompressionTest:
    """A frame between two rigid plates: the scene of a compression test.

    ``H0`` initial plate distance (mm), ``area`` nominal area for the stress (mm^2) and where it
    comes from, ``z_lo`` the bottom plate height (mm), ``fixed`` the supports (default pins
    merged with the user's), ``groups`` element groups for per-group energies.
    """

    frame: Frame
    H0: float
    area: float
    area_source: str
    z_lo: float
    fixed: dict
    groups: dict

    @classmethod
    def build(cls, frame: Frame, *, thickness=None, area=None, fixed=None, groups=None, info=None):
        """Plates touching the lowest yarn surface and ``thickness`` above it (default
        ``info["thickness"]``, else the yarns' extent); InputError for bad values."""
        if frame.dim_periodic == 3:
            raise InputError("compress: a 3-periodic frame has no free surfaces for plates")
        if frame.dim_periodic and np.any(np.abs(frame.periods[:, 2]) > 1e-9 * np.abs(frame.periods).max()):
            raise InputError(f"compress: lattice vectors must lie in the x-y plane (plates are normal to z), "
                             f"got {frame.periods.tolist()}")
        x = frame.nodes
        rn = frame.node_radius
        z_lo = float((x[:, 2] - rn).min())
        z_hi = float((x[:, 2] + rn).max())
        if thickness is None:
            thickness = info.get("thickness") if isinstance(info, dict) else None
        H0 = float(thickness) if thickness is not None else z_hi - z_lo
        if not H0 > 0:
            raise InputError(f"thickness must be positive, got {thickness!r}")
        if H0 < 0.5 * (z_hi - z_lo):
            raise InputError(f"thickness {H0:g} mm is below half the yarns' extent {z_hi - z_lo:.4g} mm: the top "
                             "plate would start deep inside the fabric (give the plate distance in mm)")
        area_source = "given"
        if area is None:
            if frame.dim_periodic == 2:
                area = float(np.linalg.norm(np.cross(frame.periods[0], frame.periods[1])))
                area_source = "|p1 x p2| of the periodic cell"
            else:
                ext = (x[:, :2] + rn[:, None]).max(axis=0) - (x[:, :2] - rn[:, None]).min(axis=0)
                area = float(ext[0] * ext[1])
                area_source = "x-y bounding box of the yarns"
        area = float(area)
        if not area > 0:
            raise InputError(f"area must be positive (mm^2), got {area!r}")
        fix = default_pins(frame, x) if fixed is None else dict(fixed)
        if fixed is not None:
            for node, spec in default_pins(frame, x).items():
                fix.setdefault(node, spec)
        groups = dict(groups or {})
        for g, mk in groups.items():
            if np.asarray(mk).shape != (frame.n_elements,):
                raise InputError(f"group {g!r}: mask must have shape ({frame.n_elements},), got {np.shape(mk)}")
        return cls(frame=frame, H0=H0, area=area, area_source=area_source, z_lo=z_lo, fixed=fix, groups=groups)

    def solver(self, contact: Contact, *, solver: str, tol: float, maxiter=None) -> ContactSolver:
        bottom = Plate(z=self.z_lo, normal=1, displacement=0.0, name="bottom")
        top = Plate(z=self.z_lo + self.H0, normal=-1, displacement=0.0, name="top")
        return ContactSolver(self.frame, self.fixed, None, contact, plates=[bottom, top], solver=solver, tol=tol,
                             maxiter=maxiter)


def _record(rec, test: CompressionTest, res, target, control, nsub, masks):
    e = res.extra
    w = float(e["plate_displacement"][1])
    F = float(e["plate_force"][1])
    c = res.contacts
    rec["strain"].append(-w / test.H0)
    rec["plate_displacement"].append(-w)
    rec["force"].append(F)
    rec["stress"].append(F / test.area * 1e3)
    rec["pressure"].append(target if control == "force" else F / test.area * 1e3)
    rec["bottom_force"].append(float(e["plate_force"][0]))
    rec["active_contacts"].append(c.n_active)
    rec["active_yarn_yarn"].append(c.n_yarn)
    rec["active_yarn_plate"].append(c.n_plate)
    rec["max_penetration"].append(e["max_penetration"])
    rec["contact_iterations"].append(e["contact_iterations"])
    rec["linear_solves"].append(e["linear"]["linear_solves"])
    rec["contact_energy"].append(e["contact_energy"])
    rec["newton_iterations"].append(int(e.get("newton_iterations", 0)))
    rec["stabilization_force"].append(float(e.get("stabilization_force", 0.0)))
    rec["substeps"].append(nsub)
    tot = np.zeros(test.frame.n_elements)
    for k in ENERGY_KEYS:
        rec[k].append(float(res.energy[k].sum()))
        tot += res.energy[k]
    rec["group_energy"].append([float(tot[mk].sum()) for mk in masks])


#: largest nodal rotation (rad) of a linear curve reported "ok": beyond it the small-rotation model
#: is out of its range whatever the cell
MAX_LINEAR_ROTATION = 0.1


def run_compression(test: CompressionTest, targets, *, control: str, contact: Contact, solver: str, tol: float,
                    maxiter=None, max_cuts: int = 4, progress: bool = False, geometry: str = "linear",
                    friction_spec: dict | None = None, validity: dict | None = None) -> xr.Dataset:
    """The compression curve of ``test`` through the load levels ``targets`` (strains or kPa).

    ``geometry="linear"``: linear beams, contact re-linearised per step. A failing step is halved
    (:func:`homtex.analysis.stepping.march`, recursive bisection, up to ``max_cuts`` levels); a
    step that still fails ends the curve: the steps before it are kept, ``attrs["status"]`` is
    "failed" and ``attrs["status_detail"]`` says where and why. ``geometry="nonlinear"``: the
    large-motion engine (:func:`homtex.contact.nl_compress.run_nonlinear_compression`;
    ``friction_spec``: a cell file's friction table). ``maxiter``: the iteration limit of the
    iterative linear solves (linear), or the engine's Newton iterations per friction round
    (nonlinear, :class:`~homtex.contact.incremental.NonlinearSettings` ``max_iter``); None: their
    defaults. ``validity``: the cell file's ``[validity]`` table; a linear curve that goes beyond its
    ``linear_strain_limit`` (measured), or whose nodes turn by more than ``MAX_LINEAR_ROTATION``, is
    "flagged" (complete, but outside the linear model's range).
    """
    with threads_for(test.frame.ndof):     # one numba thread for a small cell (homtex.config)
        if geometry == "nonlinear":
            from .incremental import NonlinearSettings
            from .nl_compress import run_nonlinear_compression

            settings = None if maxiter is None else NonlinearSettings(max_iter=int(maxiter))
            return run_nonlinear_compression(test, targets, control=control, contact=contact,
                                             friction_spec=friction_spec, max_cuts=max_cuts, progress=progress,
                                             settings=settings)
        return _linear_curve(test, targets, control=control, contact=contact, solver=solver, tol=tol,
                             maxiter=maxiter, max_cuts=max_cuts, progress=progress, geometry=geometry,
                             validity=validity)


def _linear_curve(test, targets, *, control, contact, solver, tol, maxiter, max_cuts, progress, geometry,
                  validity):
    """The linear model's curve (see :func:`run_compression`)."""
    t0 = time.perf_counter()
    cs = test.solver(contact, solver=solver, tol=tol, maxiter=maxiter)
    names = list(test.groups)
    masks = [np.asarray(test.groups[g], dtype=bool) for g in names]
    rec = {k: [] for k in ("strain", *_META, "group_energy")}
    state = {"u_ref": None, "warm": None}

    def solve(level):
        if control == "displacement":
            cs.set_plate(1, displacement=-level * test.H0)
        else:
            cs.set_plate(1, force=level * test.area * 1e-3)
        return cs.solve(u_ref=state["u_ref"], warm_keys=state["warm"])

    def retry(err):
        return "singular" not in str(err)   # a singular operator does not improve with smaller steps

    bar = Progress(len(targets), "compression steps", enabled=progress)
    status, detail = Status.OK, ""
    try:
        for st in march(solve, targets, max_cuts=max_cuts, grow="aligned", retry=retry):
            res = st.result
            e = res.extra
            if not all(np.isfinite(v).all() for v in (res.u, e["plate_force"])):
                raise StepFailure("non-finite result", level=st.level, reached=st.level, target=st.target,
                                  cuts=0, first=None, last=None)
            state.update(u_ref=e["u_ext"], warm=e["active_keys"])
            if st.target is None:
                continue
            bar.step(f"{st.substeps} sub-steps" if st.substeps > 1 else "")
            _record(rec, test, res, float(targets[st.target]), control, st.substeps, masks)
            rot = float(np.abs(res.u[:test.frame.n_nodes, 3:]).max(initial=0.0))
            state["rotation"] = max(state.get("rotation", 0.0), rot)
    except (StepFailure, RuntimeError) as err:
        k = getattr(err, "target", None)
        k = len(rec["strain"]) if k is None else k
        target = float(targets[k])
        label = f"strain {target:.4g}" if control == "displacement" else f"pressure {target:.4g} kPa"
        cause = err.first if getattr(err, "first", None) is not None else err
        halved = "" if max_cuts == 0 or "singular" in str(cause) or not isinstance(err, StepFailure) \
            or err.first is None else f" (also after halving the step {int(max_cuts)} times)"
        status, detail = Status.FAILED, f"failed at step {k + 1} ({label}){halved}: {cause}"
        log.warning("compress: %s", detail)
    bar.close()
    data = {k: ("strain", np.asarray(rec[k]), *_META[k]) for k in _META}
    if names:
        ge = np.asarray(rec["group_energy"], dtype=float).reshape(len(rec["strain"]), len(names))
        data["group_energy"] = (("strain", "group"), ge, "N mm", "strain energy per element group")
    coords = {"strain": (np.asarray(rec["strain"], dtype=float), *_STRAIN)}
    if names:
        coords["group"] = (np.array(names, dtype=str), "1", "element group")
    ds = curve_dataset(data, coords)
    ds.attrs.update(
        control=control, thickness_mm=test.H0, area_mm2=test.area, area_source=test.area_source,
        strategy=contact.strategy, enforcement=contact.enforcement, penalty_N_per_mm=cs.k,
        bottom_plate_z_mm=test.z_lo, top_plate_z_mm=test.z_lo + test.H0, solver=solver,
        seconds=time.perf_counter() - t0, geometry=geometry, supports=str(test.fixed),
        steps_requested=int(len(targets)), initial_overlap=contact.initial_overlap,
        initial_overlaps=int(cs.initial_overlaps), initial_overlap_max_mm=cs.initial_overlap_max)
    if status is Status.OK and len(rec["strain"]):
        why = _linear_validity(ds, validity or {}, state.get("rotation", 0.0))
        if why:
            status, detail = Status.FLAGGED, why
            log.warning("compress: %s", why)
    set_status(ds, status, detail)
    ds.attrs["steps_done"] = int(len(rec["strain"]))
    if control == "displacement":
        flag_force_drops(ds, what="compress")
    return ds


def _linear_validity(ds, validity: dict, rotation: float) -> str:
    """'' when a linear curve stays within the model's range, else why not."""
    msgs = []
    top = float(np.max(ds.strain.values))
    lim = validity.get("linear_strain_limit")
    ds.attrs["linear_strain_limit"] = float(lim) if lim is not None else float("nan")
    if lim is not None and top > float(lim) * (1 + 1e-9):
        msgs.append(f"the linear model holds on this cell to a compression strain of {float(lim):.3g} (its stress "
                    f"within 10 % of the large-motion engine's: {validity.get('source', 'measured')}); this curve "
                    f"goes to {top:.3g}: compress with geometry='nonlinear' beyond it")
    if rotation > MAX_LINEAR_ROTATION:
        msgs.append(f"nodes turn by up to {rotation:.3g} rad (beyond the {MAX_LINEAR_ROTATION:g} rad of small-rotation "
                    "beams): compress with geometry='nonlinear'")
    return "; ".join(msgs)


def compression_summary(curve, *, validity: float = 0.30) -> dict:
    """Modulus and DIN EN ISO 3386-1 style stresses from a ``compress`` Dataset.

    Returns {"modulus_kPa": slope of a line fit over the curve up to ``validity``,
    "stress_10_kPa", "stress_25_kPa", "stress_40_kPa": interpolated stresses (NaN where
    the curve does not reach), "beyond_validity": list of the levels above ``validity``
    (the linear small-rotation model is valid to about 30 % compression)}.
    """
    e = np.asarray(curve.strain.values, float)
    s = np.asarray(curve.stress.values, float)
    sel = e <= validity + 1e-12
    mod = float(np.polyfit(np.r_[0.0, e[sel]], np.r_[0.0, s[sel]], 1)[0]) if sel.sum() >= 1 else float("nan")
    out = {"modulus_kPa": mod, "beyond_validity": []}
    for lvl in (0.10, 0.25, 0.40):
        v = float(np.interp(lvl, np.r_[0.0, e], np.r_[0.0, s])) if lvl <= e.max() + 1e-12 else float("nan")
        out[f"stress_{int(round(lvl * 100))}_kPa"] = v
        if lvl > validity:
            out["beyond_validity"].append(lvl)
    return out
