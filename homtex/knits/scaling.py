"""The m / l^3 law of knitted fabrics (Duhovic and Bhattacharyya 2006, after Grosberg in Hearle
1969): the load to give a fixed extension is proportional to the bending rigidity m over the loop
length l cubed, ``Xcf = m / l^3`` (:func:`xcf`; their 6 / 1.54^3 = 1.64).

Where it holds exactly (:func:`scaled_cell`): scaling every length by b and the bending rigidity by
a, with the axial and shear stiffness by a / b^2, the torsional rigidity by a and the contact law
consistently (its energy by a / b), makes the whole problem similar: every energy scales by a / b,
so a force at the same strain scales by a / b^2 and, in the linear range, a force at the same
extension in mm by a / b^3. A cell file does this by scaling its lengths (loop length, spacings,
radii, element length, the compression test's travel and diameter) by b, Young's modulus by
a / b^4 and the compression test's forces by a / b^2 (so k delta^n keeps its energy scaling); the
take-down tension scales by a / b^2.

Where it holds only approximately (:func:`bending_cell`): only the bending rigidity (bending and
torsion factor, so that GJ / EI stays) and the loop length change, the yarn's radius, axial
stiffness and contact law stay: the law holds while bending dominates and fails where yarns
straighten and press on each other. Measured on the E-glass jersey pulled along the wales (loop
length x 1.54, bending rigidity x 6, take-down x a / b^2; 8 levels to 40 %): the force ratio at the
same strain, a / b^2 = 2.53 where the law holds, stays within 2.38-2.66 up to 20 %, is 2.32 at
25 % and falls to 1.99 at 30 % and 1.78-1.80 at 35-40 %, where the loops straighten
(docs/knits.md).
"""

from __future__ import annotations

from ..errors import InputError
from ..validate import check_number

__all__ = ["bending_cell", "scaled_cell", "xcf"]


def xcf(bending_ratio: float, length_ratio: float) -> float:
    """The structure size correlation factor m / l^3 for ratios of bending rigidity and loop length."""
    return check_number(bending_ratio, "bending_ratio", gt=0) / check_number(length_ratio, "length_ratio", gt=0) ** 3


def _yarn_name(cell) -> str:
    name = cell.parameters.get("yarn", next(iter(cell.yarns)))
    if name not in cell.yarns:
        raise InputError(f"scaled_cell: the cell's yarn {name!r} is not among its yarn tables")
    return name


def scaled_cell(cell, *, length: float, bending: float):
    """The cell with every length x ``length`` (b) and the bending rigidity x ``bending`` (a), the
    axial and shear stiffness x a / b^2, torsion x a, the compression law's energy x a / b: an exactly
    similar problem (see the module docstring). Returns a new :class:`homtex.Cell`."""
    b = check_number(length, "length", gt=0.0)
    a = check_number(bending, "bending", gt=0.0)
    y = _yarn_name(cell)
    yd = cell.to_dict()["yarns"][y]
    p = cell.parameters
    ch = {"parameters.loop_length": p["loop_length"] * b, f"yarns.{y}.E": yd["E"] * a / b ** 4}
    for k in ("wale_spacing", "course_spacing"):
        if k in p:
            ch[f"parameters.{k}"] = p[k] * b
    for k in ("radius", "contact_radius"):
        if k in yd:
            ch[f"yarns.{y}.{k}"] = yd[k] * b
    if "semi_axes" in yd:
        ch[f"yarns.{y}.semi_axes"] = [v * b for v in yd["semi_axes"]]
    ch["resolution.element_length"] = cell.resolution.get("element_length", p["loop_length"] / 10.0) * b
    comp = p.get("compression", {})
    for k in ("travel", "diameter", "contact_length", "shell"):
        if k in comp:
            ch[f"parameters.compression.{k}"] = [v * b for v in comp[k]] if isinstance(comp[k], list) else comp[k] * b
    if "force" in comp:
        ch["parameters.compression.force"] = [v * a / b ** 2 for v in comp["force"]]
    if "stiffness" in comp:
        n = float(comp.get("exponent", 1.0))
        ch["parameters.compression.stiffness"] = comp["stiffness"] * a / b ** (n + 2)
    return cell.replace(**ch)


def bending_cell(cell, *, loop_length: float, bending: float):
    """The cell with the loop length ``loop_length`` (mm) and the bending (and torsional) rigidity x
    ``bending``; everything else as it is (the approximate law: only m and l change)."""
    a = check_number(bending, "bending", gt=0.0)
    y = _yarn_name(cell)
    yd = cell.to_dict()["yarns"][y]
    return cell.replace(**{"parameters.loop_length": check_number(loop_length, "loop_length", gt=0.0),
                           f"yarns.{y}.bending_factor": yd.get("bending_factor", 1.0) * a,
                           f"yarns.{y}.torsion_factor": yd.get("torsion_factor", 1.0) * a})
