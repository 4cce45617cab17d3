"""The stages of the main job, each a function that computes, writes netCDF + PNG into an
output folder and returns what it wrote (the command line, the tests and the studies share them).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import matplotlib
import numpy as np
import xarray as xr

from .._version import __version__
from ..api import compress, solve_static
from ..contact.compress import compression_summary
from ..contact.options import Contact
from ..errors import InputError
from ..geometry.lattices import lattice_frame
from ..lookup import Lookup
from ..macro import macro_curve
from ..output.charts import (
    PAPER_CUSHIONS_MM,
    _tag,
    compression_chart,
    cushions_chart,
    macro_chart,
    save,
    seamed_chart,
    speed_accuracy_chart,
)
from ..output.io import write_netcdf
from ..seams import seam_compression, seam_profile
from .paths import heartbeat

log = logging.getLogger(__name__)


def _attrs(ds: xr.Dataset, **extra) -> xr.Dataset:
    ds.attrs.update({"homtex_version": __version__, **{k: str(v) for k, v in extra.items()}})
    return ds


def describe(ds: xr.Dataset, kind: str, cell=None, coords: dict | None = None) -> xr.Dataset:
    """Mark what a Dataset is (``homtex_kind``: the chart ``homtex plot`` draws), which cell it
    belongs to (``cell_name``, ``cell_file``) and give its coordinates units and long names
    (``coords``: {name: (units, long_name)}; others without them get "1" and their name)."""
    ds.attrs["homtex_kind"] = kind
    if cell is not None:
        ds.attrs["cell_name"] = str(getattr(cell, "name", cell))
        if getattr(cell, "path", None):
            ds.attrs["cell_file"] = str(cell.path)
        if isinstance(getattr(cell, "info", None), dict) and "thickness" in cell.info:
            ds.attrs.setdefault("thickness_mm", float(cell.info["thickness"]))
    for name, (units, long_name) in (coords or {}).items():
        ds[name].attrs.update(units=units, long_name=long_name)
    for name in ds.coords:
        ds[name].attrs.setdefault("units", "1")
        ds[name].attrs.setdefault("long_name", str(name))
    return ds


def _save(ds: xr.Dataset, path: Path) -> Path:
    return write_netcdf(ds, path)


def _plt():
    """matplotlib.pyplot on the file-only Agg backend (no screen needed)."""
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# ----------------------------------------------------------------------------- lattice demo
def lattice_demo(out: Path, *, repeat=(6, 6, 6), radius=0.05, elements_per_strut=2) -> dict:
    """Octet-truss block (E = 2 GPa, struts L/r = 14) pressed by 1 % of its height.

    Solved with every solver; writes the per-node displacement, per-element axial force and
    energy, and the solver reports. Returns {name: path}.
    """

    f = lattice_frame("octet", radius=radius, E=2000.0, nu=0.35, repeat=repeat, periodic=False,
                      elements_per_strut=elements_per_strut)
    z = f.nodes[:, 2]
    h = z.max() - z.min()
    bottom = np.flatnonzero(z < z.min() + 1e-9)
    top = np.flatnonzero(z > z.max() - 1e-9)
    fixed = {int(i): "all" for i in bottom}
    fixed.update({int(i): {0: 0.0, 1: 0.0, 2: -0.01 * h} for i in top})
    results = {s: solve_static(f, fixed, None, solver=s, tol=1e-10) for s in ("amg", "direct", "cg")}
    r = results["amg"]
    force = -float(r.reactions[top, 2].sum())
    reps = [results[s].report for s in results]
    ds = xr.Dataset(
        {
            "displacement": (("node", "dof"), r.u,
                             {"units": "mm | rad", "long_name": "nodal displacement and rotation"}),
            "x": (("node", "xyz"), f.nodes, {"units": "mm", "long_name": "node coordinates"}),
            "axial_force": ("element", r.axial_force, {"units": "N", "long_name": "axial force (tension positive)"}),
            **{f"energy_{k}": ("element", v, {"units": "N mm", "long_name": f"{k} strain energy"})
               for k, v in r.energy.items()},
            "setup_seconds": ("solver", [p.setup_seconds for p in reps],
                              {"units": "s", "long_name": "solver setup time"}),
            "solve_seconds": ("solver", [p.solve_seconds for p in reps], {"units": "s", "long_name": "solve time"}),
            "iterations": ("solver", [p.iterations for p in reps], {"units": "1", "long_name": "CG iterations"}),
            "residual": ("solver", [p.residual for p in reps], {"units": "1", "long_name": "true relative residual"}),
            "max_difference": ("solver", [float(np.abs(results[s].u - r.u).max() / np.abs(r.u).max()) for s in results],
                               {"units": "1", "long_name": "max displacement difference to amg, relative"}),
            "force": ((), force, {"units": "N", "long_name": "reaction force at 1 % compression"}),
        },
        coords={"solver": list(results), "dof": ["ux", "uy", "uz", "rx", "ry", "rz"], "xyz": ["x", "y", "z"]},
    )
    _attrs(ds, title="octet lattice block under 1 % compression", ndof=f.ndof, n_elements=f.n_elements)
    describe(ds, "generic", "octet lattice block", coords={
        "solver": ("1", "linear solver"), "dof": ("1", "degree of freedom (translations mm, rotations rad)"),
        "xyz": ("1", "coordinate axis")})
    nc = _save(ds, out / "lattice_demo.nc")

    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.5))
    from matplotlib.collections import LineCollection

    seg = np.stack([f.nodes[f.elements[:, 0]][:, [0, 2]], f.nodes[f.elements[:, 1]][:, [0, 2]]], axis=1)
    lim = np.abs(r.axial_force).max()
    lc = LineCollection(seg, array=r.axial_force, cmap="coolwarm", linewidths=0.6)
    lc.set_clim(-lim, lim)
    _tag(ax[0], "mm", "z", lc)
    ax[0].add_collection(lc)
    ax[0].autoscale()
    ax[0].set_aspect("equal")
    fig.colorbar(lc, ax=ax[0], label="axial force, N")
    ax[0].set(xlabel="x, mm", title=f"octet lattice block {'x'.join(map(str, repeat))}, {f.ndof} DOF, 1 % "
              "compression:\naxial force (side view)")
    names = list(results)
    bars = ax[1].bar(names, [p.setup_seconds + p.solve_seconds for p in reps])
    _tag(ax[1], "s", "setup + solve time", *bars.patches)
    for i, p in enumerate(reps):
        ax[1].text(i, p.setup_seconds + p.solve_seconds, f"{p.iterations} iterations" if p.iterations
                   else "direct solve", ha="center", va="bottom")
    ax[1].set(xlabel="linear solver", title="octet lattice block: the solvers on the same system (they agree to "
              f"{float(ds['max_difference'].max()):.0e})")
    ax[0].title.set_fontsize(9)
    ax[1].title.set_fontsize(9)
    fig.tight_layout()
    png = save(fig, out / "lattice_demo.png")
    return {"lattice demo (netCDF)": nc, "lattice demo (chart)": png}


# ----------------------------------------------------------------------------- paper study
#: the paper's seamed specimens: seam distance (mm) -> (measured cushion height, paper's simulation)
PAPER_CUSHIONS = {18.0: ("8-12", 10.23), 24.0: ("15", 14.33), 43.0: ("20", 20.3)}
SPACER_CELL = "spacer_20mm"
#: the stitch pre-strain of the linear seam cell in the main job (its former nominal value; the
#: calibrated pre-strain of the cell file belongs to the seam sewn on the engine)
LINEAR_PRESTRAIN = 0.3


def _markdown_table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def _timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t0


def unseamed_stage(cell, out: Path, *, strain=0.5, steps=25, progress=False, name="unseamed_compression",
                   geometry: str = "linear", friction: float | None = None) -> tuple:
    """Yarn-level compression of the unseamed cell between plates: curve, modulus, DIN-style
    stresses, energy by yarn system; written as ``<name>.nc/.png``. ``geometry="nonlinear"``:
    the large-motion engine, with Coulomb ``friction`` (None: the cell file's, else 0).
    Returns (curve Dataset, summary dict, {name: path})."""

    contact = None if friction is None else Contact(friction=friction)
    what = "yarn-level" if geometry == "linear" else "large-motion"
    with heartbeat(f"{what} compression of {cell.name} to {100 * strain:g} % in {steps} steps"):
        curve, sec = _timed(compress, cell, strain=strain, steps=steps, progress=progress, geometry=geometry,
                            contact=contact)
    if curve.sizes["strain"] == 0:
        raise InputError(f"unseamed compression of {cell.name} failed at once: {curve.attrs['status']}")
    summ = compression_summary(curve)
    curve.attrs.update({f"cell_{k}": v for k, v in cell.attrs().items()})
    # the linear model holds to its measured limit (the cell file's [validity]); the engine has no such bound
    lim = float((getattr(cell, "validity", None) or {}).get("linear_strain_limit", 0.30))
    curve.attrs.update(title=f"{cell.name}: {what} compression between rigid plates", seconds=sec,
                       modulus_kPa=summ["modulus_kPa"], validity_strain=lim if geometry == "linear" else 1.0)
    describe(curve, "compression", cell)
    nc = _save(_attrs(curve), out / f"{name}.nc")
    png = save(compression_chart(curve), out / f"{name}.png")
    return curve, summ, {"unseamed curve (netCDF)": nc, "unseamed curve (chart)": png}


def cushion_stage(cell, out: Path, *, distances=(18.0, 24.0, 43.0), low_prestrain=0.15) -> tuple:
    """Seam profiles for the paper's seam distances and the 15 % pre-strain case at 43 mm,
    with both seam models: the yarn-level seam cell (method "yarn": blind, from the yarns) and
    the analytical foundation model (method "foundation": eps0 = the machine's 40 %, layer rigidity
    calibrated once on d = 24 mm).

    Returns ({method: {(d, eps0 or None): profile}}, table rows, {name: path}).
    """

    methods = ("yarn", "foundation")
    profiles = {m: {} for m in methods}
    secs = {m: {} for m in methods}
    cases = [(float(d), None) for d in distances] + [(float(max(distances)), low_prestrain)]
    for m in methods:
        for d, eps0 in cases:
            with heartbeat(f"seam profile ({m} model), d = {d:g} mm" + ("" if eps0 is None else f", eps0 = {eps0:g}")):
                # the yarn-level column of this table is still the linear seam cell at its nominal
                # pre-strain (the engine's calibrated cushions: docs/seams.md)
                kw = {"geometry": "linear", "prestrain": LINEAR_PRESTRAIN if eps0 is None else eps0} \
                    if m == "yarn" else {"prestrain": eps0}
                prof, sec = _timed(seam_profile, cell, seam_distance=d, method=m, **kw)
            if prof.attrs.get("status", "ok") != "ok":
                raise InputError(f"seam profile ({m}, d = {d:g} mm) failed: {prof.attrs['status']}")
            profiles[m][(d, eps0)] = prof
            secs[m][(d, eps0)] = sec
    rows = []
    for d, eps0 in cases:
        y, f = profiles["yarn"][(d, eps0)], profiles["foundation"][(d, eps0)]
        meas, sim = PAPER_CUSHIONS.get(d, ("-", "-")) if eps0 is None else ("-", "-")
        rows.append((f"{d:g} ({y.attrs.get('effective_seam_distance_mm', d):.4g})",
                     f"{float(y['prestrain']):.2f}", f"{float(y['cushion_height']):.2f}",
                     f"{float(y['seam_height']):.2f}", f"{secs['yarn'][(d, eps0)]:.1f}",
                     f"{float(f['prestrain']):.3f}", f"{float(f['cushion_height']):.2f}", meas, sim))
    ds = _cushion_dataset(cell, profiles, secs, cases)
    nc = _save(_attrs(ds, title="cushion heights and profiles (yarn-level and foundation seam models)"),
               out / "cushions.nc")
    png = save(cushions_chart(ds), out / "cushions.png")
    return profiles, rows, {"cushion heights (netCDF)": nc, "cushion profiles (chart)": png}


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
        data[f"cushion_height_{m}"] = ("case", [float(P[k]["cushion_height"]) for k in keys],
                                       {"units": "mm", "long_name": f"cushion height, {m} model"})
        data[f"seam_height_{m}"] = ("case", [float(P[k]["seam_height"]) for k in keys],
                                    {"units": "mm", "long_name": f"height at the seam line, {m} model"})
        data[f"prestrain_{m}"] = ("case", [float(P[k]["prestrain"]) for k in keys],
                                  {"units": "1", "long_name": f"stitch-yarn pre-strain, {m} model"})
        data[f"seam_distance_{m}"] = ("case", [d_eff(P[k], k[0]) for k in keys],
                                      {"units": "mm", "long_name": f"effective seam distance (the profile's period), "
                                       f"{m} model"})
        data[f"seconds_{m}"] = ("case", [secs[m][k] for k in keys], {"units": "s", "long_name": f"run time, {m} model"})
    data["seam_distance"] = ("case", [k[0] for k in keys], {"units": "mm", "long_name": "seam distance asked for"})
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
        "case": [f"d={k[0]:g}" + ("" if k[1] is None else f", eps0={k[1]:g}") for k in keys],
        "xi": ("xi", xi, {"units": "1", "long_name": "position across the seam / effective seam distance "
                          "(0: the seam line, +-0.5: midway between seams)"})})
    y0 = profiles["yarn"][keys[0]]
    ds.attrs.update(yarn_model=str(y0.attrs.get("model", "yarn-level seam cell")),
                    yarn_geometry=str(y0.attrs.get("geometry", "linear")),
                    foundation_model=str(profiles["foundation"][keys[0]].attrs.get("description", "")))
    return describe(ds, "cushions", cell, coords={"case": ("1", "seam distance asked for, mm, and pre-strain")})


def macro_stage(cell, curve, profiles, out: Path, *, distances=(18.0, 24.0, 43.0), scatter=1.0,
                strain=0.5, seed=0) -> tuple:
    """Macro cushion-layer curves under the 121 cm^2 plate: no seams and each seam distance.
    Returns (Dataset, {name: path})."""

    cases = [None, *distances]
    curves, secs = [], []
    for d in cases:
        prof = None if d is None else profiles[(float(d), None)]
        ds, sec = _timed(macro_curve, cell, seam_distance=d, curve=curve, profile=prof,
                         height_scatter=0.0 if d is None else scatter, strain=strain, seed=seed)
        curves.append(ds)
        secs.append(sec)
    w = curves[0].plate_displacement.values
    F = np.array([np.interp(w, c.plate_displacement.values, c.force.values, right=np.nan) for c in curves])
    names = ["no seams" if d is None else f"d={d:g}" for d in cases]
    out_ds = xr.Dataset(
        {"force": (("specimen", "plate_displacement"), F, {"units": "N", "long_name": "punch force"}),
         "stress": (("specimen", "plate_displacement"), F / 12100.0 * 1e3,
                    {"units": "kPa", "long_name": "punch force / plate area"}),
         "seconds": ("specimen", secs, {"units": "s", "long_name": "macro-layer run time"})},
        coords={"specimen": names,
                "plate_displacement": ("plate_displacement", w, {"units": "mm",
                                       "long_name": "punch travel from 20 mm plate distance"})})
    out_ds.attrs.update(height_scatter_mm=scatter, seed=seed, status="; ".join(
        f"{n}: {c.attrs.get('status', 'ok')}" for n, c in zip(names, curves)),
        plate_area_mm2=float(curves[0].attrs.get("plate_area_mm2", 12100.0)))
    describe(out_ds, "macro_curves", cell, coords={"specimen": ("1", "specimen (seam distance)")})
    nc = _save(_attrs(out_ds, title="macro cushion layer: force-compression of seamed specimens"),
               out / "macro_curves.nc")
    png = save(macro_chart(out_ds), out / "macro_curves.png")
    return out_ds, {"macro curves (netCDF)": nc, "macro curves (chart)": png}


def _curve_error(ref_x, ref_y, x, y, xmax) -> float:
    """max |y - y_ref| / max |y_ref| over 0 < x <= xmax (y interpolated onto the reference x)."""
    sel = (ref_x > 0) & (ref_x <= xmax + 1e-12)
    if not sel.any() or np.nanmax(x) < ref_x[sel].max() - 1e-9:
        return float("nan")
    yi = np.interp(ref_x[sel], np.r_[0.0, x], np.r_[0.0, y])
    return float(np.abs(yi - ref_y[sel]).max() / np.abs(ref_y[sel]).max())


def seamed_stage(cell, curve, profiles, out: Path, *, seam_distance=24.0, strain=0.3, steps=15) -> tuple:
    """Yarn-level compression of the seam cell (paper's Fig. 11) against the macro layer on
    the same specimen (identical cushions, no scatter): force error up to ``strain`` and the
    run-time ratio, measured in this run. Returns (Dataset, summary dict, {name: path})."""

    H0 = float(cell.info["thickness"])
    d = float(seam_distance)
    with heartbeat(f"yarn-level seam cell d = {d:g} mm under the punch, {steps} steps to {100 * strain:g} %"):
        yarn, t_yarn = _timed(seam_compression, cell, seam_distance=d, strain=strain, steps=steps, geometry="linear",
                              prestrain=LINEAR_PRESTRAIN)
    prof = profiles[(d, None)]
    # the default pre-load law ("thread": released over the thread's slack travel) and its two limits
    laws = {}
    for ps in ("thread", "held", "released"):
        laws[ps] = _timed(macro_curve, cell, seam_distance=d, curve=curve, profile=prof,
                          height_scatter=0.0, strain=strain, steps=201, pre_stress=ps)
    macro, t_macro = laws["thread"]
    if yarn.sizes["strain"] == 0:
        raise InputError(f"yarn-level seamed compression failed at once: {yarn.attrs['status']}")
    # both as nominal stress (kPa) over punch travel from the 20 mm plate distance (the seam
    # cell's travel counts from its sewn thickness), so the plate area drops out
    w_y = yarn.plate_displacement.values - (float(yarn.attrs["thickness_mm"]) - H0)
    s_y = yarn.stress.values
    keep = w_y >= 0
    w_y, s_y = w_y[keep], s_y[keep]
    sel = w_y <= strain * H0 + 1e-9
    s_law = {ps: np.interp(w_y, m.plate_displacement.values, m.stress.values) for ps, (m, _) in laws.items()}
    err_law = {ps: float(np.abs(v[sel] - s_y[sel]).max() / max(np.abs(s_y[sel]).max(), 1e-300))
               for ps, v in s_law.items()}
    s_mi, err = s_law["thread"], err_law["thread"]
    # the punch meeting the stitch thread on the seam line: from then on the thread (tension-only,
    # its legs go slack) and the seam line take load, which the macro layer does not represent
    hit = yarn["stitch_plate_contacts"].values[keep] > 0
    w_hit = float(w_y[hit][0]) if hit.any() else float("inf")
    pre = sel & (w_y < w_hit)
    err_pre = float(np.abs(s_mi[pre] - s_y[pre]).max() / max(np.abs(s_y[pre]).max(), 1e-300)) if pre.any() \
        else float("nan")
    ds = xr.Dataset(
        {"stress_yarn": ("plate_displacement", s_y, {"units": "kPa", "long_name":
                                                       f"linear yarn-level seam cell (eps0 {LINEAR_PRESTRAIN:g})"}),
         "stress_macro": ("plate_displacement", s_mi, {"units": "kPa", "long_name": "macro cushion layer"}),
         "stress_macro_held": ("plate_displacement", s_law["held"],
                               {"units": "kPa", "long_name": "macro cushion layer, pre-load held by the thread"}),
         "stress_macro_released": ("plate_displacement", s_law["released"],
                                   {"units": "kPa", "long_name": "macro cushion layer, pre-load released at contact"}),
         "plate_contacts": ("plate_displacement", yarn["cushion_plate_contacts"].values[keep],
                            {"units": "1", "long_name": "fabric-plate contacts (yarn level)"}),
         "cushions_touched": ("plate_displacement", yarn["cushions_touched"].values[keep],
                              {"units": "1", "long_name": "wale bins of the cushion touching the plate"})},
        coords={"plate_displacement": ("plate_displacement", w_y,
                                       {"units": "mm", "long_name": "punch travel from 20 mm plate distance"})})
    ds.attrs.update(seam_distance_mm=d, cell_seam_distance_mm=float(yarn.attrs["seam_distance_mm"]),
                    yarn_seconds=t_yarn, macro_seconds=t_macro,
                    speedup=t_yarn / t_macro, max_relative_error=err, yarn_steps=int(steps),
                    yarn_status=yarn.attrs.get("status", "ok"),
                    stitch_meets_punch_mm=w_hit, max_relative_error_before_stitch_contact=err_pre,
                    pre_stress=str(macro.attrs["pre_stress"]), slack_travel_mm=macro.attrs["slack_travel_mm"],
                    max_relative_error_held=err_law["held"], max_relative_error_released=err_law["released"])
    # the macro curves at their own resolution and the unseamed curve, for the chart
    tr = macro.plate_displacement.values
    ds = ds.assign_coords(travel=("travel", tr, {"units": "mm", "long_name": "punch travel from 20 mm plate "
                                                 "distance (macro curves' resolution)"}))
    for ps, (m, _) in laws.items():
        key = "stress_macro" if ps == "thread" else f"stress_macro_{ps}"
        ds[f"{key}_curve"] = ("travel", m.stress.values, {**ds[key].attrs, "units": "kPa"})
    ds["stress_unseamed_curve"] = ("travel", np.interp(tr / H0, np.r_[0.0, curve.strain.values],
                                                       np.r_[0.0, curve.stress.values]),
                                   {"units": "kPa", "long_name": "unseamed fabric (yarn level, "
                                                f"{curve.attrs.get('geometry', 'linear')} model)"})
    describe(ds, "seamed_vs_macro", cell)
    nc = _save(_attrs(ds, title=f"seamed d = {d:g} mm: yarn level vs macro layer"), out / "seamed_yarn_vs_macro.nc")
    png = save(seamed_chart(ds), out / "seamed_yarn_vs_macro.png")
    summary = {"error": err, "error_pre": err_pre, "w_hit": w_hit, "yarn_seconds": t_yarn,
               "error_held": err_law["held"], "error_released": err_law["released"],
               "slack_travel": float(macro.attrs["slack_travel_mm"]),
               "macro_seconds": t_macro, "speedup": t_yarn / t_macro}
    return ds, summary, {"seamed yarn vs macro (netCDF)": nc, "seamed yarn vs macro (chart)": png}


def speed_accuracy_stage(cell, curve, profiles, seamed_ref, out: Path, *, quick=False,
                         seamed_steps=(4, 8)) -> tuple:
    """Error against run time over model fidelities, for two questions:

    A. the unseamed stress-strain curve to 20 % (yarn level at 1..6 elements per segment and
       with loose contact tolerances; reference: 8 elements per segment);
    B. the seamed stress curve to 30 % (macro layer; yarn-level seam cell with fewer load
       steps; reference: ``seamed_ref``, the Dataset of :func:`seamed_stage`).
    Errors of 0 (the references) are drawn at 1e-6.
    Returns (Dataset, {name: path}).
    """

    rows = []   # (question, label, seconds, error)
    # A: unseamed
    ref_n = 6 if quick else 8
    with heartbeat(f"speed-accuracy: reference curve at {ref_n} elements per segment"):
        ref = compress(cell.replace(**{"resolution.elements_per_segment": ref_n}), strain=0.2, steps=4,
                       geometry="linear")
    rx, ry = ref.strain.values, ref.stress.values
    for n in ((1, 2, 3) if quick else (1, 2, 3, 4, 6)):
        log.info("  speed-accuracy: unseamed curve at %d element(s) per segment", n)
        c = cell.replace(**{"resolution.elements_per_segment": n})
        ds, sec = _timed(compress, c, strain=0.2, steps=4, geometry="linear")
        rows.append(("A unseamed to 20 %", f"linear yarn, {n} el/seg", sec, _curve_error(rx, ry, ds.strain.values,
                                                                                   ds.stress.values, 0.2)))
    for gtol in (1e-2, 1e-4):
        log.info("  speed-accuracy: unseamed curve with contact gap tolerance %g mm", gtol)
        ds, sec = _timed(compress, cell, strain=0.2, steps=4, contact=Contact(gap_tol=gtol), geometry="linear")
        rows.append(("A unseamed to 20 %", f"linear yarn, gap tol {gtol:g} mm", sec,
                     _curve_error(rx, ry, ds.strain.values, ds.stress.values, 0.2)))

    lk, sec_fit = _timed(Lookup.from_dataset, curve, "stress")
    e = rx[rx > 0]
    val, sec = _timed(lk, e[:, None])
    rows.append(("A unseamed to 20 %", "lookup of the 2 el/seg curve", sec,
                 _curve_error(rx, ry, e, np.ravel(val), 0.2)))
    # B: seamed d = 24; reference: the seam cell with the most load steps (from seamed_stage)
    H0 = float(cell.info["thickness"])
    d = float(seamed_ref.attrs["seam_distance_mm"])
    bx = seamed_ref.plate_displacement.values / H0
    by = seamed_ref.stress_yarn.values
    label_b = f"B seamed d={d:g} to 30 %"
    rows.append((label_b, f"linear yarn seam cell, {int(seamed_ref.attrs['yarn_steps'])} steps (reference)",
                 float(seamed_ref.attrs["yarn_seconds"]),
                 0.0))
    for steps in seamed_steps:
        with heartbeat(f"speed-accuracy: yarn-level seam cell, {steps} steps"):
            ds, sec = _timed(seam_compression, cell, seam_distance=d, strain=0.3, steps=steps, geometry="linear",
                             prestrain=LINEAR_PRESTRAIN)
        w = ds.plate_displacement.values - (float(ds.attrs["thickness_mm"]) - H0)
        rows.append((label_b, f"linear yarn seam cell, {steps} steps", sec,
                     _curve_error(bx, by, w[w >= 0] / H0, ds.stress.values[w >= 0], 0.3)))
    prof = profiles[(d, None)]
    ds, sec = _timed(macro_curve, cell, seam_distance=d, curve=curve, profile=prof, strain=0.3,
                     height_scatter=0.0)
    rows.append((label_b, "macro cushion layer", sec,
                 _curve_error(bx, by, ds.plate_displacement.values / H0, ds.stress.values, 0.3)))
    q = [r[0] for r in rows]
    ds = xr.Dataset(
        {"seconds": ("model", [r[2] for r in rows], {"units": "s", "long_name": "run time"}),
         "error": ("model", [r[3] for r in rows], {"units": "1",
                   "long_name": "max stress error / max reference stress over the range"}),
         "question": ("model", q, {"units": "1", "long_name": "question answered"})},
        coords={"model": [r[1] for r in rows]})
    describe(ds, "speed_accuracy", cell, coords={"model": ("1", "model and its fidelity")})
    ds["error"].attrs["definition"] = ("max |stress - reference| / max |reference stress| over the question's "
                                       "range (0 < strain <= 20 % for A, 30 % for B); 0 for the references")
    nc = _save(_attrs(ds, title="speed against accuracy over model fidelities"), out / "speed_accuracy.nc")
    png = save(speed_accuracy_chart(ds), out / "speed_accuracy.png")
    return ds, {"speed vs accuracy (netCDF)": nc, "speed vs accuracy (chart)": png}
