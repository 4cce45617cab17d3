"""Where the contact methods fail (issue 4): penalty, removal fraction, load step, slenderness.

Every run either succeeds (its error against a reference is recorded) or stops with a
*detected* failure, classified from its message; failures are never recorded as results.

Sweeps
------
* penalty: crossing beams pressed together (hand solution: springs in series), penalty from
  1e-4 to 1e8 x the default (mean translational stiffness diagonal), enforcement "penalty"
  and "augmented", solver "direct" and "amg" (CG). Error of the contact force.
* removal fraction: the paper's removal iteration on n x n beam grids
  (:func:`homtex.contact.examples.beam_grid`), fraction 5 %..100 %, against pdas.
* load step: ``compress`` of a 2-periodic test cell to 30 % strain in 1..40 steps, both
  strategies; error of the final force against the 80-step pdas curve.
* slenderness: crossing beams with span / radius from 10 to 1e5 (augmented; pdas and removal
  with AMG-CG, pdas with Jacobi-CG capped at 3000 iterations); error against the hand solution.

Failure classes: 0 ok, 1 penetration above tolerance (penalty too soft / removal dropped a
needed contact), 2 cycling active set, 3 linear solver failure (CG stagnation, singular),
4 augmented Lagrangian gaps not closing, 5 other detected failure.

Usage::

    python studies/verification/contact_stability.py [--out DIR] [--quick | --full]

``--full``: more grids and seeds; ``--quick``: two penalties, one 3x3 grid, two removal
fractions, 1 and 2 load steps to 10 % (reference 4), one slenderness (seconds). Writes
``DIR/contact_stability.nc`` and ``DIR/contact_stability.png`` (default DIR =
results/contact_stability).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

CLASSES = ("ok", "penetration", "cycling", "linear solver", "gaps not closing", "other")


def classify(msg: str) -> int:
    m = msg.lower()
    if "cycles" in m:
        return 2
    if "gaps did not close" in m:
        return 4
    if "penetrat" in m or "penalty too soft" in m:
        return 1
    if "did not converge" in m or "singular" in m or "non-finite" in m or "stagnat" in m or "cg" in m:
        return 3
    return 5


def crossing(slender=200.0, r=0.5, E=1000.0, nu=0.3, g0=0.01, n_el=4):
    import homtex

    L = slender * r
    xs = np.linspace(-L / 2, L / 2, n_el + 1)
    nodes = np.vstack([np.column_stack([xs, 0 * xs, 0 * xs + 2 * r + g0]), np.column_stack([0 * xs, xs, 0 * xs])])
    el = np.column_stack([np.arange(n_el), np.arange(1, n_el + 1)])
    fr = homtex.Frame(nodes, np.vstack([el, el + n_el + 1]), radius=r, E=np.r_[np.full(n_el, E), np.full(n_el, 3 * E)],
                      nu=nu, yarn=np.r_[np.zeros(n_el, int), np.ones(n_el, int)])
    fixed = {0: [0, 1, 2, 3], n_el: [0, 1, 2, 3], n_el + 1: [0, 1, 2, 4], 2 * n_el + 1: [0, 1, 2, 4]}

    def flex(EE):
        A, I = np.pi * r ** 2, np.pi * r ** 4 / 4
        G, k = EE / (2 * (1 + nu)), 6 * (1 + nu) / (7 + 6 * nu)
        return L ** 3 / (48 * EE * I) + L / (4 * k * G * A)

    fA, fB = flex(E), flex(3 * E)
    P = (g0 + 0.5 * r) / fA                # free overlap would be half a radius: presses hard
    F = (P * fA - g0) / (fA + fB)
    return fr, fixed, {n_el // 2: (0, 0, -P, 0, 0, 0)}, F


def periodic_cell(a=4.0, r=0.1, E=1000.0, nu=0.3):
    import homtex

    nx = 8
    xn = np.column_stack([np.arange(nx) * a / nx, np.zeros(nx), np.zeros(nx)])
    top = np.array([[0.0, 0.0, 2 * r], [0.0, a / 2, 2 * r]])
    bot = np.array([[a / 2, 0.0, -2 * r], [a / 2, a / 2, -2 * r]])
    el = [(i, (i + 1) % nx) for i in range(nx)] + [(nx, nx + 1), (nx + 1, nx), (nx + 2, nx + 3), (nx + 3, nx + 2)]
    img = [(0, 0)] * (nx - 1) + [(1, 0)] + [(0, 0), (0, 1), (0, 0), (0, 1)]
    return homtex.Frame(np.vstack([xn, top, bot]), np.array(el), radius=r, E=E, nu=nu,
                        yarn=[0] * nx + [1, 1, 2, 2], periods=[[a, 0, 0], [0, a, 0]], images=np.array(img))


def _attempt(fn):
    from homtex.errors import SolverError

    t0 = time.perf_counter()
    try:
        out = fn()
    except SolverError as err:
        return None, classify(str(err)), str(err).splitlines()[0][:200], time.perf_counter() - t0
    return out, 0, "ok", time.perf_counter() - t0


def run(out: Path, full: bool = False, quick: bool = False):
    import xarray as xr

    import homtex
    from homtex.contact import Contact
    from homtex.contact.examples import beam_grid

    out.mkdir(parents=True, exist_ok=True)
    data, coords = {}, {}

    # ---- penalty sweep
    factors = 10.0 ** (np.array([-6, 0]) if quick else np.arange(-6, 9))
    combos = [("penalty", "direct"), ("penalty", "amg"), ("augmented", "direct"), ("augmented", "amg")]
    fr, fixed, loads, F_hand = crossing()
    from homtex.contact.solver import ContactSolver

    k0 = ContactSolver(fr, fixed, loads, Contact()).k
    code = np.zeros((len(factors), len(combos)), dtype=np.int64)
    err = np.full(code.shape, np.nan)
    its = np.full(code.shape, np.nan)
    msgs = np.empty(code.shape, dtype=object)
    for i, f in enumerate(factors):
        for j, (enf, solver) in enumerate(combos):
            res, c, msg, _ = _attempt(lambda: homtex.solve_static(
                fr, fixed, loads, solver=solver, contact=Contact(enforcement=enf, penalty=f * k0)))
            code[i, j], msgs[i, j] = c, msg
            if res is not None:
                err[i, j] = abs(res.contacts.force.sum() - F_hand) / F_hand
                its[i, j] = res.extra["linear"]["linear_solves"]
    combo_names = [f"{e}/{s}" for e, s in combos]
    coords["penalty_factor"] = ("penalty_factor", factors, {"units": "1", "long_name": "penalty / default penalty"})
    coords["method"] = ("method", np.array(combo_names), {"units": "1", "long_name": "enforcement / linear solver"})
    data["penalty_failure"] = (("penalty_factor", "method"), code, {"units": "1", "long_name": "failure class (0 ok; see attrs)"})
    data["penalty_error"] = (("penalty_factor", "method"), err, {"units": "1", "long_name": "relative contact force error vs springs in series"})
    data["penalty_linear_solves"] = (("penalty_factor", "method"), its, {"units": "1", "long_name": "linear solves"})
    data["penalty_message"] = (("penalty_factor", "method"), msgs.astype(str), {"units": "1", "long_name": "detected failure"})
    print("penalty sweep done", flush=True)

    # ---- removal fraction sweep
    fractions = np.array([0.25, 1.0] if quick else [0.05, 0.1, 0.25, 0.5, 0.75, 1.0])
    if quick:
        grids, seeds = ((3, 8),), range(1)
    else:
        grids = ((5, 12), (8, 18), (12, 26)) if full else ((5, 12), (8, 18))
        seeds = range(6 if full else 4)
    rcode = np.zeros((len(grids), len(seeds), len(fractions)), dtype=np.int64)
    rits = np.full(rcode.shape, np.nan)
    rerr = np.full(rcode.shape, np.nan)
    pits = np.full((len(grids), len(seeds)), np.nan)
    for g, (n, n_el) in enumerate(grids):
        for s in seeds:
            fr_g, fx, ld = beam_grid(n, n_el, seed=s)
            ref = homtex.solve_static(fr_g, fx, ld, solver="direct", contact=Contact())
            pits[g, s] = ref.extra["contact_iterations"]
            for q, fr_ in enumerate(fractions):
                res, c, msg, _ = _attempt(lambda: homtex.solve_static(
                    fr_g, fx, ld, solver="direct", contact=Contact(strategy="removal", removal_fraction=fr_)))
                rcode[g, s, q] = c
                if res is not None:
                    rits[g, s, q] = res.extra["contact_iterations"]
                    rerr[g, s, q] = np.abs(res.u - ref.u).max() / np.abs(ref.u).max()
    coords["removal_fraction"] = ("removal_fraction", fractions, {"units": "1", "long_name": "share of attracting contacts removed per iteration"})
    coords["grid"] = ("grid", np.array([n for n, _ in grids]), {"units": "1", "long_name": "beam grid n x n"})
    coords["seed"] = ("seed", np.array(list(seeds)), {"units": "1", "long_name": "random seed"})
    data["removal_failure"] = (("grid", "seed", "removal_fraction"), rcode, {"units": "1", "long_name": "failure class of removal"})
    data["removal_iterations"] = (("grid", "seed", "removal_fraction"), rits, {"units": "1", "long_name": "removal iterations"})
    data["removal_error"] = (("grid", "seed", "removal_fraction"), rerr, {"units": "1", "long_name": "max |u - u_pdas| / max |u_pdas|"})
    data["pdas_iterations"] = (("grid", "seed"), pits, {"units": "1", "long_name": "pdas iterations on the same problem"})
    print("removal sweep done", flush=True)

    # ---- load step sweep (compress)
    cell = periodic_cell()
    steps = np.array([1, 2] if quick else [1, 2, 5, 10, 20, 40])
    ref_steps, final = (4, 0.1) if quick else (80, 0.3)
    strats = ("pdas", "removal")
    ref_ds = homtex.compress(cell, strain=final, steps=ref_steps, geometry="linear")
    F_ref = float(ref_ds.force[-1]) if ref_ds.attrs["status"] == "ok" else np.nan
    scode = np.zeros((len(steps), len(strats)), dtype=np.int64)
    serr = np.full(scode.shape, np.nan)
    sdone = np.zeros(scode.shape)
    for i, ns in enumerate(steps):
        for j, st in enumerate(strats):
            ds = homtex.compress(cell, strain=final, steps=int(ns), contact=Contact(strategy=st), geometry="linear")
            status = ds.attrs["status"]
            sdone[i, j] = ds.sizes["strain"] / ns
            if status == "ok":
                serr[i, j] = abs(float(ds.force[-1]) - F_ref) / F_ref
            else:
                scode[i, j] = classify(ds.attrs.get("status_detail", "") or str(status))
    coords["steps"] = ("steps", steps, {"units": "1", "long_name": f"load steps to {100 * final:g} % compression"})
    coords["strategy"] = ("strategy", np.array(strats), {"units": "1", "long_name": "active-set strategy"})
    data["step_failure"] = (("steps", "strategy"), scode, {"units": "1", "long_name": "failure class of compress"})
    data["step_error"] = (("steps", "strategy"), serr, {"units": "1", "long_name": f"relative error of the final force vs {ref_steps} steps"})
    data["step_completed"] = (("steps", "strategy"), sdone, {"units": "1", "long_name": "share of steps completed"})
    print("load step sweep done", flush=True)

    # ---- slenderness sweep
    slender = 10.0 ** (np.array([3.0]) if quick else np.arange(1, 5.01, 0.5))
    sl_strats = ("pdas", "removal", "pdas/jacobi-cg")
    lcode = np.zeros((len(slender), len(sl_strats)), dtype=np.int64)
    lerr = np.full(lcode.shape, np.nan)
    lcg = np.full(lcode.shape, np.nan)
    for i, sl in enumerate(slender):
        fr_s, fx, ld, F_s = crossing(slender=sl, n_el=16 if quick else 64)
        for j, st in enumerate(sl_strats):
            solver = "cg" if st.endswith("jacobi-cg") else "amg"
            res, c, msg, _ = _attempt(lambda: homtex.solve_static(fr_s, fx, ld, solver=solver, tol=1e-10, maxiter=3000,
                                                                 contact=Contact(strategy=st.split("/")[0])))
            lcode[i, j] = c
            if res is not None:
                lerr[i, j] = abs(res.contacts.force.sum() - F_s) / F_s
                lcg[i, j] = res.extra["linear"]["cg_iterations"]
    coords["slender_method"] = ("slender_method", np.array(sl_strats), {"units": "1", "long_name": "strategy / linear solver (AMG-CG unless named)"})
    coords["slenderness"] = ("slenderness", slender, {"units": "1", "long_name": "beam span / radius"})
    data["slender_failure"] = (("slenderness", "slender_method"), lcode, {"units": "1", "long_name": "failure class"})
    data["slender_error"] = (("slenderness", "slender_method"), lerr, {"units": "1", "long_name": "relative contact force error vs springs in series"})
    data["slender_cg_iterations"] = (("slenderness", "slender_method"), lcg, {"units": "1", "long_name": "total CG iterations"})
    print("slenderness sweep done", flush=True)

    ds = xr.Dataset(data, coords=coords, attrs={
        "failure_classes": "; ".join(f"{i} {c}" for i, c in enumerate(CLASSES)),
        "default_penalty_N_per_mm": k0, "reference_steps": ref_steps, "final_strain": final, "quick": int(quick)})
    path = save_netcdf(ds, out / "contact_stability.nc")
    chart(ds, path.with_suffix(".png"))
    return path


def chart(ds, path):
    import warnings

    plt = pyplot()

    warnings.simplefilter("ignore", RuntimeWarning)
    marks = {1: ("v", "penetration"), 2: ("o", "cycling"), 3: ("s", "linear solver"), 4: ("D", "gaps not closing"),
             5: ("*", "other")}
    fig, ax = plt.subplots(2, 2, figsize=(11, 8))

    def fails(a, x, codes, y0, color):
        for c, (m, lab) in marks.items():
            sel = codes == c
            if sel.any():
                a.plot(x[sel], np.full(sel.sum(), y0), m, color=color, mfc="none", ms=8)

    a = ax[0, 0]
    x = ds["penalty_factor"].values
    for j, m in enumerate(ds["method"].values):
        line, = a.loglog(x, ds["penalty_error"].values[:, j], ".-", label=str(m))
        fails(a, x, ds["penalty_failure"].values[:, j], 1e-15 * 3 ** j, line.get_color())
    a.set_xlabel("penalty / default")
    a.set_ylabel("relative force error")
    a.set_title("penalty sweep (open marks: detected failures)")
    a.legend(fontsize=7)

    a = ax[0, 1]
    fr = ds["removal_fraction"].values
    for g, n in enumerate(ds["grid"].values):
        codes = ds["removal_failure"].values[g]
        rate = (codes != 0).mean(axis=0)
        a.plot(fr, rate, "o-", label=f"{n}x{n} grid: failure rate")
        a.plot(fr, np.nanmean(ds["removal_iterations"].values[g], axis=0) / 50.0, "s--",
               label=f"{n}x{n}: iterations / 50 (pdas {np.nanmean(ds['pdas_iterations'].values[g]):.1f})")
    a.set_xlabel("removal fraction")
    a.set_title("removal iteration: dropped needed contacts (penetration)")
    a.legend(fontsize=7)

    a = ax[1, 0]
    st = ds["steps"].values
    for j, s in enumerate(ds["strategy"].values):
        line, = a.loglog(st, ds["step_error"].values[:, j], "o-", label=f"{s}")
        fails(a, st, ds["step_failure"].values[:, j], 1e-12, line.get_color())
    a.set_xlabel(f"load steps to {100 * ds.attrs['final_strain']:g} % compression")
    a.set_ylabel(f"final force error vs {ds.attrs['reference_steps']} steps")
    a.set_title("load step size (compress, 2-periodic cell)")
    a.legend(fontsize=7)

    a = ax[1, 1]
    sl = ds["slenderness"].values
    for j, s in enumerate(ds["slender_method"].values):
        line, = a.loglog(sl, ds["slender_error"].values[:, j], "o-", label=f"{s}: force error")
        fails(a, sl, ds["slender_failure"].values[:, j], 1e-15 * 10 ** j, line.get_color())
    a.set_xlabel("span / radius")
    a.set_ylabel("relative force error")
    a.set_title("slenderness")
    a.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path)


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--full", action="store_true", help="more grids and seeds")
    a = p.parse_args(argv)
    out = setup(a)
    path = run(out, full=a.full, quick=a.quick)
    print(f"wrote {path} and {path.with_suffix('.png')}")


if __name__ == "__main__":
    main()
