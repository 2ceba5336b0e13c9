"""Width of the solid's faces: how far apart two feature curves bounding one patch run, where they do not meet.

A face narrower than the elements around it (a gear tooth's 0.25 mm chamfer at h 0.4, a 1 mm chamfer at h 4)
gets its curve nodes on both edges h apart along them, and the tetrahedra across it are flat; the thin-wall and
narrow-gap rules measure the solid between opposite faces, and see none of it. The width is measured between
samples of the curves, ``SAMPLES_PER_SIZE`` per element size H along each (``MAX_SAMPLES`` at most). A pair of
samples counts where

- the two curves share no corner (curves that meet, at an acute corner or a cusp, are packed each on its own
  by the bubble packer, and more elements there would only make the corner's triangles smaller, not better),
  or it is one curve and the samples lie at least ``ALONG`` x their distance apart along it (a slot's floor
  bounded by one loop);
- neither sample lies within their distance of a corner (the ends of a narrow face, and curves joined through
  a curve too short to mesh, engine/packing/start.py ``short_curve_groups``, are the corner's business);
- the segment between them runs on a patch both curves bound: its midpoint within ``ON_PATCH`` x its length of
  that patch's facets (not across the solid, not over another face).

A pair's distance is the width at the facet under the segment's midpoint; a facet keeps its smallest. The facets
are grouped in classes of width as the wall thicknesses are (:func:`engine.thickness.classes`): each class is
one anchor of the ``narrow-face`` pattern (patterns/narrow-face.yaml), with its L.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .features import curve_sides, curves_meeting
from .thickness import LocalPart, classes

SAMPLES_PER_SIZE = 10  # curve samples per H along each curve
REACH = 1.0  # widths up to this x H are measured (the pattern asks for stretch x L, below H only where L < H / stretch)
ALONG = 3.0  # two samples of one curve are across a face when this x their distance apart along it
ON_PATCH = 0.1  # the segment's midpoint lies within this x its length of the common patch
MAX_SAMPLES = 200_000  # curve samples at most (a size far below the model's, which the element-count guard
# refuses after the patterns are bound, would ask for millions)


def narrow_faces(geometry, features, size: float) -> list[LocalPart]:
    """The facets of faces narrower than ``REACH`` x ``size`` (H), in classes of width, narrowest first."""
    width = facet_widths(geometry, features, size)
    triangles = geometry.mesh.vertices[geometry.mesh.faces]
    return classes(triangles, width, "face")


def facet_widths(geometry, features, size: float) -> np.ndarray:
    """(f,) the width of the face at each input facet (module doc), inf where not narrower than REACH x size."""
    width = np.full(len(geometry.mesh.faces), np.inf)
    sides = curve_sides(geometry, features)
    total = sum(features.curves[c].length for c in sides)
    points, curve, along = _samples(features, sides, max(size / SAMPLES_PER_SIZE, total / MAX_SAMPLES))
    bounding = np.array([sides[c] for c in curve]).reshape(-1, 2)
    a, b, patch = [], [], []
    for p in np.unique(bounding[bounding >= 0]):  # pairs of samples around each patch
        mine = np.flatnonzero((bounding == p).any(axis=1))
        pairs = cKDTree(points[mine]).query_pairs(REACH * size, output_type="ndarray")
        a.append(mine[pairs[:, 0]])
        b.append(mine[pairs[:, 1]])
        patch.append(np.full(len(pairs), p))
    if not a:
        return width
    a, b, patch = np.concatenate(a), np.concatenate(b), np.concatenate(patch)
    distance = np.linalg.norm(points[a] - points[b], axis=1)
    keep = _apart(features, curve[a], curve[b], along[a], along[b], distance)
    if features.corners:  # a pair within its distance of a corner is that corner's (module doc)
        near_corner = cKDTree(np.array([c.point for c in features.corners])).query(points)[0]
        keep &= (near_corner[a] > distance) & (near_corner[b] > distance)
    a, b, distance, patch = a[keep], b[keep], distance[keep], patch[keep]
    _, off, facet = geometry.closest_point((points[a] + points[b]) / 2)
    on = (features.face_patch[facet] == patch) & (off <= ON_PATCH * distance)
    np.minimum.at(width, facet[on], distance[on])
    return width


def _samples(features, sides: dict, spacing: float):
    """Points along every surface curve that bounds a patch, at most ``spacing`` apart: (points (k, 3), curve
    (k,), arc length (k,))."""
    points, curve, along = [], [], []
    for index, feature in enumerate(features.curves):
        if index not in sides:
            continue
        s = np.linspace(0.0, feature.length, max(2, int(np.ceil(feature.length / spacing)) + 1))
        if feature.closed:  # its end is its start
            s = s[:-1]
        points.append(feature.point_at(s))
        curve.append(np.full(len(s), index))
        along.append(s)
    if not points:
        return np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0)
    return np.concatenate(points), np.concatenate(curve), np.concatenate(along)


def _apart(features, curve_a, curve_b, along_a, along_b, distance) -> np.ndarray:
    """Whether each pair of samples is across a face: two curves that share no corner, or one curve with the
    samples ALONG x their distance apart along it (around a loop the shorter way)."""
    curve, _, other, _ = curves_meeting(features)
    count = len(features.curves)
    touching = np.concatenate([curve * count + other, other * count + curve])
    own = curve_a == curve_b
    meet = np.isin(curve_a * count + curve_b, touching) & ~own
    length = np.array([c.length for c in features.curves])[curve_a]
    closed = np.array([c.closed for c in features.curves], dtype=bool)[curve_a]
    gap = np.abs(along_a - along_b)
    gap = np.where(closed, np.minimum(gap, length - gap), gap)
    return ~meet & (~own | (gap >= ALONG * distance)) & (distance > 0)
