"""What makes the yarn-level seam cell form cushions: a layer that bends across the seam.

In cells/spacer_20mm.toml no yarn of a surface layer runs across the wales for more than one
wale: the pillars run along the wales and the inlay (0-0/1-1) laps over one needle. Bending
across the seam then passes wale to wale through the interlacings, and the seam dip stays
local (decay length 2.6 mm, studies/seam_length_scale.py). Two things a real pillar-inlay
layer may have and this cell does not, both assumptions of the cell file that the papers do not
fix: inlays lapped over several needles (0-0/3-3: each inlay crosses three wales, so the wales
are bridged by continuous yarns), and multifilaments that bend and twist like more than loose
fibres (``bending_factor`` and ``torsion_factor`` of the yarn type, both set to the same factor
here: rigidity relative to the solid section).

This study runs the d = 24 mm seam cell at eps0 = 0.5 over inlay span (1, 3 needles) x
multifilament bending and torsion factor (1; 3.3, a solid PET rod of the yarn's section,
10 GPa against the cell's effective 3 GPa; 10; 100), plus eps0 = 0.7 for the 3-needle inlay at 10 and 100,
and records crest, seam line, mean height (the global compression) and stitch force. A point
that fails keeps its status; the others are kept.

    python studies/experiments/seam_layer_continuity.py [--out DIR] [--quick]

Default: about 8 min here. ``--quick``: d = 12 mm, 1 element per segment, 1 ramp step, two points
(1-needle inlay x1 at eps0 0.3; 3-needle inlay x10 at eps0 0.02), seconds; not the study's numbers.
Writes DIR/seam_layer_continuity.nc and DIR/seam_layer_continuity.png (default DIR =
results/seam_layer_continuity).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

D = 24.0
POINTS = [(span, f, 0.5) for span in (1, 3) for f in (1.0, 3.3, 10.0, 100.0)] + [(3, 10.0, 0.7), (3, 100.0, 0.7)]
QUICK_POINTS = [(1, 1.0, 0.3), (3, 10.0, 0.02)]


def variant(cell, span: int, factor: float):
    lap = f"0-0/{span}-{span}//"
    return cell.replace(**{"parameters.bars.top_inlay.lapping": lap, "parameters.bars.bottom_inlay.lapping": lap,
                           "yarns.multifilament.bending_factor": factor, "yarns.multifilament.torsion_factor": factor})


def run(out: Path, *, points=POINTS, d: float = D, resolution: int | None = None, steps: int = 8) -> xr.Dataset:
    import homtex

    base = homtex.load_cell("spacer_20mm")
    if resolution is not None:
        base = base.replace(**{"resolution.elements_per_segment": resolution})
    eps_main = points[0][2]
    rows, profiles = [], []
    for span, f, eps in points:
        t0 = time.perf_counter()
        try:
            p = homtex.seam_profile(variant(base, span, f), seam_distance=d, prestrain=eps, steps=steps,
                                    geometry="linear")
            status = str(p.attrs["status"])
            if status != "ok":
                status = f"{status}: {p.attrs.get('status_detail', '')}"
        except homtex.InputError as err:          # a bad variant: record it, keep the others
            p, status = None, f"failed: {err}"
        ok = status == "ok"
        h = p.height.values if ok else None
        rows.append(dict(span=span, factor=f, eps=eps, status=status, seconds=time.perf_counter() - t0,
                         crest=float(p.cushion_height) if ok else -1.0, seam=float(p.seam_height) if ok else -1.0,
                         mean=float(h.mean()) if ok else -1.0, force=float(p.stitch_force) if ok else -1.0))
        profiles.append((p.x.values, h) if ok else None)
        r = rows[-1]
        print(f"inlay over {span} needle(s), bending and torsion x{f:g}, eps0 {eps}: " + (
            f"crest {r['crest']:.2f}, seam line {r['seam']:.2f}, mean {r['mean']:.2f} mm, leg {r['force']:.2f} N"
            if ok else status) + f" ({r['seconds']:.0f} s)", flush=True)

    ds = xr.Dataset(
        {"inlay_span": ("point", [r["span"] for r in rows], {"units": "needles", "long_name": "needles an inlay laps over"}),
         "bending_factor": ("point", [r["factor"] for r in rows],
                            {"units": "1", "long_name": "multifilament bending and torsional rigidity / solid section's"}),
         "prestrain": ("point", [r["eps"] for r in rows], {"units": "1", "long_name": "stitch pre-strain eps0"}),
         "cushion_height": ("point", [r["crest"] for r in rows], {"units": "mm", "long_name": "crest (-1: failed)"}),
         "seam_height": ("point", [r["seam"] for r in rows], {"units": "mm", "long_name": "seam line (-1: failed)"}),
         "mean_height": ("point", [r["mean"] for r in rows],
                         {"units": "mm", "long_name": "mean height over the cell (-1: failed)"}),
         "stitch_force": ("point", [r["force"] for r in rows], {"units": "N", "long_name": "stitch leg force (-1: failed)"}),
         "status": ("point", [r["status"] for r in rows]),
         "seconds": ("point", [r["seconds"] for r in rows], {"units": "s"})},
        coords={"point": np.arange(len(rows))})
    ds.attrs.update(seam_distance_mm=d, cell="cells/spacer_20mm.toml", paper_cushion_24mm=14.33,
                    title=f"seam cell d = {d:g} mm: inlay span and multifilament bending",
                    homtex_version=homtex.__version__, ramp_steps=steps,
                    elements_per_segment=int(base.resolution.get("elements_per_segment", 2)))
    save_netcdf(ds, out / "seam_layer_continuity.nc")

    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.5))
    for r, pr, c in zip(rows, profiles, [f"C{i}" for i in range(len(rows))]):
        if pr is not None:
            ax[0].plot(pr[0], pr[1], "o-", ms=3, color=c,
                       label=f"inlay {r['span']} needle(s), rigidity x{r['factor']:g}, eps0 {r['eps']}")
    ax[0].axhline(14.33, color="k", ls=":", lw=0.8)
    ax[0].set(xlabel="x across the seam, mm (0 = seam line)", ylabel="height, mm",
              title=f"yarn-level seam cell, d = {d:g} mm (dotted: the paper's 14.33 mm at 24 mm)")
    ax[0].legend(fontsize=6)
    for span, mk in ((1, "o"), (3, "s")):
        sel = [r for r in rows if r["span"] == span and r["eps"] == eps_main and r["status"] == "ok"]
        ax[1].plot([r["factor"] for r in sel], [r["crest"] for r in sel], mk + "-", label=f"crest, inlay over {span}")
        ax[1].plot([r["factor"] for r in sel], [r["mean"] for r in sel], mk + "--", label=f"mean, inlay over {span}")
    ax[1].axhline(14.33, color="k", ls=":", lw=0.8)
    ax[1].set(xscale="log", xlabel="multifilament bending and torsion factor", ylabel="height, mm", ylim=(10, 21),
              title=f"eps0 = {eps_main:g}: cushion crest and mean height")
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out / "seam_layer_continuity.png", dpi=110)
    return ds


def main(argv=None):
    ap = parser(__file__, __doc__)
    a = ap.parse_args(argv)
    out = setup(a)
    if a.quick:
        run(out, points=QUICK_POINTS, d=12.0, resolution=1, steps=1)
    else:
        run(out)
    print(f"wrote {out / 'seam_layer_continuity.nc'} and {out / 'seam_layer_continuity.png'}")


if __name__ == "__main__":
    main()
