"""The contracts of the plug-ins: what the pipeline passes a packer and a mesher, and what it expects back.

A job names them (``packer:``, ``mesher:``); built-ins register by decorator, others by the entry-point
groups ``fuzzymesh.packers`` and ``fuzzymesh.meshers`` (engine/registry.py). docs/plugins.md has a worked
example; tests/test_meshers.py runs the contract tests on every registered one, plug-ins included.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from .features import Features
    from .geometry import Geometry
    from .knowledge import KnowledgeBase
    from .mesh import TetMesh
    from .packing import Packing
    from .sizing import SizingField


class Packer(Protocol):
    """Places the nodes: ``pack(geometry, features, sizing, *, seed, knowledge) -> Packing``.

    Gets the validated solid, its features (corners, curves, patches), the sizing field (``sizing(points)``
    is the target size h at each point), the job's seed and the knowledge base in force (rule bases, packer
    settings; a packer may ignore it). Returns the nodes with their ``level`` (index into
    ``engine.packing.LEVELS``), ``entity`` (the corner, curve or patch index, -1 in the volume) and
    ``radius`` (h / 2): every corner as a node, curve nodes on their curve, patch nodes on their patch,
    volume nodes inside; the same nodes for the same input and seed. ``ids`` and ``events`` (population
    history) are optional.
    """

    def __call__(
        self, geometry: Geometry, features: Features, sizing: SizingField, *, seed: int, knowledge: KnowledgeBase
    ) -> Packing: ...


class Mesher(Protocol):
    """Connects the nodes: ``mesh(packing, geometry, features, *, seed) -> TetMesh``.

    Returns positively oriented tetrahedra using every node, with the node tags taken from the packing
    (``steiner`` for nodes it adds), ``node_bubble`` the packing's ``ids`` where it has them, counts and
    stage times in ``stats``; the same mesh for the same packing and seed. A mesher that conforms to the
    surface fills ``boundary`` / ``boundary_patch``. Every mesh then passes the acceptance gate
    (engine/acceptance.py) before it is written, plug-in or not.
    """

    def __call__(self, packing: Packing, geometry: Geometry, features: Features, *, seed: int) -> TetMesh: ...
