"""Contact active-set strategies (issue 4): the paper's removal iteration vs a primal-dual
active set, on the same problems; and what reusing the AMG hierarchy across contact
iterations saves.

Problems: :func:`homtex.contact.examples.beam_grid` — n x n crossing simply supported beams
with random gaps and random loads (some crossings pushed together, some pulled apart) — for
several n and seeds. For each problem and strategy ("pdas"; "removal" with fractions 0.25
and 0.5; augmented Lagrangian enforcement, direct solver) it records active-set iterations,
linear solves, wall time, whether it succeeded (a detected failure is recorded with its
reason, never as a result) and the largest displacement difference to pdas.

AMG reuse: pdas with ``solver="amg"`` with and without ``reuse_amg`` on the same problems:
hierarchy setups, setup and solve seconds, CG iterations.

Usage::

    python studies/verification/contact_strategies.py [--out DIR] [--quick | --full]

Default sizes run in about a minute here; ``--full`` adds 16x16 and 24x24 grids; ``--quick``:
the 3x3 grid, one seed (seconds). Writes ``DIR/contact_strategies.nc`` and
``DIR/contact_strategies.png`` (default DIR = results/contact_strategies).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

DEFAULT = ((3, 8), (5, 12), (8, 18), (12, 26))
FULL = DEFAULT + ((16, 34), (24, 50))
QUICK = ((3, 8),)
SEEDS = (0, 1, 2)
STRATS = (("pdas", 0.25), ("removal", 0.25), ("removal", 0.5))


def run(out: Path, sizes, seeds=SEEDS):
    import xarray as xr

    import homtex
    from homtex.contact import Contact
    from homtex.contact.examples import beam_grid
    from homtex.errors import SolverError

    out.mkdir(parents=True, exist_ok=True)
    S, P, NS = len(STRATS), len(sizes), len(seeds)
    iters = np.full((P, NS, S), np.nan)
    solves = np.full((P, NS, S), np.nan)
    secs = np.full((P, NS, S), np.nan)
    ok = np.zeros((P, NS, S), dtype=bool)
    du = np.full((P, NS, S), np.nan)
    status = np.empty((P, NS, S), dtype=object)
    n_el_arr = np.zeros(P, dtype=np.int64)
    cand = np.zeros((P, NS), dtype=np.int64)
    amg = {key: np.full((P, NS, 2), np.nan) for key in ("setups", "setup_seconds", "solve_seconds",
                                                         "cg_iterations", "amg_seconds")}
    for i, (n, n_el) in enumerate(sizes):
        for j, seed in enumerate(seeds):
            fr, fixed, loads = beam_grid(n, n_el, seed=seed)
            n_el_arr[i] = fr.n_elements
            u_ref = None
            for q, (strategy, frac) in enumerate(STRATS):
                t0 = time.perf_counter()
                try:
                    res = homtex.solve_static(fr, fixed, loads, solver="direct",
                                              contact=Contact(strategy=strategy, removal_fraction=frac))
                except SolverError as err:
                    status[i, j, q] = str(err).splitlines()[0][:200]
                    continue
                secs[i, j, q] = time.perf_counter() - t0
                ok[i, j, q] = True
                status[i, j, q] = "ok"
                iters[i, j, q] = res.extra["contact_iterations"]
                solves[i, j, q] = res.extra["linear"]["linear_solves"]
                cand[i, j] = len(res.contacts.active) + len(res.contacts.plate_active)
                if u_ref is None:
                    u_ref = res.u
                du[i, j, q] = float(np.abs(res.u - u_ref).max())
            for r_, reuse in enumerate((False, True)):
                t0 = time.perf_counter()
                try:
                    res = homtex.solve_static(fr, fixed, loads, solver="amg", tol=1e-10,
                                              contact=Contact(reuse_amg=reuse))
                except SolverError:
                    continue
                amg["amg_seconds"][i, j, r_] = time.perf_counter() - t0
                lin = res.extra["linear"]
                for key in ("setups", "setup_seconds", "solve_seconds", "cg_iterations"):
                    amg[key][i, j, r_] = lin[key]
        with np.errstate(all="ignore"):
            print(f"n = {n} ({fr.n_elements} elements): iterations {np.nanmean(iters[i], axis=0).round(1).tolist()}, "
                  f"ok {ok[i].sum(axis=0).tolist()}/{NS}; AMG seconds (fresh, reuse) "
                  f"{np.nanmean(amg['amg_seconds'][i], axis=0).round(3).tolist()}", flush=True)
    names = [f"{s} {f:.2f}" if s == "removal" else s for s, f in STRATS]
    dims = ("problem", "seed", "strategy")
    ds = xr.Dataset(
        {"iterations": (dims, iters, {"units": "1", "long_name": "active-set iterations (linear solves with a new active set)"}),
         "linear_solves": (dims, solves, {"units": "1", "long_name": "linear solves incl. multiplier updates"}),
         "seconds": (dims, secs, {"units": "s", "long_name": "wall time of the contact solve (direct solver)"}),
         "succeeded": (dims, ok, {"units": "1", "long_name": "solve succeeded (else a detected failure)"}),
         "u_difference": (dims, du, {"units": "mm", "long_name": "max |u - u_pdas|"}),
         "status": (dims, status.astype(str), {"units": "1", "long_name": "'ok' or the detected failure"}),
         "candidates": (("problem", "seed"), cand, {"units": "1", "long_name": "contact candidates"}),
         **{f"amg_{k}": (("problem", "seed", "reuse"), v, {"units": {"setups": "1", "cg_iterations": "1"}.get(k, "s"),
                                                           "long_name": f"pdas + AMG-CG: {k.replace('_', ' ')}"})
            for k, v in amg.items()}},
        coords={"problem": ("problem", np.arange(P), {"units": "1", "long_name": "beam grid n x n"}),
                "n_beams": ("problem", np.array([s[0] for s in sizes]), {"units": "1", "long_name": "beams per direction"}),
                "n_elements": ("problem", n_el_arr, {"units": "1", "long_name": "beam elements"}),
                "seed": ("seed", np.array(seeds), {"units": "1", "long_name": "random seed of gaps and loads"}),
                "strategy": ("strategy", np.array(names), {"units": "1", "long_name": "active-set strategy"}),
                "reuse": ("reuse", np.array([0, 1]), {"units": "1", "long_name": "AMG hierarchy reused across contact iterations"})},
        attrs={"problem_family": "homtex.contact.examples.beam_grid", "enforcement": "augmented"})
    path = save_netcdf(ds, out / "contact_strategies.nc")
    chart(ds, path.with_suffix(".png"))
    return path


def chart(ds, path):
    import warnings

    plt = pyplot()

    warnings.simplefilter("ignore", RuntimeWarning)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    ne = ds["n_elements"].values
    for q, s in enumerate(ds["strategy"].values):
        it = ds["iterations"].values[:, :, q]
        ok = ds["succeeded"].values[:, :, q]
        ax[0].plot(ne, np.nanmean(it, axis=1), "o-", label=f"{s} (failed {int((~ok).sum())}/{ok.size})")
        bad = ~ok.all(axis=1)
        if bad.any():
            ax[0].plot(ne[bad], np.zeros(bad.sum()), "x", color=ax[0].lines[-1].get_color(), ms=9)
    ax[0].set_xscale("log")
    ax[0].set_xlabel("beam elements")
    ax[0].set_ylabel("active-set iterations (mean over seeds)")
    ax[0].set_title("removal vs primal-dual active set (x: detected failure)")
    ax[0].legend(fontsize=8)
    for r_, lab in enumerate(("fresh hierarchy each iteration", "reused hierarchy")):
        ax[1].plot(ne, np.nanmean(ds["amg_amg_seconds"].values[:, :, r_], axis=1), "o-", label=f"total s, {lab}")
        ax[1].plot(ne, np.nanmean(ds["amg_setup_seconds"].values[:, :, r_], axis=1), "s--", label=f"setup s, {lab}")
    ax[1].set_xscale("log")
    ax[1].set_yscale("log")
    ax[1].set_xlabel("beam elements")
    ax[1].set_ylabel("seconds (mean over seeds)")
    ax[1].set_title("pdas + AMG-CG: reusing the hierarchy")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--full", action="store_true", help="larger grids (up to 24 x 24 beams)")
    a = p.parse_args(argv)
    out = setup(a)
    if a.quick:
        path = run(out, QUICK, seeds=(0,))
    else:
        path = run(out, FULL if a.full else DEFAULT)
    print(f"wrote {path} and {path.with_suffix('.png')}")


if __name__ == "__main__":
    main()
