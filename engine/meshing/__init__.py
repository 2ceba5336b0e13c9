"""Meshers connect packed nodes into tetrahedra.

A mesher is a function ``mesh(packing, geometry, features) -> TetMesh``
registered under a name; a job picks it with ``mesher: NAME``. Third-party
meshers register through the ``fuzzymesh.meshers`` entry-point group.
"""
from __future__ import annotations

from importlib.metadata import entry_points

MESHERS: dict = {}


def register_mesher(name: str):
    def decorate(function):
        MESHERS[name] = function
        return function
    return decorate


def get_mesher(name: str):
    _load_plugins()
    return MESHERS[name]


def mesher_names() -> list[str]:
    _load_plugins()
    return sorted(MESHERS)


def _load_plugins() -> None:
    from . import delaunay  # noqa: F401  (registers the built-in meshers)
    for ep in entry_points(group="fuzzymesh.meshers"):
        MESHERS.setdefault(ep.name, ep.load())
