"""PNG charts of cells and cushion profiles (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

_COLORS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:gray"]


def plot_cell(cell_or_frame, path, *, groups: dict | None = None, view: tuple = (20.0, -60.0)) -> Path:
    """Write a 3D PNG of a frame, each element group (yarn system) in its own colour.

    cell_or_frame : Frame or Cell (its ``groups`` colour the yarn systems); path : PNG file.
    Elements crossing the periodic boundary are drawn at their unwrapped position.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fr = getattr(cell_or_frame, "frame", cell_or_frame)
    if groups is None:
        groups = getattr(cell_or_frame, "groups", None) or {"yarns": np.ones(fr.n_elements, bool)}
    a = fr.nodes[fr.elements[:, 0]]
    b = a + fr.element_vectors
    fig = plt.figure(figsize=(6, 6))
    ax = fig.add_subplot(projection="3d")
    for i, (name, mask) in enumerate(groups.items()):
        idx = np.flatnonzero(mask)
        xs = np.column_stack([a[idx, 0], b[idx, 0], np.full(len(idx), np.nan)]).ravel()
        ys = np.column_stack([a[idx, 1], b[idx, 1], np.full(len(idx), np.nan)]).ravel()
        zs = np.column_stack([a[idx, 2], b[idx, 2], np.full(len(idx), np.nan)]).ravel()
        ax.plot(xs, ys, zs, color=_COLORS[i % len(_COLORS)], lw=1.5, label=name)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.view_init(*view)
    ax.legend(fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_profile(profile, path, *, thickness: float | None = None, periods: int = 3) -> Path:
    """Write a PNG of a cushion profile (``seam_profile`` Dataset) next to the flat fabric.

    The profile is repeated over ``periods`` seam distances; the flat fabric (thickness,
    default the profile's ``thickness_mm`` attribute) is drawn beside it.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    H = float(thickness if thickness is not None else profile.attrs.get("thickness_mm", profile.height.max()))
    d = float(profile.attrs.get("seam_distance_mm", float(profile.x[-1] - profile.x[0])))
    x = profile.x.values
    h = profile.height.values
    fig, ax = plt.subplots(2, 1, figsize=(8, 4), sharex=True)
    for k in range(periods):
        xx = x + k * d
        ax[0].fill_between(xx, 0.5 * (H - h), 0.5 * (H + h), color="tab:blue", alpha=0.5, lw=0)
        ax[0].axvline(k * d, color="k", lw=0.8)
    ax[0].set(ylabel="z (mm)", title=f"seamed, d = {d:g} mm, cushion height {float(profile.cushion_height):.2f} mm")
    ax[1].fill_between([x[0], x[0] + periods * d], 0, H, color="tab:gray", alpha=0.5, lw=0)
    ax[1].set(xlabel="x across the seams (mm)", ylabel="z (mm)", title=f"flat fabric, {H:g} mm")
    for a in ax:
        a.set_aspect("equal")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
