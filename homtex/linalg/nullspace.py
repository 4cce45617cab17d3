"""Near-null spaces of beam frames (for smoothed-aggregation AMG)."""

from __future__ import annotations

import numpy as np

__all__ = ["rigid_body_modes"]


def rigid_body_modes(coords: np.ndarray, center=None) -> np.ndarray:
    """Near-null space of a beam frame: (6n, 6) translations and rotations.

    Rotation about axis k: translation u = e_k x (x - x0), rotation theta = e_k.
    Coordinates are centred and scaled to unit size so the columns are balanced.
    """
    x = np.asarray(coords, dtype=float)
    x0 = x.mean(axis=0) if center is None else np.asarray(center)
    d = x - x0
    s = max(float(np.abs(d).max()), 1e-300)
    d = d / s
    n = len(x)
    B = np.zeros((n, 6, 6))
    for k in range(3):
        B[:, k, k] = 1.0
    # omega = e_x: u = (0, -z, y); e_y: (z, 0, -x); e_z: (-y, x, 0)
    B[:, 1, 3], B[:, 2, 3] = -d[:, 2], d[:, 1]
    B[:, 0, 4], B[:, 2, 4] = d[:, 2], -d[:, 0]
    B[:, 0, 5], B[:, 1, 5] = -d[:, 1], d[:, 0]
    for k in range(3):
        B[:, 3 + k, 3 + k] = 1.0 / s   # theta = omega, consistent with the scaled lever arm
    return B.reshape(6 * n, 6)
