"""Small contact problems with known structure, for tests and studies.

:func:`beam_grid` — ``n`` straight beams along x lying over ``n`` beams along y, crossing at
nodes with small random gaps; random nodal loads push some crossings together and pull others
apart (so some initially closed candidates attract and must be released).

:func:`thick_crossing` — two straight thick yarns (hard cores under compressible shells) pressed
into each other at a given angle: a contact spread over dozens of segment pairs.
"""

from __future__ import annotations

import numpy as np

from ..model.frame import Frame
from .potential import Enforcement
from .stencil import PairStencil, pair_stencil


def beam_grid(n: int = 3, n_el: int = 4, *, L: float = 40.0, r: float = 0.5, E: float = 1000.0,
              nu: float = 0.3, gap: float = 0.03, load: float = 0.02, seed: int = 0):
    """A grid of 2n simply supported crossing beams.

    Parameters
    ----------
    n : beams per direction; n_el : elements per beam (a multiple of n + 1, so crossings are nodes).
    L : span, mm; r : radius, mm; E : MPa; gap : largest initial gap at a crossing, mm.
    load : scale of the random nodal loads, N (upper beams mostly pushed down, lower ones up).

    Returns
    -------
    frame (Frame), fixed (dict), loads (dict): arguments for ``homtex.solve_static``.
    """
    if n_el % (n + 1):
        raise ValueError(f"n_el = {n_el} must be a multiple of n + 1 = {n + 1} (crossings at nodes)")
    rng = np.random.default_rng(seed)
    xs = np.linspace(-L / 2, L / 2, n_el + 1)
    pos = -L / 2 + L * np.arange(1, n + 1) / (n + 1)
    gaps = rng.uniform(0.0, gap, (2, n))
    nodes, els, yarn, fixed, loads = [], [], [], {}, {}
    for d in range(2):
        for q, p in enumerate(pos):
            base = len(nodes)
            for xi in xs:
                nodes.append((xi, p, 2 * r + gaps[0, q]) if d == 0 else (p, xi, -gaps[1, q]))
            els += [(base + i, base + i + 1) for i in range(n_el)]
            yarn += [n * d + q] * n_el
            fixed[base] = [0, 1, 2, 3 + d]
            fixed[base + n_el] = [0, 1, 2, 3 + d]
            fz = rng.uniform(-1.0, 0.5, n_el - 1) if d == 0 else rng.uniform(-0.5, 1.0, n_el - 1)
            for i in range(1, n_el):
                loads[base + i] = (0.0, 0.0, load * fz[i - 1] / max(1.0, n_el / 4), 0.0, 0.0, 0.0)
    frame = Frame(np.array(nodes), np.array(els), radius=r, E=E, nu=nu, yarn=np.array(yarn))
    return frame, fixed, loads


def thick_crossing(depth: float, angle: float, *, n: int = 20, h: float = 0.1, core: float = 0.05,
                   outer: float = 0.5) -> tuple[np.ndarray, PairStencil, Enforcement]:
    """Two straight yarns of ``n`` elements of length ``h`` (mm) each, crossing at ``angle`` degrees,
    hard cores of radius ``core`` under compressible shells to radius ``outer`` (mm), pressed
    ``depth`` (mm) into each other: the lower along x at z = 0, the upper above it.

    Returns positions x (2 (n + 1), 3) mm (the lower yarn's nodes first), the stencil of every pair
    of a lower and an upper element, and the shell enforcement (F = 2 delta^3 over the shells).
    """
    s = (np.arange(n + 1) - n / 2) * h
    th = np.radians(angle)
    x = np.vstack([np.c_[s, 0 * s, 0 * s], np.c_[s * np.cos(th), s * np.sin(th), np.full_like(s, 2 * outer - depth)]])
    chain = np.c_[np.arange(n), np.arange(1, n + 1)]
    A, B = np.meshgrid(np.arange(n), np.arange(n) + n, indexing="ij")
    st = pair_stencil(np.vstack([chain, chain + n + 1]), np.full(2 * n, core), A.ravel(), B.ravel())
    enf = Enforcement("shell", ghat=1e-3, shell=2 * (outer - core), shell_stiffness=2.0, shell_exponent=3.0)
    return x, st, enf
