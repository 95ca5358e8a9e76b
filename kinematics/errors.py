"""Error types that carry where a problem is (file, line, field).

Every error a user can cause derives from :class:`LocatedError`; the CLI prints
``str(error)`` (``path:line: field: message``) and exits non-zero, never a traceback.
"""

from __future__ import annotations

import os


class LocatedError(Exception):
    """An error with an optional location: a file, a line in it and a field name."""

    def __init__(
        self,
        message: str,
        *,
        file: str | os.PathLike | None = None,
        line: int | None = None,
        field: str | None = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.file = os.fspath(file) if file is not None else None
        self.line = line
        self.field = field

    def located(self, *, file=None, line=None, field=None) -> LocatedError:
        """Fill in location parts that are still unknown and return self."""
        if self.file is None and file is not None:
            self.file = os.fspath(file)
        if self.line is None:
            self.line = line
        if self.field is None:
            self.field = field
        return self

    def __str__(self) -> str:
        parts = []
        if self.file is not None:
            parts.append(self.file if self.line is None else f"{self.file}:{self.line}")
        elif self.line is not None:
            parts.append(f"line {self.line}")
        if self.field:
            parts.append(self.field)
        parts.append(self.message)
        return ": ".join(parts)


class KinematicsError(LocatedError):
    """A problem with a chain, histogram archive, camera or fit input."""
