"""A hunt for silent wrong answers in path following: problems with closed-form or converged
answers, run over slenderness 1e2-1e5, planar and 3D (round rods: double eigenvalues), load,
displacement and arc-length control, step counts 1-400 and with or without an imperfection. Every
run is classed as

* ``right``: status "ok" and within the tolerance of the reference,
* ``flagged``: complete, status "flagged" (the path snapped, or a check failed: the user is told),
* ``raised``: a SolverError / InputError naming the cause,
* ``silently wrong``: status "ok" and outside the tolerance (the failure this study hunts).

Families (reference; tolerance on the compared quantity):

* ``column``: cantilever column, dead axial load 1.5 P_cr (the elastica; tip deflection / L,
  5e-3); an imperfection is a lateral load of 1e-4 P_cr.
* ``shortening``: pinned-pinned column shortened by 20 % under displacement control (the elastica's
  end force / P_cr, 5e-3); an imperfection is a lateral load of 1e-4 P_cr at mid-span.
* ``moment``: end moment 2 pi EI / L rolling a cantilever into a circle (tip at the root, 1e-3 L).
* ``string``: clamped-clamped rod under a central transverse load that a string carries at a slope
  of 0.1 (a stiffening path: the flat start's tangent sees bending only; the state of a 200-step
  run, 1e-3); an imperfection is an axial load of 1e-3 of the transverse one.
* ``arch``: clamped shallow arch (rise 2 % of the span) under a crown load far above its limit load,
  arc length (the first critical load, a limit point or an asymmetric bifurcation before it, from a
  converged run with a small reference load and the same imperfection ratio, 2 %).
* ``lee``: Lee's frame by arc length driven by the load node's prescribed motion (the final state of
  a converged run, 1e-3 of the frame).

Usage::

    python studies/verification/path_campaign.py [--out DIR] [--quick]

Default: 416 runs (about 15 minutes on the 2-core machine); ``--quick``: 13. Writes
``DIR/path_campaign.nc``, ``DIR/path_campaign.png`` and ``DIR/path_campaign.md`` (the table).
"""
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

E, NU, L = 2000.0, 0.3, 100.0
OUTCOMES = ("right", "flagged", "raised", "silently wrong")


def _planar(n, fixed):
    out = {k: [2, 3, 4] for k in range(n)}
    for k, v in fixed.items():
        out[k] = "all" if v == "all" else ({**{d: 0.0 for d in (2, 3, 4)}, **v} if isinstance(v, dict)
                                             else sorted(set(out[k]) | set(v)))
    return out


def _line(n_el, r):
    import homtex

    nodes = np.c_[np.linspace(0, L, n_el + 1), np.zeros(n_el + 1), np.zeros(n_el + 1)]
    return homtex.Frame(nodes, np.c_[np.arange(n_el), np.arange(1, n_el + 1)], radius=r, E=E, nu=NU)


def column(slender, plane, steps, imperfect):
    from scipy.optimize import brentq
    from scipy.special import ellipk

    from homtex import solve_nonlinear

    r, n_el = L / slender, 30
    fr = _line(n_el, r)
    Pcr = np.pi ** 2 * E * np.pi * r ** 4 / 4 / (4 * L ** 2)
    fixed = _planar(n_el + 1, {0: "all"}) if plane else {0: "all"}
    res = solve_nonlinear(fr, fixed, {n_el: (-1.5 * Pcr, 1e-4 * Pcr if imperfect else 0.0, 0, 0, 0, 0)}, steps=steps)
    m = brentq(lambda m: (2 * ellipk(m) / np.pi) ** 2 - 1.5, 1e-9, 0.999)
    got = np.hypot(res.x[n_el, 1], res.x[n_el, 2]) / L
    return res, got, 2 * np.sqrt(m) / ellipk(m), 5e-3


def shortening(slender, plane, steps, imperfect):
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipk

    from homtex import solve_nonlinear

    r, n_el = L / slender, 40
    fr = _line(n_el, r)
    Pcr = np.pi ** 2 * E * np.pi * r ** 4 / 4 / L ** 2
    fixed = (_planar(n_el + 1, {0: [0, 1], n_el: {0: -0.2 * L, 1: 0.0}}) if plane else
             {0: [0, 1, 2, 3], n_el: {0: -0.2 * L, 1: 0.0, 2: 0.0}})
    loads = {n_el // 2: (0, 1e-4 * Pcr, 0, 0, 0, 0)} if imperfect else None
    res = solve_nonlinear(fr, fixed, loads, control="displacement", steps=steps)
    m = brentq(lambda m: 2 - 2 * ellipe(m) / ellipk(m) - 0.2, 1e-9, 0.9999)
    return res, -res.reactions[n_el, 0] / Pcr, (2 * ellipk(m) / np.pi) ** 2, 5e-3 * (2 * ellipk(m) / np.pi) ** 2


def moment(slender, plane, steps, imperfect):
    from homtex import solve_nonlinear

    r, n_el = L / slender, 32
    fr = _line(n_el, r)
    EI = E * np.pi * r ** 4 / 4
    fixed = _planar(n_el + 1, {0: "all"}) if plane else {0: "all"}
    load = (0, 1e-6 * EI / L ** 2 if imperfect else 0.0, 0, 0, 0, 2 * np.pi * EI / L)
    res = solve_nonlinear(fr, fixed, {n_el: load}, steps=steps)
    return res, float(np.linalg.norm(res.x[n_el] - res.x[0])) / L, 0.0, 1e-3


_ARCH = {}


def arch(slender, plane, steps, imperfect):
    import homtex
    from homtex import solve_nonlinear

    span, n = 100.0, 32
    r = span / slender
    x = np.linspace(0, span, n + 1)
    z = 0.02 * span * np.sin(np.pi * x / span)
    nodes = np.c_[x, z, np.zeros_like(x)]
    fr = homtex.Frame(nodes, np.c_[np.arange(n), np.arange(1, n + 1)], radius=r, E=E, nu=NU)
    fixed = _planar(n + 1, {0: "all", n: "all"}) if plane else {0: "all", n: "all"}
    EI = E * np.pi * r ** 4 / 4
    scale = 0.0402 * EI / (E * np.pi * 0.5 ** 4 / 4)   # a load scale: the r = 0.5 arch's limit load times EI ratio
    # the first critical load: a limit point, or an asymmetric bifurcation before it (a thin arch);
    # an imperfection turns the bifurcation into a lower limit point, so each has its own reference;
    # a thick arch (rise about its thickness) has none: then none may be recorded
    key = (slender, plane, imperfect)
    lateral = 0.01 * scale if imperfect else 0.0
    if key not in _ARCH:
        ref = solve_nonlinear(fr, fixed, {n // 2: (0.04 * lateral, -5.0 * scale, 0, 0, 0, 0)},  # the same ratio
                              control="arclength", steps=800)
        crit = float(ref.path.attrs["critical_load_factor"])
        _ARCH[key] = 5.0 * scale * crit if np.isfinite(crit) else 0.0
    P = 125.0 * scale
    res = solve_nonlinear(fr, fixed, {n // 2: (lateral, -P, 0, 0, 0, 0)}, control="arclength",
                          steps=steps)
    crit = float(res.path.attrs["critical_load_factor"])
    got = P * crit if np.isfinite(crit) else 0.0
    return res, got, _ARCH[key], 0.02 * _ARCH[key]


_LEE = {}


def lee(slender, plane, steps, imperfect):
    import homtex
    from homtex import solve_nonlinear

    n = 10
    col = np.c_[np.zeros(n + 1), np.linspace(0, 120, n + 1), np.zeros(n + 1)]
    beam = np.c_[np.linspace(0, 120, n + 1)[1:], np.full(n, 120.0), np.zeros(n)]
    r = np.sqrt(6 / np.pi)
    fr = homtex.Frame(np.r_[col, beam], np.c_[np.arange(2 * n), np.arange(1, 2 * n + 1)], radius=r, E=720.0,
                      nu=0.3, bending_factor=2 / (np.pi * r ** 4 / 4))
    load = n + n // 5
    fixed = {k: [2, 3, 4] for k in range(2 * n + 1)} | {0: [0, 1, 2, 3, 4], 2 * n: [0, 1, 2, 3, 4]}
    fixed[load] = {1: -70.0, 2: 0.0, 3: 0.0, 4: 0.0}
    if "ref" not in _LEE:
        _LEE["ref"] = solve_nonlinear(fr, fixed, None, control="arclength", steps=400, tol=1e-11).x
    loads = {n // 2: (1e-3, 0, 0, 0, 0, 0)} if imperfect else None
    res = solve_nonlinear(fr, fixed, loads, control="arclength", steps=max(steps, 30))
    return res, float(np.abs(res.x - _LEE["ref"]).max()) / 120.0, 0.0, 1e-3 if not imperfect else 2e-2


_STRING = {}


def string(slender, plane, steps, imperfect):
    from homtex import solve_nonlinear

    n_el, a = 40, L / 2
    r = L / slender
    fr = _line(n_el, r)
    t = 0.1                                             # the string's slope w / a
    F = 2 * E * np.pi * r ** 2 * (np.sqrt(1 + t * t) - 1) * t / np.sqrt(1 + t * t)
    fixed = _planar(n_el + 1, {0: "all", n_el: "all"}) if plane else {0: "all", n_el: "all"}
    loads = {n_el // 2: (1e-3 * F if imperfect else 0.0, F, 0, 0, 0, 0)}
    key = (slender, plane, imperfect)
    if key not in _STRING:
        _STRING[key] = float(solve_nonlinear(fr, fixed, loads, steps=200).u[n_el // 2, 1]) / a
    res = solve_nonlinear(fr, fixed, loads, steps=steps)
    return res, float(res.u[n_el // 2, 1]) / a, _STRING[key], 1e-3 * abs(_STRING[key])


FAMILIES = {"string": string, "column": column, "shortening": shortening, "moment": moment, "arch": arch, "lee": lee}


def classify(run):
    """(outcome, got, reference, status detail) of one run."""
    from homtex.errors import InputError, SolverError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res, got, ref, tol = run()
    except (SolverError, InputError) as err:
        return "raised", np.nan, np.nan, str(err)[:200]
    status = res.path.attrs["status"]
    detail = res.path.attrs.get("status_detail", "")
    if res.load_factor < 1.0 - 1e-9 and status == "ok":
        return "silently wrong", got, ref, "stopped short of the load"
    if status != "ok":
        return "flagged", got, ref, detail[:200]
    return ("right" if np.isfinite(got) and abs(got - ref) <= tol else "silently wrong"), got, ref, detail


def cases(quick: bool):
    if quick:
        yield from [("column", 1e3, True, 3, False), ("column", 1e2, False, 29, False),
                    ("shortening", 1e2, False, 3, False), ("shortening", 1e3, True, 1, True),
                    ("moment", 1e4, False, 4, False), ("moment", 1e2, True, 1, False),
                    ("arch", 200.0, True, 10, False), ("arch", 200.0, True, 40, True),
                    ("lee", 0, True, 100, False), ("column", 1e4, True, 20, True),
                    ("shortening", 1e4, False, 20, False), ("moment", 1e5, True, 8, False),
                    ("string", 1e3, True, 1, False)]
        return
    slender = (1e2, 1e3, 1e4, 1e5)
    for fam, step_list in (("column", (1, 3, 7, 20, 29, 31)), ("shortening", (1, 3, 7, 20, 31, 100)),
                           ("moment", (1, 2, 4, 8, 16, 400))):
        for s in slender:
            for plane in (True, False):
                for steps in step_list:
                    for imp in (False, True):
                        yield fam, s, plane, steps, imp
    for s in slender:
        for plane in (True, False):
            for steps in (1, 2, 5, 20):
                for imp in (False, True):
                    yield "string", s, plane, steps, imp
    for s in (100.0, 200.0, 1e3):
        for plane in (True, False):
            for steps in (10, 20, 40, 400):
                for imp in (False, True):
                    yield "arch", s, plane, steps, imp
    for steps in (30, 100, 150, 199, 200, 201, 300, 400):
        for imp in (False, True):
            yield "lee", 0, True, steps, imp


def main(argv=None):
    a = parser(__file__, __doc__).parse_args(argv)
    out = setup(a)
    rows = []
    for fam, s, plane, steps, imp in cases(a.quick):
        t0 = time.process_time()
        outcome, got, ref, detail = classify(lambda: FAMILIES[fam](s, plane, steps, imp))
        rows.append((fam, s, plane, steps, imp, outcome, got, ref, time.process_time() - t0, detail))
        print(f"{fam:10s} L/r {s:8.0f} {'planar' if plane else '3D':6s} steps {steps:3d} "
              f"{'imperfect' if imp else 'perfect  '}: {outcome:14s} {got:.6g} (ref {ref:.6g}) {detail[:90]}")
    n = len(rows)
    col = list(zip(*rows))
    ds = xr.Dataset(
        {"outcome": ("run", np.array(col[5]), {"units": "1", "long_name": "right / flagged / raised / silently wrong"}),
         "value": ("run", np.array(col[6], float), {"units": "1", "long_name": "compared quantity (see docstring)"}),
         "reference": ("run", np.array(col[7], float), {"units": "1", "long_name": "reference value"}),
         "cpu_seconds": ("run", np.array(col[8], float), {"units": "s", "long_name": "process CPU time"}),
         "detail": ("run", np.array(col[9]), {"units": "1", "long_name": "status detail or error"})},
        coords={"run": ("run", np.arange(n), {"units": "1", "long_name": "run"}),
                "family": ("run", np.array(col[0]), {"units": "1", "long_name": "problem family"}),
                "slenderness": ("run", np.array(col[1], float), {"units": "1", "long_name": "L / r"}),
                "planar": ("run", np.array(col[2], int), {"units": "1", "long_name": "1 planar, 0 3D"}),
                "steps": ("run", np.array(col[3], int), {"units": "1", "long_name": "requested steps"}),
                "imperfect": ("run", np.array(col[4], int), {"units": "1", "long_name": "1 with an imperfection"})},
        attrs={"quick": int(a.quick)})
    save_netcdf(ds, out / "path_campaign.nc")
    fams = list(dict.fromkeys(col[0]))
    counts = {f: [sum(1 for r in rows if r[0] == f and r[5] == o) for o in OUTCOMES] for f in fams}
    lines = ["| family | runs | " + " | ".join(OUTCOMES) + " |", "|---" * (len(OUTCOMES) + 2) + "|"]
    for f in fams:
        lines.append(f"| {f} | {sum(counts[f])} | " + " | ".join(str(c) for c in counts[f]) + " |")
    tot = [sum(counts[f][i] for f in fams) for i in range(len(OUTCOMES))]
    lines.append(f"| all | {n} | " + " | ".join(str(c) for c in tot) + " |")
    (out / "path_campaign.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4))
    bottom = np.zeros(len(fams))
    for i, o in enumerate(OUTCOMES):
        v = np.array([counts[f][i] for f in fams])
        ax.bar(fams, v, bottom=bottom, label=o, color=("tab:green", "tab:orange", "tab:blue", "tab:red")[i])
        bottom += v
    ax.set_ylabel("runs (1)")
    ax.set_xlabel("problem family")
    ax.set_title(f"Path following over slenderness, planar/3D, controls and step counts ({n} runs)")
    ax.legend()
    save_figure(fig, out / "path_campaign.png")
    return ds


if __name__ == "__main__":
    main()
