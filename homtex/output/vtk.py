"""VTK export of frames for ParaView (meshio, optional dependency)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError

try:  # optional
    import meshio
except ImportError:  # pragma: no cover - depends on the environment
    meshio = None

HAVE_MESHIO = meshio is not None


def write_vtk(frame, path, fields: dict | None = None) -> Path:
    """Write a frame as VTK (.vtu) line cells with per-element data.

    Parameters
    ----------
    frame : homtex.Frame (elements crossing the periodic boundary are written unwrapped:
        their second node is duplicated at its shifted position).
    path : output file (.vtu / .vtk).
    fields : {name: (m,) or (m, c) array} per-element data, e.g. axial force (N), bending
        moment (N mm), energy (N mm). ``yarn`` is always written.

    Raises InputError when meshio is not installed or a field has the wrong length.
    """
    if meshio is None:
        raise InputError("write_vtk needs the optional package 'meshio' (pip install meshio)")
    m = frame.n_elements
    a = frame.nodes[frame.elements[:, 0]]
    b = a + frame.element_vectors
    pts = np.vstack([a, b])
    cells = np.column_stack([np.arange(m), np.arange(m) + m])
    data = {"yarn": [frame.yarn.astype(np.int64)]}
    for name, v in (fields or {}).items():
        v = np.asarray(v, dtype=float)
        if v.shape[0] != m:
            raise InputError(f"write_vtk: field {name!r} has {v.shape[0]} rows, the frame has {m} elements")
        data[name] = [v]
    mesh = meshio.Mesh(pts, [("line", cells)], cell_data=data)
    path = Path(path)
    mesh.write(path)
    return path
