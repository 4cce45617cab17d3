"""A yarn of filaments against its one-beam equivalent in tension (issue 23, item 6): the E-glass
jersey pulled along the wales with each yarn built as N parallel filaments in contact and as the
cheap equivalent yarn (the bundle's axial stiffness, the filaments' summed bending and torsion
rigidity, the packed bundle's contact radius).

``cells/jersey_eglass.toml`` with ``parameters.yarn_model.filaments = 3`` and ``model = "filaments"`` /
``"equivalent"``, each relaxed with ``homtex.relax`` (take-down 0.06 N per 5 needles) and pulled with
``homtex.tensile(..., direction="wale")`` (periodic cell, free lateral contraction, frictionless
filaments as the cell file ships them) to 30 % in 15 levels. ``--paper``: the knit paper's own
case instead, ``cells/rib_1x1_eglass.toml`` with its yarn of 20 filaments, pulled to 50 % in 25
levels (the first filament passes 2400 MPa at 44 % on the equivalent yarn), the tangent solver
MKL PARDISO where the ``pardiso`` extra is installed. Recorded per model: force per width (N/mm),
the largest axial filament stress (MPa) and the strain where it first passes the cell's failure
stress, the relaxed wale and course spacing, the stabilisation's share of the work (the energy the
snaps release), the energy balance, status, Newton iterations, process CPU seconds (relaxation,
test, per Newton iteration of the test); the filaments' force over the equivalent yarn's at each
strain both reach.

Usage::

    python studies/experiments/knit_filaments_tension.py [--quick] [--paper] [--strain S] [--out DIR] [--no-docs]

Writes ``knit_filaments_tension.nc`` (dims ``model``, ``strain``) and ``knit_filaments_tension.png``
(``knit_filaments_tension_rib20.*`` with ``--paper``) into OUT (default
results/knit_filaments_tension) and copies the chart to docs/studies/ (not with --quick). Full
run: about a minute of CPU on the 2-core machine; ``--paper`` over an hour.
"""

from __future__ import annotations

import logging
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

import homtex
from homtex.linalg.tangent_backends import pardiso_available

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import add_docs_option, parser, publish, pyplot, relaxed_yarn_model, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")
MODELS = ("filaments", "equivalent")


def run_one(name: str, model: str, n: int, strain: float, steps: int, element: float | None) -> xr.Dataset:
    """Relax and pull one model; the curve with its status, CPU and relaxed spacings."""
    relaxed, relax_cpu = relaxed_yarn_model(name, model, n, element)
    t0 = time.process_time()
    ds = homtex.tensile(relaxed, strain=strain, direction="wale", steps=steps, progress=True)
    cpu = relax_cpu + time.process_time() - t0
    work = ds.external_work.values
    share = np.divide(ds.stabilization_energy.values, work, out=np.zeros_like(work), where=work > 0)
    out = ds[["force_per_width", "energy_balance", "newton_iterations", "max_filament_stress"]]
    out["stabilization_share"] = ("strain", share, {"units": "1", "long_name": "stabilisation / external work"})
    limit = float(ds.attrs.get("failure_stress_MPa", np.nan))
    past = np.flatnonzero(ds.beyond_failure_stress.values)
    iters = int(np.nansum(ds.newton_iterations.values))
    for k, v, u, what in (("status", str(ds.attrs["status"]), "1", "status of the tensile test"),
                          ("status_detail", str(ds.attrs.get("status_detail", "")), "1", "why"),
                          ("cpu_s", cpu, "s", "process CPU of relaxation and tensile test"),
                          ("relax_cpu_s", relax_cpu, "s", "process CPU of the relaxation"),
                          ("tensile_cpu_s", cpu - relax_cpu, "s", "process CPU of the tensile test"),
                          ("cpu_per_iteration_ms", 1e3 * (cpu - relax_cpu) / max(iters, 1), "ms",
                           "process CPU of the tensile test per Newton iteration"),
                          ("failure_stress", limit, "MPa", "the cell's filament failure stress"),
                          ("strain_at_failure_stress", float(ds.strain.values[past[0]]) if len(past) else np.nan,
                           "1", "first strain whose largest axial filament stress passes the failure stress"),
                          ("wale_spacing", float(relaxed.attrs["wale_spacing_mm"]), "mm", "relaxed wale spacing"),
                          ("course_spacing", float(relaxed.attrs["course_spacing_mm"]), "mm", "relaxed course spacing")):
        out[k] = ((), v, {"units": u, "long_name": what})
    out.attrs = {}
    return out


def chart(ds: xr.Dataset, path):
    plt = pyplot()
    fig, (ax, bx, cx) = plt.subplots(1, 3, figsize=(18, 4.9))
    n = int(ds.attrs["filaments"])
    for k, m in enumerate(ds.model.values):
        c = ds.sel(model=m)
        f = c.force_per_width.values
        e = 100 * c.strain.values
        cpu = (f"{float(c.tensile_cpu_s):.0f} s CPU, {1e-3 * float(c.cpu_per_iteration_ms):.2f} s per iteration"
               if m == "filaments" else f"{float(c.tensile_cpu_s):.0f} s CPU")
        ax.plot(e, f, marker=".", color=f"C{k}", label=f"{m} ({n}), status {c.status.values}; test {cpu}")
        if str(c.status.values) == "failed":
            last = int(np.flatnonzero(np.isfinite(f))[-1])
            why = str(c.status_detail.values).split("): ", 1)[-1].split(" (")[0]
            ax.annotate(f"no equilibrium found past {e[last]:.0f} %:\n{why}", (e[last], f[last]),
                        textcoords="offset points", xytext=(10, -30), fontsize=7, color=f"C{k}")
        bx.plot(e, 100 * c.stabilization_share.values, marker=".", color=f"C{k}", label=f"{m}: stabilisation")
        bx.plot(e, 100 * np.abs(c.energy_balance.values), ls="--", color=f"C{k}", label=f"{m}: |energy balance|")
        cx.plot(e, c.max_filament_stress.values, marker=".", color=f"C{k}", label=m)
    limit = float(ds.failure_stress.max())
    if np.isfinite(limit):
        cx.axhline(limit, color="C3", lw=1, ls=":", label=f"failure stress {limit:.0f} MPa (flagged beyond)")
    ax.set_yscale("log")
    ax.set_ylabel("force per width, N/mm")
    ax.set_title(f"{ds.attrs['cell']} along the wales: filaments against the equivalent yarn\n"
                 f"(tangent solver {ds.attrs['solver']}, {ds.attrs['machine']})", fontsize=10)
    bx.axhline(1.0, color="0.5", lw=0.8, ls=":", label="1 % flag limit")
    bx.set_ylabel("share of the external work, %")
    bx.set_title("energy the snaps release (stabilisation) and the ledger's balance", fontsize=10)
    cx.set_yscale("log")
    cx.set_ylabel("largest axial filament stress, MPa")
    cx.set_title("peak filament stress", fontsize=10)
    for a in (ax, bx, cx):
        a.set_xlabel("strain (extension / gauge length), %")
        a.grid(alpha=0.3, which="both")
        a.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)


def main(argv=None):
    p = add_docs_option(parser(__file__, __doc__))
    p.add_argument("--paper", action="store_true",
                   help="the knit paper's 1x1 rib with its yarn of 20 filaments, to 50 %% (over an hour)")
    p.add_argument("--strain", type=float, default=None,
                   help="pull to this strain instead (in 2 %% levels; not with --quick)")
    args = p.parse_args(argv)
    out = setup(args)
    name, n, stem = ("rib_1x1_eglass", 20, "knit_filaments_tension_rib20") if args.paper else (
        "jersey_eglass", 3, "knit_filaments_tension")
    strain, steps, element = (0.02, 1, 0.4) if args.quick else (0.5, 25, None) if args.paper else (0.3, 15, None)
    if args.strain is not None and not args.quick:
        strain, steps = args.strain, max(int(round(args.strain / 0.02)), 1)       # the same 2 % levels
    solver = "pardiso" if pardiso_available() else "ldl"
    with homtex.set_options(tangent_solver=solver):
        runs = [run_one(name, m, n, strain, steps, element) for m in MODELS]
    res = xr.concat(runs, dim="model", join="outer").assign_coords(model=("model", list(MODELS)))
    both = np.isfinite(res.force_per_width).all("model")
    ratio = (res.force_per_width.sel(model="filaments") / res.force_per_width.sel(model="equivalent")).where(both)
    res["filaments_over_equivalent"] = ratio.assign_attrs(units="1", long_name="force per width, filaments / equivalent")
    res.attrs.update(title=f"{name} along the wales: a yarn of filaments against its equivalent yarn",
                     cell=name, filaments=n, friction=0.0, solver=solver,
                     machine=f"{platform.machine()}, {os.cpu_count()} CPUs")
    save_netcdf(res, out / f"{stem}.nc")
    path = chart(res, out / f"{stem}.png")
    for m in MODELS:
        c = res.sel(model=m)
        log.info("%s: %s, %.0f s CPU (test %.0f s, %.1f ms per Newton iteration); force per width %s N/mm; "
                 "failure stress passed at strain %s", m, c.status.values, float(c.cpu_s), float(c.tensile_cpu_s),
                 float(c.cpu_per_iteration_ms), np.array2string(c.force_per_width.values, precision=4),
                 float(c.strain_at_failure_stress))
    log.info("filaments / equivalent: %s", np.array2string(res.filaments_over_equivalent.values, precision=3))
    publish(args, path)
    return res


if __name__ == "__main__":
    main()
