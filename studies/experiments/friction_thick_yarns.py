"""Friction where a thick yarn's contact spreads over many short elements (issue 23, the acrylic knits):
why the shipped friction gives energy back there, and what rubbing once per pair would change.

The engine's lagged friction rubs every term of a pair's contact potential (edge-edge, the negative
point-edge vertex corrections, point-point) at its own closest point with its signed weight. Two
measurements, each for that form ("per term", shipped) and for a probe that rubs once per pair at
its segments' closest points with the pair's net normal force where it presses ("per pair", not
shipped):

1. a rigid slide of a thick yarn over another (straight, 20 elements of 0.1 mm each, hard cores of
   0.05 mm under compressible shells to 0.5 mm, pressed 0.05 / 0.3 / 0.6 mm into each other, crossing
   at 90 and 30 degrees, slid 0.05 mm): friction force over mu N (exact: 1);
2. the acrylic 1x1 rib (``cells/rib_1x1_acrylic.toml``, friction 0.3) relaxed and pulled along the
   wales to 2 % in two levels at 1.0 mm elements: the ledger's friction energy against the work of
   the stretch, the status, the CPU time, and (per term) the split of the dissipation by term type,
   summed over every step the solver tried.

Usage::

    python studies/experiments/friction_thick_yarns.py [--quick] [--out DIR] [--no-docs]

Writes ``friction_thick_yarns.nc`` and ``friction_thick_yarns.png`` into OUT (default
results/friction_thick_yarns); the full run (about 2 minutes of CPU) copies the chart to
docs/studies/. ``--quick``: 2.0 mm elements, one 1 % level.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import time
from pathlib import Path

import numpy as np
import xarray as xr

import homtex
from homtex.contact import incremental, ipc_scene
from homtex.contact.distance import _ee_classify
from homtex.contact.friction import FrictionLag, _basis, friction_mollifier, friction_potential, pair_friction_lag
from homtex.contact.potential import Enforcement, pair_potential
from homtex.contact.stencil import pair_stencil

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import add_docs_option, parser, publish, pyplot, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")
FORMS = ("per term", "per pair")
MU = 0.3


def per_pair(lag: FrictionLag, x, stencil) -> FrictionLag:
    """The probe: each pair of ``lag`` (the shipped per-term lag at x) rubs once, at its segments'
    closest points, with its net normal force where that presses."""
    net = lag.lam.sum(axis=1)
    na = len(lag)
    lam, coef, T = np.zeros((na, 1)), np.zeros((na, 1, 4)), np.zeros((na, 1, 3, 2))
    for r in range(na):                       # a study probe, not a hot path
        q = lag.index[r]
        P = x[stencil.nodes[q]] + stencil.shift[q]
        _, s, t, _ = _ee_classify(P)
        c = np.array([1 - s, s, -(1 - t), -t])
        n = c @ P
        d = float(np.linalg.norm(n))
        if d > 0 and net[r] > 0:
            lam[r, 0], coef[r, 0] = net[r], c
            _basis(n[0] / d, n[1] / d, n[2] / d, T[r], 0)
    return FrictionLag(nodes=lag.nodes, coef=coef, basis=T, lam=lam, mu=lag.mu, index=lag.index, plate=lag.plate)


def thick_crossing(depth: float, angle: float, n: int = 20, h: float = 0.1, core: float = 0.05, outer: float = 0.5):
    s = (np.arange(n + 1) - n / 2) * h
    th = np.radians(angle)
    x = np.vstack([np.c_[s, 0 * s, 0 * s], np.c_[s * np.cos(th), s * np.sin(th), np.full_like(s, 2 * outer - depth)]])
    chain = np.c_[np.arange(n), np.arange(1, n + 1)]
    A, B = np.meshgrid(np.arange(n), np.arange(n) + n, indexing="ij")
    st = pair_stencil(np.vstack([chain, chain + n + 1]), np.full(2 * n, core), A.ravel(), B.ravel())
    enf = Enforcement("shell", ghat=1e-3, shell=2 * (outer - core), shell_stiffness=2.0, shell_exponent=3.0)
    return x, st, enf


def rigid_slides(depths=(0.05, 0.3, 0.6), angles=(90.0, 30.0), slide=0.05) -> xr.Dataset:
    ratio = np.zeros((len(FORMS), len(depths), len(angles)))
    pairs = np.zeros((len(depths), len(angles)), dtype=int)
    negative = np.zeros_like(pairs)
    for i, depth in enumerate(depths):
        for j, angle in enumerate(angles):
            x, st, enf = thick_crossing(depth, angle)
            n = len(x) // 2
            N = -pair_potential(x, st, enf, hessian=False).grad[n:, 2].sum()
            lag = pair_friction_lag(x, st, enf, mu=MU)
            pairs[i, j], negative[i, j] = len(lag), int((lag.lam < 0).sum())
            xs = x.copy()
            xs[n:, 0] += slide
            for f, lg in enumerate((lag, per_pair(lag, x, st))):
                F = -friction_potential(lg, xs, x, 1e-4).grad[n:].sum(axis=0)
                ratio[f, i, j] = -F[0] / (MU * N)
    return xr.Dataset(
        {"force_over_mu_N": (("form", "depth", "angle"), ratio,
                             {"units": "1", "long_name": "friction force on the slid yarn / (mu N) (exact: 1)"}),
         "pairs": (("depth", "angle"), pairs, {"units": "1", "long_name": "segment pairs in contact"}),
         "negative_terms": (("depth", "angle"), negative,
                            {"units": "1", "long_name": "terms with a negative weight (per-term form)"})},
        coords={"form": ("form", list(FORMS)), "depth": ("depth", list(depths), {"units": "mm",
                                                                                 "long_name": "shell overlap"}),
                "angle": ("angle", list(angles), {"units": "degree", "long_name": "crossing angle"})})


@contextlib.contextmanager
def instrumented(form: str, split: np.ndarray):
    """Run the engine with ``form``'s friction; per term, add the ledger's dissipation by term type
    (edge-edge, point-edge, point-point) into ``split`` (3,)."""
    lag_fn, fp = ipc_scene.pair_friction_lag, incremental.friction_potential
    if form == "per pair":
        ipc_scene.pair_friction_lag = lambda x, st, enf, mu=0.0: per_pair(pair_friction_lag(x, st, enf, mu=mu),
                                                                           np.asarray(x, float).reshape(-1, 3), st)

    def ledger(lag, x, x0, eps_v, *a, **k):
        sel = lag.plate < 0
        if form == "per term" and sel.any():
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


def acrylic(element_length: float, strain: float, steps: int) -> xr.Dataset:
    cell = homtex.load_cell("rib_1x1_acrylic").replace(**{"resolution.element_length": element_length})
    relaxed = homtex.relax(cell, friction=0.0)
    runs = []
    for form in FORMS:
        split = np.zeros(3)
        t0 = time.process_time()
        with instrumented(form, split):
            ds = homtex.tensile(relaxed, strain=strain, direction="wale", steps=steps, friction=MU)
        cpu = time.process_time() - t0
        log.info("%s: %s, %.0f s CPU, friction energy %s N mm, work %s N mm", form, ds.attrs["status"], cpu,
                 np.array2string(ds.friction_energy.values, precision=4),
                 np.array2string(ds.external_work.values, precision=4))
        keep = ds[["force_per_width", "external_work", "friction_energy", "energy_balance", "newton_iterations"]]
        keep.attrs = {}
        keep["status"] = ((), str(ds.attrs["status"]))
        keep["cpu_s"] = ((), cpu, {"units": "s", "long_name": "process CPU time of the tensile test"})
        keep["dissipation_by_term"] = (("term",), split if form == "per term" else np.full(3, np.nan),
                                       {"units": "N mm", "long_name": "dissipation by term type, every step tried"})
        runs.append(keep)
    res = xr.concat(runs, dim="form", join="outer").assign_coords(form=("form", list(FORMS)),
                                                                   term=("term", ["edge-edge", "point-edge",
                                                                                  "point-point"]))
    res.attrs.update(element_length_mm=element_length, friction=MU, cell="rib_1x1_acrylic", direction="wale")
    return res


def chart(slides: xr.Dataset, rib: xr.Dataset, path):
    plt = pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 4.8))
    w = 0.35
    xs = np.arange(slides.sizes["depth"])
    for f, form in enumerate(FORMS):
        for a, angle in enumerate(slides.angle.values):
            v = slides.force_over_mu_N.sel(form=form, angle=angle).values
            ax.bar(xs + (2 * f + a - 1.5) * w / 2, v, w / 2, label=f"{form}, crossing at {angle:g} degrees",
                   color=f"C{2 * f + a}")
    ax.axhline(1.0, color="k", lw=0.8, ls=":", label="exact (mu N)")
    ax.set_xticks(xs, [f"{d:g} mm" for d in slides.depth.values])
    ax.set_xlabel("shell overlap of the two thick yarns, mm")
    ax.set_ylabel("friction force / (mu N), 1")
    ax.set_title("a thick yarn slid rigidly across another (40-310 segment pairs)", fontsize=10)
    ax.set_ylim(0.0, 2.3)
    ax.legend(fontsize=8, loc="upper center", ncol=2)
    for f, form in enumerate(FORMS):
        c = rib.sel(form=form)
        e = 100 * c.strain.values
        bx.plot(e, c.friction_energy.values, marker="o", color=f"C{2 * f}",
                label=f"friction dissipated, {form} (status {c.status.values}, {float(c.cpu_s):.0f} s CPU)")
        bx.plot(e, c.external_work.values, ls=":", color=f"C{2 * f}", label=f"work of the stretch, {form}")
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
    rib = acrylic(*((2.0, 0.01, 1) if args.quick else (1.0, 0.02, 2)))
    res = xr.merge([slides, rib], compat="override", combine_attrs="override")
    res.attrs.update(title="friction on thick yarns: per term (shipped) and per pair (probe)")
    save_netcdf(res, out / "friction_thick_yarns.nc")
    path = chart(slides, rib, out / "friction_thick_yarns.png")
    publish(args, path)
    return res


if __name__ == "__main__":
    main()
