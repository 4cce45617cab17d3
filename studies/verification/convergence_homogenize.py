"""Convergence of the effective stiffness with elements per strut (issue 3).

One periodic cell (edge 1 mm, strut radius 0.03 mm, E = 1000 MPa, nu = 0.3) of the octet
and BCC lattices, homogenised with ``homtex.homogenize`` (direct solver) for
n = 1, 2, 4, ... elements per strut:

* wavy struts (``waviness`` = 0.1: a half-sine bow of amplitude 0.1 L; the beams are chords
  of the curved strut) converge to the curved-strut stiffness; the reference is a run with
  ``--ref`` (default 256) elements per strut;
* straight struts are exact at 1 element per strut (exact Timoshenko element): the error
  against n = 1 stays at round-off for every n.

The relative error is ||C(n) - C_ref||_F / ||C_ref||_F (6x6 Voigt, MPa); the observed rate
is the least-squares slope of log(error) against log(n) over the last three points.

Usage::

    python studies/verification/convergence_homogenize.py [--out DIR] [--quick] [--nmax N] [--ref NREF]

Default n up to 32, reference 256 (about 6 s here); ``--quick``: n up to 2, reference 8.
Writes ``DIR/convergence_homogenize.nc`` (dims: lattice, struts, n) and
``DIR/convergence_homogenize.png`` (default DIR = results/convergence_homogenize).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _common import parser, pyplot, save_figure, save_netcdf, setup  # noqa: E402

RADIUS = 0.03
E_MOD, NU = 1000.0, 0.3
WAVINESS = 0.1
LATTICES = ("octet", "bcc")
STRUTS = ("wavy", "straight")


def stiffness(lattice: str, n: int, waviness: float) -> np.ndarray:
    """6x6 effective stiffness (MPa) of one periodic cell with n elements per strut."""
    import homtex
    from homtex.geometry.lattices import lattice_frame

    f = lattice_frame(lattice, radius=RADIUS, E=E_MOD, nu=NU, elements_per_strut=n,
                      waviness=waviness, periodic=True)
    return homtex.homogenize(f, solver="direct").C


def observed_rate(ns: np.ndarray, err: np.ndarray, last: int = 3) -> float:
    """Least-squares slope of log(err) vs log(n) over the last ``last`` points (NaN if < 2)."""
    ok = np.isfinite(err) & (err > 0)
    x, y = np.log(ns[ok][-last:]), np.log(err[ok][-last:])
    return float(-np.polyfit(x, y, 1)[0]) if len(x) >= 2 else np.nan


def run(out: Path, nmax: int, nref: int) -> Path:
    import xarray as xr

    ns = 2 ** np.arange(int(np.log2(nmax)) + 1)
    err = np.full((len(LATTICES), len(STRUTS), len(ns)), np.nan)
    c11 = np.full_like(err, np.nan)
    c44 = np.full_like(err, np.nan)
    rate = np.full((len(LATTICES), len(STRUTS)), np.nan)
    cref11 = np.full((len(LATTICES), len(STRUTS)), np.nan)
    for a, lat in enumerate(LATTICES):
        for s, kind in enumerate(STRUTS):
            w = WAVINESS if kind == "wavy" else 0.0
            Cs = [stiffness(lat, int(n), w) for n in ns]
            Cref = stiffness(lat, nref, w) if kind == "wavy" else Cs[0]
            cref11[a, s] = Cref[0, 0]
            for i, C in enumerate(Cs):
                err[a, s, i] = np.linalg.norm(C - Cref) / np.linalg.norm(Cref)
                c11[a, s, i], c44[a, s, i] = C[0, 0], C[3, 3]
            if kind == "wavy":
                rate[a, s] = observed_rate(ns.astype(float), err[a, s])
            print(f"{lat:6s} {kind:8s} C11 {Cref[0, 0]:.5g} MPa; errors "
                  + " ".join(f"{e:.2e}" for e in err[a, s])
                  + (f"; observed rate {rate[a, s]:.2f}" if kind == "wavy" else ""), flush=True)
    dims = ("lattice", "struts", "n")
    ds = xr.Dataset(
        {
            "relative_error": (dims, err, {"units": "1", "long_name": "||C(n) - C_ref||_F / ||C_ref||_F "
                                           "(wavy: C_ref at n_ref; straight: C at n = 1)"}),
            "C11": (dims, c11, {"units": "MPa", "long_name": "effective C11"}),
            "C44": (dims, c44, {"units": "MPa", "long_name": "effective C44 (23, engineering shear)"}),
            "observed_rate": (("lattice", "struts"), rate, {"units": "1", "long_name": "observed convergence order (slope over the last 3 points)"}),
            "C11_ref": (("lattice", "struts"), cref11, {"units": "MPa", "long_name": "reference C11"}),
        },
        coords={"lattice": ("lattice", list(LATTICES), {"units": "1", "long_name": "lattice"}),
                "struts": ("struts", list(STRUTS), {"units": "1", "long_name": "strut shape"}),
                "n": ("n", ns, {"units": "1", "long_name": "elements per strut"})},
        attrs={"radius_mm": RADIUS, "E_MPa": E_MOD, "nu": NU, "waviness": WAVINESS, "n_ref": nref,
               "solver": "direct", "cell": "one periodic cell, edge 1 mm"},
    )
    path = save_netcdf(ds, out / "convergence_homogenize.nc")
    plot(ds, out / "convergence_homogenize.png")
    return path


def plot(ds, path: Path) -> None:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    n = ds.n.values.astype(float)
    floor = 1e-16
    for lat in ds.lattice.values:
        for kind, mark in (("wavy", "o-"), ("straight", "s--")):
            e = ds.relative_error.sel(lattice=lat, struts=kind).values
            lab = f"{lat}, {kind}"
            if kind == "wavy":
                lab += f" (rate {float(ds.observed_rate.sel(lattice=lat, struts=kind)):.2f})"
            ax.loglog(n, np.maximum(e, floor), mark, label=lab)
    e0 = ds.relative_error.sel(struts="wavy").values
    ax.loglog(n[1:], e0[:, 1].max() * (n[1:] / n[1]) ** -2.0, "k:", label="O(n^-2)")
    ax.set_xlabel("elements per strut")
    ax.set_ylabel("relative error of C (Frobenius)")
    ax.set_title(f"waviness {ds.attrs['waviness']}, reference n = {ds.attrs['n_ref']}; "
                 f"straight: vs n = 1", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)


def main(argv=None) -> None:
    p = parser(__file__, __doc__)
    p.add_argument("--nmax", type=int, default=None, help="largest elements per strut (power of 2; default 32, --quick 2)")
    p.add_argument("--ref", type=int, default=None, help="elements per strut of the wavy reference (default 256, --quick 8)")
    a = p.parse_args(argv)
    out = setup(a)
    nmax = a.nmax or (2 if a.quick else 32)
    nref = a.ref or (8 if a.quick else 256)
    path = run(out, nmax, nref)
    print(f"wrote {path} and {path.with_suffix('.png')}")


if __name__ == "__main__":
    main()
