"""Cushion profiles of seamed spacer fabrics: ``seam_profile`` and the yarn-level model on the
large-motion engine behind it.

``seam_profile(method="yarn")`` sews the seam cell on the engine (:func:`homtex.seams.sew.sew`,
cached: :func:`sewn_seam`) and measures the cushion between the outer yarn surfaces;
``method="foundation"`` is the analytical beam-on-foundation model
(:mod:`homtex.seams.foundation`, milliseconds, calibrated on d = 24 mm); the geometrically
linear seam cell (``method="yarn", geometry="linear"``, :mod:`homtex.seams.yarn`) is kept for
comparison: it cannot form cushions (docs/seams.md).

The stitch parameter of the yarn model is calibrated once on d = 24 mm
(``[parameters.seam]`` of the cell file: ``stitch``, ``tension`` or ``prestrain``); the paper's
needle-thread settings map onto it by :func:`paper_setting`.
"""

from __future__ import annotations

import inspect
import logging

import numpy as np
import xarray as xr

from ..cache import cached
from ..cells import Cell
from ..contact.options import Contact
from ..errors import InputError
from ..model.results import Status, set_status
from ..validate import check_choice, check_number
from .foundation import SLACK_LONG_NAME, foundation_profile, seam_table
from .measure import leg_shortening
from .sew import SewnSeam, sew
from .yarn import linear_profile

__all__ = ["METHODS", "engine_profile", "paper_setting", "profile_dataset", "seam_profile", "sewn_seam"]

log = logging.getLogger(__name__)

METHODS = ("yarn", "foundation")

#: the paper's needle-thread tension setting of its seamed specimens (Table 1: "tension needle
#: thread 40 %"), the setting the calibrated stitch parameter stands for
PAPER_SETTING = 0.40

_SEAM_CELL_KEYS = ("stitches", "exact", "elements_per_mm", "leg_elements", "seams")


def paper_setting(cell: Cell, relative: float) -> dict:
    """The stitch arguments of ``seam_profile`` for the paper's relative needle-thread setting
    ``relative`` (its specimens: 0.40; its low-tension case: 0.15), by the documented rule: the
    calibrated stitch parameter (``[parameters.seam] tension`` in N, or ``prestrain``) stands for
    the paper's 40 %, and a setting scales it in proportion (0.15 -> 15/40 of it). Returns
    ``{"tension": T}`` or ``{"prestrain": eps0}``."""
    relative = check_number(relative, "relative", gt=0.0, le=1.0)
    seam = seam_table(cell)
    ratio = relative / PAPER_SETTING
    if seam.get("stitch", "length") == "tension":
        return {"tension": float(seam["tension"]) * ratio}
    return {"prestrain": min(float(seam.get("prestrain", 0.0)) * ratio, 0.95)}


def sewn_seam(cell: Cell, *, seam_distance: float, stitch: str | None = None, prestrain: float | None = None,
              tension: float | None = None, contact: Contact | None = None, steps: int | None = None,
              perturbation: float | None = None, imperfection: float = 0.0, seed=None, max_cuts: int = 6,
              cache: bool = True, **seam_kw) -> SewnSeam:
    """The seam cell sewn on the engine (:func:`homtex.seams.sew.sew`, same arguments), from the
    result cache when it was sewn before with the same cell content, arguments and homtex
    version (:mod:`homtex.cache`)."""
    kw = dict(seam_distance=float(seam_distance), stitch=stitch, prestrain=prestrain, tension=tension,
              contact=contact, steps=steps, perturbation=perturbation, imperfection=imperfection, seed=seed,
              max_cuts=max_cuts, **seam_kw)
    if not cache:
        return sew(cell, **kw)
    box = {}

    def compute():
        s = sew(cell, **kw)
        box["sewn"] = s
        ds = s.to_dataset()
        ds.attrs["status"] = s.status
        return ds

    ds = cached("sewn", cell, kw, compute)
    if "sewn" in box:
        return box["sewn"]
    return SewnSeam.from_dataset(cell, ds, contact=contact, **{k: v for k, v in seam_kw.items()
                                                                if k in _SEAM_CELL_KEYS})


def profile_dataset(s: SewnSeam) -> xr.Dataset:
    """The cushion profile Dataset of a sewn seam cell (see :func:`seam_profile`)."""
    x, h = s.profile()
    if s.status == "failed" and s.state is None:
        h = np.full_like(h, np.nan)
    info, frame = s.info, s.frame
    i0 = int(np.argmin(np.abs(x)))
    legs = np.asarray(info["legs"], dtype=bool)
    xyz = frame.nodes + s.u[:, :3]
    el = frame.elements
    seg = np.linalg.norm(xyz[el[:, 1]] + frame.shift - xyz[el[:, 0]], axis=1)
    m0 = int(info["fabric_elements"])
    strands = np.where(legs, 2.0, 1.0)
    per_stitch = float((seg[m0:] * strands[m0:]).sum()) / int(info["stitches"])
    N_leg = float(s.path.leg_tension.values[-1]) if s.path.sizes.get("step", 0) else 0.0
    L_legs = float(seg[legs].sum()) / int(info["stitches"])
    slack = max(N_leg, 0.0) * L_legs / (2.0 * float(info["stitch_EA"]))
    xc, loss = leg_shortening(frame, info, s.u)
    near = np.abs(xc) < 3.0
    d_eff = float(info["seam_distance"])
    ds = xr.Dataset(
        {"height": ("x", h, {"units": "mm", "long_name": "cushion height (outer yarn surfaces, per wale bin)"}),
         "cushion_height": ((), float(np.max(h)), {"units": "mm", "long_name": "cushion height (max height "
                                                   "between seams)"}),
         "seam_height": ((), float(h[i0]), {"units": "mm", "long_name": "height at the seam line"}),
         "stitch_force": ((), N_leg, {"units": "N", "long_name": "axial force of a stitch leg (two thread strands)"}),
         "slack_travel": ((), slack, {"units": "mm", "long_name": SLACK_LONG_NAME}),
         "prestrain": ((), float(s.prestrain), {"units": "1", "long_name": "stitch-yarn pre-strain eps0 "
                                                "(length-controlled stitch; 0 for a tension-controlled one)"}),
         "tension": ((), float(s.tension), {"units": "N", "long_name": "needle-thread tension per strand "
                                            "(tension-controlled stitch; 0 for a length-controlled one)"}),
         "thread_per_stitch": ((), per_stitch, {"units": "mm", "long_name": "thread length per stitch in the sewn "
                                                "state (needle and bobbin threads, both strands of each leg)"}),
         "leg_loss_near_seam": ((), float(loss[near].max(initial=0.0)),
                                {"units": "1", "long_name": "largest loss of end-to-end length of a pile leg within "
                                 "3 mm of the seam line"}),
         "seam_distance": ((), d_eff, {"units": "mm", "long_name": "effective seam distance (whole fabric repeats)"}),
         "leg_x": ("leg", xc, {"units": "mm", "long_name": "pile leg centre across the seam (0 = seam line)"}),
         "leg_loss": ("leg", loss, {"units": "1", "long_name": "loss of end-to-end length of each pile leg"})},
        coords={"x": ("x", x, {"units": "mm", "long_name": "position across the seam (0 = seam line)"}),
                "leg": ("leg", np.arange(len(xc)), {"units": "1", "long_name": "pile leg"})})
    path = s.path
    ds.attrs.update(
        model="yarn", method="yarn", geometry="nonlinear", stitch=s.stitch,
        description="yarn-level seam cell sewn on the large-motion engine (co-rotational beams, barrier contact, "
                    f"friction up to {s.attrs.get('friction_max', 0):g}, lock stitch 301 "
                    + ("fed at a constant tension, sliding through the needle holes)" if s.stitch == "tension"
                       else "with a length-controlled pre-strain)"),
        requested_seam_distance_mm=float(info["requested_seam_distance"]), effective_seam_distance_mm=d_eff,
        stitch_length_mm=float(info["stitch_length"]), stitches=int(info["stitches"]),
        thickness_mm=float(info["thickness"]), n_nodes=int(frame.n_nodes), n_elements=int(frame.n_elements),
        repeats_x=int(info["n_x"]), repeats_y=int(info["n_y"]), ramp_steps=int(s.attrs.get("ramp_steps", 0)),
        ramp_done=float(s.attrs.get("ramp_done", 0.0)),
        branch_switches=np.asarray(s.attrs.get("branch_switches", []), dtype=float).reshape(-1),
        perturbation_mm=float(s.attrs.get("perturbation_mm", 0.0)),
        imperfection_mm=float(s.attrs.get("imperfection_mm", 0.0)), seed=str(s.attrs.get("seed", "none")),
        seconds=float(s.attrs.get("seconds", 0.0)), cpu_seconds=float(s.attrs.get("cpu_seconds", 0.0)),
        stitch_fabric_contacts=int(path.stitch_fabric_contacts.values[-1]) if path.sizes.get("step", 0) else 0,
        buckled_legs=int(path.buckled_legs.values[-1]) if path.sizes.get("step", 0) else 0,
        buckled_reach_mm=float(path.buckled_reach.values[-1]) if path.sizes.get("step", 0) else 0.0,
        energy_balance=float(path.energy_balance.values[-1]) if path.sizes.get("step", 0) else 0.0)
    return set_status(ds, Status(s.status), s.detail)


def engine_profile(cell: Cell, *, seam_distance: float, prestrain: float | None = None, tension: float | None = None,
                   **options) -> xr.Dataset:
    """Cushion profile of the yarn-level seam cell sewn on the engine (``seam_profile(method="yarn")``);
    ``options`` go to :func:`sewn_seam` (stitch, contact, steps, perturbation, imperfection, seed,
    cache, stitches, exact, elements_per_mm, leg_elements)."""
    seam_distance = check_number(seam_distance, "seam_distance", gt=0.0, le=1e4)
    use_cache = bool(options.get("cache", True))

    def compute():
        ds = profile_dataset(sewn_seam(cell, seam_distance=seam_distance, prestrain=prestrain, tension=tension,
                                       **options))
        ds.attrs["validity"] = validity_note(cell)
        return ds

    if not use_cache:
        return compute()
    params = {"seam_distance": float(seam_distance), "prestrain": prestrain, "tension": tension,
              **{k: v for k, v in options.items() if k != "cache"}}
    return cached("profile", cell, params, compute)


def validity_note(cell: Cell) -> str:
    """What the calibrated yarn-level seam model stands on (every profile carries it)."""
    seam = seam_table(cell)
    par = (f"tension {float(seam['tension']):.4g} N per strand" if seam.get("stitch") == "tension"
           else f"pre-strain {float(seam.get('prestrain', 0.0)):.4g}")
    return (f"stitch calibrated once on d = 24 mm ({seam.get('stitch', 'length')}-controlled, {par}, "
            f"{seam.get('calibration', 'see the cell file')}); other seam distances are predictions; "
            "docs/seams.md gives the measured accuracy")


def seam_profile(cell: Cell, *, seam_distance: float, prestrain: float | None = None, tension: float | None = None,
                 method: str | None = None, **options) -> xr.Dataset:
    """Cushion profile of a spacer fabric with parallel lock-stitch seams.

    Parameters
    ----------
    cell : spacer Cell (``cells/spacer_20mm.toml``) with a [parameters.seam] table.
    seam_distance : d, mm.
    prestrain : pre-strain eps0 of a length-controlled stitch (None: the calibrated value of the
        method; the yarn model: ``[parameters.seam] prestrain``, the foundation model
        ``foundation_prestrain``).
    tension : needle-thread tension (N per strand) of a tension-controlled stitch (yarn model;
        None: ``[parameters.seam] tension``). The paper's settings: :func:`paper_setting`.
    method : "yarn" (the yarn-level seam cell sewn on the large-motion engine) or "foundation"
        (the analytical beam-on-foundation model); None: ``[parameters.seam] method`` of the cell
        file, else "yarn".
    options : yarn: stitch ("length" or "tension"), contact, steps, perturbation, imperfection,
        seed, cache, stitches, exact, elements_per_mm, leg_elements, geometry ("nonlinear", or
        "linear": the former small-rotation seam cell); foundation: points, exact_wales.

    Returns
    -------
    xarray.Dataset with ``height`` (mm) over ``x`` (mm, 0 = seam line), scalar ``cushion_height``
    (mm), ``seam_height`` (mm), ``stitch_force`` (N), ``slack_travel`` (mm), ``prestrain``; the
    engine also ``tension`` (N), ``thread_per_stitch`` (mm), ``leg_loss`` per pile leg; attrs
    ``method``, ``status``, ``validity``, ``effective_seam_distance_mm``.
    """
    seam = seam_table(cell)
    method = check_choice(seam.get("method", "yarn") if method is None else method, "method", METHODS)
    if method == "foundation":
        if tension is not None:
            raise InputError("seam_profile(method='foundation') takes prestrain=, not tension=")
        fn = foundation_profile
    else:
        geometry = options.pop("geometry", "nonlinear")
        check_choice(geometry, "geometry", ("linear", "nonlinear"))
        if geometry == "linear":
            if tension is not None:
                raise InputError("the linear seam cell (geometry='linear') takes prestrain=, not tension=")
            fn = linear_profile
        else:
            fn = engine_profile
            allowed = set(inspect.signature(sewn_seam).parameters) - {"cell", "seam_distance", "prestrain",
                                                                       "tension"}
            allowed |= set(_SEAM_CELL_KEYS)
            unknown = sorted(set(options) - allowed)
            if unknown:
                raise InputError(f"seam_profile(method='yarn'): unknown option(s) {unknown}; allowed: "
                                 f"{sorted(allowed | {'geometry'})}")
            return fn(cell, seam_distance=seam_distance, prestrain=prestrain, tension=tension, **options)
    allowed = set(inspect.signature(fn).parameters) - {"cell", "seam_distance", "prestrain"}
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise InputError(f"seam_profile(method={method!r}): unknown option(s) {unknown}; allowed: {sorted(allowed)}")
    return fn(cell, seam_distance=seam_distance, prestrain=prestrain, **options)
