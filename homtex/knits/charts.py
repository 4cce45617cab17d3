"""Charts and files of knitted cells and their tensile tests: pictures of (relaxed or stretched)
cells, force-extension curves, the energy split over the extension (the knit paper's Fig. 24),
VTK with per-element energies."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model.frame import Frame
from ..model.results import ENERGY_KEYS
from ..output.charts import _tag, pyplot, save

__all__ = ["draw_cell", "energy_split_chart", "knit_picture", "state_frame", "tensile_chart", "write_state_vtk"]

#: the energy split's names as the paper calls them (section axes e2 / e3 of the yarn's material frame)
SPLIT = {"axial": "axial", "torsion": "torsion", "bending_y": "bending about e2 (s-axis)",
         "bending_z": "bending about e3 (t-axis)", "shear": "shear (Timoshenko)", "contact_energy": "contact",
         "friction_energy": "friction dissipated"}


def state_frame(frame: Frame, x: np.ndarray, periods: np.ndarray) -> Frame:
    """The frame with its nodes at positions x (n, 3) and lattice vectors ``periods`` (mm)."""
    return Frame(x, frame.elements, periods=periods, images=frame.images, **frame.element_fields())


def knit_picture(frame: Frame, path, *, tiles=(3, 3), title: str = "", colour=None):
    """PNG of a knitted cell tiled ``tiles`` = (along the courses, along the wales) times: the
    technical face (x along the courses, y along the wales) and a section through the thickness
    (x, z); line width about the yarn's diameter, each course (or ``colour`` (m,) int) its own colour."""
    plt = pyplot()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 5.5), gridspec_kw={"width_ratios": [1.2, 1]})
    draw_cell(ax, bx, frame, tiles=tiles, colour=colour)
    ax.set_title("technical face", fontsize=9)
    bx.set_title("section, one row of cells", fontsize=9)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save(fig, path)


def draw_cell(ax, bx, frame: Frame, *, tiles=(3, 3), colour=None) -> None:
    """Draw a knitted cell tiled ``tiles`` times on matplotlib axes: ``ax`` the technical face
    (x, y), ``bx`` the section through the thickness (x, z) of one row of cells (mm)."""
    plt = pyplot()
    a = frame.nodes[frame.elements[:, 0]]
    b = a + frame.element_vectors
    P = frame.periods
    col = frame.yarn if colour is None else np.asarray(colour)
    cmap = plt.get_cmap("tab10")
    span = max(tiles[0] * np.linalg.norm(P[0]), tiles[1] * np.linalg.norm(P[1]))
    width_pt = 2 * float(frame.contact_radius.mean()) / span * 5.0 * 72
    for i in range(tiles[0]):
        for j in range(tiles[1]):
            s = i * P[0] + j * P[1]
            for c in np.unique(col):
                e = np.flatnonzero(col == c)
                xs = np.column_stack([a[e, 0] + s[0], b[e, 0] + s[0], np.full(len(e), np.nan)]).ravel()
                ys = np.column_stack([a[e, 1] + s[1], b[e, 1] + s[1], np.full(len(e), np.nan)]).ravel()
                zs = np.column_stack([a[e, 2] + s[2], b[e, 2] + s[2], np.full(len(e), np.nan)]).ravel()
                kw = dict(color=cmap(int(c) % 10), lw=max(0.6, width_pt), solid_capstyle="round")
                ax.plot(xs, ys, **kw)
                if j == 0:
                    bx.plot(xs, zs, **kw)
    for axis, ylab in ((ax, "y (along the wales), mm"), (bx, "z (through the thickness), mm")):
        axis.set_aspect("equal")
        axis.set_xlabel("x (along the courses), mm")
        axis.set_ylabel(ylab)


def tensile_chart(curves: dict, *, title: str = "", per_width: bool = True, marks: dict | None = None):
    """Force (per width) against strain for {label: tensile Dataset}; ``marks`` {label: (strain,
    value, text)} annotates points."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.8))
    var = "force_per_width" if per_width else "force"
    for label, ds in curves.items():
        ax.plot(100 * ds.strain.values, ds[var].values, marker=".", label=label)
    for label, (x, y, text) in (marks or {}).items():
        ax.annotate(text, (100 * x, y), textcoords="offset points", xytext=(-60, 15), fontsize=8,
                    arrowprops={"arrowstyle": "->", "lw": 0.6})
    ax.set_xlabel("strain (extension / gauge length), %")
    _tag(ax, "N/mm" if per_width else "N", "force per width" if per_width else "force", *ax.lines)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


def energy_split_chart(ds, *, title: str = "", log: bool = True):
    """The deformation energy split over the extension (mm), as the knit paper's Fig. 24 (Eq. 8):
    each mechanism and the total stored energy; right panel each term's share of the stored energy."""
    plt = pyplot()
    ext = ds.extension.values
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(12, 4.8))
    stored = sum(ds[k].values for k in ENERGY_KEYS) + ds.contact_energy.values
    for k, label in SPLIT.items():
        v = ds[k].values
        if not np.any(v > 0):
            continue
        ax.plot(ext, v, label=label)
        if k != "friction_energy":
            bx.plot(ext, 100 * v / np.where(stored > 0, stored, 1.0), label=label)
    ax.plot(ext, stored, "k--", label="total stored (strain + contact)")
    ax.plot(ext, ds.external_work.values, "k:", label="external work (from the start)")
    if log:
        ax.set_yscale("log")
    ax.set_xlabel("extension, mm")
    ax.set_ylabel("energy, N mm")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    bx.set_xlabel("extension, mm")
    bx.set_ylabel("share of the stored energy, %")
    bx.grid(alpha=0.3)
    bx.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def write_state_vtk(frame: Frame, x, periods, element_energy, path) -> Path:
    """VTK of a state with its per-element strain energy (N mm) and the split of :data:`ENERGY_KEYS`
    when ``element_energy`` is (m, 5)."""
    from ..output.vtk import write_vtk

    ee = np.asarray(element_energy, dtype=float)
    fields = {"strain_energy": ee.sum(axis=1) if ee.ndim == 2 else ee}
    if ee.ndim == 2:
        fields.update({k: ee[:, j] for j, k in enumerate(ENERGY_KEYS)})
    return write_vtk(state_frame(frame, x, periods), Path(path), fields)
