"""The unseamed spacer cell compressed to 70 % with large rotations, large-motion contact and
friction (issue 18): what the co-rotational beams, the barrier contact and Coulomb friction make
of the 20 mm spacer fabric.

For friction 0, 0.2 and 0.4 (yarn-yarn and yarn-plate) the cell (``cells/spacer_20mm.toml``) is
compressed to 70 % with ``homtex.compress(..., geometry="nonlinear")`` on a strain grid that is
fine where the pile buckles (0.05 % levels to 1 %, then 1 % levels), and again on a grid with
twice the levels (step convergence: the stress of the two at the coarse levels). Recorded per
curve: stress, yarn-yarn contacts, the energy split (bending, axial, torsion, shear, contact),
friction dissipated, stabilisation absorbed, external work and the energy balance, the first
buckling strain (the most compressed pile element loses half of its initial axial stiffness),
the run time. Below the first buckling strain the curves are compared with the linear model
(``geometry="linear"``) and with a stiff, thin barrier (ghat 0.1 um, kappa 1e5 N/mm) to separate
the barrier's compliance from the geometric softening. (The former co-rotational contact solve,
linearised contact without friction, was a third curve there; it was retired: the large-motion
engine is the package's one geometrically nonlinear contact solver.) Pictures of the cell at 0 / 30 / 50 / 70 %
(friction 0.2; 3D views like the paper's Fig. 10) and VTK files of the same states.

Usage::

    python studies/experiments/spacer_nonlinear_compression.py [--quick] [--out DIR] [--no-docs]

Writes ``spacer_nonlinear_compression.nc`` (curves), ``spacer_nonlinear_states.nc`` (node positions
at the pictured strains), ``spacer_nonlinear_compression.png`` (curves), ``spacer_nonlinear_cell.png``
(pictures) and ``vtk/*.vtu`` into OUT (default results/spacer_nonlinear_compression) and copies
the charts to ``docs/studies/`` (not with --quick). Full run: a few minutes on the 2-core machine.
"""

from __future__ import annotations

import logging
import shutil
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

import homtex
from homtex.contact.compress import CompressionTest
from homtex.contact.nl_compress import run_nonlinear_compression

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import DOCS, parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

log = logging.getLogger("studies")
FRICTIONS = (0.0, 0.2, 0.4)
PICTURED = (0.0, 0.3, 0.5, 0.7)
COLORS = {"pillar": "tab:blue", "inlay": "tab:orange", "pile": "tab:green", "interlacing": "tab:red"}


def grid(quick: bool) -> np.ndarray:
    if quick:
        return np.array([0.005, 0.01, 0.02])
    return np.unique(np.round(np.r_[np.arange(1, 21) * 0.0005, np.arange(2, 71) * 0.01], 6))


def refined(levels: np.ndarray) -> np.ndarray:
    """The grid with a level between every two: twice the steps, the coarse levels kept."""
    mids = 0.5 * (np.r_[0.0, levels[:-1]] + levels)
    return np.sort(np.r_[levels, mids])


def curve(cell, levels, mu, *, positions=False, contact=None):
    test = CompressionTest.build(cell.frame, info=cell.info, groups=cell.groups)
    t0 = time.perf_counter()
    ds = run_nonlinear_compression(test, levels, control="displacement",
                                   contact=contact or homtex.Contact(friction=mu), keep_positions=positions)
    ds.attrs["seconds"] = time.perf_counter() - t0
    log.info("friction %.1f, %d levels: %s in %.1f s, first buckling %.4f", mu, len(levels), ds.attrs["status"],
             ds.attrs["seconds"], ds.attrs["first_buckling_strain"])
    return ds


def step_convergence(coarse, fine):
    """Largest |stress difference| / the larger stress at the coarse levels both reached."""
    f = fine.sel(strain=coarse.strain.values, method="nearest", tolerance=1e-9)
    a, b = coarse.stress.values, f.stress.values
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(a), np.abs(b))))


def run(out: Path, quick: bool):
    warnings.simplefilter("ignore")
    cell = homtex.load_cell("spacer_20mm")
    levels = grid(quick)
    frictions = FRICTIONS[:2] if quick else FRICTIONS
    curves, conv, seconds = {}, {}, {}
    for mu in frictions:
        ds = curve(cell, levels, mu, positions=(mu == 0.2))
        curves[mu] = ds
        seconds[mu] = ds.attrs["seconds"]
        conv[mu] = step_convergence(ds, curve(cell, refined(levels), mu)) if not quick else np.nan
    lin = homtex.compress(cell, strain=levels, geometry="linear")
    small = levels[levels <= 0.01]
    stiff = curve(cell, small, 0.0, contact=homtex.Contact(barrier_stiffness=1e5, barrier_gap=1e-3))
    return cell, levels, curves, conv, seconds, lin, small, stiff


def summary_dataset(levels, curves, conv, seconds, lin, small, stiff) -> xr.Dataset:
    mus = list(curves)
    n = len(levels)

    def col(name):
        return np.array([np.r_[c[name].values, np.full(n - c.sizes["strain"], np.nan)] for c in curves.values()])

    lin_s = np.r_[lin.stress.values, np.full(n - lin.sizes["strain"], np.nan)]
    data = {name: (("friction", "strain"), col(name), curves[mus[0]][name].attrs)
            for name in ("stress", "active_yarn_yarn", "active_yarn_plate", "axial", "torsion", "bending_y",
                         "bending_z", "shear", "contact_energy", "friction_energy", "stabilization_energy",
                         "external_work", "energy_balance", "pile_force", "newton_iterations", "substeps")}
    data["linear_stress"] = ("strain", lin_s, {"units": "kPa", "long_name": "stress of the linear model"})
    k = len(small)
    data["stiff_barrier_stress"] = ("small_strain", stiff.stress.values[:k],
                                    {"units": "kPa", "long_name": "frictionless, barrier kappa 1e5 N/mm, ghat 0.1 um"})
    fb = [c.attrs["first_buckling_strain"] for c in curves.values()]
    data["first_buckling_strain"] = ("friction", fb, {"units": "1", "long_name": "first buckling strain of a pile leg"})
    data["step_convergence"] = ("friction", [conv[m] for m in mus],
                                {"units": "1", "long_name": "max |stress difference| / larger stress, levels vs twice"})
    data["seconds"] = ("friction", [seconds[m] for m in mus], {"units": "s", "long_name": "run time of the curve"})
    data["status"] = ("friction", [c.attrs["status"] for c in curves.values()], {"units": "1", "long_name": "status"})
    ds = xr.Dataset(data, coords={
        "friction": ("friction", mus, {"units": "1", "long_name": "Coulomb coefficient (yarn-yarn and yarn-plate)"}),
        "strain": ("strain", levels, {"units": "1", "long_name": "compression strain"}),
        "small_strain": ("small_strain", small, {"units": "1", "long_name": "compression strain below 1 %"})})
    ds.attrs.update(cell="cells/spacer_20mm.toml", machine="2-core AMD EPYC, 24 GB, shared",
                    description=__doc__.split("\n\n")[0])
    return ds


def plot_curves(ds, out):
    plt = pyplot()
    fig, ax = plt.subplots(2, 3, figsize=(15, 8.5))
    e = ds.strain.values * 100
    for mu in ds.friction.values:
        c = ds.sel(friction=mu)
        a = ax[0, 0].plot(e, c.stress, label=f"friction {mu:g}")[0]
        fb = float(c.first_buckling_strain)
        ax[0, 0].axvline(100 * fb, color=a.get_color(), ls=":", lw=1)
        ax[0, 1].plot(e, c.active_yarn_yarn, color=a.get_color(), label=f"friction {mu:g}")
        w = np.maximum(c.external_work.values, 1e-30)
        ax[1, 1].plot(e, 100 * c.energy_balance, color=a.get_color(), label=f"balance, friction {mu:g}")
        ax[1, 1].plot(e, 100 * c.stabilization_energy / w, color=a.get_color(), ls="--", lw=1)
    ax[0, 0].plot(e, ds.linear_stress, "k--", lw=1, label="linear model")
    ax[0, 0].set(xlabel="compression (%)", ylabel="stress (kPa)", ylim=(0, 1.3 * float(ds.stress.max())),
                 title="stress-strain (dotted: first pile buckling)")
    ax[0, 1].set(xlabel="compression (%)", ylabel="yarn-yarn pairs within ghat", title="yarn-yarn contacts")
    s = ds.small_strain.values * 100
    c0 = ds.sel(friction=0.0)
    lin_small = ds.linear_stress.sel(strain=ds.small_strain.values).values
    for y, lab in ((c0.stress.sel(strain=ds.small_strain.values).values, "engine, default barrier"),
                   (ds.stiff_barrier_stress.values, "engine, stiff thin barrier")):
        ax[0, 2].plot(s, 100 * (y / lin_small - 1), "o-", ms=3, label=lab)
    ax[0, 2].axvline(100 * float(c0.first_buckling_strain), color="k", ls=":", lw=1, label="first buckling")
    ax[0, 2].set(xlabel="compression (%)", ylabel="stress / linear model - 1 (%)", title="against the linear model, "
                 "friction 0")
    c2 = ds.sel(friction=0.2) if 0.2 in ds.friction.values else ds.isel(friction=-1)
    for name in ("bending_y", "bending_z", "axial", "torsion", "shear"):
        ax[1, 0].plot(e, c2[name] - c2[name][0], label=name)
    ax[1, 0].plot(e, c2.contact_energy, label="contact")
    ax[1, 0].plot(e, c2.friction_energy, label="friction dissipated")
    ax[1, 0].set(xlabel="compression (%)", ylabel="N mm", yscale="log", ylim=(1e-5, None),
                 title=f"energies, friction {float(c2.friction):g}")
    ax[1, 1].axhline(1, color="k", lw=0.5)
    ax[1, 1].axhline(-1, color="k", lw=0.5)
    ax[1, 1].set(xlabel="compression (%)", ylabel="% of the external work", ylim=(-2, 2),
                 title="energy balance (solid) and stabilisation (dashed)")
    ax[1, 2].bar(np.arange(ds.sizes["friction"]), 100 * ds.step_convergence.values, tick_label=[
        f"{m:g}" for m in ds.friction.values])
    ax[1, 2].axhline(2, color="k", ls=":", label="2 % target")
    ax[1, 2].set(xlabel="friction", ylabel="max stress difference (%)", title="step convergence: levels vs twice")
    for a in ax.ravel():
        a.grid(alpha=0.3)
        if a.get_legend_handles_labels()[0]:
            a.legend(fontsize=7)
    fig.suptitle("Spacer cell (cells/spacer_20mm.toml) compressed to 70 %: co-rotational beams, barrier contact, "
                 "friction", fontsize=10)
    fig.tight_layout()
    return save_figure(fig, out / "spacer_nonlinear_compression.png")


def pictures(cell, ds, out, docs):
    """3D views of the cell at the pictured strains, and VTK files of the same states."""
    plt = pyplot()
    fr = cell.frame
    groups = cell.groups
    strains = [e for e in PICTURED if e <= float(ds.strain.max()) + 1e-9]
    if len(strains) < 2:                       # a quick run: its last level
        strains.append(float(ds.strain.max()))
    per = fr.periods
    fig = plt.figure(figsize=(4.2 * len(strains), 5.2))
    (out / "vtk").mkdir(exist_ok=True)
    from homtex.output.vtk import HAVE_MESHIO, write_vtk

    for k, e in enumerate(strains):
        ax = fig.add_subplot(1, len(strains), k + 1, projection="3d")
        if e == 0.0:
            x, pz, en = fr.nodes, (ds.attrs["bottom_plate_z_mm"], ds.attrs["top_plate_z_mm"]), np.zeros(fr.n_elements)
        else:
            s = ds.sel(strain=e, method="nearest")
            x, pz, en = s.x.values, s.plate_z.values, s.element_energy.values
        a = x[fr.elements[:, 0]]
        b = x[fr.elements[:, 1]] + fr.shift
        for name, mask in groups.items():
            idx = np.flatnonzero(mask)
            for i in range(2):                 # 2 x 2 periodic cells
                for j in range(2):
                    t = i * per[0] + j * per[1]
                    seg = np.stack([a[idx] + t, b[idx] + t, np.full((len(idx), 3), np.nan)], axis=1).reshape(-1, 3)
                    ax.plot(seg[:, 0], seg[:, 1], seg[:, 2], color=COLORS.get(name, "k"), lw=1.0,
                            label=name if i + j == 0 else None)
        lo, hi = -1.0, 2 * per[:, :2].max() + 1.0
        xx, yy = np.meshgrid([lo, hi], [lo, hi])
        for z in pz:
            ax.plot_surface(xx, yy, np.full_like(xx, z), color="0.6", alpha=0.25)
        ax.set(xlim=(lo, hi), ylim=(lo, hi), zlim=(-0.5, 20.5), xlabel="x (mm)", ylabel="y (mm)", zlabel="z (mm)",
               title=f"{100 * e:.0f} % compression")
        ax.set_box_aspect((1, 1, 1.5))
        ax.view_init(12, -60)
        if k == 0:
            ax.legend(fontsize=7, loc="upper left")
        if HAVE_MESHIO:
            write_vtk(fr.with_(nodes=x), out / "vtk" / f"spacer_{100 * e:.0f}pct.vtu", {"strain_energy": en})
    fig.suptitle("Spacer cell compressed between plates (friction 0.2; 2 x 2 periodic cells)", fontsize=10)
    fig.tight_layout()
    path = save_figure(fig, out / "spacer_nonlinear_cell.png", dpi=110)
    return path


def report(ds, lin):
    lines = []
    for mu in ds.friction.values:
        c = ds.sel(friction=mu)
        at = {e: float(c.stress.sel(strain=e, method="nearest")) for e in (0.1, 0.3, 0.5, 0.7)
              if e <= float(ds.strain.max()) + 1e-9}
        w = c.external_work.values
        frac = np.nanmax(c.stabilization_energy.values / np.where(w > 0, w, np.nan))
        lines.append(f"friction {mu:g}: {str(c.status.values)}, {float(c.seconds):.1f} s; stress "
                     + ", ".join(f"{100 * e:.0f} % {v:.2f} kPa" for e, v in at.items())
                     + f"; first buckling {100 * float(c.first_buckling_strain):.2f} %; step convergence "
                     f"{100 * float(c.step_convergence):.2f} %; max |balance| {100 * np.nanmax(np.abs(c.energy_balance)):.2f} %;"
                     f" max stabilisation/work {100 * frac:.3f} %; yarn-yarn pairs {int(np.nanmax(c.active_yarn_yarn))}")
    c0 = ds.sel(friction=0.0)
    lin_small = ds.linear_stress.sel(strain=ds.small_strain.values).values
    rel = c0.stress.sel(strain=ds.small_strain.values).values / lin_small - 1
    fb = float(c0.first_buckling_strain)
    below = ds.small_strain.values < fb
    lines.append(f"against the linear model below first buckling ({100 * fb:.2f} %), friction 0: "
                 f"{100 * rel[0]:+.2f} % at {100 * ds.small_strain.values[0]:.3f} %, {100 * rel[below][-1]:+.2f} % at "
                 f"{100 * ds.small_strain.values[below][-1]:.2f} %; stiff thin "
                 f"barrier {100 * (ds.stiff_barrier_stress.values[0] / lin_small[0] - 1):+.2f} % / "
                 f"{100 * (ds.stiff_barrier_stress.values[below][-1] / lin_small[below][-1] - 1):+.2f} %; "
                 f"linear model: {lin.attrs['status']} {lin.attrs.get('status_detail', '')[:90]}")
    return "\n".join(lines)


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--no-docs", action="store_true", help="do not copy the charts to docs/studies")
    a = p.parse_args(argv)
    out = setup(a)
    cell, levels, curves, conv, seconds, lin, small, stiff = run(out, a.quick)
    ds = summary_dataset(levels, curves, conv, seconds, lin, small, stiff)
    save_netcdf(ds, out / "spacer_nonlinear_compression.nc")
    states = curves[0.2][["x", "plate_z", "element_energy", "stress"]]
    states.attrs.update({k: v for k, v in curves[0.2].attrs.items() if isinstance(v, (int, float, str))})
    save_netcdf(states, out / "spacer_nonlinear_states.nc")
    charts = [plot_curves(ds, out), pictures(cell, curves[0.2], out, not a.quick)]
    if not (a.quick or a.no_docs):
        (DOCS / "studies").mkdir(parents=True, exist_ok=True)
        for c in charts:
            shutil.copy(c, DOCS / "studies" / Path(c).name)
    print(report(ds, lin))


if __name__ == "__main__":
    main()
