"""Rule files (``kind: rules``): fuzzy rule bases, checked to fire a rule at every input, and the bubble
packer's settings that come with them."""

from __future__ import annotations

import numpy as np

from ..errors import KnowledgeError
from ..fuzzy import Rule, RuleBase, Term, Variable
from ..schema import INTEGER, LIST, MAPPING, NUMBER, STRING, Field, in_range, validate
from ..yamlfile import Located
from .common import OVERRIDES, _err

COVERAGE_SAMPLES = 401  # per input axis, when checking that every input fires a rule


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
