"""Meshers connect packed nodes into tetrahedra.

A mesher is a function ``mesh(packing, geometry, features) -> TetMesh``
registered under a name; a job picks it with ``mesher: NAME``. Third-party
meshers register through the ``fuzzymesh.meshers`` entry-point group.
"""
from __future__ import annotations

from ..registry import Registry

MESHERS = Registry("fuzzymesh.meshers", ["engine.meshing.delaunay"])
register_mesher = MESHERS.register
get_mesher = MESHERS.get
mesher_names = MESHERS.names
