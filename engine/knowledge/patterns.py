"""Pattern files (``kind: pattern``): a pattern's anchor, scale, parameters, roles and zones (a spacing law
h(d) and a membership mu(d) each)."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import KnowledgeError
from ..expr import Expression
from ..schema import LIST, MAPPING, NUMBER, STRING, Field, finite, validate
from ..yamlfile import Located
from .common import OVERRIDES, _err, _expression
from .values import check_values

ANCHORS = ("point", "curve", "surface", "region", "domain", "thin-wall", "narrow-gap", "narrow-face", "curvature")
LAWS = ("constant", "linear", "geometric", "power")
SCALES = (
    "none",
    "radius",
    "thickness",
    "crack_length",
    "fillet_radius",
    "edge_gap",
    "wall_thickness",
    "gap_width",
    "face_width",
    "curvature_radius",
)
DOMINANCE = ("membership", "tie")
# anchors on classes of surface pieces of like measure (engine/thickness.py, engine/facewidth.py,
# engine/curvature.py), and their L
LOCAL_SCALES = {
    "thin-wall": "wall_thickness",
    "narrow-gap": "gap_width",
    "narrow-face": "face_width",
    "curvature": "curvature_radius",
}


@dataclass
class Zone:
    """One part of a pattern: a distance, a spacing law h(d) and a membership mu(d)."""

    id: str
    distance: str  # "anchor" or "ligament:<role>"
    law: str
    near: Expression
    far: Expression | None
    over: Expression | None
    exponent: Expression | None
    trapezoid: tuple[Expression, Expression, Expression, Expression] | None  # None: constant membership
    height: Expression
    active_if: Expression | None
    source: str


@dataclass
class Parameter:
    default: float | None
    doc: str
    source: str


@dataclass
class Pattern:
    name: str
    doc: str
    anchor: str
    accepts: list[str]
    scale: str
    parameters: dict[str, Parameter]
    roles: dict[str, tuple[str | None, str]]
    zones: list[Zone]
    source: str
    dominance: str = "membership"  # or "tie": its mu is the other patterns' highest, the smaller h wins

    def expression_names(self) -> set[str]:
        names = set(self.parameters) | {"H"}
        if self.scale != "none":
            names.add("L")
        return names


PATTERN_FILE = {
    "kind": Field(STRING, required=True),
    "name": Field(STRING, required=True, doc="the pattern's name, used by recipes and jobs"),
    "overrides": OVERRIDES,
    "doc": Field(STRING, required=True, doc="what the pattern is for, shown by 'fuzzymesh patterns show'"),
    "anchor": Field(STRING, required=True, choices=ANCHORS, doc="what the pattern is placed on"),
    "accepts": Field(LIST, default=[], items=Field(STRING), doc="feature kinds 'every:' may place it on"),
    "scale": Field(STRING, default="none", choices=SCALES, doc="what the length L in expressions is"),
    "dominance": Field(
        STRING,
        default="membership",
        choices=DOMINANCE,
        doc="'membership': its own mu competes; 'tie': where it reaches, it ties with the "
        "strongest other pattern, so it wins only where it asks for smaller elements",
    ),
    "parameters": Field(MAPPING, default={}, open_keys=True, doc="NAME: {default: NUMBER, doc: TEXT}"),
    "roles": Field(MAPPING, default={}, open_keys=True, doc="other features the pattern uses: ROLE: {default, doc}"),
    "zones": Field(LIST, required=True, doc="one or more zones"),
}
PARAMETER = {
    "default": Field(NUMBER, check=finite, doc="the value when the placement gives none"),
    "doc": Field(STRING, required=True, doc="what the parameter means"),
}
ROLE = {
    "default": Field(STRING, doc="feature name used when the placement gives none"),
    "doc": Field(STRING, required=True),
}
ZONE = {
    "id": Field(STRING, required=True, doc="the zone's id, cited by the audit"),
    "distance": Field(STRING, default="anchor", doc="'anchor' or 'ligament: ROLE'"),
    "size": Field(
        MAPPING,
        required=True,
        fields={
            "law": Field(STRING, required=True, choices=LAWS),
            "near": Field((NUMBER, STRING), required=True, doc="h at distance 0"),
            "far": Field((NUMBER, STRING), doc="h at distance 'over' and beyond"),
            "over": Field((NUMBER, STRING), doc="distance over which h goes from near to far"),
            "exponent": Field((NUMBER, STRING), doc="power law exponent"),
        },
    ),
    "membership": Field(
        MAPPING,
        required=True,
        fields={
            "trapezoid": Field(LIST, doc="[a, b, c, d] over the distance"),
            "constant": Field((NUMBER, STRING), doc="the same membership everywhere"),
            "height": Field((NUMBER, STRING), default=1.0, doc="membership at the top of the trapezoid"),
        },
    ),
    "active_if": Field(STRING, doc="an expression; the zone applies only where it is > 0"),
    "doc": Field(STRING, default=""),
}


def load_pattern(raw: Located, source: str) -> Pattern:
    spec = validate(raw, PATTERN_FILE, KnowledgeError)
    params = {}
    for name, body in raw["parameters"].items() if "parameters" in raw else []:
        if not str(name).isidentifier() or name in ("H", "L"):
            raise _err(
                f"parameter name '{name}' is not allowed",
                raw["parameters"].where(name),
                "use a letter-and-underscore name other than H and L",
            )
        p = validate(body, PARAMETER, KnowledgeError, f"parameters.{name}", raw["parameters"].where(name))
        params[str(name)] = Parameter(p["default"], p["doc"], raw["parameters"].where(name))
    roles = {}
    for name, body in raw["roles"].items() if "roles" in raw else []:
        if not str(name).isidentifier():
            raise _err(f"role name '{name}' is not an identifier", raw["roles"].where(name))
        r = validate(body, ROLE, KnowledgeError, f"roles.{name}", raw["roles"].where(name))
        roles[str(name)] = (r["default"], r["doc"])
    local_scale = LOCAL_SCALES.get(spec["anchor"])
    if (local_scale or spec["scale"] in LOCAL_SCALES.values()) and spec["scale"] != local_scale:
        raise _err(
            f"anchor '{spec['anchor']}' and scale '{spec['scale']}' do not go together",
            raw.where("scale") if "scale" in raw else raw.where("anchor"),
            ", ".join(f"anchor {a} takes scale {s}" for a, s in LOCAL_SCALES.items())
            + ", and those scales no other anchor",
        )
    pattern = Pattern(
        spec["name"],
        spec["doc"],
        spec["anchor"],
        spec["accepts"],
        spec["scale"],
        params,
        roles,
        [],
        source,
        spec["dominance"],
    )
    names = pattern.expression_names()
    gap_names = names | {f"gap_{role}" for role in roles}
    if not spec["zones"]:
        raise _err("a pattern needs at least one zone", raw.where("zones"))
    seen = set()
    for body in raw["zones"]:
        if not isinstance(body, Located):
            raise _err("each zone must be a mapping", raw.where("zones"))
        pattern.zones.append(_zone(body, names, gap_names, roles, seen))
    if all(p.default is not None for p in params.values()):
        check_values(pattern, {name: p.default for name, p in params.items()})
    return pattern


def _zone(body: Located, names, gap_names, roles, seen) -> Zone:
    z = validate(body, ZONE, KnowledgeError, "zone")
    if z["id"] in seen:
        raise _err(f"duplicate zone id '{z['id']}'", body.where("id"))
    seen.add(z["id"])
    distance = z["distance"].replace(" ", "")
    if distance != "anchor":
        role = distance.split(":", 1)[1] if distance.startswith("ligament:") else None
        if role not in roles:
            raise _err(
                f"distance '{z['distance']}' is not known",
                body.where("distance"),
                f"use 'anchor' or 'ligament: ROLE' with a declared role ({', '.join(roles) or 'none declared'})",
            )
    size, raw_size = z["size"], body["size"]
    needs = {
        "constant": (),
        "linear": ("far", "over"),
        "geometric": ("far", "over"),
        "power": ("far", "over", "exponent"),
    }[size["law"]]
    for key in needs:
        if size[key] is None:
            raise _err(f"law '{size['law']}' needs '{key}'", raw_size.where(), f"add '{key}:'")
    expr = {
        k: _expression(size[k], names, raw_size.where(k)) if size[k] is not None else None
        for k in ("near", "far", "over", "exponent")
    }
    member, raw_member = z["membership"], body["membership"]
    if (member["trapezoid"] is None) == (member["constant"] is None):
        raise _err("membership needs exactly one of 'trapezoid' or 'constant'", raw_member.where())
    if member["trapezoid"] is not None:
        if len(member["trapezoid"]) != 4:
            raise _err("a trapezoid has four points [a, b, c, d]", raw_member.where("trapezoid"))
        trapezoid = tuple(_expression(v, names, raw_member.where("trapezoid")) for v in member["trapezoid"])
        height = _expression(member["height"], names, raw_member.where("height" if "height" in raw_member else None))
    else:
        trapezoid = None
        height = _expression(member["constant"], names, raw_member.where("constant"))
    active = _expression(z["active_if"], gap_names, body.where("active_if")) if z["active_if"] else None
    return Zone(
        z["id"],
        distance,
        size["law"],
        expr["near"],
        expr["far"],
        expr["over"],
        expr["exponent"],
        trapezoid,
        height,
        active,
        body.where(),
    )
