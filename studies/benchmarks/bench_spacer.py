"""Timings: unseamed 20-step curve to 30 % (per contact iteration) and seam profile d = 43 mm.

Usage: python studies/bench_spacer.py [outdir]   (default results/bench_spacer/)
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

warnings.simplefilter("ignore")
out = Path(sys.argv[1] if len(sys.argv) > 1 else "results/bench_spacer")
out.mkdir(parents=True, exist_ok=True)
cell = homtex.load_cell("cells/spacer_20mm.toml")
con = homtex.Contact(enforcement="penalty", penalty=5000.0)
homtex.compress(cell, strain=0.03, steps=2, contact=con)   # JIT warm-up
t = time.perf_counter()
ds = homtex.compress(cell, strain=0.3, steps=20, contact=con)
t_curve = time.perf_counter() - t
iters = int(ds.contact_iterations.sum())
c2 = homtex.load_cell("cells/spacer_20mm.toml")
t = time.perf_counter()
p = homtex.seam_profile(c2, seam_distance=43.0)
t_seam = time.perf_counter() - t
e = ds.strain.values
s = ds.stress.values
mod = float(np.polyfit(e, s, 1)[0])
res = xr.Dataset({
    "curve_seconds": ((), t_curve, {"units": "s", "long_name": "20-step unseamed curve to 30 %"}),
    "contact_iterations": ((), iters, {"units": "1", "long_name": "contact iterations of the curve"}),
    "seconds_per_iteration": ((), t_curve / iters, {"units": "s", "long_name": "time per contact iteration"}),
    "seam_profile_seconds": ((), t_seam, {"units": "s", "long_name": "seam_profile d = 43 mm (incl. modulus solve)"}),
    "modulus": ((), mod, {"units": "kPa", "long_name": "compression modulus (fit 0-30 %)"}),
    "stress": ("strain", s, {"units": "kPa", "long_name": "compression stress"}),
}, coords={"strain": ("strain", e, {"units": "1", "long_name": "compression strain"})})
res.attrs["status"] = ds.attrs["status"]
res.attrs["elements"] = cell.frame.n_elements
res.to_netcdf(out / "bench_spacer.nc")
fig, ax = plt.subplots()
ax.plot(e * 100, s, "o-")
ax.set(xlabel="compression (%)", ylabel="stress (kPa)", title=f"{t_curve:.2f} s, {t_curve / iters * 1e3:.1f} ms/iteration")
fig.savefig(out / "bench_spacer.png", dpi=120)
print(res)
