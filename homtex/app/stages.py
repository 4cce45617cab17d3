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
from ..output.io import write_netcdf
from ..seams import seam_compression, seam_profile

log = logging.getLogger(__name__)


def _attrs(ds: xr.Dataset, **extra) -> xr.Dataset:
    ds.attrs.update({"homtex_version": __version__, **{k: str(v) for k, v in extra.items()}})
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
    nc = _save(ds, out / "lattice_demo.nc")

    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.5))
    from matplotlib.collections import LineCollection

    seg = np.stack([f.nodes[f.elements[:, 0]][:, [0, 2]], f.nodes[f.elements[:, 1]][:, [0, 2]]], axis=1)
    lim = np.abs(r.axial_force).max()
    lc = LineCollection(seg, array=r.axial_force, cmap="coolwarm", linewidths=0.6)
    lc.set_clim(-lim, lim)
    ax[0].add_collection(lc)
    ax[0].autoscale()
    ax[0].set_aspect("equal")
    fig.colorbar(lc, ax=ax[0], label="axial force, N")
    ax[0].set(xlabel="x, mm", ylabel="z, mm", title=f"octet block, {f.ndof} DOF: axial force (side view)")
    names = list(results)
    ax[1].bar(names, [p.setup_seconds + p.solve_seconds for p in reps])
    for i, p in enumerate(reps):
        ax[1].text(i, p.setup_seconds + p.solve_seconds, f"{p.iterations} it", ha="center", va="bottom")
    ax[1].set(ylabel="setup + solve, s", title="solvers on the same system")
    fig.tight_layout()
    png = out / "lattice_demo.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return {"lattice demo (netCDF)": nc, "lattice demo (chart)": png}


# ----------------------------------------------------------------------------- paper study
#: the paper's seamed specimens: seam distance (mm) -> (measured cushion height, paper's simulation)
PAPER_CUSHIONS = {18.0: ("8-12", 10.23), 24.0: ("15", 14.33), 43.0: ("20", 20.3)}
SPACER_CELL = "spacer_20mm"


def _markdown_table(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def _timed(fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    return out, time.perf_counter() - t0


def unseamed_stage(cell, out: Path, *, strain=0.5, steps=25, progress=False) -> tuple:
    """Yarn-level compression of the unseamed cell between plates: curve, modulus, DIN-style
    stresses, energy by yarn system. Returns (curve Dataset, summary dict, {name: path})."""

    curve, sec = _timed(compress, cell, strain=strain, steps=steps, progress=progress)
    if curve.sizes["strain"] == 0:
        raise InputError(f"unseamed compression of {cell.name} failed at once: {curve.attrs['status']}")
    summ = compression_summary(curve)
    curve.attrs.update({f"cell_{k}": v for k, v in cell.attrs().items()})
    curve.attrs.update(title=f"{cell.name}: yarn-level compression between rigid plates", seconds=sec,
                       modulus_kPa=summ["modulus_kPa"], validity_strain=0.30)
    nc = _save(_attrs(curve), out / "unseamed_compression.nc")
    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    e, sg = curve.strain.values, curve.stress.values
    ok = e <= 0.30 + 1e-12
    ax[0].plot(100 * e[ok], sg[ok], "o-", ms=3, label="yarn level (model valid)")
    ax[0].plot(100 * e[~ok], sg[~ok], "o--", ms=3, color="tab:red", label="beyond 30 % (large rotations ignored)")
    ax[0].axvline(30, color="0.6", lw=0.8)
    ax[0].set(xlabel="compression, %", ylabel="stress, kPa",
              title=f"unseamed, E_c = {summ['modulus_kPa']:.0f} kPa ({sec:.1f} s)")
    ax[0].legend(fontsize=8)
    if "group_energy" in curve:
        ge = curve["group_energy"]
        for g in ge.group.values:
            ax[1].plot(100 * e, ge.sel(group=g).values, label=str(g))
    for k in ("bending_y", "bending_z", "axial", "torsion", "shear", "contact_energy"):
        ax[1].plot(100 * e, curve[k].values, ":", lw=1, label=k)
    ax[1].set(xlabel="compression, %", ylabel="energy per cell, N mm", yscale="log",
              title="energy by yarn system (solid) and mechanism (dotted)")
    ax[1].legend(fontsize=7, ncol=2)
    fig.tight_layout()
    png = out / "unseamed_compression.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
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
            prof, sec = _timed(seam_profile, cell, seam_distance=d, prestrain=eps0, method=m)
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
    keys = cases
    xi = np.linspace(-0.5, 0.5, 121)

    def on_xi(p, d):
        dd = float(p.attrs.get("effective_seam_distance_mm", d))
        xs = p.x.values - 0.5 * (p.x.values[0] + p.x.values[-1])   # centre the seam cell on 0
        return np.interp(xi * dd, xs, p.height.values)

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
        data[f"seconds_{m}"] = ("case", [secs[m][k] for k in keys], {"units": "s", "long_name": f"run time, {m} model"})
    data["seam_distance"] = ("case", [k[0] for k in keys], {"units": "mm", "long_name": "seam distance asked for"})
    ds = xr.Dataset(data, coords={
        "case": [f"d={k[0]:g}" + ("" if k[1] is None else f", eps0={k[1]:g}") for k in keys],
        "xi": ("xi", xi, {"units": "1", "long_name": "position across the seam / seam distance (0: midway)"})})
    ds.attrs.update(yarn_model=str(profiles["yarn"][keys[0]].attrs.get("model", "yarn-level seam cell")),
                    foundation_model=str(profiles["foundation"][keys[0]].attrs.get("description", "")))
    nc = _save(_attrs(ds, title="cushion heights and profiles (yarn-level and foundation seam models)"),
               out / "cushions.nc")
    plt = _plt()
    fig, axes = plt.subplots(len(keys) + 1, 2, figsize=(13, 1.7 * (len(keys) + 1)), sharex=True)
    H0 = float(cell.info["thickness"])
    width = 3 * max(k[0] for k in keys)
    for col, m in enumerate(methods):
        for ax, k in zip(axes[:, col], keys):
            p = profiles[m][k]
            dd = float(p.attrs.get("effective_seam_distance_mm", k[0]))
            # one period, closed with its first sample one seam distance on (no gaps between repeats)
            x0 = np.r_[p.x.values - p.x.values[0], dd]
            hh = np.r_[p.height.values, p.height.values[0]]
            for rep in range(int(np.ceil(width / dd)) + 1):
                ax.fill_between(x0 + rep * dd, 0.5 * (H0 - hh), 0.5 * (H0 + hh),
                                color="tab:blue" if m == "yarn" else "tab:green", alpha=0.55, lw=0)
            ax.set(ylim=(-1, H0 + 2), xlim=(0, width), ylabel="z, mm")
            ax.set_title(f"{m}: {ds.case.values[keys.index(k)]}, cushion {float(p['cushion_height']):.2f} mm, "
                         f"seam line {float(p['seam_height']):.2f} mm", fontsize=8)
        axes[-1, col].fill_between([0, width], 0, H0, color="0.6", lw=0)
        axes[-1, col].set(ylim=(-1, H0 + 2), xlabel="x across the seams, mm", ylabel="z, mm")
        axes[-1, col].set_title(f"without seams: {H0:g} mm", fontsize=8)
    fig.tight_layout()
    png = out / "cushions.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return profiles, rows, {"cushion heights (netCDF)": nc, "cushion profiles (chart)": png}


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
        f"{n}: {c.attrs.get('status', 'ok')}" for n, c in zip(names, curves)))
    nc = _save(_attrs(out_ds, title="macro cushion layer: force-compression of seamed specimens"),
               out / "macro_curves.nc")
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for n, row in zip(names, F):
        ax.plot(w, row, label=n)
    ax.axvline(0.3 * float(cell.info["thickness"]), color="0.6", lw=0.8, ls="--")
    ax.text(0.3 * float(cell.info["thickness"]), ax.get_ylim()[1] * 0.9, " 30 %", fontsize=8)
    ax.set(xlabel="compression distance from 20 mm plate distance, mm", ylabel="force, N",
           title=f"macro cushion layer, 121 cm^2 plate (cushion scatter {scatter:g} mm)")
    ax.legend()
    fig.tight_layout()
    png = out / "macro_curves.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
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
    yarn, t_yarn = _timed(seam_compression, cell, seam_distance=d, strain=strain, steps=steps)
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
    w_m, s_m = macro.plate_displacement.values, macro.stress.values
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
        {"stress_yarn": ("plate_displacement", s_y, {"units": "kPa", "long_name": "yarn-level seam cell"}),
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
    nc = _save(_attrs(ds, title=f"seamed d = {d:g} mm: yarn level vs macro layer"), out / "seamed_yarn_vs_macro.nc")
    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    ax[0].plot(w_y, s_y, "o-", ms=3, label=f"yarn-level seam cell ({t_yarn:.1f} s)")
    ax[0].plot(w_m, s_m, "-", label=f"macro cushion layer ({1e3 * t_macro:.1f} ms; thread slack after "
               f"{float(macro.attrs['slack_travel_mm']):.2f} mm)")
    for ps, ls in (("held", "--"), ("released", "-.")):
        m = laws[ps][0]
        ax[0].plot(m.plate_displacement.values, m.stress.values, ls, lw=0.8,
                   label=f"macro, pre-load {ps} (error {100 * err_law[ps]:.0f} %)")
    curve_w = curve.strain.values * H0
    ax[0].plot(curve_w[curve_w <= strain * H0], curve.stress.values[curve_w <= strain * H0], ":", color="0.4",
               label="unseamed (yarn level)")
    ax[0].set(xlabel="punch travel from 20 mm, mm", ylabel="stress, kPa",
              title=f"d = {d:g} mm: max error {100 * err:.1f} %, macro {t_yarn / t_macro:.0f}x faster")
    ax[0].legend(fontsize=8)
    ax[1].plot(w_y, ds.plate_contacts.values, "o-", ms=3, label="fabric-plate contacts")
    ax[1].plot(w_y, ds.cushions_touched.values, "s-", ms=3, label="wale bins touching")
    ax[1].set(xlabel="punch travel, mm", ylabel="count", title="the cushion meeting the punch (yarn level)")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    png = out / "seamed_yarn_vs_macro.png"
    if np.isfinite(w_hit):
        ax[0].axvline(w_hit, color="tab:red", lw=0.8, ls=":")
        ax[0].text(w_hit, 0.95 * ax[0].get_ylim()[1], " punch meets the stitch", fontsize=7, color="tab:red",
                   va="top")
    fig.savefig(png, dpi=110)
    plt.close(fig)
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
    ref = compress(cell.replace(**{"resolution.elements_per_segment": ref_n}), strain=0.2, steps=4)
    rx, ry = ref.strain.values, ref.stress.values
    for n in ((1, 2, 3) if quick else (1, 2, 3, 4, 6)):
        c = cell.replace(**{"resolution.elements_per_segment": n})
        ds, sec = _timed(compress, c, strain=0.2, steps=4)
        rows.append(("A unseamed to 20 %", f"yarn, {n} el/seg", sec, _curve_error(rx, ry, ds.strain.values,
                                                                                   ds.stress.values, 0.2)))
    for gtol in (1e-2, 1e-4):
        ds, sec = _timed(compress, cell, strain=0.2, steps=4, contact=Contact(gap_tol=gtol))
        rows.append(("A unseamed to 20 %", f"yarn, gap tol {gtol:g} mm", sec,
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
    rows.append((label_b, f"yarn seam cell, {int(seamed_ref.attrs['yarn_steps'])} steps (reference)",
                 float(seamed_ref.attrs["yarn_seconds"]),
                 0.0))
    for steps in seamed_steps:
        ds, sec = _timed(seam_compression, cell, seam_distance=d, strain=0.3, steps=steps)
        w = ds.plate_displacement.values - (float(ds.attrs["thickness_mm"]) - H0)
        rows.append((label_b, f"yarn seam cell, {steps} steps", sec,
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
    nc = _save(_attrs(ds, title="speed against accuracy over model fidelities"), out / "speed_accuracy.nc")
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 5))
    for question, marker in (("A unseamed to 20 %", "o"), (label_b, "s")):
        sel = [i for i, r in enumerate(rows) if r[0] == question]
        ax.scatter([rows[i][2] for i in sel], [max(rows[i][3], 1e-6) for i in sel], marker=marker, label=question)
        for i in sel:
            ax.annotate(rows[i][1], (rows[i][2], max(rows[i][3], 1e-6)), fontsize=7, xytext=(4, 3),
                        textcoords="offset points")
    ax.axhline(0.10, color="0.6", lw=0.8, ls="--")
    ax.set(xscale="log", yscale="log", xlabel="run time, s (2-core machine)", ylabel="relative error",
           title="which model does a question need? (error floor 1e-6 drawn at the bottom)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    png = out / "speed_accuracy.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return ds, {"speed vs accuracy (netCDF)": nc, "speed vs accuracy (chart)": png}


# ----------------------------------------------------------------------------- main job


