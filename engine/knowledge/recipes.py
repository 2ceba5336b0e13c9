"""Recipe files (``kind: recipe``): the placements of one kind of analysis."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import KnowledgeError
from ..schema import LIST, STRING, Field, validate
from ..yamlfile import Located
from .common import OVERRIDES, _err
from .placements import Placement, load_placements


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
