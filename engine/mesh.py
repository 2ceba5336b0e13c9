"""The tetrahedral mesh value object."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

@dataclass
class TetMesh:
    """Linear tetrahedra with node tags (level and entity, as in the Packing)."""

    points: np.ndarray         # (n, 3)
    tets: np.ndarray           # (m, 4) int64, positively oriented
    node_level: np.ndarray     # (n,) int8
    node_entity: np.ndarray    # (n,) int64
    stats: dict = field(default_factory=dict)

    def volumes(self) -> np.ndarray:
        p = self.points[self.tets]
        return np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6.0

    @property
    def volume(self) -> float:
        return float(self.volumes().sum())
