"""Compressible yarn contact: a soft shell over a hard core (``homtex.YarnCompression``).

A knitting yarn is no solid tube: where two yarns cross they flatten. The large-motion engine
models each yarn's section as a hard core (radius R - h, R the contact radius) under a shell of
thickness h. Where the outer surfaces of two yarns overlap by delta = (R_a + R_b) - distance, the
shells push the centre lines apart with the force of a power law

    F(delta) = k delta^n        (N; one crossing, 0 <= delta <= 2 h),

whose energy k delta^(n+1) / (n + 1) joins the contact energy; the IPC barrier acts at the cores'
surfaces, so the cores never interpenetrate and no yarn passes through another
(:mod:`homtex.contact.potential`, kind ``"shell"``). A yarn on a rigid plate compresses one shell:
F = k (2 delta)^n (the plate law below).

Parameters from a yarn compression test between flat plates (force F at travel Delta after first
contact; :meth:`YarnCompression.from_plate_test`): the test squeezes one yarn by Delta, both of its
sides by Delta / 2. Two crossing yarns each lose delta / 2 on their facing sides, so the pair's
overlap delta is what the plate test calls the travel at the same force: F_pair(delta) =
F_test(Delta = delta), the law fitted (log-log least squares) as k Delta^n. The test's force is
read as that of one crossing: the compressed length in the test is taken as one yarn diameter
(state it where a test used another length; ``contact_length`` rescales k by diameter / length).
The shell thickness h is what the travel may use before the cores meet; by default
``core_fraction`` = 0.15 of the radius is hard.

Closed forms checked in ``tests/test_knit_engine.py``: a yarn pressed by F onto a crossing one sits
at distance R_a + R_b - (F / k)^(1/n) (the shell's part of the contact force).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..validate import check_number

__all__ = ["YarnCompression"]


@dataclass(frozen=True)
class YarnCompression:
    """Soft-shell-over-hard-core contact law of the yarns (see the module docstring).

    Parameters
    ----------
    shell : shell thickness h of each yarn, mm (0 < h < the smallest contact radius).
    stiffness : k of the crossing force k delta^n, N / mm^n.
    exponent : n (1 <= n <= 20).
    source : where the numbers come from.
    """

    shell: float
    stiffness: float
    exponent: float = 1.0
    source: str = ""

    def __post_init__(self):
        object.__setattr__(self, "shell", check_number(self.shell, "YarnCompression.shell (mm)", gt=0.0, le=1e3))
        object.__setattr__(self, "stiffness", check_number(self.stiffness, "YarnCompression.stiffness (N/mm^n)",
                                                           gt=0.0, le=1e15))
        object.__setattr__(self, "exponent", check_number(self.exponent, "YarnCompression.exponent", ge=1.0,
                                                          le=20.0))

    # ------------------------------------------------------------------ the law
    def force(self, delta):
        """Force (N) of one crossing at overlap ``delta`` (mm) of the outer surfaces."""
        d = np.clip(np.asarray(delta, dtype=float), 0.0, None)
        return self.stiffness * d ** self.exponent

    def overlap(self, force):
        """Overlap (mm) of one crossing carrying ``force`` (N): (F / k)^(1/n)."""
        return (np.clip(np.asarray(force, dtype=float), 0.0, None) / self.stiffness) ** (1.0 / self.exponent)

    def check_radius(self, radius: float) -> None:
        """InputError unless the shell is thinner than the contact radius (mm)."""
        if not self.shell < radius:
            raise InputError(f"YarnCompression.shell = {self.shell:g} mm must be smaller than the yarns' smallest "
                             f"contact radius {radius:g} mm (the core must keep a positive radius)")

    def pair_params(self) -> dict:
        """Shell parameters of a yarn-yarn pair (both shells: range 2 h, F = k delta^n)."""
        return {"shell": 2.0 * self.shell, "shell_stiffness": self.stiffness, "shell_exponent": self.exponent}

    def plate_params(self) -> dict:
        """Shell parameters of a yarn on a rigid plate (one shell: range h, F = k (2 delta)^n)."""
        return {"shell": self.shell, "shell_stiffness": self.stiffness * 2.0 ** self.exponent,
                "shell_exponent": self.exponent}

    # ------------------------------------------------------------------ from a test
    @classmethod
    def from_plate_test(cls, travel, force, *, diameter: float, core_fraction: float = 0.15,
                        contact_length: float | None = None, source: str = "") -> "YarnCompression":
        """The law of a yarn compression test between flat plates (see the module docstring).

        travel : (p,) travel after first contact, mm (increasing, > 0); force : (p,) N (> 0).
        diameter : yarn diameter, mm. core_fraction : hard core radius / yarn radius, [0, 1).
        contact_length : compressed yarn length in the test, mm (default one diameter: the test's
            force is one crossing's).

        Returns the law with h = (1 - core_fraction) diameter / 2 and k, n fitted on log F =
        log k + n log Delta; ``fit_error`` (the largest relative force error at the test points) in
        its ``source``.
        """
        t = np.asarray(travel, dtype=float).ravel()
        f = np.asarray(force, dtype=float).ravel()
        if t.shape != f.shape or t.size < 2 or not (np.all(t > 0) and np.all(f > 0)):
            raise InputError("from_plate_test: travel and force need >= 2 positive points of the same length")
        diameter = check_number(diameter, "diameter (mm)", gt=0.0, le=1e3)
        core_fraction = check_number(core_fraction, "core_fraction", ge=0.0, lt=1.0)
        n, logk = np.polyfit(np.log(t), np.log(f), 1)
        k = float(np.exp(logk))
        if contact_length is not None:
            k *= diameter / check_number(contact_length, "contact_length (mm)", gt=0.0, le=1e6)
        n = float(np.clip(n, 1.0, 20.0))
        fit = k * t ** n
        if contact_length is not None:
            fit *= contact_length / diameter
        err = float(np.max(np.abs(fit / f - 1.0)))
        h = 0.5 * diameter * (1.0 - core_fraction)
        if t.max() >= 2.0 * h:
            raise InputError(f"from_plate_test: the test travels {t.max():g} mm, more than the shells allow "
                             f"(2 h = {2 * h:g} mm with core_fraction {core_fraction:g}); lower core_fraction")
        note = f"power law fitted to a plate test, largest force error {100 * err:.1f} %"
        return cls(shell=h, stiffness=k, exponent=n, source=f"{source}; {note}" if source else note)
