"""Packers place mesh nodes in the solid, sized by the sizing field.

A packer is a function ``pack(geometry, features, sizing, *, seed, knowledge) -> Packing``
(the ``Packer`` protocol of engine/plugins.py) registered under a name; a job picks it
with ``packer: NAME``. Third-party packers register through the ``fuzzymesh.packers``
entry-point group (docs/plugins.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..levels import CORNER, CURVE, LEVELS, PATCH, VOLUME  # noqa: F401  (the packers' levels)
from ..plugins import Packer
from ..registry import Registry

# one population-control event per row: the bubble deleted or inserted, its level, the packing
# iteration, the action, the id of the rule that fired most strongly and its firing degree
EVENT = np.dtype(
    [
        ("bubble", np.int64),
        ("level", "U6"),
        ("iteration", np.int32),
        ("action", "U6"),
        ("rule", object),
        ("firing", np.float64),
    ]
)


def no_events() -> np.recarray:
    return np.zeros(0, EVENT).view(np.recarray)


@dataclass(frozen=True, kw_only=True)
class Packing:
    """Nodes with where they live: level (corner/curve/patch/volume) and entity index. A value: a stage derives
    a changed one with ``dataclasses.replace``."""

    points: np.ndarray  # (n, 3)
    level: np.ndarray  # (n,) int8, index into LEVELS
    entity: np.ndarray  # (n,) index of the corner / curve / patch in Features, -1 in the volume
    radius: np.ndarray  # (n,) half the target size at the node
    stats: dict = field(default_factory=dict)
    ids: np.ndarray | None = None  # (n,) bubble ids, cited by population-control events
    events: np.recarray = field(default_factory=no_events)  # EVENT rows

    def __len__(self) -> int:
        return len(self.points)

    @staticmethod
    def concatenate(parts: list["Packing"], stats: dict | None = None, events: np.recarray | None = None) -> "Packing":
        """The parts one after the other, with ``stats``, and ``events`` (default: the parts' events in turn)."""
        ids = None
        if any(p.ids is not None for p in parts):  # parts without ids get -1
            ids = np.concatenate([p.ids if p.ids is not None else np.full(len(p), -1) for p in parts]).astype(np.int64)
        if events is None:
            events = np.concatenate([no_events()] + [p.events for p in parts]).view(np.recarray)
        return Packing(
            points=np.concatenate([p.points for p in parts]).reshape(-1, 3),
            level=np.concatenate([p.level for p in parts]).astype(np.int8),
            entity=np.concatenate([p.entity for p in parts]).astype(np.int64),
            radius=np.concatenate([p.radius for p in parts]),
            stats=stats or {},
            ids=ids,
            events=events,
        )


PACKERS = Registry(
    "fuzzymesh.packers", ["engine.packing.bubble", "engine.packing.lattice", "engine.packing.grid"], Packer
)
register_packer = PACKERS.register
get_packer = PACKERS.get
packer_names = PACKERS.names
