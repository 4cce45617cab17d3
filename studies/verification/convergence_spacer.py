"""Convergence of the spacer cell's compression modulus and cushion height with elements per
segment and with the contact penalty.

Modulus: line fit of the yarn-level stress-strain curve over 0-20 % (the linear range), default
contact (pdas, augmented Lagrangian: exact gaps) and penalty contact at growing penalties.
Cushion height and seam-line height: yarn-level seam cell, d = 24 mm, the cell's nominal
pre-strain, against elements per segment and against the penalty. Errors are relative to the finest resolution / to the augmented (exact-gap) result.

Usage::

    python studies/verification/convergence_spacer.py [--out DIR] [--quick | --full]

Default: modulus at 1/2/3/4/6 elements per segment, seam cell at 1/2/3, penalties 0.1..1000 x
default (a few minutes here; ``--full`` adds 8 and seam cells at 4 and 6, 81 s for the seam part
alone). ``--quick``: the modulus at 1 and 2 elements per segment (fitted to 10 % in 2 steps), the seam
cell at 1, penalty 100 x default on the 1-element cell, seam ramp in 1 step (seconds). Writes
``DIR/convergence_spacer.nc`` and ``DIR/convergence_spacer.png`` (default DIR =
results/convergence_spacer).
"""
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402


def modulus(cell, contact=None, strain=0.2, steps=8):
    import homtex

    ds = homtex.compress(cell, strain=strain, steps=steps, contact=contact, geometry="linear")
    if ds.attrs["status"] != "ok":
        return np.nan
    e, s = ds.strain.values, ds.stress.values
    return float(np.polyfit(np.r_[0.0, e], np.r_[0.0, s], 1)[0])


def main(argv=None):
    import homtex
    from homtex.contact import ContactSolver

    ap = parser(__file__, __doc__)
    ap.add_argument("--full", action="store_true", help="finer resolutions")
    a = ap.parse_args(argv)
    out = setup(a)
    full, quick = a.full, a.quick
    base = homtex.load_cell("spacer_20mm")
    ref_res = int(base.resolution.get("elements_per_segment", 2))   # the cell file's resolution
    if quick:
        res_list, seam_res, pen_factors = [1, 2], [1], [1e2]
        mod_kw, seam_steps = dict(strain=0.1, steps=2), 1
        ref_res = 1
        base = base.replace(**{"resolution.elements_per_segment": ref_res})
    else:
        res_list = [1, 2, 3, 4, 6, 8] if full else [1, 2, 3, 4, 6]
        seam_res = [1, 2, 3, 4, 6] if full else [1, 2, 3]
        pen_factors = [1e-1, 1e0, 1e1, 1e2, 1e3]
        mod_kw, seam_steps = {}, 4
    t0 = time.perf_counter()
    mod_r = [modulus(base.replace(**{"resolution.elements_per_segment": n}), **mod_kw) for n in res_list]
    cush, seam = [], []
    for n in seam_res:
        p = homtex.seam_profile(base.replace(**{"resolution.elements_per_segment": n}), seam_distance=24.0,
                                steps=seam_steps, prestrain=0.3, geometry="linear")
        cush.append(float(p.cushion_height) if p.attrs.get("status", "ok") == "ok" else np.nan)
        seam.append(float(p.seam_height) if p.attrs.get("status", "ok") == "ok" else np.nan)
    exact = modulus(base, **mod_kw)
    k0 = ContactSolver(base.frame, None, None, homtex.Contact()).k   # the default penalty, N/mm
    mod_p = [modulus(base, homtex.Contact(enforcement="penalty", penalty=f * k0), **mod_kw) for f in pen_factors]
    # the seam cell with penalty contact (exact gaps: the default augmented Lagrangian)
    cush_p, seam_p = [], []
    for f in pen_factors:
        try:
            p = homtex.seam_profile(base, seam_distance=24.0, steps=seam_steps, prestrain=0.3, geometry="linear",
                                    contact=homtex.Contact(enforcement="penalty", penalty=f * k0))
            okp = p.attrs.get("status", "ok") == "ok"
        except homtex.SolverError as err:   # a too-soft penalty is detected and named
            print(f"  seam cell, penalty x{f:g}: {str(err)[:100]}")
            okp = False
        cush_p.append(float(p.cushion_height) if okp else np.nan)
        seam_p.append(float(p.seam_height) if okp else np.nan)
    seconds = time.perf_counter() - t0

    mod_r, mod_p = np.array(mod_r), np.array(mod_p)
    err_r = np.abs(mod_r - mod_r[-1]) / mod_r[-1]
    err_p = np.abs(mod_p - exact) / exact
    cush, seam = np.array(cush), np.array(seam)
    strain_pct = 100 * mod_kw.get("strain", 0.2)
    ds = xr.Dataset(
        {"modulus_vs_resolution": ("elements_per_segment", mod_r,
                                   {"units": "kPa", "long_name": f"compression modulus (0-{strain_pct:g} %)"}),
         "modulus_error_vs_resolution": ("elements_per_segment", err_r,
                                         {"units": "1", "long_name": "relative difference to the finest resolution"}),
         "cushion_height": ("seam_elements_per_segment", cush,
                            {"units": "mm", "long_name": "cushion height, d = 24 mm, yarn-level seam cell"}),
         "seam_height": ("seam_elements_per_segment", seam,
                         {"units": "mm", "long_name": "seam-line height, d = 24 mm, yarn-level seam cell"}),
         "modulus_vs_penalty": ("penalty_factor", mod_p,
                                {"units": "kPa", "long_name": "compression modulus, penalty contact"}),
         "modulus_error_vs_penalty": ("penalty_factor", err_p,
                                      {"units": "1", "long_name": "relative difference to augmented Lagrangian"}),
         "modulus_augmented": ((), exact, {"units": "kPa", "long_name": "compression modulus, augmented Lagrangian"}),
         "cushion_height_vs_penalty": ("penalty_factor", np.array(cush_p),
                                       {"units": "mm", "long_name": "cushion height, d = 24 mm, penalty contact"}),
         "seam_height_vs_penalty": ("penalty_factor", np.array(seam_p),
                                    {"units": "mm", "long_name": "seam-line height, d = 24 mm, penalty contact"})},
        coords={"elements_per_segment": ("elements_per_segment", res_list,
                                         {"units": "1", "long_name": "elements per control segment"}),
                "seam_elements_per_segment": ("seam_elements_per_segment", seam_res,
                                              {"units": "1", "long_name": "elements per control segment (seam cell)"}),
                "penalty_factor": ("penalty_factor", pen_factors,
                                   {"units": "1", "long_name": f"penalty / default penalty ({k0:.4g} N/mm)"})},
        attrs={"seconds": seconds, "default_penalty_N_per_mm": k0, "seam_ramp_steps": seam_steps,
               "quick": int(quick)})
    save_netcdf(ds, out / "convergence_spacer.nc")

    plt = pyplot()
    fig, ax = plt.subplots(1, 4, figsize=(18, 4))
    ok = err_r > 0
    ax[0].loglog(np.array(res_list)[ok], err_r[ok], "o-")
    ax[0].set(xlabel="elements per segment", ylabel="relative modulus difference to finest",
              title="modulus vs resolution")
    ax[1].plot(seam_res, cush, "o-", label="cushion height")
    ax[1].plot(seam_res, seam, "s-", label="seam-line height")
    ax[1].set(xlabel="elements per segment", ylabel="mm", title="yarn-level seam cell, d = 24 mm")
    ax[1].legend()
    ok = err_p > 0
    ax[2].loglog(np.array(pen_factors)[ok], err_p[ok], "o-")
    ax[2].set(xlabel="penalty / default", ylabel="relative modulus difference to augmented",
              title="penalty contact converges to exact gaps")
    # exact gaps at the penalty runs' resolution (the cell file's: 2 elements per segment) is the reference
    i2 = seam_res.index(ref_res)
    dc = np.abs(np.array(cush_p) - cush[i2])
    dsl = np.abs(np.array(seam_p) - seam[i2])
    pf = np.array(pen_factors)
    ax[3].loglog(pf[dc > 0], dc[dc > 0], "o-", label="cushion height")
    ax[3].loglog(pf[dsl > 0], dsl[dsl > 0], "s-", label="seam-line height")
    ax[3].set(xlabel="penalty / default", ylabel="|penalty - exact gaps|, mm",
              title="seam cell d = 24 mm vs contact penalty")
    ax[3].legend()
    fig.tight_layout()
    save_figure(fig, out / "convergence_spacer.png", dpi=110)
    print(ds)
    print(f"wrote {out / 'convergence_spacer.nc'} and .png ({seconds:.1f} s)")
    return ds


if __name__ == "__main__":
    main()
