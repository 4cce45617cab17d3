"""Exceptions raised by homtex.

Every error names its culprit (element, node, yarn, parameter, file/table/key)
so that a user can find and fix the input without reading the code.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input: geometry, section, material, supports, loads or a cell file."""


class SolverError(RuntimeError):
    """A solve that cannot return a trustworthy answer.

    Raised for structures with parts that nothing holds (singular), for
    iterative solvers that miss their tolerance (with the residual history in
    ``.history``), and for non-finite results. Never silently returned.
    """

    def __init__(self, message: str, *, history=None, report=None):
        super().__init__(message)
        self.history = history
        self.report = report
