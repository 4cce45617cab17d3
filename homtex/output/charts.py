"""Charts of homtex Datasets (matplotlib, file-only Agg backend): one function per kind of result,
each taking the Dataset a stage writes and returning a matplotlib Figure (``save`` writes it).

Rules every chart keeps (tests/test_charts.py checks them):

- one unit per y axis: every drawn line, collection and image is tagged with the unit of its y
  axis (``artist.get_gid() == "unit:<unit>"``), the axes with the same tag; a second unit gets
  its own panel or a secondary axis (a rescaled copy of the same axis, e.g. kPa and the force
  on the 121 cm^2 plate);
- axis labels read "quantity, unit";
- the title names the cell (``cell_name`` attribute of the Dataset), never run times;
- where the source paper gives measured data it is drawn: cushion heights and the 500 N load
  cell of the compression test (DIN EN ISO 3386-1, plates of 121 cm^2); its compression curves
  exist only as plots, so no chart claims agreement with them. A curve of the linear model has its
  measured validity (the strain up to which it stays within 10 % of the large-motion engine, the
  cell file's ``[validity]``) shaded.

The study, homogenisation and generic charts are in :mod:`homtex.output.charts_data`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["LOAD_CELL_N", "PAPER_CUSHIONS_MM", "PLATE_AREA_MM2", "VALIDITY_STRAIN", "axis_units", "cell_label",
           "compression_chart", "cushions_chart", "macro_chart", "pyplot", "save", "seam_distance",
           "seam_profile_chart", "seamed_chart", "speed_accuracy_chart", "strip_chart"]

#: the source paper's seamed specimens: seam distance, mm -> (measured cushion height low, high, paper's
#: simulated height), mm (Table 1; d = 18 mm: 8 mm in the table, 12 mm on average in the text)
PAPER_CUSHIONS_MM = {18.0: (8.0, 12.0, 10.23), 24.0: (15.0, 15.0, 14.33), 43.0: (20.0, 20.0, 20.3)}
#: compression test of the paper (DIN EN ISO 3386-1): plate area, mm^2, and load cell range, N
PLATE_AREA_MM2 = 12100.0
LOAD_CELL_N = 500.0
#: the validity shaded on a linear curve without its own ``validity_strain`` attribute (the paper's
#: linear model agreed with its test to about 30 %; homtex's linear spacer cell holds to 0.18 %)
VALIDITY_STRAIN = 0.30

_VALID = dict(color="tab:green", alpha=0.08, lw=0)


def pyplot():
    """matplotlib.pyplot on the file-only Agg backend (no screen needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig, path, *, dpi: int = 110):
    """Write ``fig`` to ``path`` (format from the extension) and close it; returns the path."""
    from pathlib import Path

    plt = pyplot()
    try:
        fig.savefig(path, dpi=dpi)
    finally:
        plt.close(fig)
    return Path(path)


def cell_label(ds) -> str:
    """The cell a Dataset belongs to, for titles: ``cell_name`` (stages), the study's cell or '?'."""
    a = ds.attrs
    for key in ("cell_name", "cell.name", "cell.cell.name", "cell_cell.name"):
        if key in a and str(a[key]):
            return str(a[key])
    return "cell ?"


def _tag(ax, unit: str, quantity: str | None = None, *artists):
    """Mark ``ax`` (and ``artists``) as drawing ``unit`` on its y axis; label the axis
    "quantity, unit". A second unit on the same axes is a programming error."""
    unit = str(unit)
    have = ax.get_gid()
    if have not in (None, f"unit:{unit}"):
        raise ValueError(f"chart: {unit!r} drawn on an axis of {have[5:]!r}")
    ax.set_gid(f"unit:{unit}")
    if quantity is not None:
        ax.set_ylabel(f"{quantity}, {unit}")
    for a in artists:
        for x in (a if isinstance(a, (list, tuple)) else [a]):
            x.set_gid(f"unit:{unit}")
    return artists[0] if len(artists) == 1 else artists


def axis_units(ax) -> set:
    """Units of everything drawn on ``ax`` (lines, collections, images; their gid tags)."""
    arts = [*ax.lines, *ax.collections, *ax.images]
    return {a.get_gid()[5:] for a in arts if isinstance(a.get_gid(), str) and a.get_gid().startswith("unit:")}


def _units(ds, name, default="1") -> str:
    return str(ds[name].attrs.get("units", default)) if name in ds.variables else default


def _thickness(ds, default=20.0) -> float:
    for key in ("thickness_mm", "cell_thickness_mm"):
        if key in ds.attrs:
            try:
                return float(ds.attrs[key])
            except (TypeError, ValueError):
                pass
    return float(default)


def _shade_validity(ax, x_end, *, label=True):
    """Shade 0 .. x_end (the compression the linear model is valid to) on ``ax``."""
    text = f"linear model valid (to {x_end:.3g} %: within 10 % of the large-motion engine)"
    ax.axvspan(0.0, x_end, **_VALID, label=text if label else None)


# ----------------------------------------------------------------------------- compression
def compression_chart(curve, *, plate_area: float = PLATE_AREA_MM2):
    """Yarn-level compression between rigid plates (``homtex.compress`` Dataset): stress over
    compression with the validity range shaded and the 500 N load cell's range on the 121 cm^2
    plate (a secondary axis gives the force on that plate); energy by yarn system and mechanism."""
    plt = pyplot()
    cell = cell_label(curve)
    valid = float(curve.attrs.get("validity_strain", VALIDITY_STRAIN))
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.6))
    e, s = 100 * curve.strain.values, curve.stress.values
    ok = e <= 100 * valid + 1e-9
    # the large-motion engine (validity 100 %) has no small-rotation range to shade
    large = valid >= 1.0
    if not large:
        _shade_validity(ax[0], 100 * valid)
    label = "yarn level"
    if large:
        mu = curve.attrs.get("friction_max")
        label += ", large motion" + ("" if mu is None else f", friction {float(mu):g}")
    lines = ax[0].plot(e[ok], s[ok], "o-", ms=3, color="tab:blue", label=label)
    if (~ok).any():
        lines += ax[0].plot(e[~ok], s[~ok], "o--", ms=3, color="tab:red",
                            label="beyond the linear model's validity (large rotations ignored)")
    _tag(ax[0], _units(curve, "stress", "kPa"), "compressive stress", lines)
    per_kpa = plate_area * 1e-3          # N per kPa on the plate
    lc = LOAD_CELL_N / per_kpa
    _tag(ax[0], "kPa", None, ax[0].axhline(lc, color="k", lw=0.9, ls="--",
                                           label=f"500 N load cell on the 121 cm$^2$ plate ({lc:.1f} kPa)"))
    ax[0].axhspan(0.0, lc, color="0.5", alpha=0.08, lw=0)
    sec = ax[0].secondary_yaxis("right", functions=(lambda k: k * per_kpa, lambda f: f / per_kpa))
    sec.set_ylabel("force on a 121 cm$^2$ plate, N")
    ax[0].set(xlabel="compression (plate displacement / thickness), %", xlim=(0, max(e.max(initial=0), 1) * 1.02),
              ylim=(0, None))
    mod = None if large else curve.attrs.get("modulus_kPa")
    ax[0].set_title(f"{cell}: compression between rigid plates" + (f", E_c = {float(mod):.0f} kPa" if mod else ""),
                    fontsize=9)
    ax[0].legend(fontsize=7, loc="upper left")
    if "group_energy" in curve:
        ge = curve["group_energy"]
        for g in ge.group.values:
            _tag(ax[1], "N mm", None, ax[1].plot(e, ge.sel(group=g).values, label=f"yarn system {g}"))
    for k in ("bending_y", "bending_z", "axial", "torsion", "shear", "contact_energy", "friction_energy",
              "stabilization_energy"):
        if k in curve and np.any(np.asarray(curve[k].values) > 0):
            _tag(ax[1], _units(curve, k, "N mm"), None, ax[1].plot(e, curve[k].values, ":", lw=1, label=k))
    ax[1].set(xlabel="compression, %", ylabel="energy per cell, N mm", yscale="log")
    ax[1].set_title(f"{cell}: energy by yarn system (solid) and mechanism (dotted)", fontsize=9)
    if not large:
        _shade_validity(ax[1], 100 * valid, label=False)
    if ax[1].get_legend_handles_labels()[0]:
        ax[1].legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- seam profiles
def seam_distance(profile) -> float:
    """The seam distance a profile repeats with: the effective one (whole fabric repeats), mm."""
    for key in ("effective_seam_distance_mm", "seam_distance_mm"):
        if key in profile.attrs:
            try:
                return float(profile.attrs[key])
            except (TypeError, ValueError):
                pass
    if "seam_distance" in profile and profile["seam_distance"].ndim == 0:
        return float(profile["seam_distance"])
    x = np.sort(profile.x.values)
    return float(x[-1] - x[0] + (x[1] - x[0]))   # bins: one more bin width closes the period


def _period(x, h, d):
    """One closed period of a profile with x = 0 on the seam line: x in [x0, x0 + d]."""
    order = np.argsort(x)
    x, h = np.asarray(x, float)[order], np.asarray(h, float)[order]
    keep = x < x[0] + d - 1e-9 * d
    return np.r_[x[keep], x[0] + d], np.r_[h[keep], h[0]]


def _draw_profile(ax, x, h, d, H, periods, color):
    xp, hp = _period(x, h, d)
    for k in range(periods):
        _tag(ax, "mm", None, ax.fill_between(xp + k * d, 0.5 * (H - hp), 0.5 * (H + hp), color=color, alpha=0.55,
                                             lw=0))
    seams = [k * d for k in range(periods + 1) if xp[0] <= k * d <= xp[0] + periods * d]
    for i, xs in enumerate(seams):   # labelled "seam line" (legend) and "_seam line" (tests find them all)
        _tag(ax, "mm", None, ax.axvline(xs, color="k", lw=0.8, label="seam line" if i == 0 else "_seam line"))


def seam_profile_chart(profile, *, periods: int = 3):
    """A cushion profile (``homtex.seam_profile`` Dataset) repeated over ``periods`` seam
    distances, the seams drawn at the effective seam distance, next to the flat fabric; both
    panels have the same y range. The paper's measured cushion height is drawn where the
    requested distance is one of its specimens (18, 24, 43 mm)."""
    plt = pyplot()
    cell = cell_label(profile)
    d = seam_distance(profile)
    H = _thickness(profile, float(np.nanmax(profile.height.values)))
    x = profile.x.values
    fig, ax = plt.subplots(2, 1, figsize=(9, 5.2), sharex=True, sharey=True)
    method = profile.attrs.get("method", "?")
    _draw_profile(ax[0], x, profile.height.values, d, H, periods, "tab:blue" if method == "yarn" else "tab:green")
    asked = float(profile.attrs.get("requested_seam_distance_mm", d))
    ref = PAPER_CUSHIONS_MM.get(round(asked, 6))
    if ref is not None:
        for z in (0.5 * (H - ref[1]), 0.5 * (H + ref[1])):
            _tag(ax[0], "mm", None, ax[0].axhline(z, color="k", ls="--", lw=0.9))
        meas = f"{ref[0]:g}-{ref[1]:g}" if ref[0] != ref[1] else f"{ref[1]:g}"
        ax[0].lines[-1].set_label(f"measured cushion height (paper), {meas} mm; paper's simulation {ref[2]:g} mm")
    ax[0].legend(fontsize=7, loc="upper center", ncol=2, framealpha=1.0)
    ch, sh = float(profile["cushion_height"]), float(profile["seam_height"])
    ax[0].set_title(f"{cell}: seams every {d:.4g} mm ({asked:g} mm asked; {method} model), cushion {ch:.2f} mm, "
                    f"seam line {sh:.2f} mm", fontsize=9)
    ax[0].set_ylabel("z, mm")
    x0 = _period(x, profile.height.values, d)[0][0]
    _tag(ax[1], "mm", "z", ax[1].fill_between([x0, x0 + periods * d], 0, H, color="0.6", lw=0))
    ax[1].set(xlabel="x across the seams (0: a seam line), mm", xlim=(x0, x0 + periods * d), ylim=(-1, H + 5))
    ax[1].set_title(f"{cell}: flat fabric, {H:g} mm", fontsize=9)
    fig.tight_layout()
    return fig


def cushions_chart(ds):
    """The main job's cushions (``cushions.nc``): profiles of both seam models for every case
    (seams at each model's effective seam distance) and the cushion heights against the seam
    distance with the paper's measured and simulated heights."""
    plt = pyplot()
    cell = cell_label(ds)
    cases = [str(c) for c in ds.case.values]
    H0 = _thickness(ds)
    methods = [m for m in ("yarn", "foundation") if f"height_{m}" in ds]
    fig = plt.figure(figsize=(17, 1.75 * (len(cases) + 1) + 0.6))
    gs = fig.add_gridspec(len(cases) + 1, 3, width_ratios=[1, 1, 0.8])
    width = 3 * float(np.max(ds.seam_distance.values))
    first = None
    for col, m in enumerate(methods):
        for row, case in enumerate(cases):
            ax = fig.add_subplot(gs[row, col], sharex=first, sharey=first)
            first = first or ax
            d = float(ds[f"seam_distance_{m}"].values[row]) if f"seam_distance_{m}" in ds \
                else float(ds.seam_distance.values[row])
            x = ds.xi.values * d
            _draw_profile(ax, x, ds[f"height_{m}"].values[row], d, H0, int(np.ceil(width / d)) + 1,
                          "tab:blue" if m == "yarn" else "tab:green")
            ax.set_ylabel("z, mm")
            ax.tick_params(labelbottom=False)
            ax.set_title(f"{m}: {case} (seams every {d:.4g} mm), cushion {float(ds[f'cushion_height_{m}'][row]):.2f} "
                         f"mm, seam line {float(ds[f'seam_height_{m}'][row]):.2f} mm", fontsize=8)
        ax = fig.add_subplot(gs[len(cases), col], sharex=first, sharey=first)
        _tag(ax, "mm", "z", ax.fill_between([0, width], 0, H0, color="0.6", lw=0))
        ax.set(xlabel="x across the seams (0: a seam line), mm")
        ax.set_title(f"without seams: {H0:g} mm", fontsize=8)
    first.set(xlim=(0, width), ylim=(-1, H0 + 2))
    ax = fig.add_subplot(gs[:, 2])
    _cushion_heights(ax, ds, methods, H0)
    ax.set_title(f"{cell}: cushion height against seam distance", fontsize=9)
    yarn = ("seam cell sewn on the large-motion engine" if ds.attrs.get("yarn_geometry", "linear") == "nonlinear"
            else "geometrically linear seam cell")
    fig.suptitle(f"{cell}: cushion profiles, {yarn} (yarn) and foundation model", fontsize=10)
    fig.tight_layout()
    return fig


def _cushion_heights(ax, ds, methods, H0):
    d = ds.seam_distance.values
    eps = {m: ds[f"prestrain_{m}"].values for m in methods if f"prestrain_{m}" in ds}
    nominal = np.array(["eps0" not in str(c) and "setting" not in str(c) for c in ds.case.values])
    for m, mk, c in (("yarn", "o", "tab:blue"), ("foundation", "s", "tab:green")):
        if m not in methods:
            continue
        h = ds[f"cushion_height_{m}"].values
        e = eps.get(m, np.full(len(d), np.nan))
        engine = ds.attrs.get("yarn_geometry", "linear") == "nonlinear"
        name = ("sewn on the engine" if engine else "linear seam cell") if m == "yarn" else "foundation model"
        how = "calibrated on 24 mm" if m == "foundation" or engine else "nominal"
        _tag(ax, "mm", None, ax.plot(d[nominal], h[nominal], mk + "-", color=c, label=f"{name} (eps0 = "
                                     f"{e[nominal][0]:.3g}, {how})" if nominal.any() else name))
        if (~nominal).any():
            _tag(ax, "mm", None, ax.plot(d[~nominal], h[~nominal], mk, mfc="none", color=c,
                                         label=f"{name}, low setting, eps0 = {e[~nominal][0]:.3g}"))
    if "cushion_height_paper_simulation" in ds:     # the paper's data as the Dataset carries them
        rd = ds.paper_distance.values
        lo, hi, sim = (ds[f"cushion_height_{k}"].values for k in ("measured_low", "measured_high", "paper_simulation"))
    else:
        ref = sorted(PAPER_CUSHIONS_MM.items())
        rd = np.array([k for k, _ in ref])
        lo, hi, sim = (np.array([v[i] for _, v in ref]) for i in range(3))
    mid = 0.5 * (lo + hi)
    eb = ax.errorbar(rd - 0.4, mid, yerr=[mid - lo, hi - mid], fmt="D", color="k", capsize=4,
                     label="measured (paper, Table 1; 18 mm: 8-12)")
    _tag(ax, "mm", None, [eb.lines[0], *eb.lines[1], *eb.lines[2]])
    _tag(ax, "mm", None, ax.plot(rd + 0.4, sim, "x", ms=9, mew=2, color="tab:red", label="paper's simulation"))
    _tag(ax, "mm", "cushion height", ax.axhline(H0, color="0.5", lw=0.8, ls=":", label=f"without seams ({H0:g} mm)"))
    ax.set(xlabel="seam distance asked for, mm", ylim=(0, H0 + 3))
    ax.legend(fontsize=7, loc="lower right")


# ----------------------------------------------------------------------------- macro layer
def macro_chart(ds):
    """Force over punch travel of the macro cushion layer (``macro_curve`` Dataset, or the main
    job's ``macro_curves.nc`` with a ``specimen`` dimension): full range and the 500 N load cell's
    range of the paper's test."""
    plt = pyplot()
    cell = cell_label(ds)
    H0 = _thickness(ds)
    w = ds.plate_displacement.values
    F = ds.force.values if ds.force.ndim == 2 else ds.force.values[None, :]
    names = [str(s) for s in ds.specimen.values] if "specimen" in ds.dims else [_macro_name(ds)]
    area = float(ds.attrs.get("plate_area_mm2", PLATE_AREA_MM2))
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.6))
    for a, zoom in zip(ax, (False, True)):
        for n, row in zip(names, F):
            _tag(a, "N", None, a.plot(w, row, label=n))
        _tag(a, "N", "punch force", a.axhline(LOAD_CELL_N, color="k", ls="--", lw=0.9,
                                              label="500 N load cell of the paper's test"))
        a.set(xlabel=f"punch travel from the {H0:g} mm plate distance, mm", xlim=(0, w.max()))
        sec = a.secondary_xaxis("top", functions=(lambda v: 100 * v / H0, lambda p: p * H0 / 100))
        sec.set_xlabel("compression, %", fontsize=8)
    ax[1].set_ylim(0, 1.2 * LOAD_CELL_N)
    ax[0].set_ylim(0, None)
    ax[0].legend(fontsize=7, loc="upper left")
    scatter = ds.attrs.get("height_scatter_mm", 0)
    ax[0].set_title(f"{cell}: macro cushion layer, {area / 100:g} cm$^2$ plate, cushion scatter {scatter} mm",
                    fontsize=9)
    ax[1].set_title(f"{cell}: the load cell's range (0-500 N)", fontsize=9)
    fig.tight_layout()
    return fig


def _macro_name(ds) -> str:
    d = ds.attrs.get("seam_distance_mm", "none")
    return "no seams" if str(d) == "none" else f"d = {float(d):g} mm ({ds.attrs.get('pre_stress', '')})"


# ----------------------------------------------------------------------------- seamed: yarn vs macro
ERROR_DEFINITION = "max |stress - reference| / max |reference| over the range"


def seamed_chart(ds):
    """The seamed specimen at yarn level against the macro layer (``seamed_yarn_vs_macro.nc``):
    stress over punch travel, the unseamed fabric beside it and the error of each macro curve
    defined on the chart; the cushion meeting the punch (contact counts) beside it."""
    plt = pyplot()
    cell = cell_label(ds)
    d = float(ds.attrs.get("seam_distance_mm", np.nan))
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.6))
    w = ds.plate_displacement.values
    H0 = _thickness(ds)
    kpa = _units(ds, "stress_yarn", "kPa")
    _tag(ax[0], kpa, "compressive stress", ax[0].plot(w, ds.stress_yarn.values, "o-", ms=3, color="tab:blue",
                                                      label=ds.stress_yarn.attrs.get("long_name", "yarn level")
                                                      + " (reference)"))
    styles = {"stress_unseamed": (":", "0.4"), "stress_macro": ("-", "tab:orange"),
              "stress_macro_foundation": ("--", "tab:green"), "stress_macro_held": ("--", "tab:purple"),
              "stress_macro_released": ("-.", "tab:brown")}
    for name, (ls, color) in styles.items():
        key = f"{name}_curve" if f"{name}_curve" in ds else name
        if key not in ds:
            continue
        xx = ds.travel.values if "travel" in ds[key].dims else w
        _tag(ax[0], kpa, None, ax[0].plot(xx, ds[key].values, ls, lw=1.4 if ls == "-" else 1.0, color=color,
                                          label=ds[key].attrs.get("long_name", name)))
    hit = float(ds.attrs.get("stitch_meets_punch_mm", np.inf))
    if np.isfinite(hit):
        ax[0].axvline(hit, color="tab:red", lw=0.8, ls=":", label=f"punch meets the stitch ({hit:.2f} mm)")
    w_err = float(ds.attrs.get("error_range_mm", VALIDITY_STRAIN * H0))
    lines = [f"error = {ERROR_DEFINITION}"]
    for key, what in (("macro", "macro, engine cushion"), ("macro_foundation", "macro, foundation cushion")):
        e1 = ds.attrs.get(f"max_relative_error_{key}_to_error_strain")
        e2 = ds.attrs.get(f"max_relative_error_{key}_to_end")
        if e1 is not None:
            lines.append(f"{what}: {100 * float(e1):.1f} % to {100 * w_err / H0:.0f} %, {100 * float(e2):.1f} % to "
                         f"{100 * float(ds.attrs.get('end_strain', 0.7)):.0f} %")
    if "max_relative_error" in ds.attrs:        # files of the linear seam cell (before the engine)
        lines.append(f"macro {100 * float(ds.attrs['max_relative_error']):.1f} % (0 - {w_err:g} mm)")
    ax[0].text(0.02, 0.72, "\n".join(lines), transform=ax[0].transAxes, fontsize=7, va="top", ha="left",
               bbox=dict(boxstyle="round", fc="w", ec="0.7"))
    ax[0].set(xlabel=f"punch travel from the {H0:g} mm plate distance, mm", xlim=(0, w.max()), ylim=(0, None))
    sec = ax[0].secondary_xaxis("top", functions=(lambda v: 100 * v / H0, lambda p: p * H0 / 100))
    sec.set_xlabel("compression, %", fontsize=8)
    ax[0].set_title(f"{cell}: seams every {d:g} mm, yarn level against the macro layer", fontsize=9)
    ax[0].legend(fontsize=7, loc="upper left")
    for name, mk in (("plate_contacts", "o-"), ("cushions_touched", "s-")):
        if name in ds:
            _tag(ax[1], "1", None, ax[1].plot(w, ds[name].values, mk, ms=3, label=ds[name].attrs.get("long_name",
                                                                                                    name)))
    ax[1].set(xlabel="punch travel, mm", ylabel="count, 1")
    ax[1].set_title(f"{cell}: the cushion meeting the punch (yarn level)", fontsize=9)
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    return fig


def strip_chart(ds):
    """A strip of seam cells under one punch against the macro layer's predictions from single
    cushions (``strip_vs_macro.nc``): stress over compression, and the cushion heights."""
    plt = pyplot()
    cell = cell_label(ds)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.6))
    e = 100 * ds.strain.values
    _tag(a1, "kPa", "compressive stress", a1.plot(e, ds.stress_strip.values, "ko-", ms=3,
                                                  label=f"yarn level: strip of {ds.attrs['seams']} seam cells"))
    for key, ls in (("cushion_laws", "s--"), ("shifted_law", "^--"), ("columns", "v:")):
        v = ds[f"stress_{key}"]
        _tag(a1, "kPa", None, a1.plot(e, v.values, ls, ms=3, label=f"{v.attrs.get('long_name', key)} (error "
                                      f"{100 * float(ds.attrs[f'error_{key}']):.1f} %)"))
    a1.set(xlabel="compression, % (plate travel / 20 mm)", xlim=(0, None), ylim=(0, None))
    a1.set_title(f"{cell}: seam distance {ds.attrs['seam_distance_mm']:.4g} mm, strip against the macro layer\n"
                 f"error = {ERROR_DEFINITION} to {e[-1]:.0f} %", fontsize=9)
    a1.legend(fontsize=7, loc="upper left")
    k = ds.sizes["cushion"]
    _tag(a2, "mm", None, a2.bar(np.arange(k) - 0.2, ds.cushion_height_strip.values, 0.4, label="in the strip"))
    _tag(a2, "mm", "cushion height", a2.bar(np.arange(k) + 0.2, ds.cushion_height_single.values, 0.4,
                                            label="single seam cell, both seams at the left eps0"))
    eps = ds.prestrain.values
    a2.set_xticks(np.arange(k), [f"cushion {i + 1}: seams at\neps0 {eps[i]:.3f} | {eps[(i + 1) % k]:.3f}"
                                 for i in range(k)])
    a2.set(ylim=(0.0, 1.05 * _thickness(ds)))
    a2.set_title(f"{cell}: cushion heights", fontsize=9)
    a2.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- speed against accuracy
def _free_offsets():
    for r in (7, 13, 20, 28):
        for ang in (45, 135, -45, -135, 0, 180, 90, -90):
            yield r * np.cos(np.radians(ang)), r * np.sin(np.radians(ang))


def place_labels(ax, xy, texts, *, fontsize=8) -> list:
    """Write ``texts`` next to the data points ``xy`` so that no label overlaps another label
    or a point (greedy: the first free offset of a growing ring). Returns the labels' display
    boxes (x0, y0, x1, y1)."""
    fig = ax.figure
    fig.canvas.draw()
    to_px = ax.transData.transform
    pts = to_px(np.asarray(xy, float))
    r_pt = 5.0 * fig.dpi / 72.0
    boxes = [(px - r_pt, py - r_pt, px + r_pt, py + r_pt) for px, py in pts]
    scale = fig.dpi / 72.0
    placed = []
    for (px, py), t in zip(pts, texts):
        w, h = 0.62 * fontsize * len(t) * scale, 1.05 * fontsize * scale
        for dx, dy in _free_offsets():
            cx, cy = px + dx * scale, py + dy * scale
            x0 = cx if dx > 0 else (cx - w if dx < 0 else cx - w / 2)
            y0 = cy if dy > 0 else (cy - h if dy < 0 else cy - h / 2)
            box = (x0, y0, x0 + w, y0 + h)
            if not any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3] for b in boxes):
                break
        boxes.append(box)
        placed.append(box)
        xd, yd = ax.transData.inverted().transform(((box[0] + box[2]) / 2, (box[1] + box[3]) / 2))
        ax.annotate(t, (xd, yd), ha="center", va="center", fontsize=fontsize)
    return placed


def speed_accuracy_chart(ds, *, floor: float = 1e-6):
    """Error against run time over model fidelities (``speed_accuracy.nc``): numbered markers
    placed without overprinting, the numbers explained in a table beside the chart; the error
    is defined on the y axis; references (error 0) are drawn at ``floor``."""
    plt = pyplot()
    cell = cell_label(ds)
    fig = plt.figure(figsize=(13, 5.6))
    gs = fig.add_gridspec(1, 2, width_ratios=[1.25, 1])
    ax = fig.add_subplot(gs[0])
    tab = fig.add_subplot(gs[1])
    t = ds.seconds.values
    e = np.maximum(ds.error.values, floor)
    qs = [str(q) for q in ds.question.values]
    models = [str(m) for m in ds.model.values]
    markers = dict(zip(dict.fromkeys(qs), ("o", "s", "^", "D")))
    for q in markers:
        sel = [i for i, qq in enumerate(qs) if qq == q]
        _tag(ax, "1", None, ax.scatter(t[sel], e[sel], marker=markers[q], s=36, label=q, zorder=3))
    _tag(ax, "1", None, ax.axhline(0.10, color="0.6", lw=0.8, ls="--", label="10 % target"))
    ax.set(xscale="log", yscale="log", xlabel="run time, s (this machine)",
           ylabel=f"error = {ERROR_DEFINITION}, 1")
    ax.yaxis.label.set_fontsize(8)
    ax.set_xlim(t.min() / 4, t.max() * 4)
    ax.set_ylim(floor / 3, max(1.0, e.max() * 3))
    ax.set_title(f"{cell}: which model does a question need? (references: error 0, drawn at {floor:g})", fontsize=9)
    ax.legend(fontsize=7, loc="lower left")
    place_labels(ax, np.column_stack([t, e]), [str(i + 1) for i in range(len(t))])
    tab.axis("off")
    rows = [[str(i + 1), q.split(" ")[0], m, f"{s:.3g}", "0 (ref.)" if err == 0 else f"{err:.2e}"]
            for i, (q, m, s, err) in enumerate(zip(qs, models, t, ds.error.values))]
    table = tab.table(cellText=rows, colLabels=["#", "question", "model", "run time, s", "error, 1"],
                      loc="center", cellLoc="left", colWidths=[0.06, 0.12, 0.52, 0.14, 0.16])
    for c in table.get_celld().values():
        c.PAD = 0.03
    table.auto_set_font_size(False)
    table.set_fontsize(7)
    table.scale(1, 1.25)
    tab.set_title("; ".join(f"{q}" for q in markers), fontsize=8)
    fig.tight_layout()
    return fig
