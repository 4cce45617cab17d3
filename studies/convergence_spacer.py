"""Convergence of compression modulus and cushion height (d = 24 mm) with elements per segment
and contact penalty. Usage: python studies/convergence_spacer.py [outdir] [--full]
"""
import sys
import warnings
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

import homtex  # noqa: E402
from homtex.seams import compression_summary  # noqa: E402

warnings.simplefilter("ignore")
args = [a for a in sys.argv[1:] if not a.startswith("--")]
full = "--full" in sys.argv
out = Path(args[0] if args else "results/convergence_spacer")
out.mkdir(parents=True, exist_ok=True)
base = homtex.load_cell("cells/spacer_20mm.toml")
eps_list = [1, 2, 3, 4, 6] if full else [1, 2, 3]
pen_list = [1e3, 5e3, 2e4, 1e5]
mod_e, cush_e, mod_p = [], [], []
for n in eps_list:
    c = base.replace(**{"resolution.elements_per_segment": n})
    ds = homtex.compress(c, strain=0.3, steps=10, contact=homtex.Contact(enforcement="penalty", penalty=5000.0))
    mod_e.append(compression_summary(ds)["modulus_kPa"] if ds.attrs["status"] == "ok" else np.nan)
    cush_e.append(float(homtex.seam_profile(c, seam_distance=24.0).cushion_height))
for k in pen_list:
    ds = homtex.compress(base, strain=0.3, steps=10, contact=homtex.Contact(enforcement="penalty", penalty=k))
    mod_p.append(compression_summary(ds)["modulus_kPa"] if ds.attrs["status"] == "ok" else np.nan)
res = xr.Dataset({
    "modulus_vs_resolution": ("elements_per_segment", mod_e, {"units": "kPa", "long_name": "compression modulus"}),
    "cushion_vs_resolution": ("elements_per_segment", cush_e, {"units": "mm", "long_name": "cushion height d=24 mm (eps0 fixed)"}),
    "modulus_vs_penalty": ("penalty", mod_p, {"units": "kPa", "long_name": "compression modulus"}),
}, coords={"elements_per_segment": ("elements_per_segment", eps_list, {"units": "1", "long_name": "elements per control segment"}),
           "penalty": ("penalty", pen_list, {"units": "N/mm", "long_name": "contact penalty stiffness"})})
res.to_netcdf(out / "convergence_spacer.nc")
fig, ax = plt.subplots(1, 3, figsize=(12, 3.5))
ax[0].plot(eps_list, mod_e, "o-"); ax[0].set(xlabel="elements per segment", ylabel="modulus (kPa)")
ax[1].plot(eps_list, cush_e, "o-"); ax[1].set(xlabel="elements per segment", ylabel="cushion height 24 mm (mm)")
ax[2].semilogx(pen_list, mod_p, "o-"); ax[2].set(xlabel="penalty (N/mm)", ylabel="modulus (kPa)")
fig.tight_layout(); fig.savefig(out / "convergence_spacer.png", dpi=120)
print(res)
