"""The three regions of a fabric's compression curve (the measured curves of the spacer paper:
a slow rise, a steeper near-linear rise, stiffening): where the slope changes.

:func:`three_regions` fits a continuous piecewise-linear curve of three segments to stress over
strain (least squares; the two breakpoints searched on a grid of the curve's own strains, each
segment spanning at least ``min_span``) and reports the breakpoints and the segment slopes.
"""

from __future__ import annotations

import numpy as np

__all__ = ["three_regions"]


def _fit(e, s, b1, b2):
    """Least-squares continuous 3-segment fit with breakpoints b1 < b2: (rss, slopes (3,))."""
    A = np.column_stack([np.ones_like(e), e, np.maximum(e - b1, 0.0), np.maximum(e - b2, 0.0)])
    coef, *_ = np.linalg.lstsq(A, s, rcond=None)
    r = A @ coef - s
    k1 = coef[1]
    return float(r @ r), np.array([k1, k1 + coef[2], k1 + coef[2] + coef[3]])


def three_regions(strain, stress, *, min_span: float = 0.05, start: float = 0.0) -> dict:
    """Breakpoints and slopes of a 3-segment piecewise-linear fit of a compression curve.

    Parameters
    ----------
    strain : (k,) compression strain, 1 (increasing).
    stress : (k,) stress (any unit, e.g. kPa; slopes come in that unit per unit strain).
    min_span : smallest strain span of a segment.
    start : points at strains below this are left out (the first steep rise to the pile's
        buckling, far below the curve's scale, would otherwise take a segment).

    Returns
    -------
    dict: ``breaks`` (2,) strains where the slope changes, ``slopes`` (3,) slopes of the slow
    rise, the near-linear rise and the stiffening (stress per unit strain), ``rms`` of the fit
    (stress units); NaNs when the curve is too short (fewer than 6 points or a span under
    3 ``min_span``).
    """
    e = np.asarray(strain, dtype=float)
    s = np.asarray(stress, dtype=float)
    ok = np.isfinite(e) & np.isfinite(s) & (e >= start)
    e, s = e[ok], s[ok]
    nan = {"breaks": np.full(2, np.nan), "slopes": np.full(3, np.nan), "rms": float("nan")}
    if e.size < 6 or e[-1] - e[0] < 3 * min_span:
        return nan
    cand = e[(e > e[0] + min_span) & (e < e[-1] - min_span)]
    best = (np.inf, None, None)
    for i, b1 in enumerate(cand):
        for b2 in cand[i + 1:]:
            if b2 - b1 < min_span:
                continue
            rss, k = _fit(e, s, b1, b2)
            if rss < best[0]:
                best = (rss, (b1, b2), k)
    if best[1] is None:
        return nan
    return {"breaks": np.array(best[1]), "slopes": best[2], "rms": float(np.sqrt(best[0] / e.size))}
