"""The seamed stages of the main job, on the large-motion engine: cushions sewn from the yarns,
the seamed specimen under the punch (the paper's Fig. 11), the macro layer fed by them, a strip of
differing cushions against the macro layer. Each computes, writes netCDF + PNG into an output
folder and returns what it wrote; sewn states and pressed curves come from the result cache
(:mod:`homtex.cache`) when computed before, so every sewn state is computed once per cache.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np
import xarray as xr

from ..api import compress
from ..errors import InputError
from ..lookup import Lookup
from ..macro import cushion_law, macro_curve
from ..output.charts import (
    PAPER_CUSHIONS_MM,
    cushions_chart,
    macro_chart,
    save,
    seamed_chart,
    speed_accuracy_chart,
    strip_chart,
)
from ..seams import seam_profile
from ..seams.compress import strain_levels
from ..seams.foundation import seam_table
from ..seams.profile import PAPER_SETTING, paper_setting
from ..seams.strip import strip_check, strip_singles
from .paths import heartbeat
from .stages import _attrs, _save, _timed, describe

__all__ = ["cushion_stage", "curve_error", "macro_stage", "seamed_stage", "speed_accuracy_stage", "strip_stage"]

log = logging.getLogger(__name__)

#: the paper's low needle-thread setting (its specimens were sewn at 40 %)
LOW_SETTING = 0.15


def curve_error(ref_x, ref_y, x, y, xmax) -> float:
    """max |y - y_ref| / max |y_ref| over 0 < x <= xmax (y interpolated onto the reference x; both
    curves start from 0); NaN when the curve (x, y) does not reach the reference's last point."""
    ref_x, ref_y, x, y = (np.asarray(v, dtype=float) for v in (ref_x, ref_y, x, y))
    sel = (ref_x > 0) & (ref_x <= xmax + 1e-12) & np.isfinite(ref_y)
    ok = np.isfinite(x) & np.isfinite(y)
    if not sel.any() or not ok.any() or x[ok].max() < ref_x[sel].max() - 1e-9:
        return float("nan")
    yi = np.interp(ref_x[sel], np.r_[0.0, x[ok]], np.r_[0.0, y[ok]])
    return float(np.abs(yi - ref_y[sel]).max() / np.abs(ref_y[sel]).max())


# ----------------------------------------------------------------------------- cushions
def _case_label(d: float, setting) -> str:
    return f"d={d:g}" + ("" if setting is None else f", setting {100 * setting:g} %")


def cushion_stage(cell, out: Path, *, distances=(18.0, 24.0, 43.0), low_setting: float = LOW_SETTING) -> tuple:
    """Cushion profiles for the paper's seam distances and its low needle-thread setting at the
    largest one, with the yarn-level seam sewn on the engine (``seam_profile``'s default, the
    stitch calibrated once on 24 mm) and the analytical foundation model (its eps0 the machine's
    setting, layer rigidity calibrated on 24 mm). The low setting maps to each model's stitch
    parameter by the same rule (:func:`homtex.seams.profile.paper_setting`: in proportion to the
    paper's 40 %).

    Returns ({"yarn"|"foundation": {(d, setting or None): profile}}, table rows, {name: path}).
    """
    methods = ("yarn", "foundation")
    profiles = {m: {} for m in methods}
    secs = {m: {} for m in methods}
    cases = [(float(d), None) for d in distances] + [(float(max(distances)), float(low_setting))]
    eps_f = float(seam_table(cell).get("foundation_prestrain", PAPER_SETTING))
    for d, setting in cases:
        for m in methods:
            if setting is None:
                kw = {}
            elif m == "yarn":
                kw = paper_setting(cell, setting)
            else:
                kw = {"prestrain": eps_f * setting / PAPER_SETTING}
            with heartbeat(f"seam profile ({m}), {_case_label(d, setting)}"):
                prof, sec = _timed(seam_profile, cell, seam_distance=d, method=m, **kw)
            if prof.attrs.get("status", "ok") == "failed":
                raise InputError(f"seam profile ({m}, {_case_label(d, setting)}) failed: "
                                 f"{prof.attrs.get('status_detail', '')}")
            profiles[m][(d, setting)] = prof
            # a sewn state from the cache took its sewing's time once: report that, not the read
            secs[m][(d, setting)] = max(sec, float(prof.attrs.get("seconds", 0.0)))
    rows = []
    for d, setting in cases:
        y, f = profiles["yarn"][(d, setting)], profiles["foundation"][(d, setting)]
        ref = PAPER_CUSHIONS_MM.get(d) if setting is None else None
        meas, sim = ("-", "-") if ref is None else (f"{ref[0]:g}" if ref[0] == ref[1] else f"{ref[0]:g}-{ref[1]:g}",
                                                    f"{ref[2]:g}")
        stitch = (f"T = {float(y['tension']):.3g} N" if y.attrs.get("stitch") == "tension"
                  else f"eps0 = {float(y['prestrain']):.3f}")
        rows.append((f"{d:g} ({y.attrs.get('effective_seam_distance_mm', d):.4g})",
                     "40 % (calibrated)" if setting is None else f"{100 * setting:g} %", stitch,
                     f"{float(y['cushion_height']):.2f}", f"{float(y['seam_height']):.2f}",
                     f"{100 * float(y['leg_loss_near_seam']):.1f} %", f"{secs['yarn'][(d, setting)]:.0f}",
                     y.attrs.get("status", "ok"), f"{float(f['prestrain']):.3f}",
                     f"{float(f['cushion_height']):.2f}", meas, sim))
    ds = _cushion_dataset(cell, profiles, secs, cases)
    nc = _save(_attrs(ds, title="cushion heights and profiles (seam sewn on the engine; foundation model)"),
               out / "cushions.nc")
    png = save(cushions_chart(ds), out / "cushions.png")
    return profiles, rows, {"cushion heights (netCDF)": nc, "cushion profiles (chart)": png}


CUSHION_HEADER = ["d, mm (seam cell)", "needle-thread setting", "yarn stitch", "yarn cushion, mm",
                  "yarn seam line, mm", "largest pile-leg loss within 3 mm", "yarn sewing, s", "yarn status",
                  "foundation eps0", "foundation cushion, mm", "measured, mm", "paper sim., mm"]


def _cushion_dataset(cell, profiles, secs, keys) -> xr.Dataset:
    """cushions.nc: every case's profile on xi = x / effective seam distance (x = 0: the seam
    line), heights, effective seam distances and the paper's measured and simulated heights."""
    methods = ("yarn", "foundation")
    xi = np.linspace(-0.5, 0.5, 121)

    def d_eff(p, d):
        return float(p.attrs.get("effective_seam_distance_mm", d))

    def on_xi(p, d):
        dd = d_eff(p, d)   # x = 0 is the seam line in both models; the profile repeats every dd
        return np.interp(xi * dd, p.x.values, p.height.values, period=dd)

    data = {}
    for m in methods:
        P = profiles[m]
        data[f"height_{m}"] = (("case", "xi"), np.array([on_xi(P[k], k[0]) for k in keys]),
                               {"units": "mm", "long_name": f"cushion profile h(x), {m} model"})
        for var, unit, what in (("cushion_height", "mm", "cushion height"), ("seam_height", "mm", "height at the "
                                "seam line"), ("prestrain", "1", "stitch-yarn pre-strain")):
            data[f"{var}_{m}"] = ("case", [float(P[k][var]) for k in keys],
                                  {"units": unit, "long_name": f"{what}, {m} model"})
        data[f"seam_distance_{m}"] = ("case", [d_eff(P[k], k[0]) for k in keys],
                                      {"units": "mm", "long_name": f"effective seam distance (the profile's "
                                       f"period), {m} model"})
        data[f"seconds_{m}"] = ("case", [secs[m][k] for k in keys], {"units": "s", "long_name": f"run time, {m} "
                                "model (the sewing's own time when read from the result cache)"})
    Y = profiles["yarn"]
    data["leg_loss_near_seam_yarn"] = ("case", [float(Y[k]["leg_loss_near_seam"]) for k in keys],
                                       {"units": "1", "long_name": "largest loss of end-to-end length of a pile "
                                        "leg within 3 mm of the seam line, yarn model"})
    data["tension_yarn"] = ("case", [float(Y[k]["tension"]) for k in keys],
                            {"units": "N", "long_name": "needle-thread tension per strand, yarn model "
                             "(0: length-controlled stitch)"})
    data["seam_distance"] = ("case", [k[0] for k in keys], {"units": "mm", "long_name": "seam distance asked for"})
    data["needle_thread_setting"] = ("case", [PAPER_SETTING if k[1] is None else k[1] for k in keys],
                                     {"units": "1", "long_name": "the paper's relative needle-thread setting"})
    ref = sorted(PAPER_CUSHIONS_MM.items())
    for i, (var, what) in enumerate((("cushion_height_measured_low", "measured cushion height, lower end (paper, "
                                      "Table 1)"),
                                     ("cushion_height_measured_high", "measured cushion height, upper end (paper, "
                                      "Table 1)"),
                                     ("cushion_height_paper_simulation", "cushion height simulated in the paper"))):
        data[var] = ("paper_distance", [r[i] for _, r in ref], {"units": "mm", "long_name": what})
    ds = xr.Dataset(data, coords={
        "paper_distance": ("paper_distance", [d for d, _ in ref],
                           {"units": "mm", "long_name": "seam distance of the paper's specimens"}),
        "case": [_case_label(*k) for k in keys],
        "xi": ("xi", xi, {"units": "1", "long_name": "position across the seam / effective seam distance "
                          "(0: the seam line, +-0.5: midway between seams)"})})
    y0 = Y[keys[0]]
    ds.attrs.update(yarn_model=str(y0.attrs.get("description", "yarn-level seam cell")),
                    yarn_geometry=str(y0.attrs.get("geometry", "nonlinear")),
                    yarn_status="; ".join(f"{_case_label(*k)}: {Y[k].attrs.get('status', 'ok')}" for k in keys),
                    foundation_model=str(profiles["foundation"][keys[0]].attrs.get("description", "")))
    return describe(ds, "cushions", cell, coords={"case": ("1", "seam distance asked for, mm, and the needle-thread "
                                                           "setting when not the paper's 40 %")})


# ----------------------------------------------------------------------------- macro curves
def macro_stage(cell, out: Path, *, distances=(18.0, 24.0, 43.0), scatter=1.0, strain=0.7, seed=0,
                curve=None) -> tuple:
    """Macro cushion-layer curves under the 121 cm^2 plate for no seams and each seam distance,
    exactly as ``macro_curve(cell, seam_distance=d, height_scatter=scatter, strain=strain)`` gives
    them (its defaults: the engine's unseamed law, the cushions sewn on the engine; ``curve``
    another unseamed law). Returns (Dataset, {name: path})."""
    cases = [None, *distances]
    curves, secs = [], []
    for d in cases:
        with heartbeat(f"macro curve, {'no seams' if d is None else f'd = {d:g} mm'}"):
            ds, sec = _timed(macro_curve, cell, seam_distance=d, height_scatter=0.0 if d is None else scatter,
                             strain=strain, seed=seed, curve=curve)
        curves.append(ds)
        secs.append(sec)
    w = curves[0].plate_displacement.values
    F = np.array([np.interp(w, c.plate_displacement.values, c.force.values, right=np.nan) for c in curves])
    area = float(curves[0].attrs.get("plate_area_mm2", 12100.0))
    names = ["no seams" if d is None else f"d={d:g}" for d in cases]
    out_ds = xr.Dataset(
        {"force": (("specimen", "plate_displacement"), F, {"units": "N", "long_name": "punch force"}),
         "stress": (("specimen", "plate_displacement"), F / area * 1e3,
                    {"units": "kPa", "long_name": "punch force / plate area"}),
         "seconds": ("specimen", secs, {"units": "s", "long_name": "macro-layer run time (the first call: "
                                        "with its inputs' computation or cache read)"})},
        coords={"specimen": names,
                "plate_displacement": ("plate_displacement", w, {"units": "mm",
                                       "long_name": "punch travel from the 20 mm plate distance"})})
    out_ds.attrs.update(height_scatter_mm=scatter, seed=seed, plate_area_mm2=area,
                        law=str(curves[0].attrs.get("law", "columns")),
                        status="; ".join(f"{n}: {c.attrs.get('status', 'ok')}" for n, c in zip(names, curves)))
    describe(out_ds, "macro_curves", cell, coords={"specimen": ("1", "specimen (seam distance)")})
    nc = _save(_attrs(out_ds, title="macro cushion layer: force-compression of seamed specimens"),
               out / "macro_curves.nc")
    png = save(macro_chart(out_ds), out / "macro_curves.png")
    return out_ds, {"macro curves (netCDF)": nc, "macro curves (chart)": png}


# ----------------------------------------------------------------------------- seamed: yarn vs macro
def seamed_stage(cell, unseamed, profiles, out: Path, *, seam_distance=24.0, strain=0.7, steps=35,
                 error_strain=0.5, curve=None) -> tuple:
    """The seamed specimen under the punch at yarn level (the seam cell sewn and pressed on the
    engine, :func:`homtex.macro.cushion_law`, the paper's Fig. 11) beside the unseamed fabric, against
    the macro layer fed the engine's cushion (``macro_curve``'s default) and fed the foundation
    model's: force error to ``error_strain`` and to ``strain``, and the run-time ratio, measured in
    this run (``curve``: the macro layer's unseamed law, default the engine's cached one).
    Returns (Dataset, summary dict, {name: path})."""
    H0 = float(cell.info["thickness"])
    d = float(seam_distance)
    with heartbeat(f"yarn-level seam cell d = {d:g} mm under the punch to {100 * strain:g} % (engine)"):
        yarn, t_read = _timed(cushion_law, cell, seam_distance=d, strain=strain, steps=steps)
    if yarn.sizes["strain"] == 0:
        raise InputError(f"yarn-level seamed compression failed at once: {yarn.attrs.get('status_detail', '')}")
    # the press's own time (sewing + press) when it was computed, also if read from the cache now
    t_yarn = max(t_read, float(yarn.attrs.get("seconds", 0.0)) + float(yarn.attrs.get("sewn_seconds", 0.0)))
    macro_curve(cell, seam_distance=d, strain=strain, curve=curve)   # its inputs from the cache before timing
    macro, t_macro = _timed(macro_curve, cell, seam_distance=d, strain=strain, steps=201, curve=curve)
    found, t_found = _timed(macro_curve, cell, seam_distance=d, strain=strain, steps=201, curve=curve,
                            profile=profiles["foundation"][(d, None)])
    w_y, s_y = yarn.plate_displacement.values, yarn.stress.values
    errs = {}
    for key, m in (("macro", macro), ("macro_foundation", found)):
        for lim, tag in ((error_strain, "to_error_strain"), (strain, "to_end")):
            errs[f"{key}_{tag}"] = curve_error(w_y, s_y, m.plate_displacement.values, m.stress.values, lim * H0)
    tr = macro.plate_displacement.values
    ds = xr.Dataset(
        {"stress_yarn": ("plate_displacement", s_y, {"units": "kPa", "long_name": f"yarn level, seams every "
                                                      f"{d:g} mm (sewn and pressed on the engine)"}),
         "force_yarn": ("plate_displacement", yarn.force.values, {"units": "N", "long_name": "force on the seam "
                                                                   "cell (yarn level)"}),
         "plate_contacts": ("plate_displacement", yarn["cushion_plate_contacts"].values,
                            {"units": "1", "long_name": "fabric-plate contacts (yarn level)"}),
         "cushions_touched": ("plate_displacement", yarn["cushions_touched"].values,
                              {"units": "1", "long_name": "wale bins of the cushion touching the plate"}),
         "stress_macro_curve": ("travel", macro.stress.values,
                                {"units": "kPa", "long_name": "macro layer: engine cushion, unseamed law"}),
         "stress_macro_foundation_curve": ("travel", np.interp(tr, found.plate_displacement.values,
                                                               found.stress.values),
                                           {"units": "kPa", "long_name": "macro layer: foundation-model cushion, "
                                            "unseamed law"}),
         "stress_unseamed_curve": ("travel", np.interp(tr / H0, np.r_[0.0, unseamed.strain.values],
                                                       np.r_[0.0, unseamed.stress.values], right=np.nan),
                                   {"units": "kPa", "long_name": "unseamed fabric (yarn level, engine)"})},
        coords={"plate_displacement": ("plate_displacement", w_y, {"units": "mm", "long_name": "punch travel "
                                                                   "from the 20 mm plate distance"}),
                "travel": ("travel", tr, {"units": "mm", "long_name": "punch travel from the 20 mm plate distance "
                                          "(macro curves' resolution)"})})
    ds.attrs.update(seam_distance_mm=d, cell_seam_distance_mm=float(yarn.attrs.get("seam_distance_mm", d)),
                    yarn_seconds=t_yarn, macro_seconds=t_macro, foundation_macro_seconds=t_found,
                    speedup=t_yarn / t_macro, error_range_mm=error_strain * H0, end_strain=strain,
                    sewn_thickness_mm=float(yarn.attrs.get("sewn_thickness_mm", np.nan)),
                    yarn_status=yarn.attrs.get("status", "ok"), yarn_status_detail=yarn.attrs.get("status_detail", ""),
                    **{f"max_relative_error_{k}": v for k, v in errs.items()})
    describe(ds, "seamed_vs_macro", cell)
    nc = _save(_attrs(ds, title=f"seamed d = {d:g} mm: yarn level vs macro layer"), out / "seamed_yarn_vs_macro.nc")
    png = save(seamed_chart(ds), out / "seamed_yarn_vs_macro.png")
    summary = {"yarn": yarn, "seam_distance": d, "yarn_seconds": t_yarn, "macro_seconds": t_macro,
               "speedup": t_yarn / t_macro,
               "foundation_seconds": t_found, **errs}
    return ds, summary, {"seamed yarn vs macro (netCDF)": nc, "seamed yarn vs macro (chart)": png}


# ----------------------------------------------------------------------------- strip
def strip_stage(cell, out: Path, *, seam_distance=24.0, factors=(1.0, 0.9), strain=0.5, steps=25,
                curve=None, singles=None, background=None) -> tuple:
    """A strip of ``len(factors)`` seam cells side by side (seam i sewn with ``factors[i]`` x the
    calibrated stitch) under one punch at yarn level against the macro layer's predictions from
    single cushions (:func:`homtex.seams.strip.strip_check`; ``singles`` {factor: pressed single
    cell} computed before, e.g. the seamed stage's; ``background`` a job computing
    :func:`homtex.seams.strip.strip_yarn` with these arguments in another process, waited for once
    the single cells are pressed). Returns (Dataset, {name: path})."""
    t0 = time.perf_counter()
    kw = dict(seam_distance=seam_distance, factors=factors, strain=strain, steps=steps, curve=curve)
    yarn = None
    if background is not None:
        # the single cells here while the strip finishes there; then the strip from that process
        with heartbeat(f"single cells of the strip ({seam_distance:g} mm) pressed to {100 * strain:g} %"):
            strip_singles(cell, seam_distance=seam_distance, factors=factors, strain=strain, steps=steps,
                          given=singles)
        with heartbeat(f"waiting for the strip of {len(factors)} seam cells (second process)"):
            yarn = background.result()
    with heartbeat(f"strip of {len(factors)} seam cells ({seam_distance:g} mm) under one punch to "
                   f"{100 * strain:g} %"):
        ds = strip_check(cell, singles=singles, yarn=yarn, **kw)
        ds.attrs["seconds_total"] = time.perf_counter() - t0
        ds.attrs["strip_process"] = "second process, from the job's start" if background is not None else "main process"
    describe(ds, "strip_vs_macro", cell)
    nc = _save(_attrs(ds, title="strip of seam cells under one punch against the macro layer"),
               out / "strip_vs_macro.nc")
    png = save(strip_chart(ds), out / "strip_vs_macro.png")
    return ds, {"strip vs macro (netCDF)": nc, "strip vs macro (chart)": png}


# ----------------------------------------------------------------------------- speed against accuracy
def _seconds(ds, key="seconds") -> float:
    return float(ds.attrs.get(key, np.nan))


def _judged(label, ds, rx, ry, end) -> tuple:
    """(label, error) of a curve against the reference (rx, ry) to ``end``; a curve that stopped
    short or is not "ok" says so in its label, its error over the range it reached."""
    reached = float(ds.strain.values[-1]) if ds.sizes.get("strain", 0) else 0.0
    status = ds.attrs.get("status", "ok")
    if reached < end - 1e-9:
        label += f", stopped at {100 * reached:.0f} % ({status})"
    elif status != "ok":
        label += f" ({status})"
    return label, curve_error(rx, ry, ds.strain.values, ds.stress.values, min(end, reached))


def speed_accuracy_stage(cell, unseamed, seamed, strip, out: Path, *, quick: bool = False) -> tuple:
    """Error against run time over model fidelities, for three questions (each against its most
    faithful model, error 0):

    A. the unseamed curve to the law's end (engine at the shipped resolution and 2 % levels;
       against it: half the levels, coarser meshes, the linear model, a lookup);
    B. the seamed curve of :func:`seamed_stage` to its end (yarn level on the engine, with its
       sewing; against it: the macro layer fed the engine's cushion, fed the foundation model's;
       the seamed press's step and mesh convergence: studies/verification/convergence_seam_engine.py);
    C. the strip of :func:`strip_stage` to its end (yarn level; against it: the macro layer's three
       predictions from single cushions).

    ``unseamed`` the engine curve, ``seamed`` the summary of :func:`seamed_stage`, ``strip`` the
    Dataset of :func:`strip_stage`. Returns (Dataset, {name: path}).
    """
    rows = []   # (question, model, error, seconds)
    H0 = float(cell.info["thickness"])
    rx, ry = unseamed.strain.values, unseamed.stress.values
    e_end = float(rx[-1])
    qa = f"A unseamed to {100 * e_end:.0f} %"
    n_ref = int(unseamed.sizes["strain"])
    rows.append((qa, f"engine, shipped mesh, {n_ref} levels (ref.)", 0.0, _seconds(unseamed)))
    half = strain_levels(e_end, max(2, int(round(e_end / 0.04))))
    variants = [(f"engine, {half.size} levels", cell, half)]
    if not quick:
        variants += [("engine, 1 element per segment", cell.replace(**{"resolution.elements_per_segment": 1}), rx),
                     ("engine, 4 pile segments (the former mesh)", cell.replace(**{"resolution.pile_segments": 4}),
                      rx)]
    curves = []
    for label, c, lv in variants:
        with heartbeat(f"speed-accuracy: unseamed curve, {label}"):
            ds, sec = _timed(compress, c, strain=lv)
        rows.append((qa, *_judged(label, ds, rx, ry, e_end), sec))
        curves.append(ds)
    coarse = curves[0]                   # the half-level curve, stored for the lookup below
    with heartbeat("speed-accuracy: unseamed curve, linear model"):
        ds, sec = _timed(compress, cell, strain=e_end, steps=max(2, int(round(e_end / 0.02))), geometry="linear")
    # its validity (the cell file's [validity]) is in the cushion table's notes and docs/limits.md
    rows.append((qa, *_judged("linear model", ds, rx, ry, e_end), sec))
    # (a curve that stopped short is judged over the range it reached: its label says where)
    lk, _ = _timed(Lookup.from_dataset, coarse, "stress")
    q = rx[(rx >= coarse.strain.values[0]) & (rx <= coarse.strain.values[-1])]   # a lookup does not extrapolate
    val, sec = _timed(lk, q[:, None])
    rows.append((qa, f"lookup of the {half.size}-level curve", curve_error(rx, ry, q, np.ravel(val), e_end), sec))
    # B: the seamed specimen
    yarn = seamed["yarn"]
    d = float(seamed["seam_distance"])
    b_end = float(yarn.strain.values[-1])
    qb = f"B seamed d={d:g} to {100 * b_end:.0f} %"
    rows.append((qb, f"engine seam cell, {yarn.sizes['strain']} levels + sewing (ref.)", 0.0,
                 seamed["yarn_seconds"]))
    for key, sk, label in (("macro", "macro_seconds", "macro layer, engine cushion"),
                           ("macro_foundation", "foundation_seconds", "macro layer, foundation cushion")):
        rows.append((qb, label, seamed[f"{key}_to_end"], seamed[sk]))
    # C: the strip
    qc = f"C strip of {strip.attrs['seams']} cushions to {100 * float(strip.strain[-1]):.0f} %"
    rows.append((qc, "engine strip of seam cells + sewing (ref.)", 0.0,
                 float(strip.attrs["seconds_strip"])))
    for key, label in (("shifted_law", "macro, one cushion law shifted by height"),
                       ("cushion_laws", "macro, single cushions' laws"), ("columns", "macro, column model")):
        rows.append((qc, label, float(strip.attrs[f"error_{key}"]), float(strip.attrs[f"seconds_{key}"])))
    ds = xr.Dataset(
        {"seconds": ("model", [r[3] for r in rows], {"units": "s", "long_name": "run time"}),
         "error": ("model", [r[2] for r in rows], {"units": "1",
                   "long_name": "max stress error / max reference stress over the range"}),
         "question": ("model", [r[0] for r in rows], {"units": "1", "long_name": "question answered"})},
        coords={"model": [r[1] for r in rows]})
    describe(ds, "speed_accuracy", cell, coords={"model": ("1", "model and its fidelity")})
    ds["error"].attrs["definition"] = ("max |stress - reference| / max |reference stress| over the question's "
                                       "range (0 < strain <= its end); 0 for the references")
    ds.attrs["thickness_mm"] = H0
    nc = _save(_attrs(ds, title="speed against accuracy over model fidelities"), out / "speed_accuracy.nc")
    png = save(speed_accuracy_chart(ds), out / "speed_accuracy.png")
    return ds, {"speed vs accuracy (netCDF)": nc, "speed vs accuracy (chart)": png}
