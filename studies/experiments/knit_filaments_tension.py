"""A yarn of filaments against its one-beam equivalent in tension (issue 23, item 6): the E-glass
jersey pulled along the wales with each yarn built as N parallel filaments in contact and as the
cheap equivalent yarn (the bundle's axial stiffness, the filaments' summed bending and torsion
rigidity, the packed bundle's contact radius).

``cells/jersey_eglass.toml`` with ``parameters.yarn_model.filaments = 3`` (the 20 filaments of the
paper's numerical yarn relax, ``knit_filaments_relax.py``, but do not get through a first level of
the pull in half an hour, docs/knits.md) and ``model = "filaments"`` /
``"equivalent"``, each relaxed with ``homtex.relax`` (take-down 0.06 N per 5 needles) and pulled with
``homtex.tensile(..., direction="wale")`` (periodic cell, free lateral contraction, frictionless
filaments as the cell file ships them) to 30 % in 15 levels. Recorded per model: force per width
(N/mm), the relaxed wale and course spacing, the stabilisation's share of the work (the energy
the snaps release), the energy balance, status, Newton iterations and process CPU seconds; the
filaments' force over the equivalent yarn's at each strain both reach.

Usage::

    python studies/experiments/knit_filaments_tension.py [--quick] [--out DIR] [--no-docs]

Writes ``knit_filaments_tension.nc`` (dims ``model``, ``strain``) and ``knit_filaments_tension.png``
into OUT (default results/knit_filaments_tension) and copies the chart to docs/studies/ (not with
--quick). Full run: about a minute of CPU on the 2-core machine.
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

import homtex

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import add_docs_option, parser, publish, pyplot, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")
MODELS = ("filaments", "equivalent")


def run_one(model: str, n: int, strain: float, steps: int, element: float | None) -> xr.Dataset:
    """Relax and pull one model; the curve with its status, CPU and relaxed spacings."""
    changes = {"parameters.yarn_model.filaments": n, "parameters.yarn_model.model": model}
    if element is not None:
        changes["resolution.element_length"] = element
    cell = homtex.load_cell("jersey_eglass").replace(**changes)
    t0 = time.process_time()
    relaxed = homtex.relax(cell)
    relax_cpu = time.process_time() - t0
    ds = homtex.tensile(relaxed, strain=strain, direction="wale", steps=steps)
    cpu = time.process_time() - t0
    work = ds.external_work.values
    share = np.divide(ds.stabilization_energy.values, work, out=np.zeros_like(work), where=work > 0)
    out = ds[["force_per_width", "energy_balance", "newton_iterations"]]
    out["stabilization_share"] = ("strain", share, {"units": "1", "long_name": "stabilisation / external work"})
    for k, v, u, name in (("status", str(ds.attrs["status"]), "1", "status of the tensile test"),
                          ("status_detail", str(ds.attrs.get("status_detail", "")), "1", "why"),
                          ("cpu_s", cpu, "s", "process CPU of relaxation and tensile test"),
                          ("relax_cpu_s", relax_cpu, "s", "process CPU of the relaxation"),
                          ("wale_spacing", float(relaxed.attrs["wale_spacing_mm"]), "mm", "relaxed wale spacing"),
                          ("course_spacing", float(relaxed.attrs["course_spacing_mm"]), "mm", "relaxed course spacing")):
        out[k] = ((), v, {"units": u, "long_name": name})
    out.attrs = {}
    return out


def chart(ds: xr.Dataset, path):
    plt = pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 4.8))
    for k, m in enumerate(ds.model.values):
        c = ds.sel(model=m)
        f = c.force_per_width.values
        e = 100 * c.strain.values
        ax.plot(e, f, marker=".", color=f"C{k}", label=f"{m} ({int(ds.attrs['filaments'])}), status {c.status.values}")
        if str(c.status.values) == "failed":
            last = int(np.flatnonzero(np.isfinite(f))[-1])
            why = str(c.status_detail.values).split("): ", 1)[-1].split(" (")[0]
            ax.annotate(f"no equilibrium found past {e[last]:.0f} %:\n{why}", (e[last], f[last]),
                        textcoords="offset points", xytext=(10, -30), fontsize=7, color=f"C{k}")
        bx.plot(e, 100 * c.stabilization_share.values, marker=".", color=f"C{k}", label=f"{m}: stabilisation")
        bx.plot(e, 100 * np.abs(c.energy_balance.values), ls="--", color=f"C{k}", label=f"{m}: |energy balance|")
    ax.set_yscale("log")
    ax.set_ylabel("force per width, N/mm")
    ax.set_title("E-glass jersey along the wales: filaments against the equivalent yarn", fontsize=10)
    bx.axhline(1.0, color="0.5", lw=0.8, ls=":", label="1 % flag limit")
    bx.set_ylabel("share of the external work, %")
    bx.set_title("energy the snaps release (stabilisation) and the ledger's balance", fontsize=10)
    for a in (ax, bx):
        a.set_xlabel("strain (extension / gauge length), %")
        a.grid(alpha=0.3, which="both")
        a.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)


def main(argv=None):
    p = add_docs_option(parser(__file__, __doc__))
    args = p.parse_args(argv)
    out = setup(args)
    n = 3
    strain, steps, element = (0.02, 1, 0.4) if args.quick else (0.3, 15, None)
    runs = [run_one(m, n, strain, steps, element) for m in MODELS]
    res = xr.concat(runs, dim="model", join="outer").assign_coords(model=("model", list(MODELS)))
    both = np.isfinite(res.force_per_width).all("model")
    ratio = (res.force_per_width.sel(model="filaments") / res.force_per_width.sel(model="equivalent")).where(both)
    res["filaments_over_equivalent"] = ratio.assign_attrs(units="1", long_name="force per width, filaments / equivalent")
    res.attrs.update(title="E-glass jersey along the wales: a yarn of filaments against its equivalent yarn",
                     cell="jersey_eglass", filaments=n, friction=0.0)
    save_netcdf(res, out / "knit_filaments_tension.nc")
    path = chart(res, out / "knit_filaments_tension.png")
    for m in MODELS:
        c = res.sel(model=m)
        log.info("%s: %s, %.0f s CPU; force per width %s N/mm", m, c.status.values, float(c.cpu_s),
                 np.array2string(c.force_per_width.values, precision=4))
    log.info("filaments / equivalent: %s", np.array2string(res.filaments_over_equivalent.values, precision=3))
    publish(args, path)
    return res


if __name__ == "__main__":
    main()
