"""Rest states of yarns: the stress-free shape, apart from the geometry a solve starts from.

A co-rotational element (:mod:`homtex.fem.corotational`) is stress-free when its length is its
rest length and each end's rotated rest frame ``Q_a E0_a^T`` equals the element's co-rotated
frame. By default the start geometry is the rest state (``E0_a`` the element's initial frame at
both ends, the rest length its initial length). A :class:`RestState` gives every element its own
rest length (mm) and a rest frame per end, so a knitted loop generated bent can be a straight
yarn at rest: its bending, twist and the energy split then count from the rest shape.

Straight (or naturally curved and twisted) rest shapes of yarn chains, :func:`straight_rest`:
each node gets a material frame ``D_k`` (columns t, n1, n2: the tangent, the bisector of its two
elements' directions, and two normals parallel-transported along the chain, so the start carries
no spurious twist); an element end at node a is stress-free when its co-rotated frame, rotated by
the rest end rotation ``theta_r``, equals the node's current material frame:

    Er^T Q_a D_a = exp(theta_r,a),   i.e.   E0_a = exp(theta_r,a) D_a^T,

with ``theta_r`` = -/+ L/2 (twist, kappa_2, kappa_3) at the first / second end for a natural twist
(rad/mm) and curvature about the frames' n1 and n2 axes (1/mm), zero for a straight untwisted
yarn (then E0_a = D_a^T). A closed chain (a ring, or a yarn closing over the periodic boundary)
whose transported frame comes back turned by phi about the tangent gets that turn spread evenly
over its length: the start then has the twist phi / length that the closed geometry forces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import InputError

__all__ = ["RestState", "chains", "node_frames", "start_rest", "straight_rest"]


@dataclass
class RestState:
    """Rest length (m,) (mm) and per-end rest frames (m, 2, 3, 3) (rows e1, e2, e3) of every element."""

    length: np.ndarray
    frames: np.ndarray

    def check(self, frame) -> "RestState":
        """InputError unless the arrays fit ``frame`` (m elements, positive lengths, rotations)."""
        m = frame.n_elements
        L = np.asarray(self.length, dtype=float)
        F = np.asarray(self.frames, dtype=float)
        if L.shape != (m,) or F.shape != (m, 2, 3, 3):
            raise InputError(f"rest: length must have shape ({m},) and frames ({m}, 2, 3, 3) for this frame, got "
                             f"{L.shape} and {F.shape}")
        if not (np.all(np.isfinite(L)) and np.all(L > 0)):
            e = int(np.flatnonzero(~(np.isfinite(L) & (L > 0)))[0])
            raise InputError(f"rest: element {e} (yarn {frame.yarn[e]}) has rest length {L[e]!r}; rest lengths must "
                             "be positive (mm)")
        err = np.abs(np.einsum("meij,mekj->meik", F, F) - np.eye(3)).max(axis=(1, 2, 3))
        if not np.all(err < 1e-8):
            e = int(np.flatnonzero(~(err < 1e-8))[0])
            raise InputError(f"rest: the rest frames of element {e} (yarn {frame.yarn[e]}) are not rotations")
        self.length = np.ascontiguousarray(L)
        self.frames = np.ascontiguousarray(F)
        return self

    def moved(self, Q: np.ndarray, elements: np.ndarray) -> "RestState":
        """The rest state seen from a deformed state with nodal rotations Q (n, 3, 3), as the rest
        state of a frame whose nodes are that state's positions (so a relaxed cell can be the
        start of the next solve): E0_a -> E0_a Q_a^T."""
        el = np.asarray(elements, dtype=np.int64)
        F = np.empty_like(self.frames)
        F[:, 0] = np.einsum("mij,mkj->mik", self.frames[:, 0], Q[el[:, 0]])
        F[:, 1] = np.einsum("mij,mkj->mik", self.frames[:, 1], Q[el[:, 1]])
        return RestState(length=self.length.copy(), frames=np.ascontiguousarray(F))

    def select(self, idx) -> "RestState":
        """The rest state of elements ``idx`` (an index array may repeat elements: tiling)."""
        return RestState(length=np.ascontiguousarray(self.length[idx]),
                         frames=np.ascontiguousarray(self.frames[idx]))


def start_rest(frame) -> RestState:
    """The start geometry as the rest state (what the engine does without one)."""
    return RestState(length=frame.length.copy(),
                     frames=np.ascontiguousarray(np.repeat(frame.R[:, None], 2, axis=1)))


# ---------------------------------------------------------------------------------------------
def chains(frame) -> list:
    """The yarn chains of a frame: a list of (elements (c,), forward (c,) bool, closed) with the
    elements in order along the chain, ``forward`` True where the element runs i -> j along it.
    InputError where a node joins more than two elements (a branched frame has no chain)."""
    el = frame.elements
    n, m = frame.n_nodes, frame.n_elements
    deg = np.bincount(el.ravel(), minlength=n)
    if deg.max(initial=0) > 2:
        k = int(np.flatnonzero(deg > 2)[0])
        raise InputError(f"rest: node {k} joins {int(deg[k])} elements; straight rest shapes need yarn chains "
                         "(every node joins at most two elements)")
    inc = [[] for _ in range(n)]
    for e in range(m):
        inc[el[e, 0]].append(e)
        inc[el[e, 1]].append(e)
    used = np.zeros(m, dtype=bool)
    out = []

    def walk(e, node):
        """Follow the chain from element e entered at node; returns (elements, forward, closed)."""
        es, fw = [], []
        start = node
        while True:
            used[e] = True
            f = el[e, 0] == node
            es.append(e)
            fw.append(bool(f))
            node = el[e, 1] if f else el[e, 0]
            nxt = [g for g in inc[node] if g != e]
            if not nxt:
                return es, fw, False
            if used[nxt[0]]:
                return es, fw, node == start
            e = nxt[0]

    for k in np.flatnonzero(deg == 1):
        e = inc[k][0]
        if not used[e]:
            out.append(walk(e, k))
    for e in range(m):
        if not used[e]:
            out.append(walk(e, el[e, 0]))
    return [(np.array(a, dtype=np.int64), np.array(b, dtype=bool), c) for a, b, c in out]


@njit(cache=True)
def _rotate_to(D, a, b, out):
    """out (3, 3) = the minimal rotation taking unit a to unit b, applied to D (3, 3)."""
    c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    vx = a[1] * b[2] - a[2] * b[1]
    vy = a[2] * b[0] - a[0] * b[2]
    vz = a[0] * b[1] - a[1] * b[0]
    if c < -1.0 + 1e-12:
        raise ValueError("a chain turns back on itself (antiparallel neighbouring elements)")
    k = 1.0 / (1.0 + c)
    R = np.empty((3, 3))
    R[0, 0] = c + k * vx * vx
    R[0, 1] = k * vx * vy - vz
    R[0, 2] = k * vx * vz + vy
    R[1, 0] = k * vy * vx + vz
    R[1, 1] = c + k * vy * vy
    R[1, 2] = k * vy * vz - vx
    R[2, 0] = k * vz * vx - vy
    R[2, 1] = k * vz * vy + vx
    R[2, 2] = c + k * vz * vz
    for i in range(3):
        for j in range(3):
            out[i, j] = R[i, 0] * D[0, j] + R[i, 1] * D[1, j] + R[i, 2] * D[2, j]


@njit(cache=True)
def _transport(T, D0, out):
    """Parallel transport of frame D0 (columns) along unit tangents T (k, 3) into out (k, 3, 3)."""
    out[0] = D0
    for q in range(1, T.shape[0]):
        _rotate_to(out[q - 1], T[q - 1], T[q], out[q])


def _turn(D, axis, angle):
    """D (k, 3, 3) turned about unit axes (k, 3) by angles (k,) (Rodrigues)."""
    c, s = np.cos(angle)[:, None, None], np.sin(angle)[:, None, None]
    K = np.zeros((len(axis), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K = K - np.transpose(K, (0, 2, 1))
    R = np.eye(3) + s * K + (1.0 - c) * K @ K
    return R @ D


def node_frames(frame) -> np.ndarray:
    """(n, 3, 3) material frames of the nodes (columns t, n1, n2), parallel-transported along each
    chain from the local frame of its first element (see the module docstring)."""
    n = frame.n_nodes
    vec = frame.element_vectors
    D = np.zeros((n, 3, 3))
    for es, fw, closed in chains(frame):
        d = np.where(fw[:, None], vec[es], -vec[es])
        u = d / np.linalg.norm(d, axis=1)[:, None]
        el = frame.elements[es]
        first = np.where(fw, el[:, 0], el[:, 1])          # node entered by each element
        if closed:
            t = u + np.roll(u, 1, axis=0)                   # node q sits between elements q-1 and q
        else:
            t = np.vstack([u[:1], u[:-1] + u[1:], u[-1:]])
            first = np.r_[first, el[-1, 1] if fw[-1] else el[-1, 0]]
        t /= np.linalg.norm(t, axis=1)[:, None]
        e2 = frame.R[es[0], 1]
        n1 = e2 - (e2 @ t[0]) * t[0]
        if np.linalg.norm(n1) < 1e-8:
            n1 = np.cross(t[0], [1.0, 0.0, 0.0] if abs(t[0, 0]) < 0.9 else [0.0, 1.0, 0.0])
        n1 /= np.linalg.norm(n1)
        D0 = np.column_stack([t[0], n1, np.cross(t[0], n1)])
        F = np.empty((len(t), 3, 3))
        try:
            _transport(np.ascontiguousarray(t), D0, F)
        except ValueError:
            raise InputError(f"rest: yarn {frame.yarn[es[0]]} turns back on itself between two neighbouring "
                             "elements (antiparallel); no rest frame can be transported there") from None
        if closed:
            back = np.empty((3, 3))
            _rotate_to(F[-1], t[-1], t[0], back)
            phi = np.arctan2(back[:, 1] @ F[0][:, 2], back[:, 1] @ F[0][:, 1])   # turn of back about t0
            L = np.linalg.norm(d, axis=1)
            s = np.r_[0.0, np.cumsum(L)[:-1]] / L.sum()
            F = _turn(F, t, -phi * s)
        D[first[:len(F)]] = F
    return D


def straight_rest(frame, *, twist=0.0, curvature=None) -> RestState:
    """A straight rest state for the yarn chains of ``frame`` (see the module docstring).

    Parameters
    ----------
    frame : homtex.Frame whose nodes join at most two elements (yarn chains, open, closed or
        closing over the periodic boundary).
    twist : natural twist rate, rad/mm: scalar or (m,) (default 0).
    curvature : natural curvature about the material frames' n1 and n2 axes, 1/mm: (2,) or (m, 2)
        (default straight).

    Returns a :class:`RestState` (rest length = the element's length in the start geometry).
    """
    m = frame.n_elements
    tw = np.broadcast_to(np.asarray(twist, dtype=float), (m,))
    kap = np.zeros((m, 2)) if curvature is None else np.broadcast_to(np.asarray(curvature, dtype=float), (m, 2))
    if not (np.all(np.isfinite(tw)) and np.all(np.isfinite(kap))):
        raise InputError("rest: twist and curvature must be finite (rad/mm, 1/mm)")
    D = node_frames(frame)
    el = frame.elements
    vec = frame.element_vectors
    L = frame.length
    F = np.empty((m, 2, 3, 3))
    for end in range(2):
        De = D[el[:, end]].copy()
        # an element running against its chain's direction sees the frame turned by pi about n1
        back = np.einsum("mi,mi->m", De[:, :, 0], vec) < 0
        De[back] = De[back] * np.array([-1.0, 1.0, -1.0])
        F[:, end] = np.transpose(De, (0, 2, 1))
    theta = 0.5 * L[:, None] * np.column_stack([tw, kap])
    ang = np.linalg.norm(theta, axis=1)
    if np.any(ang > 0):
        # E0_a = exp(theta_r,a) D_a^T with theta_r = -theta (first end), +theta (second end)
        ax = theta / np.where(ang > 0, ang, 1.0)[:, None]
        F[:, 0] = _turn(F[:, 0], ax, -ang)
        F[:, 1] = _turn(F[:, 1], ax, ang)
    return RestState(length=L.copy(), frames=np.ascontiguousarray(F)).check(frame)
