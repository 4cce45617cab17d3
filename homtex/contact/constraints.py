"""Linearised contact constraints: yarn-yarn and node-plate rows.

Every candidate contact c gives one row of a sparse matrix C (M x 6N) and a gap g_c:

* yarn-yarn (elements a, b, b placed at image tau): closest points a(s), b(t), unit normal
  n from b to a, gap g = |a(s) - b(t)| - (r_a + r_b). The linearised constraint
  g + n . (u_a(s) - u_b(t)) >= 0 interpolates the translations of the four end nodes:
  u_a(s) = (1 - s) u_a0 + s u_a1 (periodic images share their node's displacement).
* node-plate: plate z = z_p (+ its displacement w), material side nu = +1 (above) or -1
  (below), gap g = nu (z_i - z_p) - r_i with r_i the largest contact radius at node i.
  The constraint is g + nu (u_z,i - w) >= 0; w is the plate's own DOF (an extra node).

The contact force lambda_c >= 0 (N) pushes the pair apart: f = C^T lambda.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .narrow import segment_pairs


@dataclass
class ContactSet:
    """Contacts of a solution (all candidates; ``active`` marks the closed ones).

    Yarn-yarn (c candidates): ``pairs`` (c, 2) element indices, ``image`` (c, k) periodic image
    of the second element, ``s``, ``t`` (c,) closest-point parameters on each element,
    ``normal`` (c, 3) unit normal from the second element to the first, ``gap`` (c,) gap at the
    linearisation point (mm, negative = overlap), ``gap_final`` (c,) linearised gap of the
    solution (mm), ``force`` (c,) normal force (N, >= 0 pushes apart), ``active`` (c,) bool.

    Yarn-plate (p candidates): ``plate_node`` (p,), ``plate`` (p,) plate index, ``plate_gap``,
    ``plate_gap_final`` (mm), ``plate_force`` (N), ``plate_active``.

    ``tangential_force`` (c, 3) is zero: frictionless contact (room for Coulomb friction).
    """

    pairs: np.ndarray
    image: np.ndarray
    s: np.ndarray
    t: np.ndarray
    normal: np.ndarray
    gap: np.ndarray
    gap_final: np.ndarray
    force: np.ndarray
    active: np.ndarray
    plate_node: np.ndarray
    plate: np.ndarray
    plate_gap: np.ndarray
    plate_gap_final: np.ndarray
    plate_force: np.ndarray
    plate_active: np.ndarray
    plates: list = field(default_factory=list)
    tangential_force: np.ndarray | None = None

    @property
    def n_active(self) -> int:
        return int(self.active.sum() + self.plate_active.sum())

    @property
    def n_yarn(self) -> int:
        return int(self.active.sum())

    @property
    def n_plate(self) -> int:
        return int(self.plate_active.sum())

    @property
    def max_penetration(self) -> float:
        """Largest linearised overlap of the solution over all candidates, mm (0 if none)."""
        v = np.concatenate([-self.gap_final, -self.plate_gap_final, [0.0]])
        return float(max(v.max(), 0.0))

    def plate_forces(self) -> np.ndarray:
        """(n_plates,) force each plate receives from the yarns, N (compressive positive)."""
        out = np.zeros(len(self.plates))
        np.add.at(out, self.plate, self.plate_force)
        return out

    def __repr__(self) -> str:
        return (f"ContactSet({self.n_yarn} active yarn-yarn of {len(self.active)} candidates, "
                f"{self.n_plate} active yarn-plate of {len(self.plate_active)})")


@dataclass
class Rows:
    """Candidate constraint rows at one linearisation point (yarn rows first, then plate rows)."""

    C: sp.csr_matrix           # (M, 6N)
    g: np.ndarray              # (M,) gap at the linearisation point, mm
    ea: np.ndarray             # (c,) element a
    eb: np.ndarray             # (c,) element b
    image: np.ndarray          # (c, k)
    s: np.ndarray
    t: np.ndarray
    normal: np.ndarray         # (c, 3)
    pnode: np.ndarray          # (p,) node of each plate row
    pidx: np.ndarray           # (p,) plate of each plate row
    keys: np.ndarray           # (M,) int64 identity of each candidate (for warm starts)

    @property
    def n_yarn(self) -> int:
        return len(self.ea)

    @property
    def M(self) -> int:
        return len(self.g)


def pair_keys(ea, eb, image, m):
    """int64 identity of yarn pairs (a, b, image): unique while |image| < 8."""
    key = ea.astype(np.int64) * m + eb.astype(np.int64)
    for q in range(image.shape[1]):
        key = key * 17 + (np.clip(image[:, q], -8, 8) + 8)
    return key * 2  # even: yarn pairs


def plate_keys(node, plate, n):
    return (plate.astype(np.int64) * n + node.astype(np.int64)) * 2 + 1  # odd: plate rows


def build_rows(frame, x, ea, eb, image, pnode, pidx, plates, plate_z, node_radius):
    """Constraint rows for given candidates at node positions ``x`` (n, 3).

    ``plate_z`` (P,) is the current height of each plate; rows refer to the
    N = n + P node layout (plate p is node n + p).
    """
    n = frame.n_nodes
    P = len(plates)
    N = n + P
    el = frame.elements
    k = frame.dim_periodic
    image = np.asarray(image, dtype=np.int64).reshape(len(ea), k)
    shift_e = frame.shift
    p0 = x[el[:, 0]]
    d = x[el[:, 1]] + shift_e - p0
    shift_b = image @ frame.periods if k else np.zeros((len(ea), 3))
    s, t, dist, nrm = segment_pairs(p0, d, ea, eb, shift_b)
    r = frame.contact_radius
    g_y = dist - (r[ea] + r[eb])
    c = len(ea)
    # yarn rows: 4 nodes x 3 translations
    nodes4 = np.stack([el[ea, 0], el[ea, 1], el[eb, 0], el[eb, 1]], axis=1)          # (c, 4)
    w4 = np.stack([1.0 - s, s, -(1.0 - t), -t], axis=1)                              # (c, 4)
    cols_y = (6 * nodes4[:, :, None] + np.arange(3)[None, None, :]).reshape(c, 12)
    vals_y = (w4[:, :, None] * nrm[:, None, :]).reshape(c, 12)
    rows_y = np.repeat(np.arange(c), 12)
    # plate rows
    p = len(pnode)
    nu = np.array([pl.normal for pl in plates], dtype=float)[pidx] if p else np.zeros(0)
    g_p = nu * (x[pnode, 2] - plate_z[pidx]) - node_radius[pnode] if p else np.zeros(0)
    rows_p = np.repeat(c + np.arange(p), 2)
    cols_p = np.stack([6 * pnode + 2, 6 * (n + pidx) + 2], axis=1).ravel()
    vals_p = np.stack([nu, -nu], axis=1).ravel()
    C = sp.csr_matrix((np.concatenate([vals_y.ravel(), vals_p]),
                       (np.concatenate([rows_y, rows_p]), np.concatenate([cols_y.ravel(), cols_p]))),
                      shape=(c + p, 6 * N))
    keys = np.concatenate([pair_keys(ea, eb, image, frame.n_elements), plate_keys(pnode, pidx, n)])
    return Rows(C=C, g=np.concatenate([g_y, g_p]), ea=np.asarray(ea, np.int64), eb=np.asarray(eb, np.int64),
                image=image, s=s, t=t, normal=nrm, pnode=np.asarray(pnode, np.int64),
                pidx=np.asarray(pidx, np.int64), keys=keys)


def point_keys(frame, ea, eb, image, s, t, tol: float = 1e-9) -> np.ndarray:
    """(c, 2 + k) int64 identity of the contact points of yarn-yarn candidates.

    A closest point at an element end (parameter clamped to 0 or 1) is the shared node
    (``node``, with its image), inside an element it is ``n + element``. Two candidates with
    equal keys give identical constraint rows (e.g. beams crossing at nodes: 4 element pairs,
    one node-node contact). Key = (lower code, higher code, relative image).
    """
    c = len(ea)
    n = frame.n_nodes
    el = frame.elements
    k = frame.dim_periodic
    img_el = frame.images
    image = np.asarray(image, dtype=np.int64).reshape(c, k)
    ea = np.asarray(ea, dtype=np.int64)
    eb = np.asarray(eb, dtype=np.int64)

    def point(e, par, base_img):
        at0 = par <= tol
        at1 = par >= 1.0 - tol
        code = np.where(at0, el[e, 0], np.where(at1, el[e, 1], n + e))
        im = base_img + (np.where(at1[:, None], img_el[e], 0) if k else 0)
        return code, im

    ca, ia = point(ea, np.asarray(s), np.zeros((c, k), dtype=np.int64))
    cb, ib = point(eb, np.asarray(t), image)
    rel = ib - ia
    swap = cb < ca
    lo = np.where(swap, cb, ca)
    hi = np.where(swap, ca, cb)
    rel = np.where(swap[:, None], -rel, rel)
    return np.column_stack([lo, hi, rel]).astype(np.int64)


def dedupe_pairs(frame, ea, eb, image, s, t) -> np.ndarray:
    """Sorted indices of the distinct yarn-yarn candidates (see :func:`point_keys`)."""
    if len(ea) == 0:
        return np.zeros(0, dtype=np.int64)
    _, first = np.unique(point_keys(frame, ea, eb, image, s, t), axis=0, return_index=True)
    return np.sort(first)
