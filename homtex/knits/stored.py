"""A relaxed knit cell as a Dataset: what the result cache (:mod:`homtex.cache`) keeps of
``homtex.relax``, and the :class:`~homtex.knits.relax.RelaxedCell` rebuilt from it and its cell.

The engine state (translations, rotations, lattice, the pairs touching at creation, the energy
ledger), the rest state a yarn of filaments was laid with, and the attrs are stored; the frame and
the rest state seen from the relaxed shape follow from them and the cell
(``RelaxedCell.from_state``, as ``relax`` builds them), so a stored relaxed cell continues into
``tensile`` as the computed one does.
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from ..contact.step_data import EngineState
from ..errors import InputError
from ..model.rest import RestState

__all__ = ["relaxed_dataset", "relaxed_from_dataset"]

_LEDGER = "ledger_"
_FLAG = "flag_"            # a bool attr (netCDF stores no bools)


def relaxed_dataset(rc) -> xr.Dataset:
    """The Dataset of a RelaxedCell ``rc`` (dims node, xyz, i, j, period, touch; element, end
    for a yarn of filaments' laid rest state)."""
    s = rc.state
    if len(s.plate_z):
        raise InputError("a relaxed knit cell has no plates; this state has some")
    keys, rsum, gap = (np.array(t, copy=True) for t in s.touch)
    v = {"ut": (("node", "xyz"), s.ut.copy(), {"units": "mm", "long_name": "node translation from the cell's frame"}),
         "Q": (("node", "i", "j"), s.Q.copy(), {"units": "1", "long_name": "nodal rotation matrix"}),
         "loads": (("node", "dof"), s.loads.copy(), {"units": "N, N mm", "long_name": "dead loads acting"}),
         "periods": (("period", "xyz"), s.periods.copy(), {"units": "mm", "long_name": "lattice vectors"}),
         "touch_keys": ("touch", keys.astype(np.int64), {"units": "1", "long_name": "pairs touching at creation"}),
         "touch_rsum": ("touch", rsum, {"units": "mm", "long_name": "their reduced sums of radii"}),
         "touch_gap": ("touch", gap, {"units": "mm", "long_name": "their gaps at creation"})}
    if rc.cell_rest is not None:
        v["rest_length"] = ("element", rc.cell_rest.length.copy(), {"units": "mm", "long_name": "laid rest length"})
        v["rest_frames"] = (("element", "end", "i", "j"), rc.cell_rest.frames.copy(),
                            {"units": "1", "long_name": "laid rest frames at the element ends"})
    attrs = dict((_FLAG + k, int(a)) if isinstance(a, bool) else (k, a) for k, a in rc.attrs.items()
                 if k != "from_cache")
    attrs.update({_LEDGER + k: float(a) for k, a in s.ledger.items()},
                 prestrain_scale=float(s.prestrain_scale), pseudo_time_step=float(s.delta))
    return xr.Dataset(v, attrs=attrs)


def relaxed_from_dataset(cell, ds: xr.Dataset) -> tuple:
    """(EngineState, attrs, the laid rest state or None) stored by :func:`relaxed_dataset` for
    ``cell`` (``RelaxedCell.from_state`` makes the relaxed cell of them)."""
    frame = cell.frame
    ut = np.ascontiguousarray(ds["ut"].values, dtype=float)
    if ut.shape != (frame.n_nodes, 3):
        raise InputError(f"a stored relaxed state of {ut.shape[0]} nodes does not belong to {cell.name!r} "
                         f"({frame.n_nodes} nodes); clear the result cache (homtex.clear_cache())")
    a = dict(ds.attrs)
    ledger = {k[len(_LEDGER):]: float(a.pop(k)) for k in list(a) if k.startswith(_LEDGER)}
    state = EngineState(n_nodes=frame.n_nodes, n_elements=frame.n_elements, ut=ut,
                        Q=np.ascontiguousarray(ds["Q"].values, dtype=float),
                        prestrain_scale=float(a.pop("prestrain_scale")),
                        loads=np.ascontiguousarray(ds["loads"].values, dtype=float), plate_z=np.zeros(0),
                        plate_normal=np.zeros(0), plate_force=np.zeros(0),
                        touch=(ds["touch_keys"].values.astype(np.int64), ds["touch_rsum"].values.astype(float),
                               ds["touch_gap"].values.astype(float)),
                        ledger=ledger, delta=float(a.pop("pseudo_time_step")),
                        periods=np.ascontiguousarray(ds["periods"].values, dtype=float))
    for k in ("cache_key", "cache_kind"):
        a.pop(k, None)
    attrs = dict((k[len(_FLAG):], bool(w)) if k.startswith(_FLAG) else (k, w.item() if isinstance(w, np.generic) else w)
                 for k, w in a.items())
    cell_rest = None
    if "rest_length" in ds:
        cell_rest = RestState(length=np.ascontiguousarray(ds["rest_length"].values, dtype=float),
                              frames=np.ascontiguousarray(ds["rest_frames"].values, dtype=float))
    return state, attrs, cell_rest
