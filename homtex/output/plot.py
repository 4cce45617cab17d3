"""PNG charts of cells and cushion profiles (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

_COLORS = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:gray"]


def plot_cell(cell_or_frame, path, *, groups: dict | None = None, view: tuple = (20.0, -60.0),
              title: str | None = None) -> Path:
    """Write a 3D PNG of a frame, each element group (yarn system) in its own colour.

    cell_or_frame : Frame or Cell (its ``groups`` colour the yarn systems); path : PNG file.
    Elements crossing the periodic boundary are drawn at their unwrapped position.
    title : default the cell's name and size.
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
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_zlabel("z, mm")
    ax.view_init(*view)
    if title is None:
        name = getattr(cell_or_frame, "name", "frame")
        title = f"{name}: {fr.n_elements} elements, {fr.ndof} DOF"
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_profile(profile, path, *, periods: int = 3) -> Path:
    """Write a chart of a cushion profile (``seam_profile`` Dataset) next to the flat fabric:
    :func:`homtex.output.charts.seam_profile_chart` (seams at the effective seam distance, both
    panels on the same y range)."""
    from .charts import save, seam_profile_chart

    return save(seam_profile_chart(profile, periods=periods), path, dpi=120)
