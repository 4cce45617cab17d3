"""A strip of seam cells side by side under one punch: the yarn-level check of the macro layer.

A real seamed specimen's cushions differ (the thread tension varies along the seams, the pile
varies across the fabric), so the punch meets one cushion after another. The strip is a
periodic cell of ``k`` seams ``seam_distance`` apart, each sewn with its own stitch pre-strain, so
its ``k`` cushions differ in height; it is sewn and pressed on the large-motion engine as one
cell (:func:`homtex.seams.sew.sew` with ``seams=k``, :func:`homtex.seams.press.press_sewn`).

The macro layer predicts the strip's curve from single-cushion results; :func:`strip_check`
measures three such predictions against the strip:

* ``cushion_laws``: the single seam cells, each sewn with one of the strip's pre-strains and
  pressed alone (``seam_compression``), averaged (each cushion of the strip takes the law of the
  cell sewn like its seams);
* ``shifted_law``: one cushion law (the calibrated stitch, the middle of the strip's pre-strains)
  shifted in plate travel by each strip cushion's height difference from it (a cushion delta
  higher meets the punch delta earlier): what :func:`homtex.macro.macro_curve` with
  ``law="cushion"`` and a height scatter does;
* ``columns``: the default column model of :func:`homtex.macro.macro_curve` (the unseamed law
  and the single cells' cushion profiles).
"""

from __future__ import annotations

import logging
import time

import numpy as np
import xarray as xr

from ..cache import cached
from ..cells import Cell
from ..errors import InputError
from ..model.results import Status, set_status
from ..validate import check_int, check_number
from .compress import strain_levels
from .foundation import seam_table
from .measure import measure_profile
from .press import press_sewn
from .profile import seam_profile, sewn_seam
from .sew import SewnSeam

__all__ = ["strip_check", "strip_cushions", "strip_singles", "strip_yarn", "sew_strip"]

log = logging.getLogger(__name__)


def sew_strip(cell: Cell, *, seam_distance: float, prestrain, cache: bool = True, **kw) -> SewnSeam:
    """The strip of ``len(prestrain)`` seams, seam ``i`` sewn with ``prestrain[i]`` (length-controlled
    stitch), on the engine and from the result cache (:func:`homtex.seams.profile.sewn_seam`)."""
    eps = np.asarray(prestrain, dtype=float).reshape(-1)
    if eps.size < 2:
        raise InputError(f"a strip needs at least two seams (one pre-strain per seam), got {eps.size}")
    return sewn_seam(cell, seam_distance=seam_distance, prestrain=[float(e) for e in eps],
                     seams=int(eps.size), cache=cache, **kw)


def strip_cushions(sewn: SewnSeam) -> np.ndarray:
    """Height (mm) of each cushion of a sewn strip, (k,): cushion i lies between seam i and seam
    i + 1 (the last one between seam k and the first seam's periodic image)."""
    info = sewn.info
    k = int(info.get("seams", 1))
    d = float(info["seam_distance"])
    x, h = measure_profile(sewn.frame, info, sewn.u)
    xr_ = np.mod(x, k * d)                      # from the first seam, [0, k d)
    out = np.empty(k)
    for i in range(k):
        inside = (xr_ > i * d + 1e-9) & (xr_ < (i + 1) * d - 1e-9)
        out[i] = float(h[inside].max()) if inside.any() else np.nan
    return out


def _force_on(ds: xr.Dataset, strain: np.ndarray) -> np.ndarray:
    """A press Dataset's stress (kPa) at ``strain`` (levels before first contact carry none)."""
    e = np.r_[0.0, ds.strain.values]
    s = np.r_[0.0, ds.stress.values]
    return np.interp(strain, e, s, right=np.nan)


def strip_yarn(cell: Cell, *, seam_distance: float = 24.0, factors=(1.1, 0.9, 1.0), strain: float = 0.5,
               steps: int = 25, cache: bool = True) -> tuple:
    """The yarn-level half of :func:`strip_check`: the strip sewn (seam i with ``factors[i]`` x the
    calibrated pre-strain) and pressed to ``strain`` in ``steps`` levels, both from the result cache
    when there. Returns (SewnSeam, press Dataset); their ``attrs["seconds"]`` hold the time each
    took when it was computed. Independent of the single cells, so a caller may run it in another
    process while those are pressed (the main job does)."""
    factors = _check_factors(factors)
    seam_distance = check_number(seam_distance, "seam_distance", gt=0.0, le=1e3)
    strain = check_number(strain, "strain", gt=0.0, lt=1.0)
    steps = check_int(steps, "steps", ge=2, le=1000)
    eps = _strip_prestrains(cell, factors)
    levels = strain_levels(strain, steps)
    t0 = time.perf_counter()
    sewn = sew_strip(cell, seam_distance=seam_distance, prestrain=eps, cache=cache)
    sewn.attrs.setdefault("seconds", time.perf_counter() - t0)
    if sewn.status == "failed" and sewn.state is None:
        raise InputError(f"strip_check: the strip could not be sewn: {sewn.detail}")
    key = {"seam_distance": float(seam_distance), "prestrain": [float(e) for e in eps], "levels": levels}
    H0 = float(cell.info["thickness"])
    press = cached("strip_press", cell, key, lambda: press_sewn(sewn, levels, thickness=H0)) if cache \
        else press_sewn(sewn, levels, thickness=H0)
    return sewn, press


def strip_singles(cell: Cell, *, seam_distance: float, factors, strain: float, steps: int, cache: bool = True,
                  given: dict | None = None) -> tuple:
    """The single-cushion half of :func:`strip_check`: for each factor the seam cell sewn with
    factor x the calibrated stitch alone, its profile and its press to ``strain`` (cushion laws,
    from the result cache when there; ``given`` {factor: press Dataset} pressed before).
    Returns ([press Dataset], [profile Dataset], seconds: the time the presses not given took
    when they were computed, sewing included)."""
    from ..macro import cushion_law

    factors = _check_factors(factors)
    eps_cal = float(seam_table(cell).get("prestrain", 0.0))
    eps = _strip_prestrains(cell, factors)
    given = {round(float(f), 9): v for f, v in (given or {}).items()}
    singles, profiles, seconds = [], [], 0.0
    for f, e in zip(factors, eps):
        # the calibrated stitch by its default (None), so its sewn state is the one cached for it
        pre = None if float(f) == 1.0 and eps_cal < 0.95 else float(e)
        pressed = given.get(round(float(f), 9))
        if pressed is None or float(pressed.strain.values[-1]) < strain - 1e-9:
            pressed = cushion_law(cell, seam_distance=seam_distance, prestrain=pre, strain=strain, steps=steps,
                                  cache=cache)
            seconds += float(pressed.attrs.get("seconds_total", pressed.attrs.get("seconds", 0.0)))
        singles.append(pressed)
        profiles.append(seam_profile(cell, seam_distance=seam_distance, prestrain=pre, cache=cache))
    return singles, profiles, seconds


def _check_factors(factors) -> np.ndarray:
    factors = np.asarray(factors, dtype=float).reshape(-1)
    if factors.size < 2 or not np.all((factors > 0) & np.isfinite(factors)):
        raise InputError(f"factors: at least two positive numbers, got {factors.tolist()}")
    return factors


def _strip_prestrains(cell: Cell, factors: np.ndarray) -> np.ndarray:
    """Each seam's length-controlled pre-strain: its factor x the calibrated one (at most 0.95)."""
    eps_cal = float(seam_table(cell).get("prestrain", 0.0))
    if eps_cal <= 0.0:
        raise InputError("strip_check needs a length-controlled calibrated stitch ([parameters.seam] prestrain)")
    return np.minimum(factors * eps_cal, 0.95)


def strip_check(cell: Cell, *, seam_distance: float = 24.0, factors=(1.1, 0.9, 1.0), strain: float = 0.5,
                steps: int = 25, cache: bool = True, curve=None, singles: dict | None = None,
                yarn: tuple | None = None) -> xr.Dataset:
    """The strip of ``len(factors)`` seams (seam i sewn with ``factors[i]`` x the calibrated pre-strain)
    under one punch at yarn level, against the macro layer's three predictions (module docstring).

    Returns
    -------
    xarray.Dataset over ``strain`` (plate travel / unseamed thickness, ``steps`` levels to
    ``strain``): ``stress_strip`` (kPa, the yarn-level strip), ``stress_cushion_laws``,
    ``stress_shifted_law``, ``stress_columns`` (kPa, the predictions); over ``cushion``: the strip's
    cushion heights and the single cells'; attrs: the force error of each prediction (largest
    difference over the curve / the strip's stress at ``strain``), run times (s: the strip sewn and
    pressed; each prediction once its inputs exist; the inputs' own computation), status.

    ``curve``: the unseamed law of the column model (default the engine's, :func:`homtex.macro.engine_law`).
    ``singles``: {factor: press Dataset} single cells pressed before (``seam_compression`` of the
    cell sewn with that factor x the calibrated stitch, on the same levels or further), used instead
    of pressing them again; their time is then not in ``seconds_inputs``.
    ``yarn``: (sewn strip, press Dataset) from :func:`strip_yarn` with the same arguments, computed
    before (e.g. in another process); default: computed here (or read from the cache).
    """
    # the macro layer is built on the seam models: a check of it is its client
    from ..macro import macro_curve

    factors = _check_factors(factors)
    seam_distance = check_number(seam_distance, "seam_distance", gt=0.0, le=1e3)
    strain = check_number(strain, "strain", gt=0.0, lt=1.0)
    steps = check_int(steps, "steps", ge=2, le=1000)
    eps = _strip_prestrains(cell, factors)
    H0 = float(cell.info["thickness"])
    singles, profiles, t_inputs = strip_singles(cell, seam_distance=seam_distance, factors=factors, strain=strain,
                                                steps=steps, cache=cache, given=singles)
    # the strip at yarn level (computed before, e.g. in another process, or now)
    sewn, press = yarn if yarn is not None else strip_yarn(cell, seam_distance=seam_distance, factors=factors,
                                                           strain=strain, steps=steps, cache=cache)
    t_sew = float(sewn.attrs.get("seconds", 0.0))
    t_strip = t_sew + float(press.attrs.get("seconds", 0.0))
    e_grid = press.strain.values
    y = press.stress.values
    hc_strip = strip_cushions(sewn)
    hc_single = np.array([float(p.cushion_height) for p in profiles])
    # predictions
    tp = time.perf_counter()
    p_laws = np.mean([_force_on(s, e_grid) for s in singles], axis=0)
    t_laws = time.perf_counter() - tp
    i_mid = int(np.argmin(np.abs(factors - 1.0)))
    tp = time.perf_counter()
    # a cushion delta higher than the law's own meets the punch delta earlier (shift in travel)
    p_shift = np.mean([_force_on(singles[i_mid], e_grid + (h - hc_single[i_mid]) / H0) for h in hc_strip], axis=0)
    t_shift = time.perf_counter() - tp
    # columns: the strip's period under the plate, each cushion with its single cell's profile
    d = float(sewn.info["seam_distance"])
    k = factors.size
    xs = np.concatenate([p.x.values % d + i * d for i, p in enumerate(profiles)])
    hs = np.concatenate([p.height.values for p in profiles])
    o = np.argsort(xs)
    comp = xr.Dataset({"height": ("x", hs[o], {"units": "mm"}), "cushion_height": ((), float(hs.max())),
                       "slack_travel": ((), float(np.mean([float(p.slack_travel) for p in profiles])))},
                      coords={"x": ("x", xs[o], {"units": "mm"})})
    kw = dict(seam_distance=k * d, profile=comp, plate_area=(k * d) ** 2, strain=strain, curve=curve,
              n_columns=40 * k * int(round(d / float(cell.info["wale_spacing"]))))
    macro_curve(cell, steps=2, **kw)         # the law computed (or read from the cache) before timing
    tp = time.perf_counter()
    mc = macro_curve(cell, steps=401, **kw)
    t_cols = time.perf_counter() - tp
    p_cols = np.interp(e_grid, mc.strain.values, mc.stress.values)
    ref = float(np.interp(strain, e_grid, y))
    status, detail = Status(press.attrs.get("status", "ok")), str(press.attrs.get("status_detail", ""))
    errs = {}
    for name, p in (("cushion_laws", p_laws), ("shifted_law", p_shift), ("columns", p_cols)):
        ok = np.isfinite(p) & np.isfinite(y)
        errs[name] = float(np.max(np.abs(p[ok] - y[ok])) / ref) if ok.any() and ref > 0 else np.nan
    ds = xr.Dataset(
        {"stress_strip": ("strain", y, {"units": "kPa", "long_name": "strip of seam cells at yarn level"}),
         "stress_cushion_laws": ("strain", p_laws, {"units": "kPa", "long_name": "mean of the single cushions' laws"}),
         "stress_shifted_law": ("strain", p_shift, {"units": "kPa",
                                                    "long_name": "one cushion law shifted by each cushion's height"}),
         "stress_columns": ("strain", p_cols, {"units": "kPa",
                                               "long_name": "column model (unseamed law, single-cell profiles)"}),
         "cushion_height_strip": ("cushion", hc_strip, {"units": "mm", "long_name": "cushion heights in the strip"}),
         "cushion_height_single": ("cushion", hc_single,
                                   {"units": "mm", "long_name": "cushion heights of the single cells"}),
         "prestrain": ("cushion", eps, {"units": "1",
                                        "long_name": "stitch pre-strain of the seam before the cushion"})},
        coords={"strain": ("strain", e_grid, {"units": "1", "long_name": "plate travel / unseamed thickness"}),
                "cushion": ("cushion", np.arange(k), {"units": "1", "long_name": "cushion of the strip"})},
        attrs={"seam_distance_mm": d, "seams": k, "thickness_mm": H0, "reference_stress_kPa": ref,
               **{f"error_{n}": v for n, v in errs.items()},
               "seconds_strip": t_strip, "seconds_strip_sewing": t_sew, "seconds_inputs": t_inputs,
               "seconds_cushion_laws": t_laws, "seconds_shifted_law": t_shift, "seconds_columns": t_cols,
               "strip_status": press.attrs.get("status", "ok"), "sewn_status": sewn.status})
    set_status(ds, status, detail)
    log.info("strip_check d = %g mm: cushions %s mm (single %s); errors %s", d, np.round(hc_strip, 2),
             np.round(hc_single, 2), {n: round(v, 4) for n, v in errs.items()})
    return ds
