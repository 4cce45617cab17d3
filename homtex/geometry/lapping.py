"""Warp-knitting notation: guide bars, lapping (chain notation) and threading.

Lapping notation: courses separated by ``/``, a repeat closed by ``//``; each course token
gives the guide's positions ``a-b`` on a needle bar (``1-0``: overlap from guide position 1
to 0), ``a-b-c-d`` for a pile bar that visits both needle bars in one course (front pair,
back pair). ``a == b`` is an inlay lying in gap a. See :mod:`homtex.geometry.spacer`.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["Bar", "CourseLap", "as_bar", "lcm", "parse_lapping", "parse_threading"]


# knitting description
@dataclass(frozen=True)
class Bar:
    """One guide bar.

    name : the bar's name (used in errors and as the default yarn-system name).
    lapping : chain notation, e.g. ``"1-0/0-1//"`` (see the module docstring).
    yarn : name of its yarn type.
    bed : "front" (top layer), "back" (bottom layer) or "both" (pile).
    threading : "full", "1-in 1-out" or a pattern of ``x`` / ``.`` per wale.
    system : yarn-system name for the element groups (default: ``name``).
    """

    name: str
    lapping: str
    yarn: str
    bed: str = "front"
    threading: str = "full"
    system: str | None = None

    @property
    def group(self) -> str:
        return self.system or self.name


@dataclass
class CourseLap:
    """One course of a parsed lapping: laps on the front and back needle bar.

    ``front`` / ``back`` are (a, b) guide positions or None when the bar does not
    visit that layer in this course. ``a == b`` means an inlay at gap a.
    """

    token: str
    front: tuple | None
    back: tuple | None


_TOKEN = re.compile(r"^\d+(-\d+)*$")


def parse_lapping(text: str, bar: str = "bar", bed: str = "front") -> list[CourseLap]:
    """Parse a lapping in chain notation (see the module docstring).

    Parameters
    ----------
    text : e.g. ``"1-0/0-1//"`` or ``"1-0-3-4/3-4-1-0//"``.
    bar : the bar's name (for error messages).
    bed : "front", "back" or "both".

    Returns
    -------
    list of :class:`CourseLap`, one per course of the repeat.

    Raises
    ------
    InputError naming the bar and the offending token.
    """
    if not isinstance(bed, str) or bed not in ("front", "back", "both"):
        raise InputError(f"bar {bar!r}: bed must be 'front', 'back' or 'both', got {bed!r}")
    if not isinstance(text, str):
        raise InputError(f"bar {bar!r}: lapping must be a string like '1-0/0-1//', got {text!r}")
    s = "".join(text.split())
    if not s:
        raise InputError(f"bar {bar!r}: lapping is empty")
    if not s.endswith("//"):
        last = s.rstrip("/").split("/")[-1]
        raise InputError(f"bar {bar!r}: lapping {text!r} does not close its repeat: it must end with "
                         f"'//' after the last course (token {last!r})")
    body = s[:-2]
    if "//" in body:
        extra = body.split("//", 1)[1]
        raise InputError(f"bar {bar!r}: lapping {text!r} has tokens after the end of the repeat '//' "
                         f"(token {extra.split('/')[0]!r}); write one repeat only")
    if not body:
        raise InputError(f"bar {bar!r}: lapping {text!r} has no course token before '//'")
    courses = []
    width = None
    for pos, tok in enumerate(body.split("/")):
        if not tok:
            raise InputError(f"bar {bar!r}: lapping {text!r} has an empty course token at position {pos} "
                             f"(a stray '/')")
        if not _TOKEN.match(tok):
            raise InputError(f"bar {bar!r}: token {tok!r} of lapping {text!r} does not parse: "
                             f"expected guide positions like '1-0' or '1-0-3-4' (non-negative integers "
                             f"joined by '-')")
        nums = [int(v) for v in tok.split("-")]
        if len(nums) not in (2, 4):
            raise InputError(f"bar {bar!r}: token {tok!r} has {len(nums)} numbers; a course is 'a-b' "
                             f"(one needle bar) or 'a-b-c-d' (front lap a-b, back lap c-d)")
        if width is None:
            width = len(nums)
        elif len(nums) != width:
            raise InputError(f"bar {bar!r}: token {tok!r} mixes {len(nums)}-number and {width}-number "
                             f"courses in lapping {text!r}")
        if len(nums) == 2:
            pair = (nums[0], nums[1])
            if bed == "both":
                raise InputError(f"bar {bar!r} (bed 'both') needs double-needle-bar tokens "
                                 f"'front-front-back-back', got token {tok!r}")
            front, back = (pair, None) if bed == "front" else (None, pair)
        else:
            fp, bp = (nums[0], nums[1]), (nums[2], nums[3])
            if bed == "front":
                if bp[0] != bp[1]:
                    raise InputError(f"bar {bar!r} has bed 'front' but token {tok!r} laps the back needle "
                                     f"bar ({bp[0]}-{bp[1]}); use bed = 'both' for a pile bar")
                front, back = fp, None
            elif bed == "back":
                if fp[0] != fp[1]:
                    raise InputError(f"bar {bar!r} has bed 'back' but token {tok!r} laps the front needle "
                                     f"bar ({fp[0]}-{fp[1]}); use bed = 'both' for a pile bar")
                front, back = None, bp
            else:
                front = fp if fp[0] != fp[1] else None
                back = bp if bp[0] != bp[1] else None
                if front is None and back is None:
                    raise InputError(f"bar {bar!r}: pile token {tok!r} laps neither needle bar")
        for p in (front, back):
            if p is not None and abs(p[0] - p[1]) > 1:
                raise InputError(f"bar {bar!r}: token {tok!r} overlaps {abs(p[0] - p[1])} needles "
                                 f"({p[0]}-{p[1]}); only single-needle overlaps (|a - b| = 1) are supported")
        courses.append(CourseLap(tok, front, back))
    if bed == "both":
        for side, layer, other in (("back", "bottom", "front"), ("front", "top", "back")):
            if all(getattr(c, side) is None for c in courses):
                raise InputError(
                    f"bar {bar!r}: pile lapping {text!r} never laps the {side} needle bar, so the pile never "
                    f"reaches the {layer} layer (token {courses[0].token!r} and all others lap only the "
                    f"{other} bar)")
    return courses


def parse_threading(spec: str, bar: str = "bar") -> np.ndarray:
    """Threading pattern -> bool array (one per guide/wale of its repeat)."""
    if not isinstance(spec, str):
        raise InputError(f"bar {bar!r}: threading must be a string ('full', '1-in 1-out' or 'x.' pattern), "
                         f"got {spec!r}")
    key = spec.strip().lower().replace("_", "-").replace(" ", "")
    if key in ("full", "all"):
        return np.array([True])
    if key in ("1-in1-out", "1in1out", "half"):
        return np.array([True, False])
    bad = [ch for ch in spec.strip() if ch not in "x.|-1"]
    if bad or not spec.strip():
        raise InputError(f"bar {bar!r}: threading {spec!r} is not 'full', '1-in 1-out' or a pattern of 'x' "
                         f"(threaded) and '.' (empty) guides (bad character {bad[0] if bad else ''!r})")
    pat = np.array([ch in "x|1" for ch in spec.strip()])
    if not pat.any():
        raise InputError(f"bar {bar!r}: threading {spec!r} threads no guide")
    return pat


# the generator
def lcm(values):
    out = 1
    for v in values:
        out = out * int(v) // math.gcd(out, int(v))
    return out


def as_bar(name, spec) -> Bar:
    if isinstance(spec, Bar):
        return spec
    if not isinstance(spec, dict):
        raise InputError(f"bar {name!r}: expected a table with lapping, yarn, bed, threading; got {spec!r}")
    known = {"name", "lapping", "yarn", "bed", "threading", "system"}
    unknown = sorted(set(spec) - known)
    if unknown:
        raise InputError(f"bar {name!r}: unknown key(s) {unknown}; known: {sorted(known)}")
    for key in ("lapping", "yarn"):
        if key not in spec:
            raise InputError(f"bar {name!r}: missing key {key!r}")
    return Bar(name=spec.get("name", name), lapping=spec["lapping"], yarn=spec["yarn"],
               bed=spec.get("bed", "front"), threading=spec.get("threading", "full"),
               system=spec.get("system"))
