"""Target element size h(x) and the element-count guard.

A sizing field is any object with ``__call__(points (n, 3)) -> h (n,)`` and
the attributes ``h_min`` and ``h_max``. The knowledge-driven field composed by
membership dominance comes with the knowledge base; :class:`UniformSize` is
the base case.
"""
from __future__ import annotations

import math

import numpy as np

from .errors import LimitError

# tetrahedra per node of a well-spaced Delaunay mesh, and nodes per h^3 of volume
TETS_PER_NODE = 5.5
NODES_PER_H3 = 1.0


class UniformSize:
    """h(x) = h everywhere."""

    def __init__(self, h: float):
        self.h = float(h)
        self.h_min = self.h_max = self.h

    def __call__(self, points: np.ndarray) -> np.ndarray:
        return np.full(len(points), self.h)


def estimate_counts(geometry, sizing, samples: int = 50_000, seed: int = 0) -> tuple[float, float]:
    """Expected (nodes, tetrahedra): the volume integral of the node density 1/h^3."""
    rng = np.random.default_rng(seed)
    lo, hi = geometry.bounds
    points = rng.uniform(lo, hi, size=(samples, 3))
    inside = geometry.contains(points)
    if not inside.any():
        density = 1.0 / sizing.h_min ** 3
    else:
        density = float(np.mean(1.0 / sizing(points[inside]) ** 3))
    nodes = NODES_PER_H3 * geometry.volume * density
    return nodes, nodes * TETS_PER_NODE


def check_element_limit(geometry, sizing, max_elements: float) -> float:
    """Refuse (one line) when the sizes would need more than ``max_elements`` tetrahedra."""
    _, tets = estimate_counts(geometry, sizing)
    if not math.isfinite(tets) or tets > max_elements:
        raise LimitError(
            f"the sizes would need about {tets:.3g} tetrahedra (limit {max_elements:.3g}); "
            f"the smallest size is {sizing.h_min:.4g}",
            fix="use a larger size, or raise the limit with --max-elements")
    return tets
