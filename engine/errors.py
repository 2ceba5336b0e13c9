"""Errors that reach the user as one line.

Every error caused by the user's input is a :class:`FuzzymeshError`. Its text
is complete on its own: where (file, line, column), what is wrong, and what to
do about it. The CLI prints it as one line and exits with the error's ``exit_code``:
2 for bad input or a limit, 4 for a mesh the acceptance gate rejected
(3 is an internal fault, 1 lint findings).
"""

from __future__ import annotations


class FuzzymeshError(Exception):
    """A problem with the user's input, reported as one line."""

    exit_code = 2

    def __init__(self, what: str, *, where: str | None = None, fix: str | None = None):
        self.what = what
        self.where = where
        self.fix = fix
        super().__init__(self.one_line())

    def one_line(self) -> str:
        text = f"{self.where}: {self.what}" if self.where else self.what
        if self.fix:
            text += f"; {self.fix}"
        return " ".join(text.split())


class GeometryError(FuzzymeshError):
    """The solid cannot be meshed as given (file, format, validity)."""


class JobError(FuzzymeshError):
    """The job file or job dictionary is invalid."""


class KnowledgeError(FuzzymeshError):
    """A rule, pattern or recipe file is invalid."""


class LimitError(FuzzymeshError):
    """The request is valid but would exceed a resource limit."""


class MeshRejected(FuzzymeshError):
    """The mesh failed the acceptance gate (engine/acceptance.py): nothing was written."""

    exit_code = 4

    def __init__(self, what: str, *, check: str, where: str | None = None, fix: str | None = None):
        self.check = check
        super().__init__(f"mesh rejected ({check}): {what}", where=where, fix=fix)
