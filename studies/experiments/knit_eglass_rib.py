"""The E-glass 1x1 rib of the knit paper (Duhovic and Bhattacharyya 2006) relaxed and pulled along
the wales (issue 23): the force-extension curve, the peak filament stress and strain and where
they occur, the deformation energy split of the paper's Eq. 8 (its Fig. 24) and the energy balance,
frictionless (the paper's model) and with friction 0.5 (its estimate for sized E-glass).

The periodic cell of ``cells/rib_1x1_eglass.toml`` (20-filament numerical yarn as one equivalent
yarn) is relaxed with ``homtex.relax`` (take-down 0.06 N per 5 needles) and stretched along the
wales with ``homtex.tensile(..., specimen="cell")`` to 45 % (free lateral contraction). Recorded:
force per width, the energy split (axial, torsion, bending about both section axes, shear,
contact, friction dissipated), the external work and the balance, the largest filament stress
(axial, the paper's 2058-2198 MPa at 2.8-3.0 % strain, failure 2400-3450 MPa) and the strain
where it first passes 2400 MPa, the ratios the paper reports (bending / torsion at low extension,
axial against torsion at high extension, axial / contact at its peak, bending about one axis / the
other); pictures of the cell at 0 / 20 / 40 % and VTK files with per-element energies.

Usage::

    python studies/experiments/knit_eglass_rib.py [--quick] [--out DIR] [--no-docs]

Writes ``knit_eglass_rib.nc`` (curves, friction as a dimension), ``knit_eglass_rib.png`` (force,
energy split), ``knit_eglass_rib_energy.png`` (Fig. 24-like), ``knit_eglass_rib_cell.png`` (the cell
relaxed and stretched), ``vtk/*.vtu`` into OUT (default results/knit_eglass_rib) and copies the
charts to docs/studies/ (not with --quick). Full run: several minutes on the 2-core machine.
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

import homtex
from homtex.knits.charts import energy_split_chart, knit_picture, state_frame, tensile_chart, write_state_vtk

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import add_docs_option, parser, publish, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")
FRICTIONS = (0.0, 0.5)


def ratios(ds) -> dict:
    """The paper's comparisons: bending / torsion (low extension), axial / torsion (end), axial /
    contact at the contact peak, bending about e2 / about e3."""
    bend = ds.bending_y.values + ds.bending_z.values
    low = max(1, len(bend) // 10)
    kc = int(np.argmax(ds.contact_energy.values))
    return {"bending_over_torsion_low": float(bend[low] / max(ds.torsion.values[low], 1e-300)),
            "axial_over_torsion_end": float(ds.axial.values[-1] / max(ds.torsion.values[-1], 1e-300)),
            "axial_over_contact_at_contact_peak": float(ds.axial.values[kc] / max(ds.contact_energy.values[kc],
                                                                                  1e-300)),
            "bending_e2_over_e3_mean": float(np.mean(np.maximum(ds.bending_y.values, ds.bending_z.values)
                                                     / np.maximum(np.minimum(ds.bending_y.values,
                                                                             ds.bending_z.values), 1e-300))),
            "bending_share_min": float(np.min(bend / (bend + ds.axial.values + ds.torsion.values + ds.shear.values
                                                      + ds.contact_energy.values)))}


def main(argv=None):
    args = add_docs_option(parser(__file__, __doc__)).parse_args(argv)
    out = setup(args)
    strain, steps = (0.02, 1) if args.quick else (0.45, 45)
    cell = homtex.load_cell("rib_1x1_eglass")
    if args.quick:                      # coarse elements: the suite runs the quick mode
        cell = cell.replace(**{"resolution.element_length": 0.65})
    # relaxed once: settling the frictionless equilibrium with friction moves nothing (no slip)
    relaxed = homtex.relax(cell)
    log.info("relaxed: %s", {k: v for k, v in relaxed.attrs.items() if k != "protocol"})
    runs = {}
    frictions = FRICTIONS[:1] if args.quick else FRICTIONS
    for mu in frictions:
        t1 = time.process_time()
        ds = homtex.tensile(relaxed, strain=strain, direction="wale", steps=steps, friction=mu, keep_positions=True)
        ds.attrs["cpu_seconds_total"] = time.process_time() - t1
        ds.attrs["relax_cpu_seconds"] = relaxed.attrs["cpu_seconds"]
        ds.attrs.update({k: v for k, v in ratios(ds).items()})
        runs[mu] = (relaxed, ds)
        log.info("friction %.1f: %s, %.0f s CPU; peak filament stress %.0f MPa at strain %.3f (filament strain "
                 "%.4f), first beyond 2400 MPa at %.3f; max |balance| %.2g; %s", mu, ds.attrs["status"],
                 ds.attrs["cpu_seconds_total"], ds.attrs["peak_filament_stress_MPa"], ds.attrs["peak_strain"],
                 ds.attrs["peak_axial_strain"], ds.attrs["first_failure_strain"],
                 float(np.abs(ds.energy_balance).max()), ratios(ds))
    keep = [k for k in runs[0.0][1].data_vars if k not in ("x", "element_energy", "periods")]
    curves = xr.concat([runs[mu][1][keep] for mu in frictions], dim="friction", join="outer")
    curves = curves.assign_coords(friction=("friction", np.array(frictions), {"units": "1",
                                                                              "long_name": "Coulomb friction"}))
    save_netcdf(curves, out / "knit_eglass_rib.nc")
    charts = []
    marks = {}
    for mu in frictions:
        ds = runs[mu][1]
        if np.isfinite(ds.attrs["first_failure_strain"]):
            s = ds.attrs["first_failure_strain"]
            marks[f"friction {mu:g}"] = (s, float(ds.force_per_width.sel(strain=s)), "first filament at 2400 MPa")
    fig = tensile_chart({f"friction {mu:g}": runs[mu][1] for mu in frictions}, marks=marks,
                        title="E-glass 1x1 rib (20-filament yarn, periodic cell) pulled along the wales")
    charts.append(save_figure(fig, out / "knit_eglass_rib.png"))
    for mu in frictions:
        fig = energy_split_chart(runs[mu][1], title=f"E-glass 1x1 rib, energy split over the extension (paper's "
                                                    f"Eq. 8, Fig. 24), friction {mu:g}")
        charts.append(save_figure(fig, out / f"knit_eglass_rib_energy_mu{mu:g}.png"))
    relaxed, ds = runs[0.0]
    frame = relaxed.cell.frame
    (out / "vtk").mkdir(exist_ok=True)
    pics = []
    for s in (strain,) if args.quick else (0.0, strain / 2, strain):
        k = int(np.argmin(np.abs(ds.strain.values - s)))
        P = ds.periods.values[k]
        f = state_frame(frame, ds.x.values[k], P)
        pct = int(round(100 * float(ds.strain[k])))          # the level shown, in names and title alike
        pics.append(knit_picture(f, out / f"knit_eglass_rib_cell_{pct}.png", tiles=(3, 2),
                                 title=f"E-glass 1x1 rib at {pct} % along the wales"))
        write_state_vtk(frame, ds.x.values[k], P, ds.element_energy.values[k],
                        out / "vtk" / f"knit_eglass_rib_{pct}.vtu")
    charts += pics
    publish(args, *charts)
    return runs


if __name__ == "__main__":
    main()
