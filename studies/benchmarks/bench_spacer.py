"""Timings of the spacer cell: unseamed 20-step curve to 30 % (per contact iteration) and seam profile d = 43 mm.

Measures the wall time of ``homtex.compress`` on cells/spacer_20mm.toml (penalty contact, 20
steps to 30 %, after a 2-step JIT warm-up), the time per contact iteration, the compression
modulus (line fit), and the wall time of one yarn-level ``homtex.seam_profile`` at d = 43 mm.

Usage::

    python studies/benchmarks/bench_spacer.py [--out DIR] [--quick]

Default: about 10 s here. ``--quick``: 2 steps to 5 % and the seam profile at d = 24 mm with 1
element per segment and 1 ramp step (seconds). Writes ``DIR/bench_spacer.nc`` and
``DIR/bench_spacer.png`` (default DIR = results/bench_spacer).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402


def run(out: Path, *, strain: float = 0.3, steps: int = 20, seam_distance: float = 43.0,
        seam_resolution: int | None = None, seam_steps: int = 4) -> xr.Dataset:
    import homtex

    cell = homtex.load_cell("spacer_20mm")
    con = homtex.Contact(enforcement="penalty", penalty=5000.0)
    homtex.compress(cell, strain=0.03, steps=2, contact=con, geometry="linear")   # JIT warm-up
    t = time.perf_counter()
    ds = homtex.compress(cell, strain=strain, steps=steps, contact=con, geometry="linear")
    t_curve = time.perf_counter() - t
    iters = int(ds.contact_iterations.sum())
    c2 = homtex.load_cell("spacer_20mm")
    if seam_resolution is not None:
        c2 = c2.replace(**{"resolution.elements_per_segment": seam_resolution})
    t = time.perf_counter()
    p = homtex.seam_profile(c2, seam_distance=seam_distance, steps=seam_steps, prestrain=0.3, geometry="linear")
    t_seam = time.perf_counter() - t
    e = ds.strain.values
    s = ds.stress.values
    mod = float(np.polyfit(e, s, 1)[0])
    res = xr.Dataset({
        "curve_seconds": ((), t_curve, {"units": "s", "long_name": f"{steps}-step unseamed curve to {100 * strain:g} %"}),
        "contact_iterations": ((), iters, {"units": "1", "long_name": "contact iterations of the curve"}),
        "seconds_per_iteration": ((), t_curve / iters, {"units": "s", "long_name": "time per contact iteration"}),
        "seam_profile_seconds": ((), t_seam, {"units": "s",
                                              "long_name": f"seam_profile d = {seam_distance:g} mm (incl. modulus solve)"}),
        "modulus": ((), mod, {"units": "kPa", "long_name": f"compression modulus (fit 0-{100 * strain:g} %)"}),
        "stress": ("strain", s, {"units": "kPa", "long_name": "compression stress"}),
    }, coords={"strain": ("strain", e, {"units": "1", "long_name": "compression strain"})})
    res.attrs.update(status=ds.attrs["status"], status_detail=ds.attrs.get("status_detail", ""),
                     seam_status=p.attrs["status"], elements=cell.frame.n_elements,
                     seam_elements=int(p.attrs["n_elements"]), seam_distance_mm=seam_distance)
    save_netcdf(res, out / "bench_spacer.nc")
    plt = pyplot()
    fig, ax = plt.subplots()
    ax.plot(e * 100, s, "o-")
    ax.set(xlabel="compression (%)", ylabel="stress (kPa)",
           title=f"{t_curve:.2f} s, {t_curve / iters * 1e3:.1f} ms/iteration")
    save_figure(fig, out / "bench_spacer.png")
    return res


def main(argv=None):
    ap = parser(__file__, __doc__)
    a = ap.parse_args(argv)
    out = setup(a)
    if a.quick:
        res = run(out, strain=0.05, steps=2, seam_distance=24.0, seam_resolution=1, seam_steps=1)
    else:
        res = run(out)
    print(res)
    print(f"wrote {out / 'bench_spacer.nc'} and {out / 'bench_spacer.png'}")


if __name__ == "__main__":
    main()
