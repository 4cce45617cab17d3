"""Friction where a thick yarn's contact spreads over many elements (issue 23, the acrylic knits):
the former per-term friction gave energy back there; the shipped one rubs once per pair.

The former lagged friction rubbed every term of a pair's contact potential (edge-edge, the negative
point-edge vertex corrections, point-point) at its own closest point with its signed weight ("per
term", rebuilt here as the reference). The shipped one (:mod:`homtex.contact.friction`) rubs each pair
once, along the contact normal, with its share of its contact patch's net normal force ("per pair").
Two measurements for each:

1. a rigid slide of a thick yarn over another (straight, 20 elements of 0.1 mm each, hard cores of
   0.05 mm under compressible shells to 0.5 mm, pressed 0.05 / 0.3 / 0.6 mm into each other, crossing
   at 90, 30 and 5 degrees, slid 0.05 mm along x and along y): friction force over mu N (exact: 1);
2. the acrylic 1x1 rib (``cells/rib_1x1_acrylic.toml``, friction 0.3) relaxed and pulled along the
   wales to 2 % in two levels at 1.0 mm elements: the ledger's friction energy against the work of
   the stretch, the status, the CPU time, and (per term) the split of the dissipation by term type,
   summed over every step the solver tried.

Usage::

    python studies/experiments/friction_thick_yarns.py [--quick] [--out DIR] [--no-docs]

Writes ``friction_thick_yarns.nc`` and ``friction_thick_yarns.png`` into OUT (default
results/friction_thick_yarns); the full run (about 2 minutes of CPU) copies the chart to
docs/studies/. ``--quick``: 2.0 mm elements, one 1 % level, and the former form's steps halved at
most twice for accuracy (it still gives energy back; its full refinement takes 100 s there).
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr
from numba import njit

import homtex
from homtex.contact import incremental, ipc_scene
from homtex.contact.distance import _d2_at, _ee_classify, _sin2_angle
from homtex.contact.examples import thick_crossing
from homtex.contact.friction import FrictionLag, _basis, friction_mollifier, friction_potential, pair_friction_lag
from homtex.contact.potential import (
    _blend,
    _load_stencil,
    _phi,
    _term_params,
    _term_weights,
    pair_gaps,
    pair_potential,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import add_docs_option, parser, publish, pyplot, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")
FORMS = ("per term (former)", "per pair (shipped)")
MU = 0.3


@njit
def _terms(x, nodes, shift, rsum, alpha, beta, idx, kind, kp, ghat, c0, c1, lam, coef, T):
    """The former lag: every inclusion-exclusion term of the pairs idx at its own closest point."""
    P = np.empty((4, 3))
    gc = np.empty(12)
    Hc = np.empty((1, 1))
    for r in range(idx.size):
        q = idx[r]
        _load_stencil(x, nodes, shift, q, P)
        d2e, es, et, ecase = _ee_classify(P)
        w = _blend(_sin2_angle(P, gc, Hc, 0), c0[q], c1[q])[0]
        for j in range(9):
            W = _term_weights(j, w, alpha[q], beta[q])[0]
            if W == 0.0:
                continue
            s, t, fs, ft = _term_params(P, j, es, et, ecase)
            d = np.sqrt(_d2_at(P, s, t))
            if d - rsum[q] >= ghat or d <= 0.0:
                continue
            lam[r, j] = -W * _phi(d - rsum[q], kind, kp, ghat)[1]
            coef[r, j, 0] = 1.0 - s
            coef[r, j, 1] = s
            coef[r, j, 2] = -(1.0 - t)
            coef[r, j, 3] = -t
            n = np.zeros(3)
            for k in range(4):
                n += coef[r, j, k] * P[k]
            _basis(n[0] / d, n[1] / d, n[2] / d, T[r], j)


def per_term(x, stencil, enforcement, mu=0.0) -> FrictionLag:
    """The former per-term friction lag at x (the reference; arguments as ``pair_friction_lag``)."""
    x = np.ascontiguousarray(np.asarray(x, dtype=float).reshape(-1, 3))
    mu_c = np.broadcast_to(np.asarray(mu, dtype=float), (len(stencil),))
    idx = np.flatnonzero((pair_gaps(x, stencil) < enforcement.cutoff) & (mu_c > 0)).astype(np.int64)
    na = len(idx)
    lam, coef, T = np.zeros((na, 9)), np.zeros((na, 9, 4)), np.zeros((na, 9, 3, 2))
    c0, c1 = enforcement.pair_c_range(stencil)
    if na:
        _terms(x, stencil.nodes, stencil.shift, stencil.rsum, stencil.alpha, stencil.beta, idx, enforcement.code,
               enforcement.params, enforcement.cutoff, c0, c1, lam, coef, T)
    return FrictionLag(nodes=stencil.nodes[idx], coef=coef, basis=T, lam=lam, mu=np.ascontiguousarray(mu_c[idx]),
                       index=idx, plate=np.full(na, -1, dtype=np.int64))


def rigid_slides(depths=(0.05, 0.3, 0.6), angles=(90.0, 30.0, 5.0), slide=0.05) -> xr.Dataset:
    ratio = np.zeros((len(FORMS), len(depths), len(angles), 2))
    pairs = np.zeros((len(depths), len(angles)), dtype=int)
    negative = np.zeros_like(pairs)
    for i, depth in enumerate(depths):
        for j, angle in enumerate(angles):
            x, st, enf = thick_crossing(depth, angle)
            n = len(x) // 2
            N = -pair_potential(x, st, enf, hessian=False).grad[n:, 2].sum()
            old = per_term(x, st, enf, mu=MU)
            pairs[i, j], negative[i, j] = len(old), int((old.lam < 0).sum())
            for f, lg in enumerate((old, pair_friction_lag(x, st, enf, mu=MU))):
                for k in range(2):
                    xs = x.copy()
                    xs[n:, k] += slide
                    F = -friction_potential(lg, xs, x, 1e-4).grad[n:].sum(axis=0)
                    ratio[f, i, j, k] = -F[k] / (MU * N)
    return xr.Dataset(
        {"force_over_mu_N": (("form", "depth", "angle", "slide"), ratio,
                             {"units": "1", "long_name": "friction force on the slid yarn / (mu N) (exact: 1)"}),
         "pairs": (("depth", "angle"), pairs, {"units": "1", "long_name": "segment pairs in contact"}),
         "negative_terms": (("depth", "angle"), negative,
                            {"units": "1", "long_name": "terms with a negative weight (per-term form)"})},
        coords={"form": ("form", list(FORMS)), "depth": ("depth", list(depths), {"units": "mm",
                                                                                 "long_name": "shell overlap"}),
                "angle": ("angle", list(angles), {"units": "degree", "long_name": "crossing angle"}),
                "slide": ("slide", ["x", "y"], {"long_name": "direction of the slide (x: along the lower yarn)"})})


@contextlib.contextmanager
def instrumented(form: str, split: np.ndarray, max_refine: int | None = None):
    """Run the engine with ``form``'s friction; per term, add the ledger's dissipation by term type
    (edge-edge, point-edge, point-point) into ``split`` (3,), its steps halved at most ``max_refine``
    times for accuracy (None: the shipped stepping)."""
    lag_fn, fp = ipc_scene.pair_friction_lag, incremental.friction_potential
    tensile_mod = importlib.import_module("homtex.knits.record")       # where the knit tests' stepping is set
    stepping = tensile_mod.FRICTION_STEPPING
    if form == FORMS[0]:
        ipc_scene.pair_friction_lag = per_term
        if max_refine is not None:
            tensile_mod.FRICTION_STEPPING = {**stepping, "max_refine": int(max_refine)}

    def ledger(lag, x, x0, eps_v, *a, **k):
        sel = lag.plate < 0
        if form == FORMS[0] and sel.any():
            d = np.einsum("rjk,rki->rji", lag.coef[sel], (x - x0)[lag.nodes[sel]])
            y = np.linalg.norm(np.einsum("rjic,rji->rjc", lag.basis[sel], d), axis=2)
            dis = 0.5 * lag.mu[sel, None] * lag.lam[sel] * friction_mollifier(y, eps_v)[1] * y   # trapezoid half
            split[:] += [dis[:, :1].sum(), dis[:, 1:5].sum(), dis[:, 5:].sum()]
        return fp(lag, x, x0, eps_v, *a, **k)

    incremental.friction_potential = ledger
    try:
        yield
    finally:
        ipc_scene.pair_friction_lag, incremental.friction_potential = lag_fn, fp
        tensile_mod.FRICTION_STEPPING = stepping


def acrylic(element_length: float, strain: float, steps: int, max_refine: int | None = None) -> xr.Dataset:
    cell = homtex.load_cell("rib_1x1_acrylic").replace(**{"resolution.element_length": element_length})
    relaxed = homtex.relax(cell, friction=0.0, cache=False)
    runs = []
    for form in FORMS:
        split = np.zeros(3)
        t0 = time.process_time()
        with instrumented(form, split, max_refine):
            ds = homtex.tensile(relaxed, strain=strain, direction="wale", steps=steps, friction=MU)
        cpu = time.process_time() - t0
        log.info("%s: %s, %.0f s CPU, friction energy %s N mm, work %s N mm", form, ds.attrs["status"], cpu,
                 np.array2string(ds.friction_energy.values, precision=4),
                 np.array2string(ds.external_work.values, precision=4))
        keep = ds[["force_per_width", "external_work", "friction_energy", "energy_balance", "newton_iterations"]]
        keep.attrs = {}
        keep["status"] = ((), str(ds.attrs["status"]))
        keep["cpu_s"] = ((), cpu, {"units": "s", "long_name": "process CPU time of the tensile test"})
        keep["dissipation_by_term"] = (("term",), split if form == FORMS[0] else np.full(3, np.nan),
                                       {"units": "N mm", "long_name": "dissipation by term type, every step tried"})
        runs.append(keep)
    res = xr.concat(runs, dim="form", join="outer").assign_coords(form=("form", list(FORMS)),
                                                                   term=("term", ["edge-edge", "point-edge",
                                                                                  "point-point"]))
    res.attrs.update(element_length_mm=element_length, friction=MU, cell="rib_1x1_acrylic", direction="wale",
                     former_max_refine="shipped" if max_refine is None else int(max_refine))
    return res


def chart(slides: xr.Dataset, rib: xr.Dataset, path):
    plt = pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 4.8))
    dev = np.abs(slides.force_over_mu_N - 1.0).max("slide")
    for f, form in enumerate(FORMS):
        for a, angle in enumerate(slides.angle.values):
            ax.plot(slides.depth.values, np.maximum(dev.sel(form=form, angle=angle).values, 1e-15),
                    marker="os"[f], ls="-:"[f], color=f"C{a}", label=f"{form}, crossing at {angle:g} degrees")
    ax.set_yscale("log")
    ax.set_ylim(3e-16, 1.0)
    ax.axhline(0.01, color="k", lw=0.8, ls="--", label="1 %")
    ax.set_xlabel("shell overlap of the two thick yarns, mm")
    ax.set_ylabel("|F / (mu N) - 1|, worse of two slides, 1")
    ax.annotate("1e-15: exact to round-off", (0.05, 1.5e-15), fontsize=7, color="0.3")
    ax.set_title("a thick yarn slid rigidly across another (40-310 segment pairs)", fontsize=10)
    ax.legend(fontsize=7, loc="center right")
    for f, form in enumerate(FORMS):
        c = rib.sel(form=form)
        e = 100 * c.strain.values
        bx.plot(e, c.friction_energy.values, marker="o", color=f"C{3 + f}",
                label=f"friction dissipated, {form} (status {c.status.values}, {float(c.cpu_s):.0f} s CPU)")
        bx.plot(e, c.external_work.values, ls=":", color=f"C{3 + f}", label=f"work of the stretch, {form}")
    bx.axhline(0.0, color="k", lw=0.6)
    bx.set_yscale("symlog", linthresh=1e-3)
    bx.set_xlabel("strain along the wales, %")
    bx.set_ylabel("energy since the start of the test, N mm")
    bx.set_title(f"acrylic 1x1 rib, friction {MU:g}, {rib.attrs['element_length_mm']:g} mm elements", fontsize=10)
    bx.legend(fontsize=8)
    for a in (ax, bx):
        a.grid(alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path)


def main(argv=None):
    args = add_docs_option(parser(__file__, __doc__)).parse_args(argv)
    out = setup(args)
    slides = rigid_slides()
    log.info("rigid slide, friction force / mu N (form, depth, angle):\n%s",
             np.array2string(slides.force_over_mu_N.values, precision=4))
    rib = acrylic(*((2.0, 0.01, 1, 2) if args.quick else (1.0, 0.02, 2)))
    res = xr.merge([slides, rib], compat="override", combine_attrs="override")
    res.attrs.update(title="friction on thick yarns: per term (former) and per pair (shipped)")
    save_netcdf(res, out / "friction_thick_yarns.nc")
    path = chart(slides, rib, out / "friction_thick_yarns.png")
    publish(args, path)
    return res


if __name__ == "__main__":
    main()
