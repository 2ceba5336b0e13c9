"""The knowledge base: every file read into it by its ``kind:``, names defined once (or replaced with
``overrides: true``), and the checks across files."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

from ..acceptance import Tolerances
from ..errors import FuzzymeshError, KnowledgeError
from ..fcl import load_fcl
from ..fuzzy import RuleBase
from ..schema import validate
from ..yamlfile import Located, load_yaml
from .common import _err
from .defaults import SIZING_FILE
from .feature_kinds import FeatureKind, load_feature_kinds
from .patterns import Pattern, load_pattern
from .placements import check_placement, load_placements
from .recipes import Recipe, load_recipe
from .rulebases import load_rules

FILE_KINDS = ("rules", "pattern", "recipe", "features", "sizing")


@dataclass(frozen=True, kw_only=True)
class KnowledgeBase:
    """Every knowledge file read, by kind. A frozen value: :meth:`with_file` returns a new one with a file's items
    added (the tables are new dicts; the input is never patched, nor left half-changed by a file that fails)."""

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

    def with_file(self, path: Path) -> KnowledgeBase:
        """This knowledge base with the file at ``path`` read into it by its ``kind:``."""
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
            rulebases = self._add(
                self.rulebases,
                "rule base",
                {f"{raw['id']}.{n}": (bases[f"{raw['id']}.{n}"], names.where(n)) for n in names},
                raw,
            )
            packer_settings = self.packer_settings
            if settings is not None:
                packer_settings = {**packer_settings, str(raw["id"]): settings}
            return replace(self, rulebases=rulebases, packer_settings=packer_settings)
        if kind == "pattern":
            pattern = load_pattern(raw, source)
            return replace(
                self, patterns=self._add(self.patterns, "pattern", {pattern.name: (pattern, raw.where("name"))}, raw)
            )
        if kind == "recipe":
            recipe = load_recipe(raw, source)
            return replace(
                self, recipes=self._add(self.recipes, "recipe", {recipe.name: (recipe, raw.where("name"))}, raw)
            )
        if kind == "features":
            kinds = load_feature_kinds(raw, source)
            items = {name: (fk, fk.source) for name, fk in kinds.items()}
            return replace(self, feature_kinds=self._add(self.feature_kinds, "feature kind", items, raw))
        sizing = validate(raw, SIZING_FILE, KnowledgeError)
        sizing["acceptance"] = Tolerances(**(sizing["acceptance"] or {}))
        sizing["where"] = raw.where("base_pattern")
        if "always_place" in raw:
            sizing["always_place"] = load_placements(
                raw["always_place"], raw.where("always_place"), "sizing defaults", "always"
            )
        return replace(self, sizing=sizing)

    @staticmethod
    def _add(table: dict, noun: str, items: dict, raw: Located) -> dict:
        """``table`` with a file's named items ``{name: (value, where)}`` added, a new dict: a name read before is
        an error unless the file says ``overrides: true``, and then every name must replace one (so a misspelt
        name is no new one)."""
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
        return {**table, **{key: value for key, (value, _) in items.items()}}

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
