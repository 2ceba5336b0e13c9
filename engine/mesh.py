"""The tetrahedral mesh value object."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# the four faces of a tetrahedron, each oriented outward for a positive tet
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


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

    def boundary_faces(self) -> np.ndarray:
        """Faces used by exactly one tetrahedron, oriented outward."""
        faces = self.tets[:, TET_FACES].reshape(-1, 3)
        key = np.sort(faces, axis=1)
        _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        return faces[counts[inverse.ravel()] == 1]
