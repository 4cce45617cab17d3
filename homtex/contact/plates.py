"""Yarn-plate contact for large motion: rigid planes, node gap g = n . (x - p) - r.

The node radius r is the node's contact radius (e.g. :func:`homtex.contact.constraints.node_contact_radius`);
a straight segment is never closer to a plane than its nearer end, so node gaps are exact for
the yarn's centre line. The enforcement is that of :mod:`.potential` (barrier or C2 penalty).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .potential import ContactEval, Enforcement, _positions


def _plates(origin, normal):
    o = np.ascontiguousarray(np.asarray(origin, dtype=float).reshape(-1, 3))
    nr = np.asarray(normal, dtype=float).reshape(-1, 3)
    if len(o) != len(nr):
        raise InputError(f"origin and normal need one row per plate, got {len(o)} and {len(nr)}")
    nn = np.linalg.norm(nr, axis=1)
    if not (np.isfinite(o).all() and np.isfinite(nr).all() and (nn > 0).all()):
        raise InputError("plate origin and normal must be finite, normals non-zero")
    return o, np.ascontiguousarray(nr / nn[:, None])


def _plate_args(x, nodes, radius, plate, n_plates):
    nodes = np.ascontiguousarray(nodes, dtype=np.int64).ravel()
    p = len(nodes)
    radius = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, dtype=float), (p,)))
    plate = np.ascontiguousarray(np.broadcast_to(np.asarray(plate, dtype=np.int64), (p,)))
    if p and (nodes.min() < 0 or nodes.max() >= len(x)):
        raise InputError(f"nodes must index x (0..{len(x) - 1})")
    if not (np.isfinite(radius).all() and (radius >= 0).all()):
        raise InputError("radius (node contact radius, mm) must be finite and >= 0")
    if p and (plate.min() < 0 or plate.max() >= n_plates):
        raise InputError(f"plate must index the {n_plates} plates")
    return nodes, radius, plate


def plate_gaps(x, nodes, radius, origin, normal, plate=0) -> np.ndarray:
    """(p,) gaps (mm) of nodes against their plates: n . (x - origin) - radius."""
    x = _positions(x)
    o, nr = _plates(origin, normal)
    nodes, radius, plate = _plate_args(x, nodes, radius, plate, len(o))
    return np.einsum("ij,ij->i", x[nodes] - o[plate], nr[plate]) - radius


def plate_potential(x, nodes, radius, origin, normal, enforcement: Enforcement, plate=0,
                    hessian: bool = True) -> ContactEval:
    """Node-plate contact potential at node positions x (n, 3).

    Parameters
    ----------
    nodes : (p,) candidate nodes; radius : (p,) or scalar node contact radius (mm);
    origin, normal : (P, 3) a point of each plate and its normal towards the yarns (mm);
    plate : (p,) or scalar plate of each candidate.

    Returns a :class:`ContactEval` with 3 x 3 blocks (exact and positive semi-definite: the
    enforcement is convex and the gap linear) and ``plate_force`` (P, 3), the force of the
    yarns on each plate (N).
    """
    x = _positions(x)
    o, nr = _plates(origin, normal)
    nodes, radius, plate = _plate_args(x, nodes, radius, plate, len(o))
    gap = np.einsum("ij,ij->i", x[nodes] - o[plate], nr[plate]) - radius
    idx = np.flatnonzero(gap < enforcement.cutoff)
    e, e1, e2 = enforcement.energy(gap[idx])
    nvec = nr[plate[idx]]
    grad = np.zeros_like(x)
    energy = float(e.sum())
    lam = np.zeros(len(nodes))
    lam[idx] = -e1
    pf = np.zeros((len(o), 3))
    if np.isfinite(energy):             # (a barrier at a gap <= 0: infinite energy, no forces)
        np.add.at(grad, nodes[idx], e1[:, None] * nvec)
        np.add.at(pf, plate[idx], e1[:, None] * nvec)
    H = e2[:, None, None] * nvec[:, :, None] * nvec[:, None, :] if hessian else None
    return ContactEval(energy=energy, grad=grad, gap=gap, lam=lam, active=idx, hess=H,
                       hess_nodes=nodes[idx][:, None], plate_force=pf)
