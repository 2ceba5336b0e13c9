"""The knowledge base: rule bases, patterns, recipes, feature kinds and sizing defaults.

Every file is YAML with a ``kind:`` key (``rules``, ``pattern``, ``recipe``,
``features``, ``sizing``), read with safe loading. Loading is strict: each
error is one line ``file:line:col: what is wrong; what is allowed`` (a
:class:`~engine.errors.KnowledgeError`). See ``docs/rules.md`` for the formats.

One module per concept, each name importable from here (``from engine.knowledge import X``):

- ``rulebases``: rule files (fuzzy rule bases, the packer settings that come with them);
- ``patterns``: pattern files (anchor, scale, parameters, roles, zones);
- ``values``: a pattern's zone numbers evaluated and checked at given parameters, L and H;
- ``placements``: placements (recipe, job, sizing defaults) read and checked against the knowledge base;
- ``recipes``, ``feature_kinds``, ``defaults`` (the ``kind: sizing`` file): the other file kinds;
- ``base``: ``KnowledgeBase``, every file read by its kind, and the checks across files;
- ``loading``: the shipped folders and a job's files, ``load_knowledge``;
- ``linting``: ``lint``, every file checked, one line per problem.

None of them imports a geometry library (tests/test_architecture.py), so ``fuzzymesh lint`` needs none.
"""

from __future__ import annotations

from .base import FILE_KINDS, KnowledgeBase
from .common import OVERRIDES
from .defaults import SIZING_FILE
from .feature_kinds import ANGLE_TESTS, FEATURE_KIND, FEATURE_TESTS, FeatureKind, load_feature_kinds
from .linting import lint
from .loading import KNOWLEDGE_SUFFIXES, default_paths, load_knowledge, yaml_files
from .patterns import (
    ANCHORS,
    DOMINANCE,
    LAWS,
    LOCAL_SCALES,
    PARAMETER,
    PATTERN_FILE,
    ROLE,
    SCALES,
    ZONE,
    Parameter,
    Pattern,
    Zone,
    load_pattern,
)
from .placements import PLACEMENT, Placement, check_placement, load_placements
from .recipes import RECIPE_FILE, Recipe, load_recipe
from .rulebases import COVERAGE_SAMPLES, PACKER_SETTINGS, RULE, RULEBASE, RULES_FILE, VARIABLE, load_rules
from .values import SAMPLE_H, SAMPLE_L, check_values, expression_value, zone_values

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
    # also public, used by the sizing, the job, the batch runner and tests
    "Parameter",
    "yaml_files",
    "load_rules",
    "load_pattern",
    "load_recipe",
    "load_feature_kinds",
    "check_values",
    "expression_value",
    "zone_values",
    "FILE_KINDS",
    "KNOWLEDGE_SUFFIXES",
    "ANCHORS",
    "LAWS",
    "SCALES",
    "DOMINANCE",
    "LOCAL_SCALES",
    "FEATURE_TESTS",
    "ANGLE_TESTS",
    "COVERAGE_SAMPLES",
    "OVERRIDES",
    "SAMPLE_H",
    "SAMPLE_L",
    "VARIABLE",
    "RULE",
    "RULEBASE",
    "PACKER_SETTINGS",
    "RULES_FILE",
    "PATTERN_FILE",
    "PARAMETER",
    "ROLE",
    "ZONE",
    "PLACEMENT",
    "RECIPE_FILE",
    "FEATURE_KIND",
    "SIZING_FILE",
]
