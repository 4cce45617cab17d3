"""Yarn-level compression of the seamed spacer fabric (paper's Fig. 11): d = 24 mm vs without seams.

Usage::

    python studies/experiments/seam_compression.py [--out DIR] [--quick | --full]

Default: 15 plate steps to 30 % (5 % from the step-converged curve); --full: 30 steps (1 % from
60 steps; plus halving where the contact solve cycles - fewer steps are not faster). The seamed cell is sewn first (stitch pre-strain ramp, [parameters.seam] prestrain),
then compressed between rigid plates that start on its outermost yarn surfaces; the unseamed curve
is ``homtex.compress`` on the fabric cell with the same contact options. Strain is plate
displacement over the initial plate distance of each specimen.

``--quick``: the cell with 1 element per segment, 1 plate step to 3 % (seconds; not the study's
numbers).

Writes DIR/seam_compression.nc (curves over strain, per case) and DIR/seam_compression.png
(stress-strain, force per cell area, and the number of cushion-plate contacts; default DIR =
results/seam_compression).
"""
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402


def status_text(ds) -> str:
    """'ok', or 'failed: <why>' (curves carry attrs status and status_detail)."""
    st = str(ds.attrs.get("status", "ok"))
    return st if st == "ok" else f"{st}: {ds.attrs.get('status_detail', '')}"


def run(out: Path, *, full: bool = False, quick: bool = False) -> xr.Dataset:
    import homtex
    from homtex.seams import seam_compression

    cell = homtex.load_cell("spacer_20mm")
    strain, steps = 0.3, (30 if full else 15)
    if quick:
        cell = cell.replace(**{"resolution.elements_per_segment": 1})
        strain, steps = 0.03, 1

    t0 = time.perf_counter()
    seamed = seam_compression(cell, seam_distance=24.0, strain=strain, steps=steps, prestrain=0.3, geometry="linear")
    t_seam = time.perf_counter() - t0
    t0 = time.perf_counter()
    plain = seam_compression(cell, seam_distance=None, strain=strain, steps=steps, geometry="linear")
    t_plain = time.perf_counter() - t0
    print(f"seamed d = {seamed.attrs['seam_distance_mm']:.2f} mm: {status_text(seamed)[:100]} ({t_seam:.1f} s)")
    print(f"unseamed: {status_text(plain)[:100]} ({t_plain:.1f} s)")

    cases = ["seam_24mm", "no_seam"]
    grid = np.unique(np.round(np.r_[seamed.strain.values, plain.strain.values], 9))

    def on_grid(ds, name):
        if not ds.sizes["strain"]:
            return np.full(len(grid), np.nan)
        return np.interp(grid, ds.strain.values, ds[name].values, left=np.nan, right=np.nan)

    res = xr.Dataset(
        {"stress": (("case", "strain"), np.array([on_grid(seamed, "stress"), on_grid(plain, "stress")]),
                    {"units": "kPa", "long_name": "compression stress (force / cell area)"}),
         "cushion_plate_contacts": ("strain_seamed", seamed.cushion_plate_contacts.values,
                                    {"units": "1", "long_name": "active fabric-top plate contacts, seamed cell"}),
         "cushions_touched": ("strain_seamed", seamed.cushions_touched.values,
                              {"units": "1", "long_name": "wale bins touching the top plate, seamed cell"}),
         "stitch_plate_contacts": ("strain_seamed", seamed.stitch_plate_contacts.values,
                                   {"units": "1", "long_name": "needle thread-top plate contacts, seamed cell"}),
         "force_seamed": ("strain_seamed", seamed.force.values, {"units": "N", "long_name": "plate force on the seam cell"}),
         "plate_displacement_seamed": ("strain_seamed", seamed.plate_displacement.values,
                                       {"units": "mm", "long_name": "plate displacement, seamed cell"}),
         "seconds": ("case", [t_seam, t_plain], {"units": "s", "long_name": "wall time of the curve"})},
        coords={"case": ("case", cases, {"units": "1", "long_name": "specimen"}),
                "strain": ("strain", grid, {"units": "1", "long_name": "plate displacement / initial plate distance"}),
                "strain_seamed": ("strain_seamed", seamed.strain.values,
                                  {"units": "1", "long_name": "strain steps of the seamed curve"})})
    res.attrs.update(status_seamed=status_text(seamed), status_unseamed=status_text(plain),
                     seam_distance_mm=seamed.attrs["seam_distance_mm"], prestrain=seamed.attrs["prestrain"],
                     sewn_thickness_mm=seamed.attrs["thickness_mm"], sewn_cushion_height_mm=seamed.attrs["cushion_height_mm"],
                     sewn_seam_height_mm=seamed.attrs["seam_height_mm"], steps=steps, quick=int(quick),
                     elements_per_segment=int(cell.resolution.get("elements_per_segment", 2)),
                     note="prestrain is the cell file's nominal (uncalibrated) value; "
                          "studies/experiments/calibrate_seam.py shows no value reaches the paper cushions")
    save_netcdf(res, out / "seam_compression.nc")

    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    ax[0].plot(seamed.strain, seamed.stress, "o-", label=f"seamed, d = {seamed.attrs['seam_distance_mm']:.1f} mm")
    ax[0].plot(plain.strain, plain.stress, "s-", label="without seams")
    ax[0].set(xlabel="compression strain", ylabel="stress (kPa)", title="yarn-level compression (rigid plates)")
    ax[0].legend(fontsize=8)
    ax[1].plot(seamed.strain, seamed.cushion_plate_contacts, "o-", label="fabric-plate contacts")
    ax[1].plot(seamed.strain, seamed.cushions_touched, "^-", label="cushion wale bins touched")
    ax[1].plot(seamed.strain, seamed.stitch_plate_contacts, "x-", label="needle thread-plate contacts")
    ax[1].set(xlabel="compression strain", ylabel="count", title="seamed cell: contacts with the top plate")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, out / "seam_compression.png")
    return res


def main(argv=None):
    ap = parser(__file__, __doc__)
    ap.add_argument("--full", action="store_true", help="30 plate steps (1 %% from 60 steps)")
    a = ap.parse_args(argv)
    out = setup(a)
    res = run(out, full=a.full, quick=a.quick)
    print(res)
    print(f"wrote {out / 'seam_compression.nc'} and {out / 'seam_compression.png'}")


if __name__ == "__main__":
    main()
