"""The knowledge base: rule bases, patterns, recipes, feature kinds and sizing defaults.

Every file is YAML with a ``kind:`` key (``rules``, ``pattern``, ``recipe``,
``features``, ``sizing``), read with safe loading. Loading is strict: each
error is one line ``file:line:col: what is wrong; what is allowed`` (a
:class:`~engine.errors.KnowledgeError`). See ``docs/rules.md`` for the formats.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np

from ..acceptance import Tolerances
from ..errors import FuzzymeshError, KnowledgeError
from ..expr import Expression, ExpressionError
from ..fcl import load_fcl
from ..fuzzy import Rule, RuleBase, Term, Variable
from ..regions import RegionDistance
from ..schema import BOOLEAN, INTEGER, LIST, MAPPING, NUMBER, STRING, Field, finite, in_range, positive, validate
from ..yamlfile import Located, load_yaml

FILE_KINDS = ("rules", "pattern", "recipe", "features", "sizing")
KNOWLEDGE_SUFFIXES = (".yaml", ".yml", ".fcl")  # .fcl: rule files in FCL (engine/fcl.py)
ANCHORS = ("point", "curve", "surface", "region", "domain", "thin-wall", "narrow-gap", "curvature")
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
    "curvature_radius",
)
DOMINANCE = ("membership", "tie")
# anchors on classes of surface pieces of like measure (engine/thickness.py, engine/curvature.py), and their L
LOCAL_SCALES = {"thin-wall": "wall_thickness", "narrow-gap": "gap_width", "curvature": "curvature_radius"}
FEATURE_TESTS = {
    "curve": ("closed", "circular", "convex", "sharp", "on_surface", "dihedral_above", "dihedral_below", "named"),
    "patch": ("planar", "cylindrical", "concave", "full_turn", "named"),
}
ANGLE_TESTS = ("dihedral_above", "dihedral_below")  # take an angle in degrees; "named" a name; the rest true/false
COVERAGE_SAMPLES = 401  # per input axis, when checking that every input fires a rule
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


# ----------------------------------------------------------------------------------- rule bases


def _terms_ok(value):
    if not value:
        return "needs at least one term"
    return None


VARIABLE = {
    "universe": Field(LIST, required=True, items=Field(NUMBER), doc="[low, high]"),
    "terms": Field(
        MAPPING,
        required=True,
        open_keys=True,
        check=_terms_ok,
        doc="LABEL: [a, b, c, d] trapezoid or [a, b, c] triangle",
    ),
    "default": Field(NUMBER, doc="output value when no rule fires (outputs only)"),
    "doc": Field(STRING, default=""),
}
RULE = {
    "id": Field(STRING, required=True, doc="a unique rule id, cited by the audit"),
    "if": Field(MAPPING, required=True, open_keys=True, doc="{input: LABEL, ...} joined by AND"),
    "then": Field(MAPPING, required=True, open_keys=True, doc="{output: LABEL}"),
    "doc": Field(STRING, default=""),
}
RULEBASE = {
    "doc": Field(STRING, default=""),
    "inputs": Field(MAPPING, required=True, open_keys=True, doc="input variables"),
    "outputs": Field(MAPPING, required=True, open_keys=True, doc="output variables"),
    "rules": Field(LIST, required=True, doc="a list of rules"),
    "resolution": Field(INTEGER, default=101, check=in_range(11, 10001), doc="output samples for the centroid"),
    "action": Field(MAPPING, open_keys=True, doc="{output: NAME, threshold: NUMBER}: act where output >= threshold"),
}
PACKER_SETTINGS = {
    "diameter": Field(
        NUMBER,
        default=0.87,
        check=in_range(0.5, 1.5),
        doc="bubble diameter / h: calibrated so that the median edge of the mesh is h (docs/rules.md "
        "section 4, bench/size_calibration.py); the shipped knowledge/population.yaml gives it",
    ),
    "control_interval": Field(
        INTEGER, default=10, check=in_range(1, 10_000), doc="dynamics steps between two population-control rounds"
    ),
    "control_rounds": Field(
        INTEGER,
        default=8,
        check=in_range(0, 10_000),
        doc="population-control rounds per level, after which the bubbles only settle",
    ),
    "count_radius": Field(
        NUMBER,
        default=1.25,
        check=in_range(1.0, 1.5),
        doc="neighbours closer than count_radius x r0 count for the vacancy",
    ),
    "expected_neighbours": Field(
        MAPPING,
        default=None,
        fields={
            "curve": Field(INTEGER, default=2, check=in_range(1, 100)),
            "patch": Field(INTEGER, default=6, check=in_range(1, 100)),
            "volume": Field(INTEGER, default=12, check=in_range(1, 100)),
        },
        doc="neighbour count of a well-packed bubble on each level",
    ),
}
RULES_FILE = {
    "kind": Field(STRING, required=True),
    "id": Field(STRING, required=True, doc="the rule file's id"),
    "overrides": OVERRIDES,
    "doc": Field(STRING, default=""),
    "rulebases": Field(MAPPING, required=True, open_keys=True, doc="NAME: rule base"),
    "packer": Field(MAPPING, fields=PACKER_SETTINGS, doc="settings the bubble packer reads with these rules"),
}


def _variable(name, raw: Located, is_output: bool, rb_id: str, where: str) -> Variable:
    spec = validate(raw, VARIABLE, KnowledgeError, f"{rb_id}.{name}", where)
    universe = spec["universe"]
    if len(universe) != 2 or not np.all(np.isfinite(universe)) or not universe[0] < universe[1]:
        raise _err(f"universe of '{name}' must be [low, high], finite, with low < high", raw.where("universe"))
    lo, hi = universe
    terms = {}
    for label, points in raw["terms"].items():
        term_where = raw["terms"].where(label)
        if (
            not isinstance(points, list)
            or len(points) not in (3, 4)
            or not all(isinstance(p, (int, float)) and not isinstance(p, bool) for p in points)
        ):
            raise _err(
                f"term '{label}' of '{name}' must be 3 or 4 numbers",
                term_where,
                "give [a, b, c, d] (trapezoid) or [a, b, c] (triangle)",
            )
        if len(points) == 3:
            points = [points[0], points[1], points[1], points[2]]
        if not all(points[i] <= points[i + 1] for i in range(3)):
            raise _err(f"term '{label}' of '{name}' needs a <= b <= c <= d, got {points}", term_where)
        if points[0] < lo or points[3] > hi:
            raise _err(
                f"term '{label}' of '{name}' reaches outside the universe [{lo}, {hi}]",
                term_where,
                "keep the term's points inside the universe (inputs are clipped to it)",
            )
        terms[str(label)] = Term(str(label), tuple(float(p) for p in points))
    if is_output and spec["default"] is None:
        raise _err(f"output '{name}' has no default", where, "add 'default:' (the value when no rule fires)")
    if not is_output and spec["default"] is not None:
        raise _err(f"input '{name}' cannot have a default", raw.where("default"), "remove it; inputs are measured")
    if is_output and not lo <= spec["default"] <= hi:
        raise _err(f"default of '{name}' lies outside its universe", raw.where("default"))
    return Variable(str(name), (float(lo), float(hi)), terms, spec["default"])


def _rulebase(name, raw: Located, file_id: str) -> RuleBase:
    rb_id = f"{file_id}.{name}"
    spec = validate(raw, RULEBASE, KnowledgeError, rb_id)
    inputs = {
        str(k): _variable(k, v, False, rb_id, raw["inputs"].where(k))
        for k, v in raw["inputs"].items()
        if _is_map(v, raw["inputs"], k)
    }
    outputs = {
        str(k): _variable(k, v, True, rb_id, raw["outputs"].where(k))
        for k, v in raw["outputs"].items()
        if _is_map(v, raw["outputs"], k)
    }
    if not inputs or not outputs:
        raise _err(f"rule base '{rb_id}' needs at least one input and one output", raw.where())
    rules, seen = [], {}
    for item in raw["rules"]:
        if not isinstance(item, Located):
            raise _err("each rule must be a mapping with id, if, then", raw.where("rules"))
        rule = validate(item, RULE, KnowledgeError, f"{rb_id} rule")
        if rule["id"] in seen:
            raise _err(f"duplicate rule id '{rule['id']}' (first at {seen[rule['id']]})", item.where("id"))
        seen[rule["id"]] = item.where("id")
        conditions = _clauses(item["if"], inputs, "input", item.where("if"))
        conclusions = _clauses(item["then"], outputs, "output", item.where("then"))
        rules.append(Rule(rule["id"], conditions, conclusions, item.where()))
    if not rules:
        raise _err(f"rule base '{rb_id}' has no rules", raw.where("rules"))
    extra = {}
    if spec["action"] is not None:
        action = validate(
            raw["action"],
            {
                "output": Field(STRING, required=True, choices=tuple(outputs)),
                "threshold": Field(NUMBER, required=True),
                "doc": Field(STRING, default=""),
            },
            KnowledgeError,
            f"{rb_id}.action",
        )
        lo, hi = outputs[action["output"]].universe
        if not lo <= action["threshold"] <= hi:
            raise _err(
                f"action threshold {action['threshold']} lies outside the universe of '{action['output']}'",
                raw["action"].where("threshold"),
                f"give a value in [{lo}, {hi}]",
            )
        extra["action"] = action
    base = RuleBase(rb_id, inputs, outputs, rules, spec["resolution"], raw.where(), extra)
    _check_coverage(base, raw.where("rules"))
    return base


def _is_map(value, parent: Located, key) -> bool:
    if not isinstance(value, Located):
        raise _err(f"'{key}' must be a mapping (universe, terms)", parent.where(key))
    return True


def _clauses(raw: Located, variables: dict, role: str, where: str):
    if not raw:
        raise _err(f"a rule needs at least one {role} clause", where)
    clauses = []
    for var, label in raw.items():
        if not isinstance(label, str):
            raise _err(
                f"the label of '{var}' must be a name, got {type(label).__name__}",
                raw.where(var),
                "write e.g. 'overlap: LARGE'",
            )
        if var not in variables:
            raise _err(f"unknown {role} '{var}'", raw.where(var), f"known {role}s: {', '.join(variables)}")
        if label not in variables[var].terms:
            raise _err(
                f"label '{label}' is not defined for {role} '{var}'",
                raw.where(var),
                f"defined labels: {', '.join(variables[var].terms)}",
            )
        clauses.append((str(var), str(label)))
    return tuple(clauses)


def _check_coverage(base: RuleBase, where: str) -> None:
    """Every point of the input space must fire at least one rule."""
    axes = []
    for var in base.inputs.values():
        breaks = [p for t in var.terms.values() for p in t.points]
        grid = np.unique(np.concatenate([np.linspace(*var.universe, COVERAGE_SAMPLES), breaks]))
        axes.append(grid)
    if np.prod([len(a) for a in axes]) > 4_000_000:
        axes = [np.linspace(*v.universe, 101) for v in base.inputs.values()]
    mesh = np.meshgrid(*axes, indexing="ij")
    values = {name: m.ravel() for name, m in zip(base.inputs, mesh)}
    fired = base.firing(values).max(axis=1) > 0
    if not fired.all():
        bad = np.flatnonzero(~fired)[0]
        at = ", ".join(f"{name} = {values[name][bad]:.6g}" for name in base.inputs)
        raise _err(
            f"rule base '{base.id}': no rule fires at {at}",
            where,
            "add a term or a rule that covers this input, so no input is silently ignored",
        )


def load_rules(raw: Located, source: str) -> tuple[dict[str, RuleBase], dict | None]:
    """The file's rule bases by id, and its packer settings (None if it has none)."""
    spec = validate(raw, RULES_FILE, KnowledgeError)
    bases = {}
    for name, body in raw["rulebases"].items():
        if not isinstance(body, Located):
            raise _err(f"rule base '{name}' must be a mapping", raw["rulebases"].where(name))
        bases[f"{spec['id']}.{name}"] = _rulebase(name, body, spec["id"])
    settings = spec["packer"]
    if settings is not None and settings["expected_neighbours"] is None:
        settings["expected_neighbours"] = validate({}, PACKER_SETTINGS["expected_neighbours"].fields)
    return bases, settings


# ------------------------------------------------------------------------------------- patterns


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


# ------------------------------------------------------------------------------- pattern values

# where the knowledge is checked without a solid: every pattern at these global sizes H, and lengths L of
# these multiples of H, with the gaps of its roles 0 (so ligament zones are on)
SAMPLE_H = (1.0, 10.0, 100.0)
SAMPLE_L = (0.1, 1.0, 10.0)


def check_values(pattern: Pattern, parameters: dict, placement: "Placement | None" = None) -> None:
    """Evaluate every zone of ``pattern`` with ``parameters`` at the sample L and H (L the placement's
    ``scale`` if it gives one), so a broken size law is found before any geometry is read."""
    lengths = (
        [None]
        if pattern.scale == "none"
        else [placement.scale]
        if placement is not None and placement.scale is not None
        else None
    )
    for H in SAMPLE_H:
        for L in lengths or [q * H for q in SAMPLE_L]:
            env = {
                **parameters,
                "H": H,
                **({"L": L} if L is not None else {}),
                **{f"gap_{role}": 0.0 for role in pattern.roles},
            }
            for zone in pattern.zones:
                zone_values(pattern, zone, env, placement, " at a sample L and H")


def _value_error(pattern, zone, what, exprs, problem, fix, env, placement, on) -> KnowledgeError:
    """What is wrong with a zone's value, at the expression's file:line or, when placed, at the placement."""
    names = sorted(set().union(*(e.names for e in exprs)), key=lambda n: (n in ("H", "L"), n))
    at = ", ".join(f"{n} = {env[n]:g}" for n in names)
    shown = f"({exprs[0].text})" if len(exprs) == 1 else f"[{', '.join(e.text for e in exprs)}]"
    text = f"pattern '{pattern.name}', zone '{zone.id}': {what} {shown} {problem}" + (f" at {at}" if at else "")
    if placement is None:
        return _err(f"{text}, with the default parameters{on}", exprs[0].where, fix)
    given = [n for n in names if n in placement.parameters]
    return _err(
        f"{text}, as placed here{on} (the {what} is at {exprs[0].where})",
        placement.where(f"parameters.{given[0]}") if given else placement.source,
        fix,
    )


def expression_value(
    pattern: Pattern,
    zone: Zone,
    expr: Expression,
    what: str,
    env: dict,
    placement: "Placement | None" = None,
    on: str = "",
    finite: bool = True,
) -> float:
    """``expr`` at ``env``: a finite number (``finite=False``: not NaN), else a located error."""
    try:
        number = expr(env)
    except ExpressionError as exc:
        problem = str(exc)
    else:
        if math.isfinite(number) or not finite and not math.isnan(number):
            return number
        problem = "is not a number" if math.isnan(number) else "overflows (beyond 1.8e308)"
    raise _value_error(
        pattern,
        zone,
        what,
        [expr],
        problem,
        "change the expression or the parameters so it is a finite number for every L and H",
        env,
        placement,
        on,
    )


def zone_values(
    pattern: Pattern, zone: Zone, env: dict, placement: "Placement | None" = None, on: str = ""
) -> dict | None:
    """The zone's numbers at ``env`` (``near``, ``far``, ``over``, ``exponent``, ``height``, ``trapezoid``),
    None where its ``active_if`` is off. Each must be finite, the sizes, ``over`` and ``exponent`` > 0, the
    height in [0, 1] and the trapezoid ordered; else an error naming the expression's file:line, the values
    used and, when given, the placement (``on`` says more: the feature it is bound to, or that L and H are
    samples)."""

    def value(expr, what, finite=True):
        return expression_value(pattern, zone, expr, what, env, placement, on, finite)

    def fail(what, exprs, problem, fix):
        return _value_error(pattern, zone, what, exprs, problem, fix, env, placement, on)

    height = "the membership height" if zone.trapezoid else "the membership"
    near = value(zone.near, "'near'")
    if zone.active_if is not None and not value(zone.active_if, "'active_if'", finite=False) > 0:
        return None
    numbers = {
        "near": near,
        "far": value(zone.far, "'far'") if zone.far else near,
        "over": value(zone.over, "'over'") if zone.over else 1.0,
        "exponent": value(zone.exponent, "'exponent'") if zone.exponent else 1.0,
        "height": value(zone.height, height),
        "trapezoid": None,
    }
    for key in ("near", "far", "over", "exponent"):
        expr = getattr(zone, key)
        if expr is not None and numbers[key] <= 0:
            raise fail(f"'{key}'", [expr], f"is {numbers[key]:g}, not > 0", "make it positive for every L and H")
    if not 0 <= numbers["height"] <= 1:
        raise fail(
            height, [zone.height], f"is {numbers['height']:g}, not in [0, 1]", "give a membership between 0 and 1"
        )
    if zone.trapezoid is not None:
        points = tuple(value(e, f"trapezoid point {i + 1}") for i, e in enumerate(zone.trapezoid))
        if not all(points[i] <= points[i + 1] for i in range(3)):
            raise fail(
                "the trapezoid",
                list(zone.trapezoid),
                f"is [{', '.join(f'{x:g}' for x in points)}], not ordered a <= b <= c <= d",
                "order its points for every L and H",
            )
        numbers["trapezoid"] = points
    return numbers


# -------------------------------------------------------------------------------------- recipes

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


@dataclass
class Placement:
    """A pattern placed by a recipe or a job, before it is bound to features."""

    pattern: str
    id: str
    at: str | None
    every: str | None
    point: list | None
    region: dict | None
    roles: dict
    parameters: dict
    scale: float | None
    source: str
    origin: str  # "recipe NAME" or "job"
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
                p["pattern"],
                p["id"] or f"{prefix}[{index}]",
                p["at"],
                p["every"],
                p["point"],
                p["region"],
                dict(p["roles"]),
                dict(p["parameters"]),
                p["scale"],
                body.where(),
                origin,
                key_where,
            )
        )
    return placements


@dataclass
class Recipe:
    name: str
    doc: str
    placements: list[Placement]
    source: str


RECIPE_FILE = {
    "kind": Field(STRING, required=True),
    "name": Field(STRING, required=True),
    "overrides": OVERRIDES,
    "doc": Field(STRING, required=True, doc="what analysis the recipe is for"),
    "place": Field(LIST, required=True, doc="the placements"),
}


def load_recipe(raw: Located, source: str) -> Recipe:
    spec = validate(raw, RECIPE_FILE, KnowledgeError)
    placements = load_placements(raw["place"], raw.where("place"), f"recipe {spec['name']}", f"{spec['name']}/place")
    if not placements:
        raise _err("a recipe needs at least one placement", raw.where("place"))
    return Recipe(spec["name"], spec["doc"], placements, source)


# ---------------------------------------------------------------------------- feature kinds etc.


@dataclass
class FeatureKind:
    name: str
    of: str
    tests: dict
    doc: str
    source: str


FEATURE_KIND = {
    "of": Field(STRING, required=True, choices=("curve", "patch")),
    "when": Field(MAPPING, required=True, open_keys=True, doc="TEST: value"),
    "doc": Field(STRING, required=True),
}


def load_feature_kinds(raw: Located, source: str) -> dict[str, FeatureKind]:
    spec = validate(
        raw,
        {
            "kind": Field(STRING, required=True),
            "doc": Field(STRING, default=""),
            "overrides": OVERRIDES,
            "kinds": Field(MAPPING, required=True, open_keys=True),
        },
        KnowledgeError,
    )
    kinds = {}
    for name, body in raw["kinds"].items():
        k = validate(body, FEATURE_KIND, KnowledgeError, f"kinds.{name}", raw["kinds"].where(name))
        allowed = FEATURE_TESTS[k["of"]]
        when = body["when"]
        for test, value in when.items():
            if test not in allowed:
                raise _err(
                    f"unknown test '{test}' for a {k['of']}",
                    when.where(test),
                    f"tests for a {k['of']}: {', '.join(allowed)}",
                )
            if test in ANGLE_TESTS:
                if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 180:
                    raise _err(
                        f"test '{test}' takes an angle in degrees from 0 to 180, got {value!r}",
                        when.where(test),
                        f"e.g. '{test}: 60' (the angle between the faces' normals)",
                    )
            elif not isinstance(value, str if test == "named" else bool):
                raise _err(
                    f"test '{test}' takes {'a feature name' if test == 'named' else 'true or false'}",
                    when.where(test),
                    f"e.g. '{test}: {'crack-front' if test == 'named' else 'true'}'",
                )
        if set(ANGLE_TESTS) <= set(when) and when["dihedral_above"] >= when["dihedral_below"]:
            raise _err(
                f"no curve passes dihedral_above: {when['dihedral_above']} and dihedral_below: "
                f"{when['dihedral_below']}",
                when.where("dihedral_below"),
                "make dihedral_above the smaller",
            )
        kinds[str(name)] = FeatureKind(str(name), k["of"], dict(body["when"]), k["doc"], raw["kinds"].where(name))
    del spec
    return kinds


SIZING_FILE = {
    "kind": Field(STRING, required=True),
    "doc": Field(STRING, default=""),
    "gradation": Field(
        NUMBER,
        default=1.3,
        check=in_range(1.01, 3.0),
        doc="the largest ratio of sizes one element apart: h(y) <= h(x) + (g - 1)|x - y|",
    ),
    "base_pattern": Field(STRING, default="uniform-domain", doc="the pattern placed when a job places none"),
    "always_place": Field(
        LIST, default=[], doc="placements added to every job, unless it places the same pattern itself"
    ),
    "acceptance": Field(
        MAPPING,
        default=None,
        doc="the acceptance gate's tolerances (engine/acceptance.py)",
        fields={
            "min_dihedral": Field(
                NUMBER,
                default=Tolerances.min_dihedral,
                check=in_range(0.0, 60.0),
                doc="smallest dihedral angle of any tetrahedron, degrees",
            ),
            "volume": Field(
                NUMBER,
                default=Tolerances.volume,
                check=in_range(0.0, 1.0),
                doc="largest |mesh volume / input volume - 1|",
            ),
            "hausdorff": Field(
                NUMBER,
                default=Tolerances.hausdorff,
                check=in_range(0.0, 100.0),
                doc="largest distance between the mesh boundary and the input surface, each way, "
                "over the target size h there",
            ),
            "quadratic_jacobian": Field(
                NUMBER,
                default=Tolerances.quadratic_jacobian,
                check=in_range(0.0, 1.0),
                doc="smallest scaled Jacobian of a 10-node tetrahedron",
            ),
        },
    ),
}


# ------------------------------------------------------------------------------ knowledge base


@dataclass
class KnowledgeBase:
    rulebases: dict[str, RuleBase] = field(default_factory=dict)
    patterns: dict[str, Pattern] = field(default_factory=dict)
    recipes: dict[str, Recipe] = field(default_factory=dict)
    feature_kinds: dict[str, FeatureKind] = field(default_factory=dict)
    sizing: dict = field(
        default_factory=lambda: {
            "gradation": 1.3,
            "base_pattern": "uniform-domain",
            "always_place": [],
            "acceptance": Tolerances(),
            "where": "built-in defaults",
        }
    )
    packer_settings: dict[str, dict] = field(default_factory=dict)  # rule file id -> its packer settings

    def add_file(self, path: Path) -> None:
        raw = load_fcl(path) if Path(path).suffix == ".fcl" else load_yaml(path, KnowledgeError)
        source = str(path)
        if not isinstance(raw, Located):
            raise _err("a knowledge file must be a YAML mapping with 'kind:'", f"{source}:1:1")
        kind = raw.get("kind")
        if kind not in FILE_KINDS:
            raise _err(
                f"unknown or missing kind '{kind}'" if kind else "missing 'kind:'",
                raw.where("kind") if "kind" in raw else raw.where(),
                f"kind is one of: {', '.join(FILE_KINDS)}",
            )
        if kind == "rules":
            bases, settings = load_rules(raw, source)
            names = raw["rulebases"]
            self._add(
                self.rulebases,
                "rule base",
                {f"{raw['id']}.{n}": (bases[f"{raw['id']}.{n}"], names.where(n)) for n in names},
                raw,
            )
            if settings is not None:
                self.packer_settings[str(raw["id"])] = settings
        elif kind == "pattern":
            pattern = load_pattern(raw, source)
            self._add(self.patterns, "pattern", {pattern.name: (pattern, raw.where("name"))}, raw)
        elif kind == "recipe":
            recipe = load_recipe(raw, source)
            self._add(self.recipes, "recipe", {recipe.name: (recipe, raw.where("name"))}, raw)
        elif kind == "features":
            kinds = load_feature_kinds(raw, source)
            self._add(self.feature_kinds, "feature kind", {name: (fk, fk.source) for name, fk in kinds.items()}, raw)
        else:
            self.sizing = validate(raw, SIZING_FILE, KnowledgeError)
            self.sizing["acceptance"] = Tolerances(**(self.sizing["acceptance"] or {}))
            self.sizing["where"] = raw.where("base_pattern")
            if "always_place" in raw:
                self.sizing["always_place"] = load_placements(
                    raw["always_place"], raw.where("always_place"), "sizing defaults", "always"
                )

    @staticmethod
    def _add(table: dict, noun: str, items: dict, raw: Located) -> None:
        """Add a file's named items ``{name: (value, where)}``: a name read before is an error unless the file
        says ``overrides: true``, and then every name must replace one (so a misspelt name is no new one)."""
        overrides = raw.get("overrides") is True
        for key, (value, where) in items.items():
            if key in table and not overrides:
                first = getattr(table[key], "source", "")
                raise _err(
                    f"{noun} '{key}' is defined twice (also in {first})",
                    where,
                    "rename it, or add 'overrides: true' to this file to replace the other",
                )
            if key not in table and overrides:
                raise _err(
                    f"'overrides: true', but no {noun} '{key}' is defined before this file",
                    where,
                    f"remove 'overrides: true', or name the {noun} it replaces",
                )
        table.update({key: value for key, (value, _) in items.items()})

    def problems(self, sizings: list[dict] | None = None) -> list[FuzzymeshError]:
        """The cross-file checks, the first problem of each recipe and of the sizing defaults (``sizings``: of
        each sizing file read, not only the one in force): their placements name existing patterns,
        parameters, roles and feature kinds and evaluate (:func:`check_values`), the base pattern exists."""

        def placements(items):
            for placement in items:
                check_placement(self, placement)

        def defaults(sizing):
            placements(sizing["always_place"])
            if sizing["base_pattern"] not in self.patterns and self.patterns:
                raise _err(
                    f"base pattern '{sizing['base_pattern']}' is not in the pattern library",
                    sizing["where"],
                    f"name one of: {', '.join(sorted(self.patterns))}",
                )

        found = []
        for check in [
            *(partial(placements, r.placements) for r in self.recipes.values()),
            *(partial(defaults, sizing) for sizing in sizings or [self.sizing]),
        ]:
            try:
                check()
            except FuzzymeshError as exc:
                found.append(exc)
        return found

    def check(self) -> None:
        """Raise the first of :meth:`problems`."""
        problems = self.problems()
        if problems:
            raise problems[0]


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


def default_paths() -> list[Path]:
    """The shipped knowledge/ and patterns/ folders (installed wheel or source checkout)."""
    here = Path(__file__).resolve().parents[1]  # engine/
    installed = here / "_data"
    root = installed if installed.is_dir() else here.parent
    return [root / "knowledge", root / "patterns"]


def yaml_files(paths) -> list[Path]:
    files = []
    for path in map(Path, paths):
        if path.is_dir():
            files += sorted(p for p in path.rglob("*") if p.suffix in KNOWLEDGE_SUFFIXES)
        else:
            files.append(path)
    return files


def load_knowledge(extra_paths=()) -> KnowledgeBase:
    """The default knowledge base plus ``extra_paths`` (files or folders)."""
    kb = KnowledgeBase()
    for path in yaml_files([*default_paths(), *extra_paths]):
        kb.add_file(path)
    kb.check()
    return kb


def lint(paths) -> list[str]:
    """The first error of each file, one line each, empty when all is well: loading (patterns evaluated at sample
    L and H), then the recipes and sizing defaults checked against the shipped knowledge and the linted files."""
    files = yaml_files(paths)
    linted = {f.resolve() for f in files if f.exists()}
    kb = KnowledgeBase()
    for path in yaml_files(default_paths()):  # what the linted files add to, or must say they override
        if path.resolve() not in linted:
            try:
                kb.add_file(path)
            except FuzzymeshError:
                pass
    errors, sizings = [], []
    for path in files:
        try:
            before = kb.sizing
            kb.add_file(path)
            if kb.sizing is not before:
                sizings.append(kb.sizing)
        except FuzzymeshError as exc:
            errors.append(exc.one_line())
        except Exception as exc:  # a loader fault must not hide the other files' findings
            errors.append(f"{path}: internal error while reading ({exc.__class__.__name__}: {exc}); please report it")
    return errors + [exc.one_line() for exc in kb.problems(sizings)]


__all__ = [
    "KnowledgeBase",
    "Pattern",
    "Zone",
    "Recipe",
    "Placement",
    "FeatureKind",
    "load_knowledge",
    "lint",
    "load_placements",
    "check_placement",
    "default_paths",
]
