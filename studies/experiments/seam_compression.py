"""Yarn-level compression of the seamed spacer fabric (paper's Fig. 11): d = 24 mm vs without seams.

Usage: python studies/seam_compression.py [outdir] [--full]   (default results/seam_compression/)

Default: 15 plate steps to 30 % (5 % from the step-converged curve); --full: 30 steps (1 % from
60 steps; plus halving where the contact solve cycles - fewer steps are not faster). The seamed cell is sewn first (stitch pre-strain ramp, [parameters.seam] prestrain),
then compressed between rigid plates that start on its outermost yarn surfaces; the unseamed curve
is ``homtex.compress`` on the fabric cell with the same contact options. Strain is plate
displacement over the initial plate distance of each specimen.

Writes seam_compression.nc (curves over strain, per case) and seam_compression.png (stress-strain,
force per cell area, and the number of cushion-plate contacts).
"""
import sys
import time
import warnings
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

import homtex  # noqa: E402
from homtex.seams import seam_compression  # noqa: E402

warnings.simplefilter("ignore")
args = [a for a in sys.argv[1:] if not a.startswith("--")]
full = "--full" in sys.argv
out = Path(args[0] if args else "results/seam_compression")
out.mkdir(parents=True, exist_ok=True)
cell = homtex.load_cell("cells/spacer_20mm.toml")
steps = 30 if full else 15

t0 = time.perf_counter()
seamed = seam_compression(cell, seam_distance=24.0, strain=0.3, steps=steps)
t_seam = time.perf_counter() - t0
t0 = time.perf_counter()
plain = seam_compression(cell, seam_distance=None, strain=0.3, steps=steps)
t_plain = time.perf_counter() - t0
print(f"seamed d = {seamed.attrs['seam_distance_mm']:.2f} mm: {seamed.attrs['status'][:100]} ({t_seam:.1f} s)")
print(f"unseamed: {plain.attrs['status'][:100]} ({t_plain:.1f} s)")

cases = ["seam_24mm", "no_seam"]
grid = np.unique(np.round(np.r_[seamed.strain.values, plain.strain.values], 9))


def on_grid(ds, name):
    return np.interp(grid, ds.strain.values, ds[name].values, left=np.nan, right=np.nan) if ds.sizes["strain"] else np.full(len(grid), np.nan)


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
res.attrs.update(status_seamed=seamed.attrs["status"], status_unseamed=plain.attrs["status"],
                 seam_distance_mm=seamed.attrs["seam_distance_mm"], prestrain=seamed.attrs["prestrain"],
                 sewn_thickness_mm=seamed.attrs["thickness_mm"], sewn_cushion_height_mm=seamed.attrs["cushion_height_mm"],
                 sewn_seam_height_mm=seamed.attrs["seam_height_mm"], steps=steps,
                 note="prestrain is the cell file's nominal (uncalibrated) value; studies/calibrate_seam.py shows no value reaches the paper cushions")
res.to_netcdf(out / "seam_compression.nc")

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
fig.savefig(out / "seam_compression.png", dpi=120)
print(res)
