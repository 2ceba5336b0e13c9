"""Feature-kind files (``kind: features``): named tests on curves and patches (``hole``, ``fillet``, ...) that
``every:`` placements use."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import KnowledgeError
from ..schema import MAPPING, STRING, Field, validate
from ..yamlfile import Located
from .common import OVERRIDES, _err

FEATURE_TESTS = {
    "curve": ("closed", "circular", "convex", "sharp", "on_surface", "dihedral_above", "dihedral_below", "named"),
    "patch": ("planar", "cylindrical", "concave", "full_turn", "sweep_above", "sweep_below", "named"),
}
ANGLE_TESTS = {  # take an angle in degrees up to the bound; "named" a name; the rest true/false
    "dihedral_above": 180,
    "dihedral_below": 180,
    "sweep_above": 360,
    "sweep_below": 360,
}


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
                bound = ANGLE_TESTS[test]
                if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= bound:
                    meaning = "the angle between the faces' normals" if bound == 180 else "the turn round the axis"
                    raise _err(
                        f"test '{test}' takes an angle in degrees from 0 to {bound}, got {value!r}",
                        when.where(test),
                        f"e.g. '{test}: {60 if bound == 180 else 170}' ({meaning})",
                    )
            elif not isinstance(value, str if test == "named" else bool):
                raise _err(
                    f"test '{test}' takes {'a feature name' if test == 'named' else 'true or false'}",
                    when.where(test),
                    f"e.g. '{test}: {'crack-front' if test == 'named' else 'true'}'",
                )
        for angle in ("dihedral", "sweep"):
            above, below = f"{angle}_above", f"{angle}_below"
            if {above, below} <= set(when) and when[above] >= when[below]:
                raise _err(
                    f"no {k['of']} passes {above}: {when[above]} and {below}: {when[below]}",
                    when.where(below),
                    f"make {above} the smaller",
                )
        kinds[str(name)] = FeatureKind(str(name), k["of"], dict(body["when"]), k["doc"], raw["kinds"].where(name))
    del spec
    return kinds
