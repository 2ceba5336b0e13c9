"""Meshers connect packed nodes into tetrahedra.

A mesher is a function ``mesh(packing, geometry, features, *, seed) -> TetMesh``
(the ``Mesher`` protocol of engine/plugins.py) registered under a name; a job picks
it with ``mesher: NAME``. Third-party meshers register through the
``fuzzymesh.meshers`` entry-point group (docs/plugins.md).

The contract (tests/test_meshers.py runs it on every registered mesher):
positively oriented tetrahedra, every node used, node tags from the packing
(``steiner`` for nodes the mesher adds), the same mesh for the same packing
and seed, counts and stage times in ``TetMesh.stats``. A mesher that
conforms to the surface also fills ``TetMesh.boundary`` / ``boundary_patch``.
"""

from __future__ import annotations

from ..plugins import Mesher
from ..registry import Registry

MESHERS = Registry(
    "fuzzymesh.meshers", ["engine.meshing.delaunay", "engine.meshing.qhull", "engine.meshing.hexcore"], Mesher
)
register_mesher = MESHERS.register
get_mesher = MESHERS.get
mesher_names = MESHERS.names
