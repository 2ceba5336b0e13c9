"""Packers place mesh nodes in the solid, sized by the sizing field.

A packer is a function ``pack(geometry, features, sizing, *, seed) -> Packing``
registered under a name; a job picks it with ``packer: NAME``. Third-party
packers register through the ``fuzzymesh.packers`` entry-point group.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import numpy as np

from ..registry import Registry

LEVELS = ("corner", "curve", "patch", "volume")
CORNER, CURVE, PATCH, VOLUME = range(4)


@dataclass
class Packing:
    """Nodes with where they live: level (corner/curve/patch/volume) and entity index."""

    points: np.ndarray          # (n, 3)
    level: np.ndarray           # (n,) int8, index into LEVELS
    entity: np.ndarray          # (n,) index of the corner / curve / patch in Features, -1 in the volume
    radius: np.ndarray          # (n,) half the target size at the node
    stats: dict = field(default_factory=dict)
    ids: np.ndarray | None = None   # (n,) bubble ids, cited by population-control events
    events: list = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.points)

    @staticmethod
    def concatenate(parts: list["Packing"], stats: dict | None = None) -> "Packing":
        ids = None
        if any(p.ids is not None for p in parts):   # parts without ids get -1
            ids = np.concatenate([p.ids if p.ids is not None else np.full(len(p), -1) for p in parts]).astype(np.int64)
        return Packing(np.concatenate([p.points for p in parts]).reshape(-1, 3),
                       np.concatenate([p.level for p in parts]).astype(np.int8),
                       np.concatenate([p.entity for p in parts]).astype(np.int64),
                       np.concatenate([p.radius for p in parts]), stats or {}, ids,
                       [e for p in parts for e in p.events])


PACKERS = Registry("fuzzymesh.packers", ["engine.packing.bubble", "engine.packing.lattice"])
register_packer = PACKERS.register
get_packer = PACKERS.get
packer_names = PACKERS.names
