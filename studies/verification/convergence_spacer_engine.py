"""Mesh convergence of the spacer cell's compression curve on the large-motion engine, to 70 %.

The curve to 70 % (friction 0.2, 70 steps) at the shipped resolution (elements per yarn segment,
pile segments per leg) and with each of the two refined twice, and both; the shipped resolution is
converged when its 70 % stress is within 2 % of every twice-finer mesh.

Usage::

    python studies/verification/convergence_spacer_engine.py [--out DIR] [--quick]

Default: resolutions (2, 4), (2, 8), (4, 8), (2, 16), (4, 16) (about 15 minutes of CPU on the
2-core machine). ``--quick``: (1, 2) and (1, 4) to 10 % in 5 steps. Writes
``DIR/convergence_spacer_engine.nc`` and ``DIR/convergence_spacer_engine.png``.
"""
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

LEVELS = (0.1, 0.3, 0.5, 0.7)


def main(argv=None):
    import homtex

    a = parser(__file__, __doc__).parse_args(argv)
    out = setup(a)
    base = homtex.load_cell("spacer_20mm")
    shipped = (int(base.resolution["elements_per_segment"]), int(base.resolution["pile_segments"]))
    if a.quick:
        res, strain, steps, levels = [(1, 2), (1, 4)], 0.1, 5, (0.05, 0.1)
    else:
        res, strain, steps, levels = [(2, 4), (2, 8), (4, 8), (2, 16), (4, 16)], 0.7, 70, LEVELS
    rows, curves = [], []
    for eps, ps in res:
        cell = base.replace(**{"resolution.elements_per_segment": eps, "resolution.pile_segments": ps})
        t0 = time.process_time()
        ds = homtex.compress(cell, strain=strain, steps=steps, geometry="nonlinear",
                             contact=homtex.Contact(friction=0.2))
        cpu = time.process_time() - t0
        e = ds.strain.values
        s = [float(np.interp(lv, e, ds.stress.values)) if lv <= e.max() + 1e-12 else np.nan for lv in levels]
        rows.append((eps, ps, cell.frame.n_elements, cpu, ds.attrs["status"], *s))
        curves.append((e, ds.stress.values))
        print(f"{eps} elements per segment, {ps} pile segments ({cell.frame.n_elements} elements): "
              + ", ".join(f"{100 * lv:.0f} %: {v:.4g} kPa" for lv, v in zip(levels, s))
              + f"  [{ds.attrs['status']}, {cpu:.0f} s CPU]")
    n = len(rows)
    c = list(zip(*rows))
    stress = np.array([r[5:] for r in rows])
    ds = xr.Dataset(
        {"stress": (("resolution", "level"), stress, {"units": "kPa", "long_name": "nominal stress (friction 0.2)"}),
         "elements": ("resolution", np.array(c[2]), {"units": "1", "long_name": "elements of the cell"}),
         "cpu_seconds": ("resolution", np.array(c[3], float), {"units": "s", "long_name": "process CPU time"}),
         "status": ("resolution", np.array(c[4]), {"units": "1", "long_name": "curve status"})},
        coords={"resolution": ("resolution", np.arange(n), {"units": "1", "long_name": "resolution"}),
                "elements_per_segment": ("resolution", np.array(c[0]), {"units": "1", "long_name":
                                                                         "elements per yarn segment"}),
                "pile_segments": ("resolution", np.array(c[1]), {"units": "1", "long_name": "segments per pile leg"}),
                "level": ("level", np.array(levels), {"units": "1", "long_name": "compression strain"})},
        attrs={"shipped": f"{shipped[0]} elements per segment, {shipped[1]} pile segments",
               "friction": 0.2, "steps": steps, "quick": int(a.quick)})
    if not a.quick:
        k = [i for i, r in enumerate(rows) if (r[0], r[1]) == shipped]
        if k:
            ref = stress[k[0], -1]
            for i, r in enumerate(rows):
                if (r[0], r[1]) in ((2 * shipped[0], shipped[1]), (shipped[0], 2 * shipped[1]),
                                    (2 * shipped[0], 2 * shipped[1])):
                    print(f"shipped vs ({r[0]}, {r[1]}): {100 * (ref / stress[i, -1] - 1):+.2f} % at 70 %")
    save_netcdf(ds, out / "convergence_spacer_engine.nc")
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for (eps, ps, m, *_), (e, s) in zip(rows, curves):
        ax.plot(100 * e, s, label=f"{eps} el./segment, {ps} pile segments ({m} elements)"
                + ("  (shipped)" if (eps, ps) == shipped else ""), lw=2 if (eps, ps) == shipped else 1)
    ax.set_xlabel("compression strain (%)")
    ax.set_ylabel("nominal stress (kPa)")
    ax.set_title("Spacer cell on the large-motion engine (friction 0.2): mesh convergence")
    ax.legend(fontsize=8)
    save_figure(fig, out / "convergence_spacer_engine.png")
    return ds


if __name__ == "__main__":
    main()
