"""Calibration of the yarn-level stitch on one seam distance.

The length-controlled stitch has one parameter, the pre-strain eps0 (the thread consumed per stitch
is (1 - eps0) of the sewn-in leg length). :func:`calibrate_stitch` finds the eps0 whose sewn cushion
has a target height at one seam distance (the paper's d = 24 mm, 15 mm measured): one ramp to an
upper bracket ``eps_max`` records the cushion at every level, the crossing of the target is
interpolated, and a fresh sewing at that eps0 checks it (with friction the ramp is path dependent,
so the check is a sewing of its own); a secant step follows while the check misses by more than
``tol``.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from ..cells import Cell
from ..contact.options import Contact
from ..errors import InputError, SolverError
from ..validate import check_number
from .sew import sew

__all__ = ["calibrate_stitch"]

log = logging.getLogger(__name__)


def calibrate_stitch(cell: Cell, *, seam_distance: float = 24.0, cushion_height: float = 15.0,
                     eps_max: float = 0.8, tol: float = 0.005, max_checks: int = 3,
                     contact: Contact | None = None, steps: int | None = None, **seam_kw) -> dict:
    """The stitch pre-strain eps0 whose cushion at ``seam_distance`` (mm) is ``cushion_height`` (mm).

    Parameters
    ----------
    cell : spacer Cell with a [parameters.seam] table (its friction and resolution are used).
    seam_distance, cushion_height : the calibration point (the paper: 24 mm, 15 mm measured).
    eps_max : upper bracket of eps0: the ramp to it must bring the cushion below the target.
    tol : relative miss of the checking sewing that is accepted.
    max_checks : sewings at the interpolated eps0 (secant steps between them), at most.
    contact, steps, seam_kw : as for :func:`homtex.seams.sew.sew` (``steps``: ramp levels of
        every sewing; the bracket ramp uses twice as many).

    Returns
    -------
    dict: ``prestrain`` (the calibrated eps0), ``cushion_height`` (mm, of the last checking
    sewing), ``miss`` (relative), ``history`` [(eps0, cushion mm)] of every sewing's end state,
    ``bracket`` (eps0 levels, cushions of the bracket ramp), ``seconds``.
    """
    check_number(seam_distance, "seam_distance", gt=0.0, le=1e4)
    target = check_number(cushion_height, "cushion_height", gt=0.0, le=1e3)
    eps_max = check_number(eps_max, "eps_max", gt=0.0, lt=1.0)
    t0 = time.perf_counter()
    n = 10 if steps is None else int(steps)
    ramp = sew(cell, seam_distance=seam_distance, stitch="length", prestrain=eps_max, contact=contact,
               steps=2 * n, stop=lambda row: row["cushion_height"] <= target, **seam_kw)
    eps = ramp.path.prestrain_scale.values * eps_max
    h = ramp.path.cushion_height.values
    below = np.nonzero(h <= target)[0]
    if not len(below):
        raise InputError(f"calibrate_stitch: the ramp to eps0 = {eps_max:g} ({ramp.status}) leaves a cushion of "
                         f"{h.min(initial=np.nan):.4g} mm at d = {seam_distance:g} mm, above the target "
                         f"{target:g} mm; raise eps_max")
    k = int(below[0])
    e0, h0 = (0.0, float(ramp.info["thickness"])) if k == 0 else (float(eps[k - 1]), float(h[k - 1]))
    guess = e0 + (target - h0) * (float(eps[k]) - e0) / (float(h[k]) - h0)
    history = []
    pts = [(e0, h0), (float(eps[k]), float(h[k]))]
    for _ in range(int(max_checks)):
        s = sew(cell, seam_distance=seam_distance, stitch="length", prestrain=float(guess), contact=contact,
                steps=n, **seam_kw)
        if s.status == "failed":
            raise SolverError(f"calibrate_stitch: sewing at eps0 = {guess:.5g} failed: {s.detail}")
        hc = float(s.profile()[1].max())
        history.append((float(guess), hc))
        log.info("calibrate_stitch: eps0 %.5f -> cushion %.4f mm (target %g)", guess, hc, target)
        if abs(hc - target) <= tol * target:
            break
        # secant through the check and the nearest point on the other side of the target
        other = [p for p in pts if (p[1] - target) * (hc - target) < 0] or pts
        ep, hp = min(other, key=lambda p: abs(p[0] - guess))
        pts.append((float(guess), hc))
        guess = guess + (target - hc) * (ep - guess) / (hp - hc)
    eps_c, hc = history[-1]
    return {"prestrain": eps_c, "cushion_height": hc, "miss": (hc - target) / target, "history": history,
            "bracket": (eps, h), "seam_distance": float(seam_distance), "target": target,
            "seconds": time.perf_counter() - t0}
