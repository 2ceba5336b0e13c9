"""Placements: a pattern placed by a recipe, a job or the sizing defaults (``at`` a feature name, ``every``
feature of a kind, a ``point`` or a ``region``), read and checked against the knowledge base."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..errors import KnowledgeError
from ..regions import RegionDistance
from ..schema import LIST, MAPPING, NUMBER, STRING, Field, positive, validate
from ..yamlfile import Located
from .common import _err
from .patterns import LOCAL_SCALES, Pattern
from .values import check_values

if TYPE_CHECKING:
    from .base import KnowledgeBase

PLACEMENT = {
    "pattern": Field(STRING, required=True, doc="a pattern name (fuzzymesh patterns list)"),
    "id": Field(STRING, doc="the placement's id, cited by the audit"),
    "at": Field(STRING, doc="a feature name, e.g. junction"),
    "every": Field(STRING, doc="a feature kind, e.g. hole"),
    "point": Field(LIST, items=Field(NUMBER), doc="[x, y, z] for point patterns"),
    "region": Field(
        MAPPING, open_keys=True, doc="{box: {min, max}} | {sphere: {centre, radius}} | {cylinder: {start, end, radius}}"
    ),
    "roles": Field(MAPPING, default={}, open_keys=True, doc="ROLE: feature name"),
    "parameters": Field(MAPPING, default={}, open_keys=True, doc="PARAMETER: number"),
    "scale": Field(NUMBER, check=positive, doc="the length L, overriding the one taken from the feature"),
}


@dataclass(frozen=True, kw_only=True)
class Placement:
    """A pattern placed by a recipe or a job, before it is bound to features (a value: derive a changed one
    with ``dataclasses.replace``)."""

    pattern: str
    id: str
    source: str
    origin: str  # "recipe NAME", "job" or "default"
    at: str | None = None
    every: str | None = None
    point: list | None = None
    region: dict | None = None
    roles: dict = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)
    scale: float | None = None
    key_where: dict = field(default_factory=dict)  # key -> file:line:col

    def where(self, key: str | None = None) -> str:
        return self.key_where.get(key, self.source)


def load_placements(raw_list, where: str, origin: str, prefix: str) -> list[Placement]:
    if not isinstance(raw_list, list):
        raise _err("placements must be a list", where)
    placements = []
    for index, body in enumerate(raw_list):
        if not isinstance(body, Located):
            raise _err("each placement must be a mapping with 'pattern:'", where)
        p = validate(body, PLACEMENT, KnowledgeError, "placement")
        given = [k for k in ("at", "every", "point", "region") if p[k] is not None]
        if len(given) > 1:
            raise _err(
                f"a placement takes one of at / every / point / region, got {', '.join(given)}", body.where(given[1])
            )
        if p["point"] is not None and len(p["point"]) != 3:
            raise _err("'point' needs three coordinates [x, y, z]", body.where("point"))
        for name, value in p["parameters"].items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
                raise _err(f"parameter '{name}' must be a finite number", body["parameters"].where(name))
        if p["region"] is not None:
            RegionDistance(p["region"], body.where("region"))
        key_where = {key: body.where(key) for key in body}
        for section in ("parameters", "roles"):
            if section in body:
                key_where.update({f"{section}.{k}": body[section].where(k) for k in body[section]})
        placements.append(
            Placement(
                pattern=p["pattern"],
                id=p["id"] or f"{prefix}[{index}]",
                at=p["at"],
                every=p["every"],
                point=p["point"],
                region=p["region"],
                roles=dict(p["roles"]),
                parameters=dict(p["parameters"]),
                scale=p["scale"],
                source=body.where(),
                origin=origin,
                key_where=key_where,
            )
        )
    return placements


def check_placement(kb: KnowledgeBase, placement: Placement) -> Pattern:
    """The placement's pattern, after checking its parameters, roles and anchor keys."""
    pattern = kb.patterns.get(placement.pattern)
    if pattern is None:
        raise _err(
            f"unknown pattern '{placement.pattern}'",
            placement.where("pattern"),
            f"known patterns: {', '.join(sorted(kb.patterns))}",
        )
    for name in placement.parameters:
        if name not in pattern.parameters:
            raise _err(
                f"pattern '{pattern.name}' has no parameter '{name}'",
                placement.where(f"parameters.{name}"),
                f"its parameters: {', '.join(pattern.parameters) or 'none'}",
            )
    for name in placement.roles:
        if name not in pattern.roles:
            raise _err(
                f"pattern '{pattern.name}' has no role '{name}'",
                placement.where(f"roles.{name}"),
                f"its roles: {', '.join(pattern.roles) or 'none'}",
            )
    missing = [n for n, p in pattern.parameters.items() if p.default is None and n not in placement.parameters]
    if missing:
        raise _err(
            f"pattern '{pattern.name}' needs parameter(s) {', '.join(missing)}",
            placement.source,
            "give them under 'parameters:'",
        )
    check_values(pattern, {**{n: p.default for n, p in pattern.parameters.items()}, **placement.parameters}, placement)
    anchor_key = {
        "point": ("point", "at"),
        "curve": ("at", "every"),
        "surface": ("at", "every"),
        "region": ("region",),
        "domain": (),
        **{local: () for local in LOCAL_SCALES},
    }[pattern.anchor]
    given = [k for k in ("at", "every", "point", "region") if getattr(placement, k) is not None]
    if pattern.anchor == "domain" and given:
        raise _err(
            f"pattern '{pattern.name}' covers the whole domain and takes no '{given[0]}'",
            placement.where(given[0]),
            f"remove '{given[0]}:'",
        )
    if not anchor_key and given:
        raise _err(
            f"pattern '{pattern.name}' (anchor: {pattern.anchor}) finds its place on the solid by itself "
            f"and takes no '{given[0]}'",
            placement.where(given[0]),
            f"remove '{given[0]}:'",
        )
    if anchor_key and (not given or given[0] not in anchor_key):
        raise _err(
            f"pattern '{pattern.name}' (anchor: {pattern.anchor}) needs one of: {', '.join(anchor_key)}",
            placement.where(given[0]) if given else placement.source,
        )
    if placement.every is not None:
        if kb.feature_kinds and placement.every not in kb.feature_kinds:
            raise _err(
                f"unknown feature kind '{placement.every}'",
                placement.where("every"),
                f"known kinds: {', '.join(sorted(kb.feature_kinds))}",
            )
        if placement.every not in pattern.accepts:
            raise _err(
                f"pattern '{pattern.name}' is not placed on '{placement.every}' features",
                placement.where("every"),
                f"it accepts: {', '.join(pattern.accepts) or 'none (use at:)'}",
            )
    return pattern
