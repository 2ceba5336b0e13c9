"""Errors that reach the user as one line.

Every error caused by the user's input is a :class:`FuzzymeshError`. Its text
is complete on its own: where (file, line, column), what is wrong, and what to
do about it. The CLI prints it as one line and exits with code 2.
"""
from __future__ import annotations


class FuzzymeshError(Exception):
    """A problem with the user's input, reported as one line."""

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
