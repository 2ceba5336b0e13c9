"""Local feature size of a solid: wall thickness and gap width over its surface, by ray casting.

From a surface point, a ray along the inward normal measures the wall thickness (the distance to the
first face it hits) and a ray along the outward normal the gap width (the distance at which it enters
the solid again; a ray that leaves for good measures none). A hit counts only where the face hit is
within ``OPPOSITE_WITHIN`` degrees of facing the start (antiparallel normals): the other side of a wall
or of a gap, not the neighbouring face of a sharp corner (a wedge or groove opening wider than that has
no thickness here). Ray origins sit ``RAY_OFFSET`` x the model size off the surface, on the ray's side.

The surface is cut into pieces adaptively: a piece is measured at the centroids of its four midpoint
sub-triangles; where those disagree (ratio above ``CLASS_RATIO``, or a hit and a miss) and the piece is
longer than its smallest measure, it is split into those four and each is measured again. A wall of
constant thickness keeps its pieces (facets first split down to ``START_AREA`` x the model size squared, so
every patch of that area is measured); the surface is cut finer only where the measure changes.
A piece keeps the smallest of its four measures. Measured once per geometry (:func:`local_size`).

Pieces are grouped in classes of thickness (gap) [L, q L), q = ``CLASS_RATIO``, L the smallest measure not in
a class yet: each class is one anchor of a ``thin-wall`` (``narrow-gap``) pattern, with its L, so a placed
pattern has one L and its sizes and bounds stay exact (see :mod:`engine.sizing`). :func:`classes` does this
for any measure over surface pieces (the radius of curvature too, :mod:`engine.curvature`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import igl
import numpy as np

from .anchors import FeatureDistance

OPPOSITE_WITHIN = 15.0  # degrees between the face hit and the reversed start normal
RAY_OFFSET = 1e-7  # ray origins off the surface, times the model size
CLASS_RATIO = 2**0.25  # measures within this ratio are one class (and do not split a piece)
MIN_PIECE = 1e-3  # pieces are not split below this length, times the model size
START_AREA = 1 / 16**2  # facets are first split down to this area, times the model size squared
MAX_LEVELS = 16  # splits of one facet at most
MEASURES = {"thin-wall": "thickness", "narrow-gap": "gap"}  # anchor kind -> what it measures


@dataclass
class LocalPart:
    """The surface pieces of one class of a measure: one anchor of a thin-wall, narrow-gap or curvature
    pattern."""

    id: str  # e.g. "wall-0.297": L in [0.297, 0.297 q), its pieces measuring [L, q L)
    length: float  # L: the smallest measure of its pieces
    triangles: np.ndarray  # (m, 3, 3)

    def distance(self, spacing: float) -> FeatureDistance:
        """Exact distance to the pieces (gaps to them measured on edge samples ``spacing`` apart)."""
        count = len(self.triangles)
        return FeatureDistance(self.triangles.reshape(-1, 3), np.arange(3 * count).reshape(count, 3), spacing)


@dataclass
class LocalSize:
    """Thickness and gap width of the surface, per piece (inf where not measured)."""

    triangles: np.ndarray  # (m, 3, 3) the pieces, covering the surface
    thickness: np.ndarray  # (m,)
    gap: np.ndarray  # (m,)
    rays: int
    seconds: float

    def parts(self, anchor: str) -> list[LocalPart]:
        """The pieces of the anchor kind's measure, in classes, thinnest first."""
        return classes(self.triangles, getattr(self, MEASURES[anchor]), "wall" if anchor == "thin-wall" else "gap")


def classes(triangles: np.ndarray, measure: np.ndarray, prefix: str) -> list[LocalPart]:
    """Pieces (m, 3, 3) with a measure each (inf: none) in classes, smallest first: a class starts at the smallest
    measure L not in one yet and takes every piece measuring below q L, q = ``CLASS_RATIO`` (so measures scattered
    about a power of q make one class, not two). One part per class: L, its pieces, id ``PREFIX-q^k`` (q^k <= L)."""
    return [
        LocalPart(f"{prefix}-{CLASS_RATIO**level:.3g}", length, triangles[rows])
        for length, level, rows in class_rows(measure)
    ]


def class_rows(measure: np.ndarray) -> list[tuple[float, float, np.ndarray]]:
    """The classes of :func:`classes` as (L, k with q^k <= L, sorted rows of their pieces), smallest first."""
    order = np.flatnonzero(np.isfinite(measure))
    order = order[np.argsort(measure[order], kind="stable")]
    values = measure[order]
    out, start = [], 0
    while start < len(order):
        end = int(np.searchsorted(values, values[start] * CLASS_RATIO))
        out.append(
            (float(values[start]), np.floor(np.log(values[start]) / np.log(CLASS_RATIO)), np.sort(order[start:end]))
        )
        start = end
    return out


def local_size(geometry) -> LocalSize:
    """The geometry's local feature size, measured on the first call and kept with the geometry."""
    cached = geometry.__dict__.get("_local_size")
    if cached is None:
        cached = geometry.__dict__["_local_size"] = measure(geometry.vertices, geometry.faces)
    return cached


def measure(vertices: np.ndarray, faces: np.ndarray) -> LocalSize:
    """Thickness and gap over the closed, outward-oriented surface (V, F), on adaptive pieces."""
    start = time.perf_counter()
    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.ascontiguousarray(faces, dtype=np.int64)
    tree = igl.AABB()
    tree.init(V, F)
    normals = _normals(V[F])
    scale = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    caster = _Caster(tree, V, F, normals, RAY_OFFSET * scale)
    pieces, owner = _split_to_area(V[F], START_AREA * scale**2)
    done_tri, done_thick, done_gap = [], [], []
    rays = 0
    for level in range(MAX_LEVELS + 1):
        children = _split(pieces)  # (m, 4, 3, 3)
        points = children.mean(axis=2).reshape(-1, 3)
        n = np.repeat(normals[owner], 4, axis=0)
        thick = caster.cast(points, n, -1.0).reshape(-1, 4)
        gap = caster.cast(points, n, 1.0).reshape(-1, 4)
        rays += 2 * len(points)
        longest = np.linalg.norm(pieces - np.roll(pieces, 1, axis=1), axis=2).max(axis=1)
        smallest = np.minimum(thick.min(axis=1), gap.min(axis=1))
        split = (_varies(thick) | _varies(gap)) & (longest > np.maximum(smallest, MIN_PIECE * scale))
        if level == MAX_LEVELS:
            split[:] = False
        done_tri.append(pieces[~split])
        done_thick.append(thick[~split].min(axis=1))
        done_gap.append(gap[~split].min(axis=1))
        if not split.any():
            break
        pieces = children[split].reshape(-1, 3, 3)
        owner = np.repeat(owner[split], 4)
    return LocalSize(
        np.concatenate(done_tri),
        np.concatenate(done_thick),
        np.concatenate(done_gap),
        rays,
        time.perf_counter() - start,
    )


class _Caster:
    """First hits of rays against the surface, kept only where the face hit faces the start."""

    def __init__(self, tree, V, F, normals, offset):
        self.tree, self.V, self.F, self.normals, self.offset = tree, V, F, normals, offset
        self.facing = -np.cos(np.radians(OPPOSITE_WITHIN))

    def cast(self, points: np.ndarray, normals: np.ndarray, sign: float) -> np.ndarray:
        """Distance from each point along sign x its unit normal to the first face facing it; inf if none."""
        directions = sign * normals
        origins = np.ascontiguousarray(points + self.offset * directions)
        hit, t, _ = self.tree.intersect_ray_first(self.V, self.F, origins, np.ascontiguousarray(directions))
        distance = np.full(len(points), np.inf)
        ok = np.flatnonzero(hit >= 0)
        ok = ok[np.einsum("ij,ij->i", self.normals[hit[ok]], normals[ok]) <= self.facing]
        distance[ok] = t[ok] + self.offset
        return distance


def _normals(triangles: np.ndarray) -> np.ndarray:
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    return cross / np.linalg.norm(cross, axis=1, keepdims=True)


def _split_to_area(triangles: np.ndarray, area: float):
    """Triangles split (midpoint, 1 to 4) until none is larger than ``area``, and where each comes from."""
    owner = np.arange(len(triangles))
    done, done_owner = [], []
    while len(triangles):
        large = (
            np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1)
            > 2 * area
        )
        done.append(triangles[~large])
        done_owner.append(owner[~large])
        triangles, owner = _split(triangles[large]).reshape(-1, 3, 3), np.repeat(owner[large], 4)
    return np.concatenate(done), np.concatenate(done_owner)


def _split(triangles: np.ndarray) -> np.ndarray:
    """The four midpoint sub-triangles of each triangle: (m, 4, 3, 3)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
    return np.stack([np.stack(t, axis=1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))], axis=1)


def _varies(values: np.ndarray) -> np.ndarray:
    """Rows whose values differ by more than the class ratio, or mix finite and infinite."""
    finite = np.isfinite(values)
    low = np.where(finite, values, np.inf).min(axis=1)
    high = np.where(finite, values, 0.0).max(axis=1)
    return (finite.any(axis=1) & ~finite.all(axis=1)) | (high > CLASS_RATIO * low)
