"""Does thread sliding explain why the yarn-level seam dips only locally?

The yarn-level stitch is a chain of beams with one pre-strain eps0: the needle and bobbin
threads along the seam (periodic, they cannot shorten) keep a high tension while the legs that
pull the layers together relax. A real thread slides through the needle holes and the interlock
and has one tension T along its length. This study imposes that: after each contact solve,
T = EA (L / L_rest - 1) from the current stitch length L (legs count as two strands) and the
rest length L_rest = (1 - eps0) L0, and each stitch element's pre-strain is set (damped) so
that its axial force is T per strand; repeated to a fixed point. It records the cushion and
seam-line heights before (beam stitch) and after (sliding thread).

Usage: python studies/seam_sliding_thread.py [OUTDIR] [--distance 24] [--prestrain 0.3]
"""
import argparse
import time
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

import homtex  # noqa: E402
from homtex.errors import SolverError  # noqa: E402
from homtex.geometry.seam import seam_cell  # noqa: E402
from homtex.output.io import write_netcdf  # noqa: E402
from homtex.seams import SeamSolver, measure_profile  # noqa: E402
from homtex.analysis.static import prestrain_load  # noqa: E402

warnings.simplefilter("ignore")   # creation overlaps are reported by the cell


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("out", nargs="?", default="results/seam_sliding_thread")
    p.add_argument("--distance", type=float, default=24.0)
    p.add_argument("--prestrain", type=float, default=0.3)
    p.add_argument("--iterations", type=int, default=30)
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    cell = homtex.load_cell("spacer_20mm")
    fr, info = seam_cell(cell, seam_distance=a.distance, prestrain=a.prestrain)
    st = np.arange(int(info["fabric_elements"]), fr.n_elements)
    strands = np.where(np.asarray(info["legs"])[st], 2.0, 1.0)
    EA = float(info["stitch_EA"])
    l0 = fr.length[st]
    L_rest = (1.0 - a.prestrain) * float((strands * l0).sum())
    ss = SeamSolver(fr, info)
    ss.ramp(4)
    _, h = measure_profile(fr, info, ss.result.u)
    N = ss.result.axial_force[st] / strands
    rec = {"tension_min": [float(N.min())], "tension_max": [float(N.max())],
           "cushion_height": [float(np.nanmax(h))], "seam_height": [float(h[len(h) // 2])]}
    status = "ok"
    pre = fr.prestrain
    for it in range(a.iterations):
        u = ss.result.u
        du = u[fr.elements[st, 1], :3] - u[fr.elements[st, 0], :3]
        delta = np.einsum("ij,ij->i", fr.R[st, 0], du)
        T = max(EA * ((strands * (l0 + delta)).sum() / L_rest - 1.0), 0.0)
        target = T / EA - delta / l0
        change = float(np.abs(target - pre[st]).max())
        pre[st] = pre[st] + 0.5 * (target - pre[st])    # damped: the contact state follows
        ss.f_pre = prestrain_load(fr)
        try:
            res = ss._solve(1.0)
        except SolverError as err:
            status = f"stopped at iteration {it + 1}: {err}"
            break
        ss._accept(res, 1.0)
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
                           "prestrain": a.prestrain, "seconds": time.perf_counter() - t0})
    write_netcdf(ds, out / "seam_sliding_thread.nc")
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
    fig.savefig(out / "seam_sliding_thread.png", dpi=110)
    plt.close(fig)
    print(ds.to_dataframe())
    print(f"status: {status}; wrote {out}/seam_sliding_thread.nc and .png")
    return ds


if __name__ == "__main__":
    main()
