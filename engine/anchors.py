"""Distances from points to what a pattern is placed on: features, points, regions, the domain.

Curves (segments) and patches (triangles) are measured exactly with libigl's
AABB tree; a k-d tree over sample points would degenerate near the axis of a
circle or cylinder, where thousands of samples are equally far. Points beyond
a pattern's reach (outside the anchor's box grown by the bound) are skipped.
Gaps between features are measured on samples of their edges, made only when
a gap is asked for.
"""

from __future__ import annotations

from functools import cached_property

import igl
import numpy as np
from scipy.spatial import cKDTree

WORKERS = -1  # k-d tree queries use every core


class SampledDistance:
    """Distance to a dense point sample of a curve, patch or point."""

    def __init__(self, samples: np.ndarray):
        self.samples = np.asarray(samples, dtype=float).reshape(-1, 3)
        self.tree = cKDTree(self.samples)
        self.lo, self.hi = self.samples.min(axis=0), self.samples.max(axis=0)

    def __call__(self, points: np.ndarray, bound: float = np.inf) -> np.ndarray:
        """Distances; ``inf`` where farther than ``bound``."""
        distance = np.full(len(points), np.inf)
        near = (
            np.all((points >= self.lo - bound) & (points <= self.hi + bound), axis=1)
            if np.isfinite(bound)
            else np.ones(len(points), bool)
        )
        if near.any():
            distance[near], _ = self.tree.query(points[near], distance_upper_bound=bound, workers=WORKERS)
        return distance


class FeatureDistance:
    """Exact distance to segments (a curve) or triangles (a patch)."""

    def __init__(self, vertices: np.ndarray, simplices: np.ndarray, spacing: float):
        used = np.unique(simplices)
        remap = np.zeros(len(vertices), dtype=np.int64)
        remap[used] = np.arange(len(used))
        self.vertices = np.ascontiguousarray(vertices[used], dtype=np.float64)
        self.simplices = np.ascontiguousarray(remap[simplices], dtype=np.int64)
        self.spacing = spacing
        self.lo, self.hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        self.tree = igl.AABB()
        self.tree.init(self.vertices, self.simplices)

    def __call__(self, points: np.ndarray, bound: float = np.inf) -> np.ndarray:
        """Distances; ``inf`` where farther than ``bound``."""
        distance = np.full(len(points), np.inf)
        near = np.all((points >= self.lo - bound) & (points <= self.hi + bound), axis=1)
        if near.any():
            squared, _, _ = self.tree.squared_distance(
                self.vertices, self.simplices, np.ascontiguousarray(points[near], dtype=np.float64)
            )
            distance[near] = np.sqrt(squared)
        distance[distance > bound] = np.inf
        return distance

    @cached_property
    def samples(self) -> np.ndarray:
        """Points on every edge of the simplices, at most ``spacing`` apart (made when first asked)."""
        return edge_samples(self.vertices, self.simplices, self.spacing)

    def gap_to(self, other) -> float:
        """Distance to ``other`` (a distance with samples), exceeding the true one by at most spacing / 2.

        Two triangles (or a segment and a triangle) are closest at a point on
        an edge of one of them, so both sides' edge samples are measured
        exactly against the other side.
        """
        return float(min(other(self.samples).min(), self(other.samples).min()))


def curve_distance(curve, spacing: float) -> FeatureDistance:
    line = curve.polyline
    segments = np.column_stack([np.arange(len(line) - 1), np.arange(1, len(line))])
    return FeatureDistance(line, segments, spacing)


def patch_distance(geometry, patch, spacing: float) -> FeatureDistance:
    return FeatureDistance(geometry.mesh.vertices, geometry.mesh.faces[patch.faces], spacing)


MAX_EDGE_SAMPLES = 2_000_000


def edge_samples(vertices: np.ndarray, simplices: np.ndarray, spacing: float) -> np.ndarray:
    """Points on every edge of the segments or triangles, at most ``spacing`` apart (at most ~2M)."""
    corners = simplices.shape[1]
    pairs = [simplices] if corners == 2 else [simplices[:, [i, (i + 1) % corners]] for i in range(corners)]
    edges = np.unique(np.sort(np.concatenate(pairs), axis=1), axis=0)
    start, vector = vertices[edges[:, 0]], vertices[edges[:, 1]] - vertices[edges[:, 0]]
    length = np.linalg.norm(vector, axis=1)
    spacing = max(spacing, float(length.sum()) / MAX_EDGE_SAMPLES)
    steps = np.maximum(1, np.ceil(length / spacing)).astype(np.int64)
    edge = np.repeat(np.arange(len(edges)), steps + 1)
    first = np.repeat(np.cumsum(steps + 1) - (steps + 1), steps + 1)
    t = (np.arange(len(edge)) - first) / steps[edge]
    return start[edge] + t[:, None] * vector[edge]


class DomainDistance:
    """Distance 0 everywhere: for patterns over the whole solid."""

    def __call__(self, points: np.ndarray, bound: float = np.inf) -> np.ndarray:
        return np.zeros(len(points))
