"""Density-following starting nodes, level by level, shared by the packers: corners as nodes, curves at equal
steps of the integral of 1/h along their arc length, patches from an adaptive subdivision of their triangles
thinned to the local spacing, the volume from an octree lattice (a cell of size s emits its jittered centre
where s matches h, else splits) thinned against the boundary nodes and itself."""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from ..sampling import thin
from . import CORNER, CURVE, PATCH, VOLUME, Packing

SPACING_SLACK = 2 ** (1 / 3)  # a lattice cell of size s serves h in [s / slack, s * slack]
SURFACE_EXCLUSION = 0.8  # fraction of h kept free between surface nodes
VOLUME_EXCLUSION = 0.7  # fraction of h kept free between volume and other nodes
JITTER = 0.1  # lattice jitter, fraction of the cell size
CANDIDATES_PER_H2 = 8.0  # surface candidates per h^2 of area before thinning
SHORT_CURVE = 0.1  # a curve shorter than this x h is no mesh edge: its end corners share one node


def corner_nodes(features, sizing) -> Packing:
    """One node per corner, at the corner, except that corners joined by surface curves shorter than SHORT_CURVE x h
    (h the smaller of their ends') share the node of the first of them (see :func:`short_curve_groups`)."""
    points = np.array([c.point for c in features.corners]).reshape(-1, 3)
    keep = np.flatnonzero(short_curve_groups(features, sizing) == np.arange(len(points)))
    return Packing(points=points[keep], level=np.full(len(keep), CORNER), entity=keep, radius=sizing(points[keep]) / 2)


def short_curve_groups(features, sizing) -> np.ndarray:
    """(corners,) per corner the first corner of its group: corners joined by open surface curves shorter than
    SHORT_CURVE x h (the smaller h of the curve's ends), in groups no wider than that, are one mesh node.

    A CAD model's sliver edge (0.004 mm where a gear tooth's flank, tip and 0.25 mm chamfer meet, at h 0.4) would
    otherwise be a mesh edge h / 100 long, and every tetrahedron on it flat; Gmsh's Mesh.ToleranceEdgeLength
    skips such edges the same way. The node stays on a corner, so the surface moves by less than the curve's
    length there."""
    count = len(features.corners)
    if count == 0:
        return np.zeros(0, np.int64)
    points = np.array([c.point for c in features.corners]).reshape(-1, 3)
    h = sizing(points)
    corner_of_vertex = {c.vertex: k for k, c in enumerate(features.corners)}
    pairs = []
    for curve in features.curves:
        if curve.closed or not curve.on_surface or curve.vertices is None:
            continue
        a = corner_of_vertex.get(int(curve.vertices[0]))
        b = corner_of_vertex.get(int(curve.vertices[-1]))
        if a is not None and b is not None and a != b and curve.length < SHORT_CURVE * min(h[a], h[b]):
            pairs.append((a, b))
    first = np.arange(count)
    if not pairs:
        return first
    pairs = np.array(pairs)
    graph = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(count, count))
    _, group = csgraph.connected_components(graph, directed=False)
    order = np.argsort(group, kind="stable")  # corners by group, lowest index first
    starts = np.flatnonzero(np.r_[True, np.diff(group[order]) != 0])
    lead = np.repeat(order[starts], np.diff(np.r_[starts, count]))  # the first corner of each corner's group
    first[order] = lead
    width = np.linalg.norm(points - points[first], axis=1)
    narrow = np.ones(count, bool)  # a chain of short curves adding up to more than SHORT_CURVE x h stays apart
    np.logical_and.at(narrow, first, width < SHORT_CURVE * h)
    return np.where(narrow[first], first, np.arange(count))


def curve_nodes(features, sizing, existing) -> Packing:
    """Nodes at equal increments of the integral of 1/h along each surface curve (ends excluded)."""
    points, entity = [], []
    for index, curve in enumerate(features.curves):
        if not curve.on_surface:
            continue
        length = curve.length
        count = int(min(1e6, max(8, np.ceil(8 * length / sizing.h_min))))
        s = np.linspace(0.0, length, count + 1)
        h = sizing(curve.point_at(s))
        steps = np.concatenate([[0.0], np.cumsum(np.diff(s) * 0.5 * (1 / h[1:] + 1 / h[:-1]))])
        segments = max(3 if curve.closed else 1, int(np.round(steps[-1])))
        targets = (
            np.linspace(0.0, steps[-1], segments + 1)[1:-1]
            if not curve.closed
            else np.linspace(0.0, steps[-1], segments + 1)[:-1]
        )
        points.append(curve.point_at(np.interp(targets, steps, s)))
        entity.append(np.full(len(targets), index))
    points = np.concatenate(points).reshape(-1, 3) if points else np.zeros((0, 3))
    entity = np.concatenate(entity) if entity else np.zeros(0, int)
    if len(existing) and len(points):  # a loop that starts at a corner repeats it
        gap, _ = cKDTree(existing).query(points)
        points, entity = points[gap > 1e-9 * sizing.h_min], entity[gap > 1e-9 * sizing.h_min]
    return Packing(points=points, level=np.full(len(points), CURVE), entity=entity, radius=sizing(points) / 2)


def _subdivide(triangles: np.ndarray, sizing, max_levels: int = 64):
    """Bisect triangles at the midpoint of their longest edge until that edge is below h at their centroid.

    Longest-edge bisection keeps the leaves' count proportional to area / h^2 whatever the triangles'
    shape (1-to-4 splits keep a long, thin facet's aspect ratio and make leaves far finer than h).
    """
    leaves, owners = [], []
    owner = np.arange(len(triangles))
    for _ in range(max_levels):
        if len(triangles) == 0:
            break
        lengths = np.linalg.norm(triangles - np.roll(triangles, -1, axis=1), axis=2)  # edge k: vertex k to k+1
        longest = lengths.argmax(axis=1)
        fine = lengths.max(axis=1) <= sizing(triangles.mean(axis=1))
        leaves.append(triangles[fine])
        owners.append(owner[fine])
        t, k, owner = triangles[~fine], longest[~fine], owner[~fine]
        rows = np.arange(len(t))[:, None]
        a, b, c = np.moveaxis(t[rows, (k[:, None] + np.arange(3)) % 3], 1, 0)  # a-b is the longest edge
        middle = 0.5 * (a + b)
        triangles = np.concatenate([np.stack([a, middle, c], 1), np.stack([middle, b, c], 1)])
        owner = np.tile(owner, 2)
    leaves.append(triangles)
    owners.append(owner)
    return np.concatenate(leaves), np.concatenate(owners)


def patch_nodes(geometry, features, sizing, boundary: Packing, rng) -> Packing:
    mesh = geometry.mesh
    leaves, owner = _subdivide(mesh.triangles, sizing)
    # about CANDIDATES_PER_H2 uniform random candidates per h^2 of area
    area = 0.5 * np.linalg.norm(np.cross(leaves[:, 1] - leaves[:, 0], leaves[:, 2] - leaves[:, 0]), axis=1)
    expected = CANDIDATES_PER_H2 * area / sizing(leaves.mean(axis=1)) ** 2
    count = np.floor(expected).astype(int) + (rng.random(len(leaves)) < expected % 1)
    tri = np.repeat(leaves, count, axis=0)
    owner = np.repeat(owner, count)
    u = rng.random((len(tri), 2))
    flip = u.sum(axis=1) > 1
    u[flip] = 1 - u[flip]
    candidates = tri[:, 0] + u[:, :1] * (tri[:, 1] - tri[:, 0]) + u[:, 1:] * (tri[:, 2] - tri[:, 0])
    patch = features.face_patch[owner]
    all_points = np.concatenate([boundary.points, candidates])
    h = sizing(all_points)
    keep = thin(all_points, SURFACE_EXCLUSION * h, rng, fixed=np.arange(len(all_points)) < len(boundary))
    keep = keep[len(boundary) :]
    points = candidates[keep]
    return Packing(
        points=points, level=np.full(len(points), PATCH), entity=patch[keep], radius=h[len(boundary) :][keep] / 2
    )


def _octree_lattice(geometry, sizing, rng, density: float | None = None) -> np.ndarray:
    """Jittered centres of octree cells matched to h. With ``density`` (nodes per h^3), cells no
    larger than density^(-1/3) h emit with probability (s / (density^(-1/3) h))^3, so the expected
    count follows density / h^3 even where the octree level jumps by 2."""
    lo, hi = geometry.bounds
    slack = SPACING_SLACK if density is None else 1.0
    reach = 1.0 if density is None else density ** (-1.0 / 3.0)
    size = sizing.h_max * slack * reach * (1 - 1e-9)  # the coarsest cells emit (no round-off split)
    counts = np.maximum(1, np.ceil((hi - lo) / size)).astype(int)
    axes = [lo[k] + (np.arange(counts[k]) + 0.5) * size for k in range(3)]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    emitted = []
    octants = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    while len(centres):
        h = sizing(centres)
        done = size <= h * slack * reach
        keep = done if density is None else done & (rng.random(len(centres)) < (size / (h * reach)) ** 3)
        emitted.append(centres[keep] + rng.uniform(-JITTER, JITTER, (int(keep.sum()), 3)) * size)
        size /= 2
        centres = (centres[~done][:, None, :] + 0.5 * size * octants[None]).reshape(-1, 3)
    return np.concatenate(emitted)


def volume_nodes(geometry, sizing, boundary: Packing, rng, density: float | None = None) -> Packing:
    candidates = _octree_lattice(geometry, sizing, rng, density)
    candidates = candidates[geometry.contains(candidates)]
    h = sizing(candidates)
    if len(boundary):
        gap, _ = cKDTree(boundary.points).query(candidates)
        candidates, h = candidates[gap >= VOLUME_EXCLUSION * h], h[gap >= VOLUME_EXCLUSION * h]
    keep = thin(candidates, VOLUME_EXCLUSION * h, rng)
    points = candidates[keep]
    return Packing(
        points=points, level=np.full(len(points), VOLUME), entity=np.full(len(points), -1), radius=h[keep] / 2
    )
