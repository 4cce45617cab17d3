"""Which parts of a structure are held: connected components and their free rigid motions.

A part is a connected component over the elements (and extra edges such as active contacts);
it is held when its constrained DOFs remove every rigid motion that periodicity allows it.
Failures name the yarns and nodes of each free part.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import SolverError

__all__ = ["check_held", "components", "singular_diagnosis", "unheld_parts", "weak_elements"]

MOTION_NAMES = ("translation x", "translation y", "translation z",
                "rotation about x", "rotation about y", "rotation about z")


@njit(cache=True)
def _components(n, node_ptr, nbr, nbr_img, k):
    """Connected components by BFS, with each node's lattice image tau (n, k)."""
    label = np.full(n, -1, dtype=np.int64)
    tau = np.zeros((n, k), dtype=np.int64)
    queue = np.empty(n, dtype=np.int64)
    c = 0
    for s in range(n):
        if label[s] >= 0:
            continue
        label[s] = c
        head = 0
        tail = 0
        queue[tail] = s
        tail += 1
        while head < tail:
            a = queue[head]
            head += 1
            for p in range(node_ptr[a], node_ptr[a + 1]):
                b = nbr[p]
                if label[b] < 0:
                    label[b] = c
                    for q in range(k):
                        tau[b, q] = tau[a, q] + nbr_img[p, q]
                    queue[tail] = b
                    tail += 1
        c += 1
    return label, tau


def components(n_nodes, edges, edge_images):
    """Component label (n,) and lattice image tau (n, k) of every node.

    ``edges`` (p, 2) joins node i to node j shifted by ``edge_images`` (p, k).
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    img = np.asarray(edge_images, dtype=np.int64).reshape(len(edges), -1)
    k = img.shape[1]
    src = np.concatenate([edges[:, 0], edges[:, 1]])
    dst = np.concatenate([edges[:, 1], edges[:, 0]])
    dimg = np.concatenate([img, -img])
    order = np.argsort(src, kind="stable")
    ptr = np.zeros(n_nodes + 1, dtype=np.int64)
    np.cumsum(np.bincount(src, minlength=n_nodes), out=ptr[1:])
    return _components(n_nodes, ptr, np.ascontiguousarray(dst[order]),
                       np.ascontiguousarray(dimg[order]), k)


def _ranges(idx) -> str:
    idx = np.sort(np.asarray(idx))
    if idx.size == 0:
        return ""
    breaks = np.flatnonzero(np.diff(idx) != 1)
    starts = np.concatenate([[idx[0]], idx[breaks + 1]])
    ends = np.concatenate([idx[breaks], [idx[-1]]])
    parts = [f"{a}" if a == b else f"{a}-{b}" for a, b in zip(starts, ends)]
    if len(parts) > 6:
        parts = parts[:6] + [f"... ({len(idx)} nodes)"]
    return ", ".join(parts)


def unheld_parts(frame, mask, extra_edges=None, extra_images=None, tol=1e-10):
    """Parts of the structure that the constraints do not hold.

    A part (connected component over elements and ``extra_edges``, e.g. active
    contacts) is held when its constrained DOFs remove every rigid motion that
    periodicity allows it. Returns a list of dicts with ``nodes``, ``yarns`` and
    ``free`` (names of the free rigid motions); empty when all is held.
    """
    n = frame.n_nodes
    k = frame.dim_periodic
    edges = frame.elements
    imgs = frame.images
    if extra_edges is not None and len(extra_edges):
        edges = np.vstack([edges, np.asarray(extra_edges, dtype=np.int64).reshape(-1, 2)])
        ei = (np.zeros((len(extra_edges), k), dtype=np.int64) if extra_images is None
              else np.asarray(extra_images, dtype=np.int64).reshape(len(extra_edges), k))
        imgs = np.vstack([imgs, ei])
    label, tau = components(n, edges, imgs)
    ncomp = int(label.max()) + 1
    x = frame.nodes + (tau @ frame.periods if k else 0.0)
    # cycle images: lattice vectors along which a part wraps (it cannot rotate about others)
    wraps = np.zeros((ncomp, 3, 3))
    if k:
        c = tau[edges[:, 0]] + imgs - tau[edges[:, 1]]
        w = c @ frame.periods
        nz = np.any(c != 0, axis=1)
        if nz.any():
            wn = w[nz] / np.linalg.norm(w[nz], axis=1)[:, None]
            np.add.at(wraps, label[edges[nz, 0]], np.eye(3)[None] - wn[:, :, None] * wn[:, None, :])
    centers = np.zeros((ncomp, 3))
    np.add.at(centers, label, x)
    centers /= np.bincount(label, minlength=ncomp)[:, None]
    d = x - centers[label]
    size = np.zeros(ncomp)
    np.maximum.at(size, label, np.abs(d).max(axis=1))
    d /= np.maximum(size[label], 1e-300)[:, None]
    B = np.zeros((n, 6, 6))
    for q in range(3):
        B[:, q, q] = 1.0
        B[:, 3 + q, 3 + q] = 1.0
    B[:, 1, 3], B[:, 2, 3] = -d[:, 2], d[:, 1]
    B[:, 0, 4], B[:, 2, 4] = d[:, 2], -d[:, 0]
    B[:, 0, 5], B[:, 1, 5] = -d[:, 1], d[:, 0]
    rows = B.reshape(6 * n, 6)[mask]
    owner = label[np.flatnonzero(mask) // 6]
    G = np.zeros((ncomp, 6, 6))
    np.add.at(G, owner, rows[:, :, None] * rows[:, None, :])
    out = []
    for comp in range(ncomp):
        # allowed rotations: null space of sum (I - w w^T) over wrap directions
        if k and np.any(wraps[comp]):
            ew, ev = np.linalg.eigh(wraps[comp])
            rot = ev[:, ew < 1e-9 * max(ew.max(), 1.0)]
        else:
            rot = np.eye(3)
        Q = np.zeros((6, 3 + rot.shape[1]))
        Q[:3, :3] = np.eye(3)
        Q[3:, 3:] = rot
        Gc = Q.T @ G[comp] @ Q
        ew, ev = np.linalg.eigh(Gc)
        free = ev[:, ew < tol]
        if free.shape[1] == 0:
            continue
        motions = Q @ free
        names = [MOTION_NAMES[i] for i in range(6) if np.abs(motions[i]).max() > 1e-6]
        nodes = np.flatnonzero(label == comp)
        in_comp = label[frame.elements[:, 0]] == comp
        out.append({"nodes": nodes, "yarns": np.unique(frame.yarn[in_comp]).tolist(),
                    "free": names, "elements": np.flatnonzero(in_comp)})
    return out


def check_held(frame, mask, extra_edges=None, extra_images=None):
    """Raise SolverError naming every part of the structure that nothing holds."""
    parts = unheld_parts(frame, mask, extra_edges, extra_images)
    if not parts:
        return
    lines = []
    for p in parts[:10]:
        lines.append(f"  yarn(s) {p['yarns']} (nodes {_ranges(p['nodes'])}) is free to move: "
                     f"{', '.join(p['free'])}")
    more = f"\n  ... and {len(parts) - 10} more parts" if len(parts) > 10 else ""
    raise SolverError(f"{len(parts)} part(s) of the structure are held by nothing "
                      f"(singular stiffness):\n" + "\n".join(lines) + more +
                      "\nAdd supports (or contacts) that hold them.")


def weak_elements(frame, rel: float = 1e-10) -> np.ndarray:
    """Elements whose axial (EA/L), bending (E I_min/L^3) or torsional (GJ/L) stiffness is below
    ``rel`` x the median of the frame's: against the others they hold nothing, and the stiffness
    matrix is singular in double precision (an E of 1e-30 MPa among yarns of 1000 MPa)."""
    L = frame.length
    measures = (frame.E * frame.A / L, frame.E * np.minimum(frame.Iy, frame.Iz) / L ** 3, frame.G * frame.J / L)
    weak = np.zeros(frame.n_elements, dtype=bool)
    for k in measures:
        med = float(np.median(k))
        if med > 0:
            weak |= k < rel * med
    return np.flatnonzero(weak)


def singular_diagnosis(frame, mask=None) -> str:
    """What makes the stiffness matrix of ``frame`` singular, in lines naming yarns, nodes and
    elements: parts that the supports ``mask`` (6n,) do not hold (when given), and elements of
    almost no stiffness (:func:`weak_elements`); "" when neither is found."""
    lines = []
    if mask is not None:
        for p in unheld_parts(frame, mask)[:10]:
            lines.append(f"  yarn(s) {p['yarns']} (nodes {_ranges(p['nodes'])}) is held by nothing: "
                         f"{', '.join(p['free'])} free; add supports for it")
    weak = weak_elements(frame)
    for e in weak[:10]:
        lines.append(f"  element {int(e)} (yarn {int(frame.yarn[e])}, nodes {frame.elements[e].tolist()}) has almost "
                     f"no stiffness against the others (E {frame.E[e]:.3g} MPa, A {frame.A[e]:.3g} mm^2, length "
                     f"{frame.length[e]:.3g} mm): fix its properties or remove it")
    if len(weak) > 10:
        lines.append(f"  ... and {len(weak) - 10} more such elements")
    return "\n".join(lines)
