"""Which uncertain input sets the unseamed spacer fabric's plateau on the large-motion engine, and
by how much (issue 22, item 4): the defaults of ``cells/spacer_20mm.toml`` are chosen from this.

The unseamed cell is compressed to 70 % with ``homtex.compress(..., geometry="nonlinear")`` for
one input changed at a time from the base (yarn-yarn and yarn-plate friction 0.2, pile bow 8 %,
pile clamped in the loops by the interlacing beams, pile monofilament E = 5 GPa):

* friction mu = 0 / 0.1 / 0.3 (yarns and plates alike);
* plate friction 0 with yarn friction 0.2;
* pile bow 4 % / 12 % of the leg length;
* pile clamping: the interlacing beams' bending rigidity x 0.01 (the pile nearly hinged in its loops);
* pile modulus 3 / 8 GPa.

Recorded per curve: stress (kPa) and force on the paper's 121 cm^2 plate at 10 / 30 / 50 / 70 %,
the plateau (mean stress over 10-40 %), the three regions of the curve (the strains where the
slope changes, :func:`homtex.analysis.regions.three_regions`), the energy balance, run time.

Usage::

    python studies/experiments/spacer_engine_defaults.py [--quick] [--out DIR]

Writes ``spacer_engine_defaults.nc`` and ``spacer_engine_defaults.png`` into OUT (default
results/spacer_engine_defaults). Full run: 10 curves of 38 levels, about 10 minutes on the
2-core machine (more when it is shared).
"""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import xarray as xr

import homtex
from homtex.analysis.regions import three_regions

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")
PLATE_AREA = 12100.0      # mm^2, DIN EN ISO 3386-1 plates of the paper
LOAD_CELL = 500.0         # N, the paper's force sensor

#: (name, group, what changes): friction (yarns, plates), cell keys, bond bending factor
VARIANTS = [
    ("base (mu 0.2)", "base", {}),
    ("mu 0", "friction", {"mu": 0.0}),
    ("mu 0.1", "friction", {"mu": 0.1}),
    ("mu 0.3", "friction", {"mu": 0.3}),
    ("plate mu 0", "plate friction", {"plate_mu": 0.0}),
    ("bow 4 %", "pile bow", {"keys": {"parameters.shape.pile_bow": 0.04}}),
    ("bow 12 %", "pile bow", {"keys": {"parameters.shape.pile_bow": 0.12}}),
    ("hinged pile", "clamping", {"bond_bending": 0.01}),
    ("pile E 3 GPa", "yarn data", {"keys": {"yarns.monofilament.E": 3000.0}}),
    ("pile E 8 GPa", "yarn data", {"keys": {"yarns.monofilament.E": 8000.0}}),
]


def levels(quick: bool) -> np.ndarray:
    if quick:
        return np.array([0.01, 0.02, 0.04])
    return np.unique(np.round(np.r_[np.arange(1, 5) * 0.005, np.arange(2, 36) * 0.02], 6))


def variant_cell(cell, spec):
    """The cell (or a stand-in with .frame/.groups/.info) of one variant."""
    c = cell.replace(**spec["keys"]) if spec.get("keys") else cell
    if "bond_bending" in spec:
        bf = np.asarray(c.frame.bending_factor, dtype=float).copy()
        bf[np.asarray(c.groups["interlacing"], dtype=bool)] *= spec["bond_bending"]
        tf = np.asarray(c.frame.torsion_factor, dtype=float).copy()
        tf[np.asarray(c.groups["interlacing"], dtype=bool)] *= spec["bond_bending"]
        return SimpleNamespace(frame=c.frame.replace(bending_factor=bf, torsion_factor=tf), groups=c.groups,
                               info=c.info)
    return c


def run(cell, lv, spec):
    mu = spec.get("mu", 0.2)
    pmu = spec.get("plate_mu", mu)
    t0 = time.process_time()
    ds = homtex.compress(variant_cell(cell, spec), strain=lv, geometry="nonlinear",
                         contact=homtex.Contact(friction=mu, plate_friction=pmu))
    return ds, time.process_time() - t0


def main(argv=None):
    args = parser(__file__, __doc__).parse_args(argv)
    out = setup(args)
    cell = homtex.load_cell("spacer_20mm")
    lv = levels(args.quick)
    variants = VARIANTS[:2] if args.quick else VARIANTS
    stress, rows = [], []
    for name, group, spec in variants:
        ds, cpu = run(cell, lv, spec)
        s = np.full(len(lv), np.nan)
        s[:ds.sizes["strain"]] = ds.stress.values
        stress.append(s)
        reg = three_regions(lv, s, start=0.02, min_span=0.02 if args.quick else 0.05)
        at = {p: float(np.interp(p, lv, s)) if p <= lv[-1] + 1e-12 else np.nan for p in (0.1, 0.3, 0.5, 0.7)}
        plateau = float(np.nanmean(s[(lv >= 0.1) & (lv <= 0.4)])) if lv[-1] >= 0.4 else np.nan
        rows.append((at, plateau, reg, float(np.nanmax(np.abs(ds.energy_balance.values), initial=0.0)), cpu,
                     ds.attrs["status"]))
        log.info("%-14s %s: stress 10/30/50/70 %% = %s kPa, plateau %.2f kPa, breaks %s, %.0f s CPU", name,
                 ds.attrs["status"], " / ".join(f"{v:.2f}" for v in at.values()), plateau,
                 np.round(reg["breaks"], 3), cpu)
    names = [v[0] for v in variants]
    res = xr.Dataset(
        {"stress": (("variant", "strain"), np.array(stress), {"units": "kPa", "long_name": "compressive stress"}),
         "force_121cm2": (("variant", "strain"), np.array(stress) * PLATE_AREA * 1e-3,
                          {"units": "N", "long_name": "force on the paper's 121 cm^2 plate"}),
         **{f"stress_{int(100 * p)}": ("variant", [r[0][p] for r in rows],
                                       {"units": "kPa", "long_name": f"stress at {100 * p:g} % compression"})
            for p in (0.1, 0.3, 0.5, 0.7)},
         "plateau": ("variant", [r[1] for r in rows], {"units": "kPa", "long_name": "mean stress over 10-40 %"}),
         "region_breaks": (("variant", "break"), np.array([r[2]["breaks"] for r in rows]),
                           {"units": "1", "long_name": "strains where the slope changes (3-segment fit from 2 %)"}),
         "region_slopes": (("variant", "region"), np.array([r[2]["slopes"] for r in rows]),
                           {"units": "kPa", "long_name": "slope of each region (stress per unit strain)"}),
         "max_energy_imbalance": ("variant", [r[3] for r in rows], {"units": "1",
                                                                    "long_name": "largest |energy balance|"}),
         "cpu_seconds": ("variant", [r[4] for r in rows], {"units": "s", "long_name": "process CPU time"}),
         "group": ("variant", [v[1] for v in variants], {"units": "1", "long_name": "input changed"}),
         "status": ("variant", [r[5] for r in rows], {"units": "1", "long_name": "curve status"})},
        coords={"variant": ("variant", names, {"units": "1", "long_name": "input changed from the base"}),
                "strain": ("strain", lv, {"units": "1", "long_name": "plate travel / thickness"}),
                "break": ("break", [1, 2], {"units": "1", "long_name": "breakpoint"}),
                "region": ("region", ["slow rise", "near-linear rise", "stiffening"],
                           {"units": "1", "long_name": "region of the curve"})})
    res.attrs.update(base="friction 0.2 (yarns and plates), pile bow 0.08, interlacing beams clamp the pile, pile "
                     "E 5 GPa", plate_area_mm2=PLATE_AREA, load_cell_N=LOAD_CELL)
    save_netcdf(res, out / "spacer_engine_defaults.nc")
    plt = pyplot()
    groups = [g for g in dict.fromkeys(v[1] for v in variants) if g != "base"]
    fig, axes = plt.subplots(1, len(groups), figsize=(4.2 * len(groups), 4.2), sharey=True, squeeze=False)
    for ax, g in zip(axes[0], groups):
        for i, v in enumerate(variants):
            if v[1] in (g, "base"):
                ax.plot(100 * lv, stress[i] * PLATE_AREA * 1e-3, "k-" if v[1] == "base" else "-", label=v[0])
        ax.axhline(LOAD_CELL, color="tab:red", ls=":", label="test's 500 N load cell")
        ax.set(xlabel="compression, % of 20 mm", title=f"changed: {g}")
        ax.legend(fontsize=8)
    axes[0][0].set_ylabel("force on the 121 cm$^2$ plate, N (yarn-level engine)")
    fig.suptitle("unseamed spacer cell on the large-motion engine: what sets the plateau (no measured data shown: the "
                 "paper gives its curves only as plots)", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out / "spacer_engine_defaults.png")
    return res


if __name__ == "__main__":
    main()
