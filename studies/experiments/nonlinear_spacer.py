"""Large rotations in the spacer cell: what co-rotational beams change, and what they do not.

Three experiments, one Dataset each (netCDF) and one chart:

1. ``unseamed``: compression of the unseamed cell with linear and with co-rotational beams
   (the former co-rotational contact solve with viscous stabilisation at two factors, to show
   its bias, and the large-motion engine that replaced it in ``compress(geometry="nonlinear")``;
   its own study is ``spacer_nonlinear_compression.py``), stress against strain, Newton
   iterations, the largest stabilisation force against the plate force, run time.
2. ``seam``: the d = 24 mm seam cell, stitch pre-strain ramped with co-rotational beams as far
   as the solve goes; the linear cell at the same pre-strain for comparison (seam-line and
   cushion heights, the profile).
3. ``layer_rigidity``: the linear seam cell with the surface layers' Young's modulus (so their
   bending rigidity) scaled by 1, 5, 15, 50: how far the seam dip spreads into the cushion.

Usage::

    python studies/experiments/nonlinear_spacer.py [--out DIR] [--strain 0.3] [--steps 60] [--quick] [--plot-only]

Default: about 6 min here (325 s; the co-rotational seam ramp has a 240 s budget). ``--quick``:
the cell with 1 element per segment; unseamed to 1 % in 1 step (stabilisation 1e-6 only); the
co-rotational seam ramp on d = 12 mm to eps0 = 0.02 in 1 step; layer factors 1 and 15 on
d = 12 mm with a 1-step ramp (seconds; the numbers are not the study's). Writes DIR/unseamed.nc, DIR/seam.nc,
DIR/layer_rigidity.nc and DIR/nonlinear_spacer.png (default DIR = results/nonlinear_spacer).
"""
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402


def former_corotational(cell, strain, steps, stabilize):
    """The unseamed curve of the former co-rotational contact solve (``newton_contact``: linearised
    contact, viscous stabilisation), as ``compress(geometry="nonlinear", stabilize=...)`` ran it
    before the large-motion engine took over (steps halved up to 4 times on failure)."""
    import homtex
    from homtex.analysis.corotational import Corotational
    from homtex.analysis.stepping import StepFailure, march
    from homtex.contact.compress import CompressionTest
    from homtex.contact.newton import newton_contact
    from homtex.output.datasets import curve_dataset

    test = CompressionTest.build(cell.frame, info=cell.info, groups=cell.groups)
    cs = test.solver(homtex.Contact(), solver="direct", tol=1e-10)
    cor = Corotational(cell.frame, cs.assembler)
    st = {"pu": None, "warm": None}
    rows = {"strain": [], "stress": [], "force": [], "newton_iterations": [], "stabilization_force": []}

    def solve(level):
        cs.set_plate(1, displacement=-level * test.H0)
        res, pu, it = newton_contact(cs, cor, plate_u=st["pu"], warm_keys=st["warm"], stabilize=stabilize)
        return res, pu, it

    status, detail = "ok", ""
    try:
        for step in march(solve, strain * np.arange(1, steps + 1) / steps, max_cuts=4):
            res, pu, it = step.result
            st.update(pu=pu, warm=res.extra["active_keys"])
            if step.target is None:
                continue
            F = float(res.extra["plate_force"][1])
            for k, v in (("strain", step.level), ("stress", F / test.area * 1e3), ("force", F),
                         ("newton_iterations", it), ("stabilization_force", res.extra["stabilization_force"])):
                rows[k].append(v)
    except StepFailure as err:
        status, detail = "failed", str(err.first or err)
    units = {"stress": "kPa", "force": "N", "newton_iterations": "1", "stabilization_force": "N"}
    ds = curve_dataset({k: ("strain", rows[k], units[k], k.replace("_", " ")) for k in units},
                       {"strain": (rows["strain"], "1", "compression strain")})
    ds.attrs.update(status=status, status_detail=detail, steps_done=len(rows["strain"]))
    return ds


def unseamed(cell, strain, steps, factors):
    import homtex

    curves, rows = [], []
    for geometry, c in [("linear", 0.0), ("engine", 0.0)] + [("nonlinear", f) for f in factors]:
        t = time.perf_counter()
        if geometry == "nonlinear":
            ds = former_corotational(cell, strain, steps, c)
        else:
            ds = homtex.compress(cell, strain=strain, steps=steps, geometry="nonlinear" if geometry == "engine" else
                                 "linear")
        sec = time.perf_counter() - t
        label = {"linear": "linear", "engine": "large-motion engine (barrier, PTC)"}.get(
            geometry, f"co-rotational, stabilise {c:g}")
        ratio = (ds.stabilization_force / np.maximum(ds.force, 1e-300)).values
        curves.append(ds[["stress", "newton_iterations"]].assign(stab_ratio=("strain", ratio)).expand_dims(model=[label]))
        rows.append((label, sec, status_text(ds), int(ds.attrs["steps_done"])))
        print(f"  {label:36s} {sec:6.1f} s  steps {ds.attrs['steps_done']:3d}  {status_text(ds)[:90]}", flush=True)
    out = xr.concat(curves, dim="model", join="outer")
    out["stress"].attrs.update(units="kPa", long_name="nominal compressive stress")
    out["newton_iterations"].attrs.update(units="1", long_name="Newton iterations of the step (0: linear)")
    out["stab_ratio"].attrs.update(units="1", long_name="largest stabilisation force on a node / top plate force")
    out["seconds"] = ("model", [r[1] for r in rows], {"units": "s", "long_name": "run time of the curve"})
    out["status"] = ("model", [r[2] for r in rows], {"long_name": "'ok' or why the curve ended"})
    out.attrs.update(experiment="unseamed compression, linear vs co-rotational beams", steps=int(steps))
    return out


def status_text(ds) -> str:
    """'ok', or 'failed: <why>' (curves and profiles carry attrs status and status_detail)."""
    st = str(ds.attrs.get("status", "ok"))
    return st if st == "ok" else f"{st}: {ds.attrs.get('status_detail', '')}"


def seam(cell, d, eps0, ramp_steps, stabilize, seconds, lin_steps=4):
    import homtex
    from homtex.errors import SolverError
    from homtex.geometry.seam import seam_cell
    from homtex.seams import SeamSolver, measure_profile

    fr, info = seam_cell(cell, seam_distance=d, prestrain=eps0)
    ss = SeamSolver(fr, info, geometry="nonlinear", stabilize=stabilize)
    t = time.perf_counter()
    status = "ok"
    try:
        ss.ramp(ramp_steps, max_cuts=2, time_limit=seconds)
    except SolverError as err:
        status = f"stopped: {err}"
    sec = time.perf_counter() - t
    alpha = float(ss.alpha)
    if ss.result is None:
        raise SystemExit(f"the co-rotational seam ramp failed at its first step: {status}")
    x, h_nl = measure_profile(fr, info, ss.result.u)
    reached = alpha * eps0
    print(f"  co-rotational ramp reached eps0 = {reached:.4f} ({alpha:.3f} of {eps0}) in {sec:.1f} s: {status[:120]}",
          flush=True)
    lin = homtex.seam_profile(cell, seam_distance=d, prestrain=reached, steps=lin_steps)
    ds = xr.Dataset(
        {"height": (("model", "x"), np.vstack([h_nl, lin.height.values]),
                    {"units": "mm", "long_name": "fabric height per wale bin"}),
         "seam_height": ("model", [float(h_nl[np.argmin(np.abs(x))]), float(lin.seam_height)], {"units": "mm"}),
         "cushion_height": ("model", [float(np.max(h_nl)), float(lin.cushion_height)], {"units": "mm"})},
        coords={"model": ["co-rotational", "linear"], "x": ("x", x, {"units": "mm", "long_name": "position across the seam"})})
    ds.attrs.update(experiment="seam cell, stitch pre-strain ramp", seam_distance_mm=float(info["seam_distance"]),
                    target_prestrain=eps0, reached_prestrain=reached, status=status, seconds=sec,
                    stabilize=stabilize, ramp_steps=int(ramp_steps), accepted_steps=len(ss.history))
    return ds


def layer_rigidity(d, eps0, factors, resolution=None, steps=4):
    import homtex

    rows = []
    for f in factors:
        cell = homtex.load_cell("spacer_20mm")
        if resolution is not None:
            cell = cell.replace(**{"resolution.elements_per_segment": resolution})
        E = cell.frame.E.copy()
        layer = np.zeros(len(E), dtype=bool)
        for g, m in cell.groups.items():
            if g != "pile":
                layer |= np.asarray(m, dtype=bool)
        E[layer] *= f
        cell._frame = cell.frame.with_(E=E)       # a what-if: same geometry, stiffer layer yarns
        ds = homtex.seam_profile(cell, seam_distance=d, prestrain=eps0, steps=steps)
        rows.append(ds.height.values)
        x = ds.x.values
        print(f"  layer E x{f:<4g}: seam {float(ds.seam_height):.2f} mm, mid-cushion "
              f"{float(ds.height.values[np.argmax(np.abs(x))]):.2f} mm, max {float(ds.cushion_height):.2f} mm "
              f"({status_text(ds)[:40]})", flush=True)
    out = xr.Dataset({"height": (("layer_factor", "x"), np.vstack(rows), {"units": "mm", "long_name": "fabric height"})},
                     coords={"layer_factor": ("layer_factor", np.asarray(factors, float),
                                              {"units": "1", "long_name": "factor on the surface layers' Young's modulus"}),
                             "x": ("x", x, {"units": "mm", "long_name": "position across the seam"})})
    out.attrs.update(experiment="seam dip against the layers' bending rigidity (linear beams)", prestrain=eps0,
                     seam_distance_mm=float(d))
    return out


def main(argv=None):
    import homtex

    p = parser(__file__, __doc__)
    p.add_argument("--strain", type=float, default=None, help="unseamed compression (default 0.3; --quick 0.01)")
    p.add_argument("--steps", type=int, default=None, help="unseamed load steps (default 60; --quick 1)")
    p.add_argument("--distance", type=float, default=24.0)
    p.add_argument("--prestrain", type=float, default=0.3)
    p.add_argument("--seam-seconds", type=float, default=240.0, help="time budget of the co-rotational seam ramp")
    p.add_argument("--plot-only", action="store_true", help="redraw the chart from DIR's netCDF files")
    a = p.parse_args(argv)
    out = setup(a)
    strain = a.strain or (0.01 if a.quick else 0.3)
    steps = a.steps or (1 if a.quick else 60)
    t0 = time.perf_counter()
    if a.plot_only:
        un, se, lr = (xr.load_dataset(out / f) for f in ("unseamed.nc", "seam.nc", "layer_rigidity.nc"))
    else:
        cell = homtex.load_cell("spacer_20mm")
        if a.quick:
            cell = cell.replace(**{"resolution.elements_per_segment": 1})
        print("1. unseamed compression", flush=True)
        un = unseamed(cell, strain, steps, (1e-6,) if a.quick else (1e-6, 1e-7))
        save_netcdf(un, out / "unseamed.nc")
        print("2. seam cell with co-rotational beams", flush=True)
        if a.quick:
            se = seam(cell, 12.0, 0.02, 1, 1e-7, 60.0, lin_steps=1)
        else:
            se = seam(cell, a.distance, a.prestrain, 40, 1e-7, a.seam_seconds)
        save_netcdf(se, out / "seam.nc")
        print("3. layer rigidity", flush=True)
        if a.quick:
            lr = layer_rigidity(12.0, a.prestrain, (1.0, 15.0), resolution=1, steps=1)
        else:
            lr = layer_rigidity(a.distance, a.prestrain, (1.0, 5.0, 15.0, 50.0))
        save_netcdf(lr, out / "layer_rigidity.nc")

    plt = pyplot()
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    for m in un.model.values:
        s = un.stress.sel(model=m)
        ax[0].plot(100 * un.strain, s, "o-" if m == "linear" else ".-", ms=3, label=f"{m} ({float(un.seconds.sel(model=m)):.0f} s)")
    ax[0].set(xlabel="compression (%)", ylabel="stress (kPa)", title="unseamed cell: linear vs co-rotational beams")
    ax[0].legend(fontsize=7)
    for m in se.model.values:
        ax[1].plot(se.x, se.height.sel(model=m), "o-", ms=3, label=m)
    ax[1].set(xlabel="x across the seam (mm)", ylabel="height (mm)",
              title=f"seam d = {se.attrs['seam_distance_mm']:.1f} mm, eps0 = {se.attrs['reached_prestrain']:.3f}")
    ax[1].legend(fontsize=8)
    for f in lr.layer_factor.values:
        ax[2].plot(lr.x, lr.height.sel(layer_factor=f), "o-", ms=3, label=f"layers E x{f:g}")
    ax[2].axhline(14.33, color="k", ls=":", lw=1, label="paper: cushion 14.33 mm")
    ax[2].set(xlabel="x across the seam (mm)", ylabel="height (mm)",
              title=f"linear seam cell, eps0 = {lr.attrs['prestrain']}: layer stiffness")
    ax[2].legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out / "nonlinear_spacer.png")
    print(f"wrote {out}/unseamed.nc, seam.nc, layer_rigidity.nc, nonlinear_spacer.png in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
