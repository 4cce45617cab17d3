"""The seamed fabric on the large-motion engine end to end, from a cold result cache: what each
default call costs and what it answers.

With the result cache in a fresh folder (OUT/cache), on ``cells/spacer_20mm.toml``:

1. the unseamed law (:func:`homtex.macro.engine_law`: the engine's curve to 70 %, friction 0.2);
2. ``homtex.seam_profile`` for d = 43, 24, 18 mm (sewn on the engine, calibrated stitch), each timed
   cold (the issue's target: d = 43 mm within 120 s);
3. ``homtex.macro_curve`` for no seams and the three distances to 50 % (first call: what the
   profiles did not already compute; second call in the same process: the cache, target 10 ms);
   the plate travel at which the force first reaches 50 N and the force at 4 mm of travel;
4. ``homtex.seam_compression(strain=0.7)`` for no seams and d = 24 mm (the sewn state from the
   cache; its sewing time is the profile's): stress, force on the paper's 121 cm^2 plate, the
   largest force drop, the three regions (:func:`homtex.analysis.regions.three_regions`).

Usage::

    python studies/benchmarks/bench_seams_engine.py [--quick] [--out DIR]

``--quick``: d = 8.5 mm sewn at eps0 = 0.15 in 2 ramp levels, 3 plate steps to 10 % (seconds;
not the study's numbers). Writes ``bench_seams_engine.nc`` and ``bench_seams_engine.png`` into OUT (default
results/bench_seams_engine). Full run: about 15 minutes on the 2-core machine.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")
PLATE = 12100.0     # mm^2, the paper's 121 cm^2 plates
LOAD_CELL = 500.0   # N


def timed(fn, *a, **k):
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn(*a, **k)
    return out, time.perf_counter() - t0, time.process_time() - c0


def first_reach(w, f, level):
    i = np.flatnonzero(np.asarray(f) >= level)
    return float(w[i[0]]) if len(i) else np.nan


def main(argv=None):
    args = parser(__file__, __doc__).parse_args(argv)
    out = setup(args)
    os.environ["HOMTEX_CACHE_DIR"] = str(out / "cache")
    import homtex
    from homtex import cache
    from homtex.analysis.regions import three_regions
    from homtex.macro import engine_law

    cache.clear_cache()
    cell = homtex.load_cell("spacer_20mm")
    D = [8.5] if args.quick else [43.0, 24.0, 18.0]
    seam_kw = {"steps": 2, "prestrain": 0.15} if args.quick else {}
    strain_macro = 0.1 if args.quick else 0.5
    strain_yarn = 0.1 if args.quick else 0.7
    yarn_steps = 3 if args.quick else None
    rows = {}
    law, t_law, c_law = timed(engine_law, cell, strain=0.1, steps=3) if args.quick else timed(engine_law, cell)
    log.info("unseamed engine law to %.0f %%: %.1f s (%.1f s CPU), status %s", 100 * float(law.strain[-1]), t_law,
             c_law, law.attrs["status"])
    profiles = {}
    for d in D:
        p, t, c = timed(homtex.seam_profile, cell, seam_distance=d, **seam_kw)
        profiles[d] = p
        rows[f"seam_profile d={d:g}"] = (t, c)
        log.info("seam_profile d = %g mm (cold): cushion %.2f mm, %.1f s (%.1f s CPU), %s", d, float(p.cushion_height),
                 t, c, p.attrs["status"])
    macro = {}
    specimens = [None, *D]
    mk = {} if not args.quick else {"profile_options": seam_kw}
    for d in specimens:
        kw = dict(seam_distance=d, strain=strain_macro, steps=201, **(mk if d else {}))
        if args.quick:
            kw["curve"] = law
        m1, t1, _ = timed(homtex.macro_curve, cell, **kw)
        m2, t2, _ = timed(homtex.macro_curve, cell, **kw)
        macro[d] = m1
        name = "none" if d is None else f"{d:g}"
        rows[f"macro_curve {name} first"] = (t1, np.nan)
        rows[f"macro_curve {name} second"] = (t2, np.nan)
        w, f = m1.plate_displacement.values, m1.force.values
        log.info("macro_curve %s: first call %.3f s, second %.2f ms; 50 N at %.2f mm, force at 4 mm %.1f N", name, t1,
                 1e3 * t2, first_reach(w, f, 50.0), float(np.interp(4.0, w, f)))
    yarn = {}
    for d in (None, D[len(D) // 2] if not args.quick else D[0]):
        s, t, c = timed(homtex.seam_compression, cell, seam_distance=d, strain=strain_yarn, steps=yarn_steps,
                        **({"ramp_steps": 2, "prestrain": 0.15} if args.quick and d else {}))
        yarn[d] = s
        name = "none" if d is None else f"{d:g}"
        rows[f"seam_compression {name} (press)"] = (t, c)
        reg = three_regions(s.strain.values, s.stress.values, start=0.02, min_span=0.05) if not args.quick else None
        log.info("seam_compression %s to %.0f %%: %s, %.1f s (%.1f s CPU), stress at end %.2f kPa (%.0f N on 121 cm2), "
                 "force drop %.3g, regions %s", name, 100 * float(s.strain[-1]), s.attrs["status"], t, c,
                 float(s.stress[-1]), float(s.stress[-1]) * PLATE * 1e-3, float(s.attrs.get("force_drop_max", 0.0)),
                 None if reg is None else np.round(reg["breaks"], 3))
    # the dataset
    names = list(rows)
    ds = xr.Dataset(
        {"wall_seconds": ("call", [rows[k][0] for k in names], {"units": "s", "long_name": "wall time"}),
         "cpu_seconds": ("call", [rows[k][1] for k in names], {"units": "s", "long_name": "process CPU time"})},
        coords={"call": ("call", names, {"units": "1", "long_name": "call (cold cache unless 'second')"})})
    ds["law_seconds"] = ((), t_law, {"units": "s", "long_name": "unseamed engine law, wall time"})
    for d, m in macro.items():
        name = "none" if d is None else f"{d:g}"
        ds[f"macro_force_{name}"] = (("travel",), np.interp(np.linspace(0, strain_macro * 20.0, 101),
                                                             m.plate_displacement.values, m.force.values),
                                     {"units": "N", "long_name": f"macro_curve force, seams {name}"})
        ds[f"travel_50N_{name}"] = ((), first_reach(m.plate_displacement.values, m.force.values, 50.0),
                                    {"units": "mm", "long_name": "plate travel where the force first reaches 50 N"})
        ds[f"force_4mm_{name}"] = ((), float(np.interp(4.0, m.plate_displacement.values, m.force.values)),
                                   {"units": "N", "long_name": "force at 4 mm of plate travel"})
    ds = ds.assign_coords(travel=("travel", np.linspace(0, strain_macro * 20.0, 101),
                                  {"units": "mm", "long_name": "plate travel from 20 mm"}))
    for d, s in yarn.items():
        name = "none" if d is None else f"{d:g}"
        ds[f"yarn_stress_{name}"] = ((f"strain_{name}",), s.stress.values,
                                     {"units": "kPa", "long_name": f"seam_compression stress, seams {name}"})
        ds = ds.assign_coords({f"strain_{name}": (f"strain_{name}", s.strain.values,
                                                  {"units": "1", "long_name": "plate travel / 20 mm"})})
        ds[f"yarn_status_{name}"] = ((), str(s.attrs["status"]), {"units": "1", "long_name": "status"})
    save_netcdf(ds, out / "bench_seams_engine.nc")

    plt = pyplot()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.6))
    for d, m in macro.items():
        a1.plot(m.plate_displacement.values, m.force.values,
                label=f"macro layer, {'no seams' if d is None else f'd = {d:g} mm'}")
    for d, s in yarn.items():
        a1.plot(s.plate_displacement.values, s.force.values * PLATE / float(s.attrs["area_mm2"]), "k--" if d is None
                else "k:", label=f"yarn level (engine), {'no seams' if d is None else f'd = {d:g} mm'}")
    a1.axhline(LOAD_CELL, color="tab:red", lw=0.8, ls="-.", label="test's 500 N load cell")
    a1.set(xlabel="plate travel from 20 mm, mm", ylabel="force on the 121 cm$^2$ plate, N",
           title="seamed spacer fabric under the punch (no measured data: the paper's curves are plots)")
    a1.legend(fontsize=7)
    a2.barh(np.arange(len(names)), ds.wall_seconds.values, color="tab:gray")
    a2.set_yticks(np.arange(len(names)))
    a2.set_yticklabels(names, fontsize=7)
    a2.set_xscale("log")
    a2.set(xlabel="wall time, s (log)", title="cost of each default call, cold cache (second calls: the cache)")
    fig.tight_layout()
    save_figure(fig, out / "bench_seams_engine.png")
    return ds


if __name__ == "__main__":
    main()
