"""A small declarative validator for YAML mappings with located errors.

A schema is a dict ``key -> Field``. :func:`validate` checks a
:class:`~engine.yamlfile.Located` mapping against it and returns a plain dict
with defaults filled in. Every error names ``file:line:col``, what is wrong
and what is allowed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

from .errors import FuzzymeshError
from .yamlfile import Located, located

NUMBER = "number"
INTEGER = "integer"
STRING = "string"
BOOLEAN = "boolean"
MAPPING = "mapping"
LIST = "list"
ANY = "any"


def _type_ok(kind: str, value) -> bool:
    if kind == ANY:
        return True
    if kind == NUMBER:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if kind == INTEGER:
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == STRING:
        return isinstance(value, str)
    if kind == BOOLEAN:
        return isinstance(value, bool)
    if kind == MAPPING:
        return isinstance(value, dict)
    if kind == LIST:
        return isinstance(value, list)
    raise ValueError(kind)


def _describe(value) -> str:
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return f"boolean {value}"
    if isinstance(value, (int, float)):
        return f"number {value}"
    if isinstance(value, str):
        return f"string '{value}'"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    return type(value).__name__


@dataclass(frozen=True)
class Field:
    """One allowed key: its type(s), whether required, its default and checks.

    ``kind`` is one of the type names above or a tuple of them. ``check``
    returns an error text (what is wrong; what to do) or None. ``fields`` is the
    schema of a nested mapping; ``items`` the Field of each list element.
    """

    kind: str | tuple = ANY
    required: bool = False
    default: Any = None
    choices: tuple | None = None
    check: Callable[[Any], str | None] | None = None
    fields: dict | None = None
    items: "Field | None" = None
    open_keys: bool = False
    doc: str = ""


def positive(value) -> str | None:
    if not math.isfinite(value) or value <= 0:
        return f"must be a finite number > 0, got {value}"
    return None


def non_negative(value) -> str | None:
    if not math.isfinite(value) or value < 0:
        return f"must be a finite number >= 0, got {value}"
    return None


def finite(value) -> str | None:
    if not math.isfinite(value):
        return f"must be a finite number, got {value}"
    return None


def in_range(lo: float, hi: float) -> Callable[[Any], str | None]:
    def check(value):
        if not (lo <= value <= hi):
            return f"must be between {lo} and {hi}, got {value}"
        return None

    return check


def validate(mapping, schema: dict, error=FuzzymeshError, context: str = "", where: str | None = None) -> dict:
    """Check ``mapping`` against ``schema``; return a plain dict with defaults.

    ``context`` names the section in messages, e.g. ``geometry``; ``where`` is
    the position of the mapping's key, for when the value is not a mapping.
    """
    mapping = located(mapping)
    label = f"in '{context}'" if context else "at the top level"
    if not isinstance(mapping, Located):
        raise error(f"expected a mapping {label}, got {_describe(mapping)}", where=where)
    allowed = ", ".join(schema)
    for key in mapping:
        if key not in schema:
            raise error(f"unknown key '{key}' {label}", where=mapping.where(key), fix=f"allowed keys: {allowed}")
    out = {}
    for key, spec in schema.items():
        name = f"{context}.{key}" if context else str(key)
        if key not in mapping or mapping[key] is None and spec.required:
            if spec.required:
                raise error(
                    f"missing key '{key}' {label}",
                    where=mapping.where(),
                    fix=f"add '{key}:' ({_kind_text(spec.kind)}){_doc(spec)}",
                )
            out[key] = spec.default
            continue
        out[key] = check_value(mapping[key], spec, name, mapping.where(key), error)
    return out


def _kind_text(kind) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    return " or ".join(kinds)


def _doc(spec: Field) -> str:
    return f", {spec.doc}" if spec.doc else ""


def check_value(value, spec: Field, name: str, where: str, error=FuzzymeshError):
    """Check one value against its Field; return the validated value."""
    kinds = spec.kind if isinstance(spec.kind, tuple) else (spec.kind,)
    if not any(_type_ok(k, value) for k in kinds):
        raise error(
            f"'{name}' must be {_kind_text(spec.kind)}, got {_describe(value)}", where=where, fix=spec.doc or None
        )
    if spec.choices is not None and value not in spec.choices:
        raise error(
            f"'{name}' is '{value}', which is not known",
            where=where,
            fix=f"choose one of: {', '.join(map(str, spec.choices))}",
        )
    if isinstance(value, dict):
        if spec.fields is not None:
            value = validate(value, spec.fields, error, name, where)
        elif not spec.open_keys:
            value = dict(value)
    elif isinstance(value, list) and spec.items is not None:
        value = [
            check_value(v, spec.items, f"{name}[{i}]", getattr(v, "where", lambda: where)(), error)
            for i, v in enumerate(value)
        ]
    if spec.check is not None:
        problem = spec.check(value)
        if problem:
            raise error(f"'{name}' {problem}", where=where, fix=spec.doc or None)
    return value
