"""Benchmark: homtex's co-rotational engine against OpenSeesPy's corotational frame (issue 17).

Cases (same meshes, same load steps, Newton with the same absolute tolerance on the out-of-balance
force, NormUnbalance in OpenSees):

* Bathe and Bolourchi's 45-degree bend (R = 100, 1 x 1 section, E = 1e7, nu = 0, tip load 600 out
  of plane; Simo and Vu-Quoc: tip displacement about (-23.5, -13.4, 53.4)) with 8, 16 and 32
  elements, 10 load steps;
* a 3D frame of 10 224 elements: a square net of 72 x 72 crossing yarns (100 x 100 mm, r = 0.1 mm,
  E = 3000 MPa, nu = 0.3, edges clamped) under a point load at its centre (about 10 mm deflection,
  membrane action), 5 load steps.

The element is the same: homtex's exact Timoshenko beam, OpenSees' forceBeamColumn with an elastic
section with shear (``section Elastic ... alphaY alphaZ``, 3 Lobatto points: exact for end loads),
both with a corotational transformation; elasticBeamColumn (Euler-Bernoulli, no shear) is timed
too as OpenSees' fastest beam (its answer differs by the shear flexibility). Times are wall
seconds of the solve (homtex: ``solve_nonlinear``, pattern and symbolic analysis included, numba
compiled beforehand; OpenSees: from ``analysis`` to the last ``analyze``, the model built before),
median of ``--repeats`` runs. homtex also computes the inertia of every converged state.

Usage::

    python studies/benchmarks/bench_corotational.py [--quick] [--out DIR] [--repeats N]

Writes DIR/bench_corotational.nc and DIR/bench_corotational.png (default DIR =
results/bench_corotational) and copies the chart to docs/studies/. ``--quick``: the bend at 8/16
elements and a 24 x 24 net, one repeat (a smoke test, about a minute).
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


# ---------------------------------------------------------------------------------------------
# models
def bend_model(n: int):
    """Nodes, elements and section data of the 45-degree bend with n elements."""
    ph = np.arange(n + 1) * np.pi / 4 / n
    nodes = np.c_[100 * np.sin(ph), 100 * (1 - np.cos(ph)), np.zeros(n + 1)]
    els = np.c_[np.arange(n), np.arange(1, n + 1)]
    sec = dict(E=1e7, nu=0.0, A=1.0, I=1 / 12, J=0.1406)
    return dict(name=f"bend{n}", nodes=nodes, elements=els, sec=sec, clamped=[0], load_node=n,
                load=np.array([0, 0, 600.0, 0, 0, 0]), steps=10, vecxz=(0.0, 0.0, 1.0))


def net_model(nx: int, force: float = 0.2):
    """A square net of nx x nx nodes (crossing yarns), 100 mm wide, clamped edges, centre load."""
    xs = np.linspace(0, 100, nx)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    nodes = np.c_[X.ravel(), Y.ravel(), np.zeros(nx * nx)]
    idx = np.arange(nx * nx).reshape(nx, nx)
    els = np.r_[np.c_[idx[:-1].ravel(), idx[1:].ravel()], np.c_[idx[:, :-1].ravel(), idx[:, 1:].ravel()]]
    edge = np.zeros((nx, nx), bool)
    edge[0] = edge[-1] = edge[:, 0] = edge[:, -1] = True
    r = 0.1
    A = np.pi * r * r
    sec = dict(E=3000.0, nu=0.3, A=A, I=np.pi * r ** 4 / 4, J=np.pi * r ** 4 / 2)
    c = idx[nx // 2, nx // 2]
    return dict(name=f"net{nx}", nodes=nodes, elements=els, sec=sec, clamped=np.flatnonzero(edge.ravel()),
                load_node=int(c), load=np.array([0, 0, force, 0, 0, 0]), steps=5, vecxz=(0.0, 0.0, 1.0))


def homtex_frame(m):
    import homtex

    s = m["sec"]
    if m["name"].startswith("bend"):       # a circle of area 1 with the square's I and J
        r = 1 / np.sqrt(np.pi)
        return homtex.Frame(m["nodes"], m["elements"], radius=r, E=s["E"], nu=s["nu"],
                            bending_factor=s["I"] / (np.pi * r ** 4 / 4), torsion_factor=s["J"] / (np.pi * r ** 4 / 2))
    return homtex.Frame(m["nodes"], m["elements"], radius=np.sqrt(s["A"] / np.pi), E=s["E"], nu=s["nu"])


def run_homtex(m, atol: float, repeats: int):
    from homtex import solve_nonlinear

    fr = homtex_frame(m)
    fixed = {int(i): "all" for i in m["clamped"]}
    loads = {m["load_node"]: m["load"]}
    times, res = [], None
    warm = len(m["elements"]) < 1000          # one untimed run first (small cases: caches, first calls)
    for rep in range(repeats + warm):
        t0 = time.perf_counter()
        res = solve_nonlinear(fr, fixed, loads, steps=m["steps"], atol=atol, max_iter=50)
        if rep >= warm:
            times.append(time.perf_counter() - t0)
    its = res.path.iterations.values
    return dict(u=res.u[m["load_node"], :3], time=float(np.median(times)), iterations=float(its.sum()) / m["steps"],
                states=int(res.path.sizes["step"]), shear_k=float(fr.k[0]), stable=bool(res.stable))


def run_opensees(m, atol: float, repeats: int, element: str = "force", shear_k: float = 1.0):
    import openseespy.opensees as ops

    s = m["sec"]
    G = s["E"] / (2 * (1 + s["nu"]))
    times, u, its = [], None, 0
    warm = len(m["elements"]) < 1000
    for rep in range(repeats + warm):
        ops.wipe()
        ops.model("basic", "-ndm", 3, "-ndf", 6)
        for k, x in enumerate(m["nodes"]):
            ops.node(k, *map(float, x))
        for k in m["clamped"]:
            ops.fix(int(k), 1, 1, 1, 1, 1, 1)
        ops.geomTransf("Corotational", 1, *m["vecxz"])
        if element == "force":
            ops.section("Elastic", 1, s["E"], s["A"], s["I"], s["I"], G, s["J"], shear_k, shear_k)
            ops.beamIntegration("Lobatto", 1, 1, 3)
        for e, (i, j) in enumerate(m["elements"]):
            if element == "force":
                ops.element("forceBeamColumn", e + 1, int(i), int(j), 1, 1)
            else:
                ops.element("elasticBeamColumn", e + 1, int(i), int(j), s["A"], s["E"], G, s["J"], s["I"], s["I"], 1)
        ops.timeSeries("Linear", 1)
        ops.pattern("Plain", 1, 1)
        ops.load(int(m["load_node"]), *map(float, m["load"]))
        t0 = time.perf_counter()
        ops.system("SparseSYM" if len(m["elements"]) > 1000 else "ProfileSPD")
        ops.numberer("RCM")
        ops.constraints("Plain")
        ops.test("NormUnbalance", atol, 50, 0)
        ops.algorithm("Newton")
        ops.integrator("LoadControl", 1.0 / m["steps"])
        ops.analysis("Static")
        its = 0
        for _ in range(m["steps"]):
            if ops.analyze(1) != 0:
                raise RuntimeError(f"OpenSees did not converge on {m['name']}")
            its += ops.testIter()
        if rep >= warm:
            times.append(time.perf_counter() - t0)
        u = np.array([ops.nodeDisp(int(m["load_node"]), d) for d in (1, 2, 3)])
    ops.wipe()
    return dict(u=u, time=float(np.median(times)), iterations=its / m["steps"])


# ---------------------------------------------------------------------------------------------
def main(argv=None):
    import xarray as xr

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small cases, one repeat (smoke test)")
    ap.add_argument("--out", default=str(ROOT / "results" / "bench_corotational"))
    ap.add_argument("--repeats", type=int, default=None, help="repeats per solve (median; default 5, 3 for the net)")
    ap.add_argument("--no-docs", action="store_true", help="do not copy the chart to docs/studies")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    models = [bend_model(n) for n in ((8, 16) if a.quick else (8, 16, 32))] + [net_model(24 if a.quick else 72)]
    rep_small = a.repeats or (1 if a.quick else 5)
    rep_big = a.repeats or (1 if a.quick else 3)

    from homtex import solve_nonlinear

    solve_nonlinear(homtex_frame(bend_model(4)), {0: "all"}, {4: (0, 0, 600, 0, 0, 0)}, steps=2)   # compile
    if not a.quick:                                                                                 # parallel kernels
        solve_nonlinear(homtex_frame(net_model(64)), {0: "all", 4095: "all"}, {2080: (0, 0, 1e-3, 0, 0, 0)}, steps=1)
    load_before = os.getloadavg()[0]
    rows = []
    for m in models:
        atol = 1e-9 * float(np.linalg.norm(m["load"]))
        rep = rep_big if m["name"].startswith("net") else rep_small
        h = run_homtex(m, atol, rep)
        o = run_opensees(m, atol, rep, "force", h["shear_k"])
        e = run_opensees(m, atol, rep, "elastic")
        rows.append((m, h, o, e))
        print(f"{m['name']:>7}: homtex {h['time']:.4f} s ({h['iterations']:.2f} it/step), OpenSees force "
              f"{o['time']:.4f} s ({o['iterations']:.2f}), elastic {e['time']:.4f} s ({e['iterations']:.2f}); "
              f"speed-up x{o['time'] / h['time']:.2f} / x{e['time'] / h['time']:.2f}; |du| / |u| = "
              f"{np.linalg.norm(h['u'] - o['u']) / np.linalg.norm(o['u']):.2e}", flush=True)

    cases = [m["name"] for m, *_ in rows]
    solvers = ["homtex", "opensees_force", "opensees_elastic"]
    U = np.array([[r[1]["u"], r[2]["u"], r[3]["u"]] for r in rows])          # case, solver, xyz
    T = np.array([[r[1]["time"], r[2]["time"], r[3]["time"]] for r in rows])
    IT = np.array([[r[1]["iterations"], r[2]["iterations"], r[3]["iterations"]] for r in rows])
    diff = np.linalg.norm(U[:, 0] - U[:, 1], axis=1) / np.linalg.norm(U[:, 1], axis=1)
    ds = xr.Dataset(
        {"tip_displacement": (("case", "solver", "xyz"), U, {"units": "mm", "long_name": "displacement of the loaded node"}),
         "time": (("case", "solver"), T, {"units": "s", "long_name": "wall time per solve, median of repeats"}),
         "iterations_per_step": (("case", "solver"), IT, {"units": "1", "long_name": "Newton iterations per load step"}),
         "difference": ("case", diff, {"units": "1", "long_name": "|u_homtex - u_opensees_force| / |u_opensees_force| "
                                                                   "at the loaded node"}),
         "speedup": ("case", T[:, 1] / T[:, 0], {"units": "1", "long_name": "OpenSees forceBeamColumn time / homtex time"}),
         "speedup_elastic": ("case", T[:, 2] / T[:, 0], {"units": "1",
                                                          "long_name": "OpenSees elasticBeamColumn time / homtex time"}),
         "elements": ("case", [len(m["elements"]) for m, *_ in rows], {"units": "1", "long_name": "beam elements"}),
         "steps": ("case", [m["steps"] for m, *_ in rows], {"units": "1", "long_name": "load steps"})},
        coords={"case": cases, "solver": solvers, "xyz": ["x", "y", "z"]},
        attrs={"machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores (shared)",
               "load_average": f"{load_before:.2f} before, {os.getloadavg()[0]:.2f} after (other jobs on the machine)",
               "quick": int(a.quick), "tolerance": "NormUnbalance 1e-9 x |load| in both",
               "note": "homtex: exact Timoshenko beam, consistent co-rotational tangent, qdldl LDL^T, inertia per state; "
                       "OpenSees: forceBeamColumn (elastic section with shear, 3 Lobatto points) or elasticBeamColumn, "
                       "Corotational transformation, SparseSYM/ProfileSPD, RCM"})
    ds.to_netcdf(out / "bench_corotational.nc")
    png = chart(ds, out / "bench_corotational.png")
    if not a.no_docs and not a.quick:
        shutil.copy(png, ROOT / "docs" / "studies" / "bench_corotational.png")
    print(f"wrote {out / 'bench_corotational.nc'} and {png}")
    return ds


def chart(ds, path: Path) -> Path:
    """Accuracy against run time: the bend's tip error against the Richardson limit of the finest two
    meshes (each solver its own), and the net's homtex-OpenSees difference."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bends = [c for c in ds.case.values if str(c).startswith("bend")]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    for s, mk, lab in (("homtex", "o-", "homtex"), ("opensees_force", "s--", "OpenSees forceBeamColumn"),
                       ("opensees_elastic", "^:", "OpenSees elasticBeamColumn (no shear)")):
        u = ds.tip_displacement.sel(case=bends, solver=s).values
        ref = u[-1] + (u[-1] - u[-2]) / 3.0                   # O(h^2) Richardson limit of this solver
        err = np.linalg.norm(u - ref, axis=1)
        err = np.where(err > 0, err, np.nan)
        ax[0].loglog(ds.time.sel(case=bends, solver=s).values, err, mk, label=lab)
        for c, t, e in zip(bends, ds.time.sel(case=bends, solver=s).values, err):
            ax[0].annotate(str(c).replace("bend", ""), (t, e), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax[0].set_xlabel("wall time per solve, s")
    ax[0].set_ylabel("tip displacement error vs own h->0 limit, mm")
    ax[0].set_title("45-degree bend, 10 load steps (labels: elements)")
    ax[0].legend(fontsize=8)
    x = np.arange(len(ds.case))
    w = 0.27
    for k, (s, lab) in enumerate((("homtex", "homtex"), ("opensees_force", "OpenSees force"),
                                  ("opensees_elastic", "OpenSees elastic"))):
        ax[1].bar(x + (k - 1) * w, ds.time.sel(solver=s).values, w, label=lab)
    ax[1].set_yscale("log")
    ax[1].set_xticks(x, [f"{c}\n{int(n)} el." for c, n in zip(ds.case.values, ds.elements.values)], fontsize=8)
    ax[1].set_ylabel("wall time per solve, s")
    ax[1].set_title("run time (median), same steps and tolerance")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


if __name__ == "__main__":
    main()
