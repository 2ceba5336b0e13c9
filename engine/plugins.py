"""The contracts of the named kinds: what the pipeline passes each and what it expects back.

One :class:`~engine.registry.Registry` per kind, each checking its entries against one of these protocols:
packers and meshers (plug-in kinds: a job names them, ``packer:``, ``mesher:``; built-ins register by
decorator, others by the entry-point groups ``fuzzymesh.packers`` and ``fuzzymesh.meshers``), the built-in
shapes (``engine.shapes.SHAPES``), the validation cases (``engine.validation.CASES``) and the output
writers (``engine.io.WRITERS``). docs/plugins.md has a worked example; tests/test_meshers.py runs the
contract tests on every registered packer and mesher, plug-ins included.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from pathlib import Path

    from .features import Features
    from .geometry import Geometry
    from .io import FEModel
    from .knowledge import KnowledgeBase
    from .mesh import TetMesh
    from .packing import Packing
    from .shapes import Shape
    from .sizing import SizingField
    from .validation import CaseResult


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


class ShapeBuilder(Protocol):
    """Builds a built-in solid: ``build(**parameters) -> Shape``, the parameters those of the schema it is
    registered with (``@SHAPES.register(name, parameters={...})``, each a validated ``engine.schema.Field``)."""

    def __call__(self, **parameters) -> Shape: ...


class ValidationCase(Protocol):
    """Meshes, solves and compares one validation case: ``run(*, scale, seed) -> CaseResult`` (``scale``
    multiplies every target size)."""

    def __call__(self, *, scale: float, seed: int) -> CaseResult: ...


class Writer(Protocol):
    """Writes one output format: ``write(path, model)``, the FE model (``engine.io.FEModel``) to ``path`` (a
    temporary file that the all-or-nothing output renames, engine/atomic.py)."""

    def __call__(self, path: Path, model: FEModel) -> None: ...
