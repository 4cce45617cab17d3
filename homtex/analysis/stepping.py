"""The one step-control loop: a load parameter followed through increasing levels, a failed
step cut in half, the history recorded. ``compress``, the seam ramp and the seamed
compression all step with :func:`march`; curves they produce are checked for force drops
with :func:`flag_force_drops`.
"""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np

from ..errors import InputError, SolverError

__all__ = ["FORCE_DROP_CAUSES", "GROWTH", "Step", "StepFailure", "flag_force_drops", "march"]

log = logging.getLogger(__name__)

#: how the increment grows back after a cut step succeeded
GROWTH = ("aligned", "double", "reset")


@dataclass
class Step:
    """An accepted step: the ``level`` reached, the solve's ``result``, ``target`` (index of the
    target reached, None for an intermediate level), the ``substeps`` it took since the previous
    target, and ``cuts`` (halvings in force when it was taken)."""

    level: float
    result: object
    target: int | None
    substeps: int
    cuts: int


class StepFailure(SolverError):
    """A step failed after ``cuts`` halvings: ``level`` (the level last tried), ``reached`` (the
    last accepted level), ``target`` (index of the target being approached), ``first`` (the
    error at the full step) and ``last`` (the error at the smallest step)."""

    def __init__(self, message, *, level, reached, target, cuts, first, last):
        super().__init__(message)
        self.level, self.reached, self.target, self.cuts = level, reached, target, cuts
        self.first, self.last = first, last


def march(solve: Callable[[float], object], targets, *, start: float = 0.0, step: float | None = None,
          max_cuts: int = 4, grow: str = "aligned", retry: Callable[[Exception], bool] | None = None,
          time_limit: float | None = None) -> Iterator[Step]:
    """Follow a load parameter from ``start`` through the increasing ``targets``.

    Parameters
    ----------
    solve : ``solve(level) -> result``: the state at ``level``, starting from the last accepted
        state (the caller accepts a state when :func:`march` yields it; a failed solve must leave
        the accepted state as it was). A failure raises SolverError or numpy's LinAlgError.
    targets : increasing levels that must be reached (each is yielded with its index).
    step : nominal increment (default: the distance to the next target).
    max_cuts : a failed step is halved, at most this many times in a row; then StepFailure.
    grow : after a success at a cut increment: "aligned" doubles it when the level lies on the
        grid of the doubled increment (the levels of recursive bisection of the nominal step:
        a failed step is done as two halves, each halved again if it fails), "double" doubles it
        up to the nominal one, "reset" goes back to the nominal one.
    retry : ``retry(err)`` False: raise at once without cutting (e.g. a singular operator).
    time_limit : seconds; StepFailure once it is exceeded (the accepted steps stay yielded).

    Yields
    ------
    :class:`Step` for every accepted level, in order.
    """
    if grow not in GROWTH:
        raise InputError(f"grow must be one of {GROWTH}, got {grow!r}")
    if int(max_cuts) != max_cuts or max_cuts < 0:
        raise InputError(f"max_cuts must be a non-negative integer, got {max_cuts!r}")
    targets = [float(t) for t in np.atleast_1d(targets)]
    max_cuts = int(max_cuts)
    t0 = time.perf_counter()
    level = float(start)
    for k, target in enumerate(targets):
        nominal = target - level if step is None else float(step)
        if not nominal > 0:
            raise InputError(f"march: targets must increase from {level:g}, got {target:g}")
        unit = nominal / 2 ** max_cuts           # the finest increment
        base = level                             # grid origin of the aligned growth
        size = 2 ** max_cuts                     # current increment in units
        cuts = 0
        substeps = 0
        first = None
        while level < target - 1e-12 * max(abs(target), 1.0):
            if time_limit is not None and time.perf_counter() - t0 > time_limit:
                raise StepFailure(f"time limit {time_limit:g} s reached at level {level:.4g}", level=level,
                                  reached=level, target=k, cuts=cuts, first=None, last=None)
            trial = min(target, level + size * unit)
            try:
                result = solve(trial)
            except (SolverError, np.linalg.LinAlgError) as err:
                if first is None:
                    first = err
                if cuts >= max_cuts or (retry is not None and not retry(err)):
                    raise StepFailure(str(err), level=trial, reached=level, target=k, cuts=cuts, first=first,
                                      last=err) from err
                cuts += 1
                size //= 2
                log.debug("step to %.6g failed (%s); halved (%d cuts)", trial, err, cuts)
                continue
            level = trial
            substeps += 1
            done = level >= target - 1e-12 * max(abs(target), 1.0)
            yield Step(level=level, result=result, target=k if done else None, substeps=substeps, cuts=cuts)
            if done:
                break
            if cuts:
                if grow == "reset":
                    size, cuts = 2 ** max_cuts, 0
                elif grow == "double":
                    size, cuts = size * 2, cuts - 1
                else:
                    pos = int(round((level - base) / unit))
                    while cuts and pos % (2 * size) == 0:
                        size, cuts = size * 2, cuts - 1
            first = None if cuts == 0 else first
        level = target


#: what a force drop may be, per model (the second cause is the model's own artefact)
FORCE_DROP_CAUSES = {
    "linear": "a snap-through or a load step too large for the re-linearised contact",
    "nonlinear": "a snap-through or buckling of the yarns (physical), or a load step too large for the "
                 "large-motion engine's step control",
}


def flag_force_drops(ds, *, rel: float = 0.02, what: str = "curve", model: str = "linear"):
    """Mark a displacement-controlled curve whose force falls on the way (in place; returns ds).

    A drop of more than ``rel`` x the force reached so far is either a snap-through (physical:
    a yarn buckles or slips past another) or an artefact of a load step too large for the
    model: the per-step re-linearised contact (``model="linear"``) or the large-motion engine's
    step control (``model="nonlinear"``); the two differ in that the artefact moves with the step
    count. ``attrs``: ``force_drop_max`` (largest drop / force reached, 0 for a monotone curve),
    ``force_drop_strain`` (where it ends, NaN if none) and, above ``rel``, ``check`` (message,
    also warned).
    """
    if model not in FORCE_DROP_CAUSES:
        raise InputError(f"flag_force_drops: model must be one of {sorted(FORCE_DROP_CAUSES)}, got {model!r}")
    f = np.asarray(ds["force"].values, dtype=float)
    e = np.asarray(ds["strain"].values, dtype=float)
    ds.attrs["force_drop_max"] = 0.0
    ds.attrs["force_drop_strain"] = float("nan")
    if len(f) < 2 or not np.all(np.isfinite(f)):
        return ds
    top = np.maximum.accumulate(f)
    drop = np.where(top > 0, (top - f) / np.where(top > 0, top, 1.0), 0.0)
    k = int(np.argmax(drop))
    ds.attrs["force_drop_max"] = float(drop[k])
    if drop[k] > rel:
        ds.attrs["force_drop_strain"] = float(e[k])
        msg = (f"{what}: the force falls by {100 * drop[k]:.1f} % of the force reached, ending at strain "
               f"{e[k]:.4g} (step {k + 1} of {len(f)}): {FORCE_DROP_CAUSES[model]}; run it again with twice "
               "the steps - an artefact moves, a snap stays")
        ds.attrs["check"] = msg
        warnings.warn(msg, UserWarning, stacklevel=3)
        log.warning(msg)
    return ds
