"""How far the sewn cushion heights can be trusted: step and mesh convergence of the yarn-level
seam on the large-motion engine, and its sensitivity to friction and to the calibrated stitch.

With the cell file's calibrated stitch (``[parameters.seam] prestrain``) the seam cells of
d = 18 / 24 / 43 mm are sewn (:func:`homtex.seams.sew.sew`)

* ``steps``: with twice the shipped ramp's levels (the cell file's ``ramp_steps``; the shipped ramp
  is the mesh part's first case);
* ``mesh``: at the shipped resolution (2 elements per segment, 8 pile segments) and two finer ones
  (12 and 16 pile segments: the pile legs buckle, the layers barely bend; the seam thread twice
  as fine in the finest);
* ``sensitivity`` (d = 24 mm): friction 0 and 0.4 (the cell file: 0.2), and eps0 within +-10 % of
  the calibrated value (one ramp to 1.1 eps0, its levels 0.9 and 1.0 of the way read off).

Every case records the cushion and seam-line heights, the ramp's status, its energy balance and
its wall and CPU times; the chart shows the relative change of the cushion with each refinement.

Usage::

    python studies/verification/convergence_seam_engine.py [--quick] [--out DIR] [--part steps|mesh|sensitivity|all]

Parts can run in separate processes (each writes ``convergence_seam_engine_<part>.nc``); the chart
``convergence_seam_engine.png`` is drawn from what the folder holds. ``--quick``: one sewing of
d = 8.5 mm at eps0 = 0.15 per part (seconds; not the study's numbers). Full run: about 40 CPU minutes on the 2-core machine.
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")

PARTS = ("steps", "mesh", "sensitivity")


def one(cell, d, *, label, group, steps, prestrain=None, contact=None, seam_kw=None, read_levels=None):
    """Sew one case; returns a list of row dicts (several when ``read_levels`` reads a ramp)."""
    from homtex.seams.sew import sew

    t0, c0 = time.perf_counter(), time.process_time()
    s = sew(cell, seam_distance=d, prestrain=prestrain, steps=steps, contact=contact, **(seam_kw or {}))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    p = s.path
    rows = []
    levels = [1.0] if read_levels is None else read_levels
    for lv in levels:
        k = int(np.argmin(np.abs(p.prestrain_scale.values - lv))) if p.sizes["step"] else -1
        ok = k >= 0 and abs(float(p.prestrain_scale.values[k]) - lv) < 1e-9
        rows.append({"label": label if read_levels is None else f"{label} x{1.1 * lv:.2f}",
                     "group": group, "seam_distance": float(d),
                     "effective_seam_distance": float(s.info["seam_distance"]),
                     "prestrain": float(s.prestrain) * lv,
                     "cushion_height": float(p.cushion_height.values[k]) if ok else np.nan,
                     "seam_height": float(p.seam_height.values[k]) if ok else np.nan,
                     "energy_balance": float(p.energy_balance.values[k]) if ok else np.nan,
                     "status": s.status, "wall_seconds": wall, "cpu_seconds": cpu, "n_nodes": s.frame.n_nodes,
                     "ramp_levels": steps})
        log.info("%s d = %g: cushion %.3f mm, seam line %.3f mm, %s, %.0f s", rows[-1]["label"], d,
                 rows[-1]["cushion_height"], rows[-1]["seam_height"], s.status, wall)
    return rows


def run_part(part, cell, quick):
    import homtex

    D = [8.5] if quick else [18.0, 24.0, 43.0]
    n = 1 if quick else int(cell.parameters["seam"].get("ramp_steps", 10))
    eps = 0.15 if quick else None         # quick: one small sewing per part at a small pre-strain
    rows = []
    if part == "steps":
        for d in D:        # the shipped ramp (n levels) at the shipped mesh is the mesh part's first case
            rows += one(cell, d, label=f"{2 * n} levels", group="steps", steps=2 * n, prestrain=eps)
    elif part == "mesh":
        res = [(8, {})] if quick else [(8, {}), (12, {}), (16, {"elements_per_mm": 2.0, "leg_elements": 8})]
        for d in D:
            for ps, kw in res:
                c = cell.replace(**{"resolution.pile_segments": ps})
                rows += one(c, d, label=f"{ps} pile segments" + (", thread x2" if kw else ""), group="mesh",
                            steps=n, seam_kw=kw, prestrain=eps)
    elif part == "sensitivity":
        d = D[len(D) // 2]
        for mu in (0.0,) if quick else (0.0, 0.4):
            rows += one(cell, d, label=f"friction {mu:g}", group="friction", steps=n, prestrain=eps,
                        contact=homtex.Contact(friction=mu, plate_friction=mu))
        if not quick:
            eps = float(cell.parameters["seam"]["prestrain"])
            k = 11          # levels 9/11 and 10/11 of a ramp to 1.1 eps0 are 0.9 and 1.0 eps0
            rows += one(cell, d, label="eps0", group="stitch", steps=k, prestrain=1.1 * eps,
                        read_levels=[(k - 2) / k, (k - 1) / k, 1.0])
    return rows


def to_dataset(rows, part):
    keys = [k for k in rows[0] if k not in ("label", "group", "status")]
    data = {k: (("case",), np.array([r[k] for r in rows], dtype=float)) for k in keys}
    units = {"seam_distance": "mm", "effective_seam_distance": "mm", "prestrain": "1", "cushion_height": "mm",
             "seam_height": "mm", "energy_balance": "1", "wall_seconds": "s", "cpu_seconds": "s", "n_nodes": "1",
             "ramp_levels": "1"}
    ds = xr.Dataset({k: (dims, v, {"units": units[k], "long_name": k.replace("_", " ")}) for k, (dims, v) in
                     data.items()})
    for k in ("label", "group", "status"):
        ds[k] = (("case",), np.array([r[k] for r in rows]), {"units": "1", "long_name": k})
    ds = ds.assign_coords(case=("case", np.arange(len(rows)), {"units": "1", "long_name": "case"}))
    ds.attrs.update(part=part)
    return ds


def chart(out):
    plt = pyplot()
    parts = {p: xr.open_dataset(out / f"convergence_seam_engine_{p}.nc") for p in PARTS
             if (out / f"convergence_seam_engine_{p}.nc").exists()}
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.4))
    for ax, p in zip(axes, PARTS):
        ds = parts.get(p)
        if ds is None:
            ax.set_title(f"{p}: not run")
            continue
        if p == "steps" and "mesh" in parts:      # the shipped ramp: the mesh part's shipped resolution
            m = parts["mesh"]
            base = m.isel(case=[i for i, lab in enumerate(m.label.values) if str(lab).startswith("8 pile")])
            n = int(base.ramp_levels.values[0]) if "ramp_levels" in base else 10   # (older files: 10)
            base = base.assign(label=("case", np.array([f"{n} levels"] * base.sizes["case"])))
            ds = xr.concat([base, ds], dim="case")
            ds = ds.isel(case=np.argsort(ds.seam_distance.values, kind="stable"))
        if p in ("steps", "mesh"):
            for d in np.unique(ds.seam_distance.values):
                sel = ds.where(ds.seam_distance == d, drop=True)
                ax.plot(np.arange(sel.sizes["case"]), sel.cushion_height.values, "o-",
                        label=f"d = {float(sel.effective_seam_distance[0]):.1f} mm")
                for i, (lab, h) in enumerate(zip(sel.label.values, sel.cushion_height.values)):
                    if i:
                        prev = float(sel.cushion_height.values[i - 1])
                        ax.annotate(f"{100 * (h - prev) / prev:+.2f} %", (i, h), textcoords="offset points",
                                    xytext=(4, 4), fontsize=7)
                ax.set_xticks(np.arange(sel.sizes["case"]))
                ax.set_xticklabels([str(v) for v in sel.label.values], fontsize=7)
            ax.set(ylabel="cushion height, mm")
            ax.set_title(f"{'ramp levels' if p == 'steps' else 'mesh'}: change with each refinement", fontsize=9)
        else:
            h = ds.cushion_height.values
            ax.barh(np.arange(ds.sizes["case"]), h, color="tab:gray", label="cushion height")
            for i, v in enumerate(h):
                ax.text(v, i, f" {v:.2f}", va="center", fontsize=7)
            ax.set_yticks(np.arange(ds.sizes["case"]))
            ax.set_yticklabels([str(v) for v in ds.label.values], fontsize=7)
            ax.set_xlim(0.8 * np.nanmin(h), 1.08 * np.nanmax(h))
            ax.set_xlabel("cushion height, mm")
            ax.set_title(f"d = {float(ds.effective_seam_distance[0]):.1f} mm: sensitivity (shipped: friction 0.2, "
                         "eps0 x1.00)", fontsize=9)
        ax.legend(fontsize=7) if p != "sensitivity" else None
    fig.suptitle("yarn-level seam on the large-motion engine: cushion height under refinement and changed inputs",
                 fontsize=9)
    fig.tight_layout()
    return save_figure(fig, out / "convergence_seam_engine.png")


def main(argv=None):
    import homtex

    ap = parser(__file__, __doc__)
    ap.add_argument("--part", choices=(*PARTS, "all"), default="all")
    args = ap.parse_args(argv)
    out = setup(args)
    cell = homtex.load_cell("spacer_20mm")
    parts = PARTS if args.part == "all" else (args.part,)
    for p in parts:
        ds = to_dataset(run_part(p, cell, args.quick), p)
        save_netcdf(ds, out / f"convergence_seam_engine_{p}.nc")
    chart(out)


if __name__ == "__main__":
    main()
