"""Experiment: a tension-controlled stitch (constant thread tension, as a sewing machine's
tensioner sets it) instead of the legs' pre-strain, whose rest length caps the pinch.

The stitch legs become force elements (axial stiffness x1e-3, pre-load T per leg = two strands);
the threads along the seam carry the same T. If the beam-on-foundation bound of
studies/experiments/seam_length_scale.py holds for the yarn-level cell, a stronger stitch pulls
the seam line deeper while the cushion crest does NOT come down (it bulges up slightly).

How: the legs' axial stiffness is scaled with the contact solver's state API
(``ss.cs.set_axial_scale``), and every stitch element gets the pre-strain T / EA_eff (EA_eff: its
scaled axial stiffness) in the frame, so that the pre-strain ramp of :class:`SeamSolver` loads it
with alpha x T (alpha: the ramp's factor); the fabric carries none.

Usage::

    python studies/experiments/seam_tension_stitch.py [--out DIR] [--distance 24] [--tension T ...] [--quick]

Default: d = 24 mm, T = 0.5 / 1 / 2 / 4 / 8 N per leg, 8 ramp steps (a few minutes here; 8 N
fails on contact re-detection, which is recorded). ``--quick``: d = 12 mm, 1 element per segment,
T = 0.5 N in 2 ramp steps (seconds; not the study's numbers). Writes DIR/seam_tension_stitch.nc
(heights, stitch force and the profile per tension) and DIR/seam_tension_stitch.png (default DIR
= results/seam_tension_stitch).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

LEG_STIFFNESS = 1e-3     # legs: force elements (constant tension), tiny axial stiffness
EPS0 = 0.3               # the seam cell's nominal pre-strain (replaced by the tension load)


def tension_stitch(cell, d: float, T: float, *, ramp_steps: int = 8, max_cuts: int = 5):
    """Sew the seam cell with a tension-controlled stitch: (x, h, stitch leg force N, status)."""
    from homtex.errors import SolverError
    from homtex.geometry.seam import seam_cell
    from homtex.seams import SeamSolver, measure_profile

    frame, info = seam_cell(cell, seam_distance=d, prestrain=EPS0)
    legs = np.asarray(info["legs"], bool)
    stitch = np.zeros(frame.n_elements, bool)
    stitch[int(info["fabric_elements"]):] = True
    scale = np.ones(frame.n_elements)
    scale[legs] = LEG_STIFFNESS
    pre = np.zeros(frame.n_elements)
    pre[stitch] = T / (frame.EA[stitch] * scale[stitch])    # pre-load EA_eff eps = T in every stitch element
    frame.prestrain[:] = pre
    ss = SeamSolver(frame, info)
    ss.cs.set_axial_scale(scale)
    try:
        ss.ramp(ramp_steps, max_cuts=max_cuts)
        status = "ok"
    except SolverError as err:
        status = f"failed: {err}"
    if ss.result is None or status != "ok":
        x, h = measure_profile(frame, info, None)
        return x, np.full_like(h, np.nan), np.nan, status, info
    x, h = measure_profile(frame, info, ss.result.u)
    # the result's element forces use the frame's EA, not the scaled one (ContactSolver.set_axial_scale
    # changes stiffness and load only): EA scale (strain + eps) = scale x the reported force
    force = float(np.mean(scale[legs] * ss.result.axial_force[legs]))
    return x, h, force, status, info


def run(out: Path, *, distance: float = 24.0, tensions=(0.5, 1.0, 2.0, 4.0, 8.0), resolution: int | None = None,
        ramp_steps: int = 8) -> xr.Dataset:
    import homtex

    cell = homtex.load_cell("spacer_20mm")
    if resolution is not None:
        cell = cell.replace(**{"resolution.elements_per_segment": resolution})
    rows, profiles, x = [], [], None
    for T in tensions:
        t = time.perf_counter()
        x, h, force, status, info = tension_stitch(cell, distance, T, ramp_steps=ramp_steps)
        sec = time.perf_counter() - t
        i0 = int(np.argmin(np.abs(x)))
        rows.append(dict(T=T, seam=float(h[i0]), crest=float(np.max(h)), force=force, status=status, seconds=sec))
        profiles.append(h)
        if status == "ok":
            print(f"d = {distance:g} mm, T = {T:g} N per leg: seam line {h[i0]:.2f} mm, crest {h.max():.2f} mm, "
                  f"leg force {force:.3f} N ({sec:.1f} s)", flush=True)
        else:
            print(f"d = {distance:g} mm, T = {T:g} N per leg: {status} ({sec:.1f} s)", flush=True)
    ds = xr.Dataset(
        {"height": (("tension", "x"), np.vstack(profiles),
                    {"units": "mm", "long_name": "cushion height (outer yarn surfaces, per wale bin; NaN: failed)"}),
         "seam_height": ("tension", [r["seam"] for r in rows], {"units": "mm", "long_name": "height at the seam line"}),
         "cushion_height": ("tension", [r["crest"] for r in rows], {"units": "mm", "long_name": "crest (max height)"}),
         "stitch_force": ("tension", [r["force"] for r in rows],
                          {"units": "N", "long_name": "mean axial force of a stitch leg (two strands)"}),
         "status": ("tension", [r["status"] for r in rows], {"long_name": "'ok' or why the ramp failed"}),
         "seconds": ("tension", [r["seconds"] for r in rows], {"units": "s", "long_name": "wall time of the ramp"})},
        coords={"tension": ("tension", np.asarray(tensions, float), {"units": "N", "long_name": "thread tension per leg"}),
                "x": ("x", x, {"units": "mm", "long_name": "position across the seam (0 = seam line)"})},
        attrs={"seam_distance_mm": float(info["seam_distance"]), "leg_stiffness_factor": LEG_STIFFNESS,
               "ramp_steps": ramp_steps, "elements_per_segment": int(cell.resolution.get("elements_per_segment", 2)),
               "title": "tension-controlled stitch: seam line and crest over thread tension"})
    save_netcdf(ds, out / "seam_tension_stitch.nc")

    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for T, h in zip(tensions, profiles):
        ax[0].plot(x, h, "o-", ms=3, label=f"T = {T:g} N")
    ax[0].set(xlabel="x across the seam, mm (0 = seam line)", ylabel="height, mm",
              title=f"tension-controlled stitch, d = {ds.attrs['seam_distance_mm']:.1f} mm")
    ax[0].legend(fontsize=7)
    ax[1].plot(ds.tension, ds.seam_height, "s-", label="seam line")
    ax[1].plot(ds.tension, ds.cushion_height, "o-", label="crest")
    ax[1].set(xscale="log", xlabel="thread tension per leg, N", ylabel="height, mm", title="seam line and crest")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, out / "seam_tension_stitch.png", dpi=110)
    return ds


def main(argv=None):
    ap = parser(__file__, __doc__)
    ap.add_argument("--distance", type=float, default=None, help="seam distance, mm (default 24; --quick 12)")
    ap.add_argument("--tension", type=float, nargs="+", default=None,
                    help="thread tensions per leg, N (default 0.5 1 2 4 8; --quick 0.5)")
    a = ap.parse_args(argv)
    out = setup(a)
    if a.quick:
        run(out, distance=a.distance or 12.0, tensions=tuple(a.tension or (0.5,)), resolution=1, ramp_steps=2)
    else:
        run(out, distance=a.distance or 24.0, tensions=tuple(a.tension or (0.5, 1.0, 2.0, 4.0, 8.0)))
    print(f"wrote {out / 'seam_tension_stitch.nc'} and {out / 'seam_tension_stitch.png'}")


if __name__ == "__main__":
    main()
