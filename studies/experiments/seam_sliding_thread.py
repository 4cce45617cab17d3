"""Does thread sliding explain why the yarn-level seam dips only locally?

The yarn-level stitch is a chain of beams with one pre-strain eps0: the needle and bobbin
threads along the seam (periodic, they cannot shorten) keep a high tension while the legs that
pull the layers together relax. A real thread slides through the needle holes and the interlock
and has one tension T along its length. This study imposes that: after each contact solve,
T = EA (L / L_rest - 1) from the current stitch length L (legs count as two strands) and the
rest length L_rest = (1 - eps0) L0, and each stitch element's pre-strain is set (damped) so
that its axial force is T per strand; repeated to a fixed point. It records the cushion and
seam-line heights before (beam stitch) and after (sliding thread).

The new pre-strains go into the frame's per-element ``prestrain``; the contact solver reads them
when its pre-strain scale is set (``ss.cs.set_prestrain_scale(1.0)``, which :meth:`SeamSolver.solve`
does), so the load and the element forces follow.

Usage::

    python studies/experiments/seam_sliding_thread.py [--out DIR] [--distance 24] [--prestrain 0.3]
        [--iterations 30] [--quick]

Default: a few minutes here. ``--quick``: d = 12 mm, 1 element per segment, a 1-step ramp and 1
update (seconds; not the study's numbers). Writes DIR/seam_sliding_thread.nc and
DIR/seam_sliding_thread.png (default DIR = results/seam_sliding_thread).
"""
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402


def main(argv=None):
    import homtex
    from homtex.errors import SolverError
    from homtex.geometry.seam import seam_cell
    from homtex.seams import SeamSolver, measure_profile

    p = parser(__file__, __doc__)
    p.add_argument("--distance", type=float, default=None, help="seam distance, mm (default 24; --quick 12)")
    p.add_argument("--prestrain", type=float, default=0.3)
    p.add_argument("--iterations", type=int, default=None, help="sliding-thread updates (default 30; --quick 1)")
    a = p.parse_args(argv)
    out = setup(a)
    iterations = a.iterations or (1 if a.quick else 30)
    distance = a.distance or (12.0 if a.quick else 24.0)
    ramp_steps = 1 if a.quick else 4
    t0 = time.perf_counter()
    cell = homtex.load_cell("spacer_20mm")
    if a.quick:
        cell = cell.replace(**{"resolution.elements_per_segment": 1})
    fr, info = seam_cell(cell, seam_distance=distance, prestrain=a.prestrain)
    st = np.arange(int(info["fabric_elements"]), fr.n_elements)
    strands = np.where(np.asarray(info["legs"])[st], 2.0, 1.0)
    EA = float(info["stitch_EA"])
    l0 = fr.length[st]
    L_rest = (1.0 - a.prestrain) * float((strands * l0).sum())
    ss = SeamSolver(fr, info)
    ss.ramp(ramp_steps)
    _, h = measure_profile(fr, info, ss.result.u)
    N = ss.result.axial_force[st] / strands
    rec = {"tension_min": [float(N.min())], "tension_max": [float(N.max())],
           "cushion_height": [float(np.nanmax(h))], "seam_height": [float(h[len(h) // 2])]}
    status = "ok"
    pre = fr.prestrain          # the frame's per-element pre-strain, updated in place below
    for it in range(iterations):
        u = ss.result.u
        du = u[fr.elements[st, 1], :3] - u[fr.elements[st, 0], :3]
        delta = np.einsum("ij,ij->i", fr.R[st, 0], du)
        T = max(EA * ((strands * (l0 + delta)).sum() / L_rest - 1.0), 0.0)
        target = T / EA - delta / l0
        change = float(np.abs(target - pre[st]).max())
        pre[st] = pre[st] + 0.5 * (target - pre[st])    # damped: the contact state follows
        ss.cs.set_prestrain_scale(1.0)                  # the load of the new pre-strains
        try:
            res = ss.solve(1.0)
        except SolverError as err:
            status = f"stopped at iteration {it + 1}: {err}"
            break
        ss.accept(res, 1.0)
        _, h = measure_profile(fr, info, res.u)
        N = res.axial_force[st] / strands
        rec["tension_min"].append(float(N.min()))
        rec["tension_max"].append(float(N.max()))
        rec["cushion_height"].append(float(np.nanmax(h)))
        rec["seam_height"].append(float(h[len(h) // 2]))
        if change < 1e-5:
            break
    meta = {"tension_min": ("N", "smallest stitch tension per strand"),
            "tension_max": ("N", "largest stitch tension per strand"),
            "cushion_height": ("mm", "cushion height"), "seam_height": ("mm", "seam-line height")}
    ds = xr.Dataset({k: ("iteration", np.array(v), {"units": meta[k][0], "long_name": meta[k][1]})
                     for k, v in rec.items()},
                    coords={"iteration": ("iteration", np.arange(len(rec["cushion_height"])),
                                          {"units": "1", "long_name": "0: beam stitch; then sliding-thread updates"})},
                    attrs={"status": status, "seam_distance_mm": float(info["seam_distance"]),
                           "prestrain": a.prestrain, "seconds": time.perf_counter() - t0, "ramp_steps": ramp_steps,
                           "elements_per_segment": int(cell.resolution.get("elements_per_segment", 2))})
    save_netcdf(ds, out / "seam_sliding_thread.nc")
    plt = pyplot()
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    ax[0].plot(ds.iteration, ds.cushion_height, "o-", label="cushion")
    ax[0].plot(ds.iteration, ds.seam_height, "s-", label="seam line")
    ax[0].set(xlabel="iteration (0: beam stitch)", ylabel="mm", title=f"d = {ds.attrs['seam_distance_mm']:.4g} mm")
    ax[0].legend()
    ax[1].semilogy(ds.iteration, ds.tension_max, "o-", label="max")
    ax[1].semilogy(ds.iteration, np.maximum(ds.tension_min, 1e-3), "s-", label="min (floor 1e-3)")
    ax[1].set(xlabel="iteration", ylabel="tension per strand, N", title="stitch tension")
    ax[1].legend()
    fig.tight_layout()
    save_figure(fig, out / "seam_sliding_thread.png", dpi=110)
    print(ds.to_dataframe())
    print(f"status: {status}; wrote {out}/seam_sliding_thread.nc and .png")
    return ds


if __name__ == "__main__":
    main()
