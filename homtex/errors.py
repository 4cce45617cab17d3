"""Exceptions raised by homtex.

Every error names its culprit (element, node, yarn, parameter, file/table/key)
so that a user can find and fix the input without reading the code.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input: geometry, section, material, supports, loads, options or a file."""


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


class CellError(InputError):
    """A bad cell file or cell parameter, naming the file, table and key.

    ``str(err)`` reads ``cells/x.toml: [yarns.pile] key 'radius': must be > 0, got -0.1``.
    """

    def __init__(self, message: str, *, file=None, table: str | None = None, key: str | None = None):
        super().__init__(message)
        self.message = message
        self.file = None if file is None else str(file)
        self.table = table
        self.key = key

    def __str__(self) -> str:
        parts = []
        if self.file:
            parts.append(f"{self.file}:")
        if self.table:
            parts.append(f"[{self.table}]")
        if self.key:
            parts.append(f"key '{self.key}':")
        elif self.table:
            parts[-1] += ":"
        parts.append(self.message)
        return " ".join(parts)


class StudyError(CellError):
    """A bad study file or option, naming the file, table and key (formatted like CellError)."""


class StrainWarning(UserWarning):
    """A large-rotation solve reached strains beyond an element's elastic limit (``strain_limit``):
    the co-rotational beam is exact for large rotations but linear elastic in small strains."""
