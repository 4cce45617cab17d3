"""Calibrate the stitch pre-strain eps0 of the YARN-level seam model once on d = 24 mm, then predict 18 and 43 mm.

Usage::

    python studies/experiments/calibrate_seam.py [--out DIR] [--quick | --full]

Default: 5-point scan, a few minutes here; ``--full``: a finer scan. ``--quick``: the same steps
on d = 12 mm (scan at eps0 0.15 and 0.3, the prediction and the 15 % case for 12 mm only), on the
cell with 1 element per segment and 1 ramp step (seconds; the numbers are not the study's).

Calibration target: the paper's simulated cushion height 14.33 mm for d = 24 mm (the measured value
is 15 mm; the paper's simulation is the like-for-like model target). eps0 is scanned on d = 24 mm
(default grid 0.05 .. 0.45; --full: a finer grid); if the target lies inside the scanned range of
cushion heights it is bracketed and refined (brentq) and the result is written into the dataset
(store it as ``[parameters.seam] prestrain`` in cells/spacer_20mm.toml); otherwise the script says
so and does NOT invent a value: the profiles for 18 / 24 / 43 mm are then shown at the cell file's
current (uncalibrated, nominal) eps0, next to the 15 % case for 43 mm and the foundation model.

Writes DIR/calibrate_seam.nc (scan, predictions, measured and paper values, timings) and
DIR/calibrate_seam.png (default DIR = results/calibrate_seam).
"""
import sys
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

TARGET = 14.33
paper = {18.0: 10.23, 24.0: 14.33, 43.0: 20.3}
measured = {18.0: 8.0, 24.0: 15.0, 43.0: 20.0}


def status_text(ds) -> str:
    """'ok', or 'failed: <why>' (curves and profiles carry attrs status and status_detail)."""
    st = str(ds.attrs.get("status", "ok"))
    return st if st == "ok" else f"{st}: {ds.attrs.get('status_detail', '')}"


def run(out: Path, *, full: bool = False, quick: bool = False) -> xr.Dataset:
    import homtex

    cell = homtex.load_cell("spacer_20mm")
    D = [18.0, 24.0, 43.0]
    d_cal = 24.0                  # the calibration distance (the paper's 14.33 mm)
    kw = {}
    if quick:
        cell = cell.replace(**{"resolution.elements_per_segment": 1})
        D, d_cal, kw = [12.0], 12.0, {"steps": 1}

    # ---- scan on d = d_cal (24 mm)
    grid = np.array([0.15, 0.3]) if quick else np.round(np.arange(0.05, 0.451, 0.025 if full else 0.1), 4)
    scan_c, scan_s, scan_t, scan_ok = [], [], [], []
    for e in grid:
        p = homtex.seam_profile(cell, seam_distance=d_cal, prestrain=float(e), **kw)
        scan_c.append(float(p.cushion_height))
        scan_s.append(float(p.seam_height))
        scan_t.append(p.attrs["seconds"])
        scan_ok.append(p.attrs["status"] == "ok")
        print(f"eps0 {e:.3f}: cushion {scan_c[-1]:.3f} mm, seam {scan_s[-1]:.3f} mm, {scan_t[-1]:.1f} s, "
              f"{status_text(p)[:80]}")
    c = np.array(scan_c)
    ok = np.array(scan_ok) & np.isfinite(c)
    calibrated = np.nan
    calib_status = "target not reached"
    cs = c[ok]
    if ok.any() and cs.min() <= TARGET <= cs.max():
        from scipy.optimize import brentq
        i = int(np.flatnonzero(ok & (c - TARGET <= 0))[0])
        lo = grid[max(i - 1, 0)]
        calibrated = brentq(lambda e: float(homtex.seam_profile(cell, seam_distance=d_cal, prestrain=e,
                                                                **kw).cushion_height) - TARGET, lo, grid[i], xtol=1e-4)
        calib_status = "calibrated"
    else:
        calib_status = (f"target {TARGET} mm NOT reachable: over eps0 in [{grid[0]}, {grid[-1]}] the yarn model's "
                        f"cushion height (max h) stays in [{np.nanmin(cs) if ok.any() else np.nan:.2f}, "
                        f"{np.nanmax(cs) if ok.any() else np.nan:.2f}] mm (the seam dip is local and the cushion "
                        "bulges slightly): no eps0 is stored from this calibration")
    print(calib_status)
    eps_used = float(calibrated) if np.isfinite(calibrated) else float(cell.parameters["seam"]["prestrain"])

    # ---- predictions with nothing changed
    rows, profiles, secs, stat = [], [], [], []
    for d in D:
        p = homtex.seam_profile(cell, seam_distance=d, prestrain=eps_used, **kw)
        rows.append(float(p.cushion_height))
        profiles.append(p)
        secs.append(p.attrs["seconds"])
        stat.append(status_text(p))
        print(f"d {d:g} (effective {p.attrs['effective_seam_distance_mm']:.2f}) mm: cushion {rows[-1]:.2f} mm, seam "
              f"{float(p.seam_height):.2f} mm, stitch force {float(p.stitch_force):.2f} N, {secs[-1]:.1f} s, {stat[-1][:60]}")
    p15 = homtex.seam_profile(cell, seam_distance=D[-1], prestrain=0.15, **kw)
    fnd = [homtex.seam_profile(cell, seam_distance=d, method="foundation") for d in D]
    res = xr.Dataset({
        "scan_cushion_height": ("prestrain_scan", c, {"units": "mm", "long_name": f"cushion height, d = {d_cal:g} mm, yarn model"}),
        "scan_seam_height": ("prestrain_scan", np.array(scan_s), {"units": "mm", "long_name": f"seam height, d = {d_cal:g} mm, yarn model"}),
        "scan_seconds": ("prestrain_scan", np.array(scan_t), {"units": "s", "long_name": "wall time per seam solve"}),
        "cushion_height": ("seam_distance", rows, {"units": "mm", "long_name": "cushion height, yarn model"}),
        "seam_height": ("seam_distance", [float(p.seam_height) for p in profiles], {"units": "mm", "long_name": "seam height, yarn model"}),
        "effective_seam_distance": ("seam_distance", [p.attrs["effective_seam_distance_mm"] for p in profiles], {"units": "mm", "long_name": "seam distance of the cell (whole fabric repeats)"}),
        "seconds": ("seam_distance", secs, {"units": "s", "long_name": "wall time of the seam solve"}),
        "foundation_cushion_height": ("seam_distance", [float(p.cushion_height) for p in fnd], {"units": "mm", "long_name": "cushion height, foundation model (layer rigidity calibrated on 24 mm)"}),
        "paper_simulation": ("seam_distance", [paper.get(d, np.nan) for d in D], {"units": "mm", "long_name": "cushion height simulated in the paper"}),
        "measured": ("seam_distance", [measured.get(d, np.nan) for d in D], {"units": "mm", "long_name": "cushion height measured (Table 1; 18 mm: 8, text 12)"}),
        "cushion_height_15pct_43": ((), float(p15.cushion_height), {"units": "mm", "long_name": f"cushion height d={D[-1]:g} mm, eps0=0.15"}),
        "seam_height_15pct_43": ((), float(p15.seam_height), {"units": "mm", "long_name": f"seam height d={D[-1]:g} mm, eps0=0.15"}),
        "calibrated_prestrain": ((), calibrated, {"units": "1", "long_name": f"eps0 calibrated on d = {d_cal:g} mm (NaN: target not reachable)"}),
        "prestrain_used": ((), eps_used, {"units": "1", "long_name": "eps0 used for the predictions"}),
    }, coords={"seam_distance": ("seam_distance", D, {"units": "mm", "long_name": "requested seam distance"}),
               "prestrain_scan": ("prestrain_scan", grid, {"units": "1", "long_name": "stitch pre-strain eps0 (scan)"})})
    res.attrs.update(calibration_target_mm=TARGET, calibration_target="paper simulation, d = 24 mm",
                     calibration_distance_mm=d_cal,
                     calibration_status=calib_status, status="; ".join(stat), model="yarn",
                     description=profiles[0].attrs["description"], quick=int(quick),
                     elements_per_segment=int(cell.resolution.get("elements_per_segment", 2)))
    save_netcdf(res, out / "calibrate_seam.nc")

    plt = pyplot()
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    for d, p in zip(D, profiles):
        ax[0].plot(p.x, p.height, "o-", ms=3, label=f"d = {p.attrs['effective_seam_distance_mm']:.1f} mm, eps0 = {eps_used:.2f}")
    ax[0].plot(p15.x, p15.height, "k--", label=f"d = {p15.attrs['effective_seam_distance_mm']:.1f} mm, eps0 = 0.15")
    ax[0].axhline(20.0, color="gray", lw=0.8, label="flat fabric")
    ax[0].set(xlabel="x across the seam (mm)", ylabel="height h(x) (mm)", title="yarn-level seam profiles")
    ax[0].legend(fontsize=7)
    ax[1].plot(grid, c, "o-", label="cushion height (max h)")
    ax[1].plot(grid, scan_s, "s-", label="seam height h(0)")
    ax[1].axhline(TARGET, color="r", ls=":", label="target 14.33 mm (paper, 24 mm)")
    ax[1].set(xlabel="stitch pre-strain eps0", ylabel="mm", title=f"calibration scan, d = {d_cal:g} mm")
    ax[1].legend(fontsize=7)
    ax[2].plot(D, rows, "o-", label=f"yarn model (eps0 = {eps_used:.2f}{'' if np.isfinite(calibrated) else ', uncalibrated'})")
    ax[2].plot(D, [float(p.cushion_height) for p in fnd], "d-.", label="foundation model (D calibrated on 24 mm)")
    ax[2].plot(D, [paper.get(d, np.nan) for d in D], "s--", label="paper simulation")
    ax[2].plot(D, [measured.get(d, np.nan) for d in D], "^:", label="measured")
    ax[2].set(xlabel="seam distance (mm)", ylabel="cushion height (mm)")
    ax[2].legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out / "calibrate_seam.png")
    return res


def main(argv=None):
    ap = parser(__file__, __doc__)
    ap.add_argument("--full", action="store_true", help="a finer eps0 scan")
    a = ap.parse_args(argv)
    out = setup(a)
    res = run(out, full=a.full, quick=a.quick)
    print(res)
    print(f"wrote {out / 'calibrate_seam.nc'} and {out / 'calibrate_seam.png'}")


if __name__ == "__main__":
    main()
