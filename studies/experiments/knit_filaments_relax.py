"""The paper's yarn of 20 filaments relaxed (issue 23, items 5 and 6): the E-glass 1x1 rib with each
yarn built as 20 parallel filaments in contact (``parameters.yarn_model.model = "filaments"``)
against the cheap one-beam equivalent yarn, both relaxed with ``homtex.relax`` (take-down 0.06 N
per 5 needles, frictionless as the cell file ships them; a yarn of filaments starts from its axes
relaxed as equivalent yarns of the bundle's outer radius, docs/knits.md).

Recorded per model: the relaxed loop length, wale and course spacing, loop height and width (mm),
status, stability, the ledger's balance, Newton iterations (of the filament stage and of the axis
stage) and process CPU seconds. The tangent solver is MKL PARDISO where the ``pardiso`` extra is
installed (the Dataset's attrs say which): a tangent whose bundles couple 20 filaments at every
node costs qdldl about six times as much per factorisation.

Usage::

    python studies/experiments/knit_filaments_relax.py [--quick] [--out DIR] [--no-docs]

``--quick``: the jersey with 3 filaments at 0.65 mm elements (seconds). Writes
``knit_filaments_relax.nc`` (dim ``model``) and ``knit_filaments_relax.png`` (the relaxed filaments
on the technical face and through the thickness, and the loop measures of both models) into OUT
(default results/knit_filaments_relax) and copies the chart to docs/studies/ (not with --quick).
Full run: about 7 minutes of CPU on the 2-core machine with PARDISO.
"""

from __future__ import annotations

import logging
import os
import platform
import sys
from pathlib import Path

import numpy as np
import xarray as xr

import homtex
from homtex.knits.charts import draw_cell
from homtex.linalg.tangent_backends import pardiso_available

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import add_docs_option, parser, publish, pyplot, relaxed_yarn_model, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")
MODELS = ("filaments", "equivalent")
MEASURES = ("loop_length", "wale_spacing", "course_spacing", "loop_height", "loop_width")


def relax_one(name: str, model: str, n: int, element: float | None):
    """(RelaxedCell, Dataset of one model's figures)."""
    r, cpu = relaxed_yarn_model(name, model, n, element)
    a = r.attrs
    data = {k: ((), float(a[f"relaxed_{k}_mm"]), {"units": "mm", "long_name": f"relaxed {k.replace('_', ' ')}"})
            for k in MEASURES}
    for k, v, u, what in (("cpu_s", cpu, "s", "process CPU of the relaxation"),
                          ("newton_iterations", int(a["newton_iterations"]), "1", "Newton iterations, all stages"),
                          ("axis_newton_iterations", int(a.get("axis_newton_iterations", 0)), "1",
                           "Newton iterations of the axis stage"),
                          ("energy_balance", float(a["energy_balance"]), "1", "ledger balance"),
                          ("stable", int(bool(a["stable"])), "1", "no negative eigenvalue at the end"),
                          ("n_elements", r.cell.frame.n_elements, "1", "beam elements"),
                          ("status", str(a["status"]), "1", "status of the relaxation")):
        data[k] = ((), v, {"units": u, "long_name": what})
    return r, xr.Dataset(data)


def chart(res: xr.Dataset, relaxed, path):
    plt = pyplot()
    fig, (ax, bx, cx) = plt.subplots(1, 3, figsize=(16, 5.2), gridspec_kw={"width_ratios": [1.1, 1.1, 1]})
    draw_cell(ax, bx, relaxed.frame, tiles=(2, 2), colour=relaxed.info["course"])
    n = int(res.attrs["filaments"])
    ax.set_title(f"{res.attrs['cell']} relaxed, {n} filaments per yarn (2 x 2 cells;\none colour per course)",
                 fontsize=9)
    bx.set_title("section, one row of cells", fontsize=9)
    w = 0.38
    y = np.arange(len(MEASURES))
    for k, m in enumerate(res.model.values):
        c = res.sel(model=m)
        label = (f"{m}: {float(c.cpu_s):.0f} s CPU, {int(c.newton_iterations)} iterations, {c.status.values}"
                 if m == "filaments" else f"{m} yarn: {float(c.cpu_s):.1f} s CPU, {c.status.values}")
        cx.barh(y + (k - 0.5) * w, [float(c[q]) for q in MEASURES], height=w, color=f"C{k}", label=label)
    cx.set_yticks(y, [q.replace("_", " ") for q in MEASURES])
    cx.set_xlabel("relaxed, mm")
    cx.set_title(f"loop measures, filaments against the equivalent yarn\n(tangent solver {res.attrs['solver']}, "
                 f"{res.attrs['machine']})", fontsize=9)
    cx.grid(alpha=0.3, axis="x")
    cx.legend(fontsize=7, loc="center right")
    fig.tight_layout()
    return save_figure(fig, path)


def main(argv=None):
    p = add_docs_option(parser(__file__, __doc__))
    args = p.parse_args(argv)
    out = setup(args)
    name, n, element = ("jersey_eglass", 3, 0.65) if args.quick else ("rib_1x1_eglass", 20, None)
    solver = "pardiso" if pardiso_available() else "ldl"
    runs, relaxed = [], None
    with homtex.set_options(tangent_solver=solver):
        for m in MODELS:
            r, ds = relax_one(name, m, n, element)
            runs.append(ds)
            relaxed = r if m == "filaments" else relaxed
    res = xr.concat(runs, dim="model").assign_coords(model=("model", list(MODELS)))
    res.attrs.update(title="a yarn of filaments relaxed against its equivalent yarn", cell=name, filaments=n,
                     solver=solver, machine=f"{platform.machine()}, {os.cpu_count()} CPUs",
                     protocol=str(relaxed.attrs["protocol"]))
    save_netcdf(res, out / "knit_filaments_relax.nc")
    path = chart(res, relaxed, out / "knit_filaments_relax.png")
    for m in MODELS:
        c = res.sel(model=m)
        log.info("%s: %s, %.1f s CPU, %d Newton iterations; %s", m, c.status.values, float(c.cpu_s),
                 int(c.newton_iterations), ", ".join(f"{q} {float(c[q]):.4f} mm" for q in MEASURES))
    publish(args, path)
    return res


if __name__ == "__main__":
    main()
