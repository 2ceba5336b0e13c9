"""What every loader of the knowledge base shares: the located error, expressions checked against the names
in scope, and the ``overrides:`` key of every file kind."""

from __future__ import annotations

from ..errors import KnowledgeError
from ..expr import Expression, ExpressionError
from ..schema import BOOLEAN, Field

OVERRIDES = Field(
    BOOLEAN,
    default=False,
    doc="true: every name this file defines replaces the one of that name read before it (e.g. a shipped pattern)",
)


def _err(what, where, fix=None):
    return KnowledgeError(what, where=where, fix=fix)


def _expression(value, names: set[str], where: str) -> Expression:
    try:
        return Expression(value, names, where)
    except ExpressionError as exc:
        raise _err(str(exc), where, "use numbers, parameter names, + - * / **, min(), max()") from None
