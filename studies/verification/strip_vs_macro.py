"""The macro layer against a yarn-level strip of seam cells whose cushions differ, under one punch.

A strip of three seams 24 mm apart, sewn on the large-motion engine in one periodic cell, each
seam with its own stitch pre-strain (1.1, 0.9 and 1.0 x the calibrated one: the scatter of a
real specimen's thread tension), so its three cushions differ; the punch then meets one cushion
after another (:func:`homtex.seams.strip.strip_check`). The macro layer predicts the strip's
curve from single-cushion results, three ways: the mean of the single seam cells' yarn-level
curves (each sewn like one of the strip's seams), the calibrated cushion's curve shifted by each
strip cushion's height difference (what ``macro_curve(law="cushion", ...)`` does with a height
scatter), and the column model (``macro_curve``'s default: the unseamed law and the single cells'
profiles). Measured: the force error of each (largest difference over the curve to 50 % / the
strip's stress at 50 %) and the run times (the strip sewn and pressed against each prediction).

Usage::

    python studies/verification/strip_vs_macro.py [--quick] [--out DIR]

``--quick``: two seams 4.25 mm apart (one fabric repeat), frictionless, eps0 0.1 in one ramp level, pressed to 8 % (1.3 % past first contact)
(seconds; checks the plumbing, not the study's numbers). Writes ``strip_vs_macro.nc`` and
``strip_vs_macro.png``. Full run: about 30 minutes on the 2-core machine from a cold result cache
(the sewn states are kept in it).
"""

from __future__ import annotations

import logging
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")


def main(argv=None):
    import homtex
    from homtex.seams.strip import strip_check

    args = parser(__file__, __doc__).parse_args(argv)
    out = setup(args)
    cell = homtex.load_cell("spacer_20mm")
    if args.quick:
        os.environ["HOMTEX_CACHE"] = "0"      # sewn states kept in memory only
        cell = cell.replace(**{"contact.friction": 0.0, "contact.plate_friction": 0.0,
                               "parameters.seam.prestrain": 0.1, "parameters.seam.ramp_steps": 1})
        curve = homtex.compress(cell, strain=[0.04, 0.08])
        ds = strip_check(cell, seam_distance=4.25, factors=(1.0, 1.0), strain=0.08, steps=4, curve=curve)
    else:
        ds = strip_check(cell, seam_distance=24.0, factors=(1.1, 0.9, 1.0), strain=0.5, steps=25)
    for k in ("cushion_laws", "shifted_law", "columns"):
        log.info("%-13s error %.1f %% of the strip's %.2f kPa at %.0f %%; %.3g s against the strip's %.0f s",
                 k, 100 * ds.attrs[f"error_{k}"], ds.attrs["reference_stress_kPa"], 100 * float(ds.strain[-1]),
                 ds.attrs[f"seconds_{k}"], ds.attrs["seconds_strip"])
    save_netcdf(ds, out / "strip_vs_macro.nc")

    chart(ds, out / "strip_vs_macro.png")
    return ds


def chart(ds, path):
    """The strip's curve against the three predictions, and the cushion heights, as a PNG
    (:func:`homtex.output.charts.strip_chart`, the main job's chart)."""
    from homtex.output.charts import strip_chart

    save_figure(strip_chart(ds), path)


if __name__ == "__main__":
    main()
