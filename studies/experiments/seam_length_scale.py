"""Why the yarn-level seam cell does not form cushions: the length scale of the seam dip.

The surface layer over the pile is a beam on an elastic foundation: a stitch pulling at the
seam line bends it over a decay length lambda = (4 D / k)^(1/4) (D: layer bending rigidity,
k: pile foundation stiffness). The cushion crest, d/2 away from the seam line, only comes down
if lambda is comparable with d/2. This study

1. measures lambda of the YARN-level seam cell by fitting the periodic beam-on-foundation
   Green's function (free amplitude, offset and lambda) to its cushion profiles h(x);
2. bounds the crest height from below for a given lambda: the strongest possible stitch closes
   the seam line completely (each layer moves H/2 there), so the crest moves at most
   H * G(d/2) / G(0) (linear superposition of the periodic point loads);
3. finds the smallest lambda for which that bound reaches the paper's 14.33 mm at d = 24 mm,
   and the layer rigidity it means (D = k lambda^4 / 4, k from the unseamed cell's modulus).

If lambda of the yarn-level cell is below that minimum, no stitch pre-strain (and no stitch
model, pre-strain or tension controlled) can give the paper's cushions: the calibration is
impossible with this layer/pile pair, whatever eps0.

    python studies/experiments/seam_length_scale.py [--out DIR] [--quick]

Default: about 40 s here. ``--quick``: d = 18 and 24 mm on the cell with 1 element per segment and
a 1-step ramp (seconds; not the study's numbers). Writes DIR/seam_length_scale.nc (fits and
bounds) and DIR/seam_length_scale.png (default DIR = results/seam_length_scale).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr
from scipy.optimize import brentq, least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

DISTANCES = (18.0, 24.0, 43.0)
TARGET = {18.0: 10.23, 24.0: 14.33, 43.0: 20.3}   # the paper's simulated cushion heights, mm
MEASURED = {18.0: "8-12", 24.0: "15", 43.0: "20"}


def shape(x, d, lam):
    """Periodic beam-on-foundation deflection shape, 1 at the seam line (x = 0)."""
    from homtex.seams.foundation import _green

    g = _green(np.asarray(x, float), d, 1.0 / lam, 1.0)
    return g / _green(np.array([0.0]), d, 1.0 / lam, 1.0)[0]


def fit_lambda(x, h, d):
    """(lambda mm, dip amplitude mm, crest offset mm, rms mm): h = a - b shape(x; lambda)."""
    best = None
    for lam0 in (1.0, 2.0, 4.0, 8.0, 16.0):
        r = least_squares(lambda p: p[0] - p[1] * shape(x, d, np.exp(p[2])) - h, [h.max(), np.ptp(h), np.log(lam0)],
                          bounds=([0, 0, np.log(0.2)], [40, 40, np.log(200.0)]))
        if best is None or r.cost < best.cost:
            best = r
    a, b, ll = best.x
    return float(np.exp(ll)), float(b), float(a), float(np.sqrt(np.mean(best.fun ** 2)))


def crest_bound(lam, d, H):
    """Lowest crest height (mm) any stitch can give: seam line fully closed."""
    return H * (1.0 - shape(np.array([0.5 * d]), d, lam)[0])


def run(out: Path, *, distances=DISTANCES, resolution: int | None = None, steps: int = 4) -> xr.Dataset:
    import homtex
    from homtex.seams.foundation import fabric_modulus, layer_rigidity

    t0 = time.perf_counter()
    cell = homtex.load_cell("spacer_20mm")
    if resolution is not None:
        cell = cell.replace(**{"resolution.elements_per_segment": resolution})
    H = float(cell.info["thickness"])
    s = float(cell.parameters["seam"]["stitch_length"])
    Ec = fabric_modulus(cell)                  # MPa, unseamed yarn-level cell
    k = 2.0 * Ec * s / H                       # N/mm per mm of x over one stitch length (pile strain 2 w / H)
    D_yarn = layer_rigidity(cell, s)           # N mm^2 per stitch length, sum over the layer's yarns
    lam_yarnsum = (4 * D_yarn / k) ** 0.25
    ds_list, rows = [], []
    for d in distances:
        p = homtex.seam_profile(cell, seam_distance=d, steps=steps, prestrain=0.3, geometry="linear")
        x, h = p.x.values, p.height.values
        de = float(p.seam_distance)
        lam, amp, crest, rms = fit_lambda(x, h, de)
        rows.append((d, de, lam, amp, crest, rms, float(p.cushion_height), float(p.seam_height)))
        xf = np.linspace(-de / 2, de / 2, 201)
        ds_list.append((d, x, h, xf, crest - amp * shape(xf, de, lam)))
        print(f"d = {d:g} mm (cell {de:.2f}): yarn-level cushion {float(p.cushion_height):.2f} mm, seam line "
              f"{float(p.seam_height):.2f} mm; fitted lambda {lam:.2f} mm (rms {rms:.2f} mm)", flush=True)
    lam_fit = float(np.mean([r[2] for r in rows]))
    lam_grid = np.geomspace(1.0, 40.0, 161)
    bound = np.array([[crest_bound(lam, d, H) for lam in lam_grid] for d in distances])
    d24 = next(r[1] for r in rows if r[0] == 24.0)
    lam_min = brentq(lambda lam: crest_bound(lam, d24, H) - TARGET[24.0], 0.5, 200.0)
    D_min = k * lam_min ** 4 / 4.0
    D_fit = k * lam_fit ** 4 / 4.0
    bound_yarn = [crest_bound(lam_fit, r[1], H) for r in rows]
    res = xr.Dataset(
        {"lambda_fit": ("seam_distance", [r[2] for r in rows],
                        {"units": "mm", "long_name": "decay length fitted to the yarn-level cushion profile"}),
         "fit_rms": ("seam_distance", [r[5] for r in rows], {"units": "mm", "long_name": "rms of the fit"}),
         "cushion_yarn": ("seam_distance", [r[6] for r in rows],
                          {"units": "mm", "long_name": "yarn-level cushion height (nominal eps0)"}),
         "seam_height_yarn": ("seam_distance", [r[7] for r in rows],
                              {"units": "mm", "long_name": "yarn-level height at the seam line"}),
         "crest_bound_yarn": ("seam_distance", bound_yarn,
                              {"units": "mm", "long_name": "lowest crest any stitch gives at the fitted lambda "
                               "(seam line closed)"}),
         "cushion_paper": ("seam_distance", [TARGET.get(r[0], np.nan) for r in rows],
                           {"units": "mm", "long_name": "the paper's simulated cushion height"}),
         "crest_bound": (("seam_distance", "lam"), bound,
                         {"units": "mm", "long_name": "lowest crest any stitch gives (seam line closed)"})},
        coords={"seam_distance": ("seam_distance", [r[0] for r in rows], {"units": "mm", "long_name": "seam distance"}),
                "lam": ("lam", lam_grid, {"units": "mm", "long_name": "decay length of the seam dip"})})
    res.attrs.update(foundation_modulus_MPa=Ec, foundation_k_N_per_mm2=k, stitch_length_mm=s, thickness_mm=H,
                     lambda_yarn_mean_mm=lam_fit, lambda_from_yarn_sum_rigidity_mm=lam_yarnsum,
                     layer_rigidity_yarn_sum_Nmm2=D_yarn, layer_rigidity_implied_by_fit_Nmm2=D_fit,
                     lambda_min_for_paper_24mm_mm=lam_min, layer_rigidity_min_for_paper_24mm_Nmm2=D_min,
                     rigidity_factor_needed=D_min / D_fit, seconds=time.perf_counter() - t0,
                     title="length scale of the seam dip: yarn-level cell against the paper's cushions",
                     homtex_version=homtex.__version__, ramp_steps=steps,
                     elements_per_segment=int(cell.resolution.get("elements_per_segment", 2)))
    save_netcdf(res, out / "seam_length_scale.nc")
    print(f"unseamed modulus {1e3 * Ec:.0f} kPa -> k = {k:.4f} N/mm^2 per stitch; layer rigidity from the yarns "
          f"{D_yarn:.2f} N mm^2 (lambda {lam_yarnsum:.2f} mm); fitted lambda {lam_fit:.2f} mm "
          f"(D = {D_fit:.2f} N mm^2)")
    print("lowest crest any stitch gives at the fitted lambda: " +
          ", ".join(f"d = {r[0]:g}: {b:.2f} mm" for r, b in zip(rows, bound_yarn)))
    print(f"the paper's 14.33 mm at d = 24 mm needs lambda >= {lam_min:.2f} mm, i.e. D >= {D_min:.1f} N mm^2 per "
          f"stitch: {D_min / D_fit:.0f}x the yarn-level cell's")

    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.5))
    for (d, x, h, xf, hf), c in zip(ds_list, ("tab:red", "tab:blue", "tab:green")):
        ax[0].plot(x, h, "o", ms=3, color=c, label=f"yarn level, d = {d:g} mm")
        ax[0].plot(xf, hf, "-", lw=0.8, color=c)
    ax[0].axhline(TARGET[24.0], color="tab:blue", ls=":", lw=0.8)
    ax[0].text(0, TARGET[24.0] + 0.2, "paper, d = 24: 14.33 mm", fontsize=7, color="tab:blue", ha="center")
    ax[0].set(xlabel="x across the seam, mm (0 = seam line)", ylabel="height, mm", ylim=(8, 21.5),
              title=f"yarn-level profiles and beam-on-foundation fits (lambda {lam_fit:.1f} mm)")
    ax[0].legend(fontsize=7)
    for row, d, c in zip(bound, distances, ("tab:red", "tab:blue", "tab:green")):
        ax[1].plot(lam_grid, row, color=c, label=f"d = {d:g} mm: crest with the seam line closed")
        if d in TARGET:
            ax[1].axhline(TARGET[d], color=c, ls=":", lw=0.8)
    ax[1].axvline(lam_fit, color="0.3", lw=0.8)
    ax[1].text(lam_fit, 12, f" yarn level\n {lam_fit:.1f} mm", fontsize=7)
    ax[1].axvline(lam_min, color="tab:blue", lw=0.8, ls="--")
    ax[1].text(lam_min, 5, f" needed for 14.33 mm\n at d = 24: {lam_min:.1f} mm\n ({D_min / D_fit:.0f}x rigidity)",
               fontsize=7, color="tab:blue")
    ax[1].set(xscale="log", xlabel="decay length lambda of the seam dip, mm", ylabel="lowest crest height, mm",
              ylim=(0, 21), title="lowest cushion any stitch can give (dotted: the paper's cushions)")
    ax[1].legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    save_figure(fig, out / "seam_length_scale.png", dpi=110)
    return res


def main(argv=None):
    ap = parser(__file__, __doc__)
    a = ap.parse_args(argv)
    out = setup(a)
    if a.quick:
        run(out, distances=(18.0, 24.0), resolution=1, steps=1)
    else:
        run(out)
    print(f"wrote {out / 'seam_length_scale.nc'} and {out / 'seam_length_scale.png'}")


if __name__ == "__main__":
    main()
