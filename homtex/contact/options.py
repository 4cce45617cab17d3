"""Contact options: how yarns meet each other and rigid plates (``homtex.Contact``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..validate import check_choice, check_int, check_number

__all__ = ["Contact", "ENFORCEMENTS", "STRATEGIES"]


STRATEGIES = ("pdas", "removal")


ENFORCEMENTS = ("augmented", "penalty")


@dataclass
class Contact:
    """Contact options (frictionless, normal contact between yarns and with rigid plates).

    Parameters
    ----------
    strategy : "pdas" (primal-dual active set) or "removal" (the paper's algorithm).
    enforcement : "augmented" (exact gaps, Uzawa updates) or "penalty".
    penalty : contact stiffness k = 1/gamma, N/mm. Default: the mean translational diagonal
        of the frame stiffness (about EA/L of an element).
    removal_fraction : share of the attracting contacts removed per iteration ("removal"), (0, 1].
    margin : search distance added to r_a + r_b, mm (default: the largest contact radius).
    exclude_hops : same-yarn elements this many elements apart or closer are never in
        contact (default: enough to cover the contact diameter, at least 2).
    gap_tol : gap accuracy of "augmented", relative to the mean contact radius.
    max_penetration : largest accepted overlap of "penalty", relative to the smallest contact radius.
    detect_tol : after a solve, pairs not yet candidates that overlap by more than
        detect_tol x smallest contact radius are added and the step re-solved (up to detect_rounds).
    max_iter : active-set iterations; max_updates : multiplier updates per active set.
    reuse_amg : reuse the AMG hierarchy across contact iterations ...
    reuse_tol : ... when at most this share of the active rows changed since it was built (pdas).
    penalty_growth_max : "augmented" multiplies the penalty by 10 (up to this factor) while the
        Uzawa updates contract slowly (nearly dependent contacts).
    initial_overlap : "touch" (default): yarn pairs that overlap in the undeformed frame (a geometry
        artefact) count as touching: their gap is offset to zero, they may separate but not
        overlap further; "resolve": they are pushed apart in the first solve.
    friction : Coulomb coefficient; only 0 (frictionless) is implemented.
    max_forward_error : with the direct solver, each solve is refined once; a relative
        correction above this (an ill-conditioned system, e.g. a penalty far above the beam
        stiffness) raises SolverError instead of returning an inaccurate state.
    """

    strategy: str = "pdas"
    enforcement: str = "augmented"
    penalty: float | None = None
    removal_fraction: float = 0.25
    margin: float | None = None
    exclude_hops: int | None = None
    gap_tol: float = 1e-9
    max_penetration: float = 0.05
    max_iter: int = 200
    max_updates: int = 100
    reuse_amg: bool = True
    reuse_tol: float = 0.05
    detect_rounds: int = 5
    detect_tol: float = 1e-3
    friction: float = 0.0
    penalty_growth_max: float = 1e4
    initial_overlap: str = "touch"
    max_forward_error: float = 1e-6

    def __post_init__(self):
        def named(name):
            return f"Contact option '{name}'"

        check_choice(self.strategy, named("strategy"), STRATEGIES)
        check_choice(self.enforcement, named("enforcement"), ENFORCEMENTS)
        if self.penalty is not None:
            self.penalty = check_number(self.penalty, named("penalty") + " (N/mm)", gt=0.0, le=1e15)
        self.removal_fraction = check_number(self.removal_fraction, named("removal_fraction"), gt=0.0, le=1.0)
        if self.margin is not None:
            self.margin = check_number(self.margin, named("margin") + " (mm)", ge=0.0, le=1e6)
        if self.exclude_hops is not None:
            self.exclude_hops = check_int(self.exclude_hops, named("exclude_hops"), ge=1)
        for name in ("gap_tol", "max_penetration", "detect_tol", "reuse_tol", "max_forward_error"):
            setattr(self, name, check_number(getattr(self, name), named(name), gt=0.0))
        self.penalty_growth_max = check_number(self.penalty_growth_max, named("penalty_growth_max"), ge=1.0)
        for name in ("max_iter", "max_updates", "detect_rounds"):
            setattr(self, name, check_int(getattr(self, name), named(name), ge=1, le=10 ** 6))
        if not isinstance(self.reuse_amg, (bool, np.bool_)):
            raise InputError(f"{named('reuse_amg')} must be True or False, got {self.reuse_amg!r}")
        check_choice(self.initial_overlap, named("initial_overlap"), ("touch", "resolve"))
        self.friction = check_number(self.friction, named("friction"), ge=0.0)
        if self.friction != 0.0:
            raise InputError(f"{named('friction')} = {self.friction!r}: Coulomb friction is not "
                             "implemented for the linear contact solve (frictionless contact only, friction=0)")
