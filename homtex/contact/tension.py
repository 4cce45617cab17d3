"""Elements pulled at a constant axial force: a thread fed at a set tension (a sewing machine's
tension disc) that slides freely through the holes it passes.

The potential of the elements e in the set is

    V = s * sum_e T_e l_e(x),        l_e = |x_j + shift_e - x_i|   (the current length, mm)

with T_e the force (N; a leg of two thread strands carries 2 T), s a scale the path ramps
(the large-motion engine ties it to its pre-strain scale, so the same ramp sews a
length-controlled or a tension-controlled stitch). Its force on the nodes is T_e along each
element: the tension is the same in every element whatever its length, so the thread is pulled
in or paid out wherever the fabric lets it (equal tension along the stitch: the thread slides
through the needle holes). The Hessian of a term, s T_e / l_e (I - e e^T) on the blocks
[[A, -A], [-A, A]], is positive semi-definite. dV/ds = sum_e T_e l_e is what the ramp's work
integrates (the engine books it as pre-strain work, and V with the stored energy).

The elements' own axial stiffness is not part of this (an engine that uses it scales the
elements' EA down, :meth:`ConstantTension.soften`: the force then stays T_e within EA_soft x
the strain change).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["ConstantTension", "TensionOnly"]


class ConstantTension:
    """Constant axial forces on a set of elements of a frame.

    Parameters
    ----------
    frame : homtex.Frame.
    elements : (k,) element indices.
    force : (k,) or scalar axial force T_e at scale 1, N (>= 0).
    """

    def __init__(self, frame, elements, force):
        el = np.asarray(elements, dtype=np.int64).reshape(-1)
        if el.size and (el.min() < 0 or el.max() >= frame.n_elements):
            raise InputError(f"ConstantTension: element indices must lie in 0..{frame.n_elements - 1}")
        T = np.broadcast_to(np.asarray(force, dtype=float), el.shape).copy()
        if not np.all(np.isfinite(T)) or np.any(T < 0):
            raise InputError(f"ConstantTension: forces must be finite and >= 0 (N), got {force!r}")
        self.elements = el
        self.force = T
        self.nodes = np.ascontiguousarray(frame.elements[el])
        self.shift = np.ascontiguousarray(frame.shift[el])

    def lengths(self, x: np.ndarray) -> np.ndarray:
        """(k,) current element lengths at node positions x (n, 3), mm."""
        d = x[self.nodes[:, 1]] + self.shift - x[self.nodes[:, 0]]
        return np.sqrt(np.einsum("ij,ij->i", d, d))

    def rate(self, x: np.ndarray) -> float:
        """dV/ds = sum T_e l_e, N mm."""
        return float(self.force @ self.lengths(x))

    def evaluate(self, x: np.ndarray, scale: float, hessian: bool):
        """(energy N mm, gradient (n, 3) N, stencil nodes (k, 2), blocks (k, 6, 6) N/mm or None)."""
        n = len(x)
        d = x[self.nodes[:, 1]] + self.shift - x[self.nodes[:, 0]]
        ln = np.sqrt(np.einsum("ij,ij->i", d, d))
        if np.any(ln <= 0):
            raise InputError("ConstantTension: an element has collapsed to zero length")
        e = d / ln[:, None]
        T = scale * self.force
        f = T[:, None] * e
        g = np.zeros((n, 3))
        np.add.at(g, self.nodes[:, 1], f)
        np.add.at(g, self.nodes[:, 0], -f)
        H = None
        if hessian:
            A = (T / ln)[:, None, None] * (np.eye(3)[None] - e[:, :, None] * e[:, None, :])
            H = np.empty((len(ln), 6, 6))
            H[:, :3, :3] = A
            H[:, 3:, 3:] = A
            H[:, :3, 3:] = -A
            H[:, 3:, :3] = -A
        return float(T @ ln), g, self.nodes, H

    def soften(self, cor, factor: float) -> None:
        """Scale the axial stiffness EA of the elements in a
        :class:`~homtex.analysis.corotational.Corotational` state by ``factor`` (their bending and
        torsion stay): the tension then comes from this term, not from their stretch."""
        cor.arrays[0][self.elements] *= float(factor)


class TensionOnly:
    """Elements that pull like an elastic thread and go slack when shorter than their free length
    (a sewn thread under the punch: it cannot push).

    V = sum_e k_e / (2 L_e) max(l_e - L_e, 0)^2 with k_e = EA (N) and L_e the free length (mm); the
    force k_e (l_e - L_e) / L_e acts along the element while it is longer than L_e, none when it is
    shorter. The Hessian of a stretched element, t/l (I - e e^T) + k/L e e^T on [[A, -A], [-A, A]],
    is positive semi-definite; a slack one adds nothing. Not ramped: ``scale`` is ignored and
    :meth:`rate` is 0. The elements' own axial stiffness is to be softened
    (:meth:`ConstantTension.soften`, the same method) so that the axial force is this term's.
    """

    def __init__(self, frame, elements, stiffness, free_length):
        el = np.asarray(elements, dtype=np.int64).reshape(-1)
        if el.size and (el.min() < 0 or el.max() >= frame.n_elements):
            raise InputError(f"TensionOnly: element indices must lie in 0..{frame.n_elements - 1}")
        k = np.broadcast_to(np.asarray(stiffness, dtype=float), el.shape).copy()
        L = np.broadcast_to(np.asarray(free_length, dtype=float), el.shape).copy()
        if not (np.all(np.isfinite(k)) and np.all(k > 0) and np.all(np.isfinite(L)) and np.all(L > 0)):
            raise InputError("TensionOnly: stiffness (N) and free length (mm) must be finite and > 0")
        self.elements, self.k, self.L = el, k, L
        self.nodes = np.ascontiguousarray(frame.elements[el])
        self.shift = np.ascontiguousarray(frame.shift[el])

    lengths = ConstantTension.lengths
    soften = ConstantTension.soften

    def rate(self, x: np.ndarray) -> float:
        return 0.0

    def forces(self, x: np.ndarray) -> np.ndarray:
        """(k,) axial force of each element at positions x, N (0 when slack)."""
        return self.k * np.maximum(self.lengths(x) - self.L, 0.0) / self.L

    def evaluate(self, x: np.ndarray, scale: float, hessian: bool):
        """(energy N mm, gradient (n, 3) N, stencil nodes (k, 2), blocks (k, 6, 6) N/mm or None)."""
        d = x[self.nodes[:, 1]] + self.shift - x[self.nodes[:, 0]]
        ln = np.sqrt(np.einsum("ij,ij->i", d, d))
        e = d / ln[:, None]
        s = np.maximum(ln - self.L, 0.0)
        t = self.k * s / self.L
        g = np.zeros((len(x), 3))
        f = t[:, None] * e
        np.add.at(g, self.nodes[:, 1], f)
        np.add.at(g, self.nodes[:, 0], -f)
        H = None
        if hessian:
            ee = e[:, :, None] * e[:, None, :]
            A = (t / ln)[:, None, None] * (np.eye(3)[None] - ee) + ((s > 0) * self.k / self.L)[:, None, None] * ee
            H = np.empty((len(ln), 6, 6))
            H[:, :3, :3] = A
            H[:, 3:, 3:] = A
            H[:, :3, 3:] = -A
            H[:, 3:, :3] = -A
        return float(0.5 * np.sum(self.k * s * s / self.L)), g, self.nodes, H
