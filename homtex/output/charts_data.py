"""Charts of study results, homogenisations and any other Dataset, and :func:`chart`, which picks
the dedicated chart of a Dataset by its kind (``homtex plot``). Same rules as
:mod:`homtex.output.charts`: one unit per y axis, labels "quantity, unit", the cell in the title.
"""

from __future__ import annotations

import json

import numpy as np

from ..errors import InputError
from .charts import (
    _tag,
    cell_label,
    compression_chart,
    cushions_chart,
    macro_chart,
    pyplot,
    seam_profile_chart,
    seamed_chart,
    speed_accuracy_chart,
    strip_chart,
)

__all__ = ["KINDS", "chart", "dataset_kind", "generic_chart", "homogenization_chart", "knit_tensile_chart",
           "study_chart"]


def _label(da, name=None) -> str:
    """ "long_name, unit" of a DataArray."""
    name = name or str(da.name)
    return f"{da.attrs.get('long_name', name)}, {da.attrs.get('units', '1')}"


def _numeric(da) -> bool:
    return np.issubdtype(da.dtype, np.number) and da.dtype != bool


# ----------------------------------------------------------------------------- homogenisation
def homogenization_chart(ds):
    """Effective stiffness matrix C (Voigt) with its values and the engineering constants."""
    plt = pyplot()
    cell = cell_label(ds)
    C = ds["C"]
    unit = C.attrs.get("units", "1")
    fig, ax = plt.subplots(figsize=(6.2, 5.0))
    im = _tag(ax, "1", None, ax.imshow(C.values, cmap="viridis"))
    mid = 0.5 * (np.nanmin(C.values) + np.nanmax(C.values))
    tiny = 1e-9 * np.nanmax(np.abs(C.values))     # round-off of an exact zero
    for (i, j), v in np.ndenumerate(C.values):
        ax.text(j, i, "0" if abs(v) <= tiny else f"{v + 0.0:.3g}", ha="center", va="center", fontsize=7,
                color="k" if v > mid else "w")
    rows, cols = (list(map(str, C[d].values)) for d in C.dims)
    ax.set_xticks(range(len(cols)), cols)
    ax.set_yticks(range(len(rows)), rows)
    ax.set(xlabel=f"{C.dims[1]} (Voigt component)", ylabel=f"{C.dims[0]} (Voigt component)")
    fig.colorbar(im, ax=ax, label=f"effective stiffness, {unit}")
    consts = [f"{k} = {float(ds[k]) + 0.0:.3g} {ds[k].attrs.get('units', '')}".removesuffix(" 1").rstrip()
              for k in ds.data_vars if ds[k].ndim == 0 and _numeric(ds[k])]
    ax.set_title(f"{cell}: effective stiffness C, {unit}\n" + ", ".join(consts[:6]), fontsize=8)
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- studies
def _study_params(ds) -> list:
    try:
        names = json.loads(ds.attrs.get("study_parameters", "[]"))
    except (TypeError, ValueError):
        names = []
    return [n for n in names if n in ds.variables]


def _coerce(values, text):
    """The coordinate value matching ``text`` (exact string, else the nearest number)."""
    strs = [str(v) for v in values]
    if text in strs:
        return values[strs.index(text)]
    try:
        x = float(text)
        num = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"no value {text!r}; values: {', '.join(strs[:20])}") from None
    i = int(np.argmin(np.abs(num - x)))
    if not np.isclose(num[i], x, rtol=1e-9, atol=1e-12):
        raise InputError(f"no value {text!r}; values: {', '.join(strs[:20])}")
    return values[i]


def select(da, sel: dict | None, keep: list):
    """``da`` with every dimension outside ``keep`` reduced by ``sel`` ({dim: value text});
    dimensions of length 1 are dropped. InputError names what is missing."""
    sel = dict(sel or {})
    for dim, text in sel.items():
        if dim not in da.dims:
            raise InputError(f"--sel {dim}={text}: {da.name!r} has no dimension {dim!r} (its dimensions: "
                             f"{', '.join(map(str, da.dims))})")
        vals = da[dim].values if dim in da.coords else np.arange(da.sizes[dim])
        try:
            v = _coerce(list(vals), str(text))
        except InputError as exc:
            raise InputError(f"--sel {dim}={text}: {exc}") from None
        da = da.sel({dim: v}) if dim in da.coords else da.isel({dim: int(v)})
    extra = [d for d in da.dims if d not in keep]
    for d in [d for d in extra if da.sizes[d] == 1]:
        da = da.isel({d: 0})
    extra = [d for d in da.dims if d not in keep]
    if extra:
        opts = "; ".join(f"{d}: " + ", ".join(_values(da, d)[:12]) for d in extra)
        raise InputError(f"variable {da.name!r} has the extra dimension(s) {', '.join(extra)}: pick one value of "
                         f"each with --sel DIM=VALUE ({opts})")
    return da


def _values(da, dim) -> list:
    return [str(v) for v in (da[dim].values if dim in da.coords else range(da.sizes[dim]))]


def _plottable(ds, keep) -> list:
    skip = {"status", "error", "check"}
    return [str(n) for n, v in ds.data_vars.items() if n not in skip and _numeric(v) and v.ndim > 0]


def study_chart(ds, *, var: str | None = None, sel: dict | None = None):
    """A study result (``homtex study``): samples as scatter plots of ``var`` over each sampled
    parameter (coloured by the next one), 1-D grids as lines, 2-D grids as a heat map next to
    lines over the first parameter. ``var``: default the first variable that has no dimensions
    beyond the study's; ``sel``: {dim: value} for the others."""
    params = _study_params(ds)
    if not params:
        raise InputError("not a study result: no 'study_parameters' attribute naming its parameters")
    samples = ds.attrs.get("study_layout") != "grid"
    keep = ["sample"] if samples else params
    names = _plottable(ds, keep)
    if var is None:
        plain = [n for n in names if set(ds[n].dims) <= set(keep)]
        if not plain and not names:
            raise InputError("the study result has no numeric variable to plot")
        var = (plain or names)[0]
    if var not in ds.data_vars:
        raise InputError(f"--var {var}: no such variable; variables: {', '.join(names)}")
    da = select(ds[var], sel, keep)
    others = [n for n in names if n != var]
    note = f"--var {var}; others: {', '.join(others[:10])}" + (" ..." if len(others) > 10 else "")
    if samples:
        fig = _samples(ds, da, params)
    else:
        extra = [p for p in params if p in da.dims][2:]
        for p in extra:      # 3-D grids and more: the first value of the further parameters
            da = da.isel({p: 0})
        fig = _grid(ds, da, [p for p in params if p in da.dims])
        if extra:
            note += "; at " + ", ".join(f"{p} = {ds[p].values[0]}" for p in extra) + " (--sel to choose)"
    failed = int(ds.attrs.get("points_failed", 0))
    fig.suptitle(f"{cell_label(ds)}: study {ds.attrs.get('study_name', '?')} ({ds.attrs.get('study_task', '?')}, "
                 f"{ds.attrs.get('points_ok', '?')} of {ds.attrs.get('points_total', '?')} points ok"
                 + (f", {failed} failed: not drawn" if failed else "") + ")", fontsize=10)
    fig.text(0.01, 0.005, note, fontsize=7, color="0.4")
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    return fig


def _samples(ds, da, params):
    plt = pyplot()
    n = min(len(params), 4)
    fig, axes = plt.subplots(1, n, figsize=(5.2 * n, 4.4), squeeze=False)
    unit = da.attrs.get("units", "1")
    for ax, p in zip(axes[0], params):
        c = next((q for q in params if q != p), None)
        kw = {"c": ds[c].values, "cmap": "viridis"} if c is not None else {}
        sc = _tag(ax, unit, None, ax.scatter(ds[p].values, da.values, s=22, **kw))
        if c is not None:
            fig.colorbar(sc, ax=ax, label=_label(ds[c], c))
        ax.set(xlabel=_label(ds[p], p), ylabel=_label(da, str(da.name)))
        ax.set_title(f"{da.name} over {p} (samples, no order)", fontsize=9)
    return fig


def _grid(ds, da, dims):
    plt = pyplot()
    unit = da.attrs.get("units", "1")
    if len(dims) == 1:
        fig, ax = plt.subplots(figsize=(7, 4.4))
        p = dims[0]
        _tag(ax, unit, None, ax.plot(ds[p].values, da.values, "o-", ms=4, label=str(da.name)))
        ax.set(xlabel=_label(ds[p], p), ylabel=_label(da))
        ax.set_title(f"{da.name} over {p}", fontsize=9)
        return fig
    p, q = dims[0], dims[1]
    z = da.transpose(q, p).values
    fig, ax = plt.subplots(1, 2, figsize=(12.5, 4.6))
    xs, ys = _edges(ds[p].values), _edges(ds[q].values)
    qunit = ds[q].attrs.get("units", "1")
    mesh = _tag(ax[0], qunit, None, ax[0].pcolormesh(xs, ys, z, cmap="viridis", shading="flat"))
    if z.size <= 64:
        for (j, i), v in np.ndenumerate(z):
            ax[0].text(0.5 * (xs[i] + xs[i + 1]), 0.5 * (ys[j] + ys[j + 1]), f"{v:.3g}", ha="center",
                       va="center", fontsize=7, color="w")
    fig.colorbar(mesh, ax=ax[0], label=_label(da))
    ax[0].set(xlabel=_label(ds[p], p), ylabel=_label(ds[q], q))
    ax[0].set_title(f"{da.name} (heat map)", fontsize=9)
    for j, qv in enumerate(ds[q].values):
        _tag(ax[1], unit, None, ax[1].plot(ds[p].values, z[j], "o-", ms=3, label=f"{q} = {qv:g} {qunit}"
                                           if np.issubdtype(np.asarray(qv).dtype, np.number) else f"{q} = {qv}"))
    ax[1].set(xlabel=_label(ds[p], p), ylabel=_label(da))
    ax[1].set_title(f"{da.name} over {p}, one line per {q}", fontsize=9)
    ax[1].legend(fontsize=7)
    return fig


def _edges(v):
    """Cell edges around (sorted or not) grid values, for pcolormesh."""
    v = np.asarray(v, dtype=float)
    if v.size == 1:
        return np.r_[v[0] - 0.5, v[0] + 0.5]
    mid = 0.5 * (v[1:] + v[:-1])
    return np.r_[v[0] - (mid[0] - v[0]), mid, v[-1] + (v[-1] - mid[-1])]


# ----------------------------------------------------------------------------- anything else
def generic_chart(ds, *, var: str | None = None, max_panels: int = 6):
    """Any Dataset: its 1-D numeric variables over their dimension, one panel per (dimension,
    unit); ``var`` draws only that variable."""
    plt = pyplot()
    groups: dict = {}
    for name, v in ds.data_vars.items():
        if var is not None and name != var:
            continue
        if v.ndim == 1 and _numeric(v):
            groups.setdefault((v.dims[0], str(v.attrs.get("units", "1"))), []).append(str(name))
    if not groups:
        what = ", ".join(f"{n} {tuple(v.dims)}" for n, v in ds.data_vars.items()) or "no variables"
        raise InputError(("no variable " + repr(var) if var is not None and var not in ds.data_vars
                          else "no 1-D numeric variable to draw") + f" ({what})")
    keys = list(groups)[:max_panels]
    fig, axes = plt.subplots(len(keys), 1, figsize=(8, 2.9 * len(keys) + 0.4), squeeze=False)
    for ax, (dim, unit) in zip(axes[:, 0], keys):
        x = ds[dim] if dim in ds.coords else None
        xv = x.values if x is not None and _numeric(x) else np.arange(ds.sizes[dim])
        for name in groups[(dim, unit)][:8]:
            v = ds[name]
            _tag(ax, unit, None, ax.plot(xv, v.values, marker=".", label=str(v.attrs.get("long_name", name))))
        names = groups[(dim, unit)]
        ax.set_ylabel(f"{ds[names[0]].attrs.get('long_name', names[0]) if len(names) == 1 else 'value'}, {unit}")
        ax.set_xlabel(_label(x, dim) if x is not None and _numeric(x) else f"{dim} (index)")
        if x is not None and not _numeric(x):
            ax.set_xticks(xv, [str(s) for s in x.values], fontsize=7, rotation=20)
        ax.legend(fontsize=7)
    left = len(groups) - len(keys)
    fig.suptitle(f"{cell_label(ds)}: {ds.attrs.get('title', 'homtex Dataset')}"
                 + (f" ({left} more panels: --var NAME)" if left else ""), fontsize=9)
    fig.tight_layout()
    return fig


def knit_tensile_chart(ds):
    """Force per width over the strain of a knit tensile test (``homtex tensile``,
    ``homtex.tensile``); one curve per friction coefficient where ``friction`` is a dimension."""
    from ..knits.charts import tensile_chart

    if "friction" in ds.dims:
        curves = {f"friction {float(mu):g}": ds.sel(friction=mu) for mu in ds.friction.values}
    else:
        curves = {f"friction {float(ds.attrs.get('friction', 0.0)):g}": ds}
    where = str(ds.attrs.get("direction", "?"))
    name = cell_label(ds) if "cell_name" in ds.attrs or "cell" not in ds.attrs else str(ds.attrs["cell"])
    return tensile_chart(curves, title=f"{name}\n{ds.attrs.get('specimen', 'tensile test')}, along the {where}s")


KINDS = {"compression": compression_chart, "seam_profile": seam_profile_chart, "macro_curve": macro_chart,
         "macro_curves": macro_chart, "cushions": cushions_chart, "seamed_vs_macro": seamed_chart,
         "speed_accuracy": speed_accuracy_chart, "homogenization": homogenization_chart, "study": study_chart,
         "knit_tensile": knit_tensile_chart, "strip_vs_macro": strip_chart}


def dataset_kind(ds) -> str:
    """What a Dataset is: its ``homtex_kind`` attribute (set by the stages) or, for older files and
    Datasets from the API, what its variables say; "generic" if nothing fits."""
    kind = str(ds.attrs.get("homtex_kind", ""))
    if kind in KINDS or kind == "generic":
        return kind
    v, dims = ds.variables, ds.dims
    if "study_parameters" in ds.attrs:
        return "study"
    if "C" in v and "row" in dims and "col" in dims:
        return "homogenization"
    if "height_yarn" in v and "case" in dims and "xi" in dims:
        return "cushions"
    if "height" in v and "x" in dims and "cushion_height" in v:
        return "seam_profile"
    if "stress_yarn" in v:
        return "seamed_vs_macro"
    if "stress_strip" in v and "cushion" in dims:
        return "strip_vs_macro"
    if "error" in v and "seconds" in v and "model" in dims and "question" in v:
        return "speed_accuracy"
    if "force" in v and "plate_displacement" in dims and "specimen" in dims:
        return "macro_curves"
    if "force" in v and "plate_displacement" in dims and "column_height" in v:
        return "macro_curve"
    if "force_per_width" in v and "strain" in dims:
        return "knit_tensile"
    if "stress" in v and "strain" in dims:
        return "compression"
    return "generic"


def chart(ds, *, var: str | None = None, sel: dict | None = None):
    """The chart of a Dataset: the dedicated one of its kind (:func:`dataset_kind`), else
    :func:`generic_chart`. ``var``/``sel`` choose what a study or generic chart draws."""
    kind = dataset_kind(ds)
    if kind == "study":
        return study_chart(ds, var=var, sel=sel)
    if var is not None or kind == "generic":
        for dim, text in (sel or {}).items():
            if dim not in ds.dims:
                raise InputError(f"--sel {dim}={text}: no dimension {dim!r} (dimensions: "
                                 f"{', '.join(map(str, ds.dims))})")
            try:
                ds = ds.sel({dim: _coerce(list(ds[dim].values), str(text))}) if dim in ds.coords \
                    else ds.isel({dim: int(text)})
            except (InputError, ValueError, IndexError) as exc:
                raise InputError(f"--sel {dim}={text}: {exc}") from None
        return generic_chart(ds, var=var)
    return KINDS[kind](ds)
