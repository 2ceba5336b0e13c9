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
ROW_SPACING = np.sqrt(3) / 2  # rows of a hexagonal lattice are this x its spacing apart
RING_SAMPLES = 256  # samples round a ring and along a wall where h is integrated
RING_PROBES = 64  # samples round a ring where its smallest h is taken and where it is tested against the patch
WASHER_REACH = 4.0  # x the radius: how far out the rings round a cylinder's end go at most (a hole pattern's
# extent is 3 radii)
CIRCLE_GAP = 0.02  # x the radius: a node this near a cylinder's end circle is on it (24 facets: chords 0.009 r in)
PLANE_SQUARE = 0.999  # |normal . axis| above this: a plane at right angles to a cylinder's axis


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
        steps = _integral_of_inverse(s, sizing(curve.point_at(s)))
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
    """Starting nodes of every patch, kept SURFACE_EXCLUSION x h from the boundary nodes and each other: a full
    turn of a cylinder (a hole's or a boss's wall) and the plane round each of its ends on rings
    (:func:`ring_nodes`), and what the rings leave open from density-following random samples of the triangles
    (:func:`random_patch_nodes`)."""
    placed, owners = [boundary.points], [np.zeros(0, np.int64)]
    for index, patch in enumerate(features.patches):
        if patch.cylinder is not None and patch.cylinder.full_turn:
            for points, owner in ring_nodes(geometry, features, index, sizing, np.concatenate(placed), rng):
                placed.append(points)
                owners.append(np.full(len(points), owner))
    points, entity = np.concatenate(placed[1:] or [np.zeros((0, 3))]), np.concatenate(owners)
    everywhere = np.ones(len(features.face_patch), bool)  # between the rings no sample is SURFACE_EXCLUSION h clear
    random, owner = random_patch_nodes(geometry, features, sizing, np.concatenate(placed), rng, everywhere)
    points, entity = np.concatenate([points, random]), np.concatenate([entity, owner])
    return Packing(points=points, level=np.full(len(points), PATCH), entity=entity, radius=sizing(points) / 2)


def ring_nodes(geometry, features, index: int, sizing, fixed: np.ndarray, rng) -> list:
    """Starting nodes, as rows of a hexagonal lattice, of patch ``index`` (a full turn of a cylinder) and of each
    plane round one of its ends: [(points (k, 3), patch)], the wall first, each kept SURFACE_EXCLUSION x h from
    the ``fixed`` nodes (the curves' nodes, other rings) and from each other.

    The wall: rings at right angles to the axis, ROW_SPACING x h apart along it; a plane at right angles to the
    axis at an end: concentric rings round the end circle, as far out (or in, for a boss's top) as a whole ring
    stays on the plane, ROW_SPACING x h from every node already placed but the circle's. Ring spacing follows
    the integral of 1/h (h the smallest round the ring); round a ring the nodes are at equal steps of it,
    shifted half a step from the ring before, counting from the end circle, whose nodes the first ring is
    shifted half a step from.

    A random start relaxed for a few dozen steps leaves a hole's wall and the plate round it irregular (rows 6,
    7.5, 10.5 and 6 mm apart on a 30 mm wall at h 7.5, long thin triangles at the root), and the averaged
    stress at the root scatters with it: Gmsh's rows of near-equilateral triangles there, moved off their rows
    by 0.13 h, moved its Kt from -1.0 % to anywhere between +0.2 and -3.9 % (plate with a hole,
    bench/fe_study.py). Ring nodes off their patch (where another hole cuts the wall) are left out; the rest
    lie on the patch's facets."""
    cylinder = features.patches[index].cylinder
    frame = _CylinderFrame(cylinder)
    along = (features.patches[index].vertices - cylinder.point) @ frame.axis
    ends = (along.min(), along.max())
    fixed = fixed[frame.near(fixed, ends, (1 + WASHER_REACH) * cylinder.radius + sizing.h_max)]
    turn = np.linspace(0.0, 2 * np.pi, RING_PROBES + 1)
    heights = np.linspace(*ends, RING_SAMPLES + 1)
    rows = _row_levels(heights, frame, heights, np.full_like(heights, cylinder.radius), sizing, turn)[1:-1]
    from_start = np.arange(1, len(rows) + 1)
    nearer_start = from_start <= from_start[::-1]
    wall = frame.rings(
        rows,
        np.full(len(rows), cylinder.radius),
        sizing,
        np.where(nearer_start, ends[0], ends[1]),
        np.minimum(from_start, from_start[::-1]) % 2 * 0.5,
        fixed,
    )
    out = [(_on_patch(geometry, features, wall, index, sizing, fixed, rng), index)]
    fixed = np.concatenate([fixed, out[0][0]])
    for end in ends:
        plane, side = _plane_at_end(geometry, features, frame, end, sizing)
        if plane is None:
            continue
        reach = cylinder.radius if side < 0 else WASHER_REACH * cylinder.radius
        radii = cylinder.radius + side * np.linspace(0.0, reach, RING_SAMPLES + 1)
        radii = radii[radii > 0]
        levels = _row_levels(radii, frame, np.full_like(radii, end), radii, sizing, turn)[1:]
        rings = frame.valid_rings(geometry, features, plane, end, levels, sizing, fixed, turn)
        if not len(rings):
            continue
        points = frame.rings(
            np.full(len(rings), end),
            rings,
            sizing,
            np.full(len(rings), end),
            np.arange(1, len(rings) + 1) % 2 * 0.5,
            fixed,
        )
        out.append((_on_patch(geometry, features, points, plane, sizing, fixed, rng), plane))
        fixed = np.concatenate([fixed, out[-1][0]])
    return out


class _CylinderFrame:
    """A cylinder's axis and two directions at right angles to it: points on rings round the axis."""

    def __init__(self, cylinder):
        self.cylinder = cylinder
        self.axis = cylinder.axis / np.linalg.norm(cylinder.axis)
        e1 = np.cross(self.axis, np.eye(3)[np.argmin(np.abs(self.axis))])
        self.e1 = e1 / np.linalg.norm(e1)
        self.e2 = np.cross(self.axis, self.e1)

    def at(self, heights, radii, angles) -> np.ndarray:
        """(r, a, 3) points at ``angles`` (a,) round the rings of ``heights`` and ``radii`` (r,)."""
        round_ = np.cos(angles)[:, None] * self.e1 + np.sin(angles)[:, None] * self.e2
        return self.cylinder.point + heights[:, None, None] * self.axis + radii[:, None, None] * round_[None]

    def near(self, points, ends, reach: float) -> np.ndarray:
        """(k,) whether each point lies within ``reach`` of the axis and of the span between heights ``ends``: the
        nodes a ring there may come near (the rest are left out of its clearance tests)."""
        relative = points - self.cylinder.point
        along = relative @ self.axis
        radius = np.linalg.norm(relative - along[:, None] * self.axis, axis=1)
        return (along > ends[0] - reach) & (along < ends[1] + reach) & (radius < reach)

    def on_circle(self, points, height: float) -> np.ndarray:
        """(k,) whether each point lies on the cylinder's circle at ``height``: in its plane, within CIRCLE_GAP x the
        radius of it (a faceted circle's nodes lie on its chords)."""
        relative = points - self.cylinder.point
        along = relative @ self.axis
        radius = np.linalg.norm(relative - along[:, None] * self.axis, axis=1)
        gap = CIRCLE_GAP * self.cylinder.radius
        return (np.abs(along - height) < gap) & (np.abs(radius - self.cylinder.radius) < gap)

    def rings(self, heights, radii, sizing, reference, shifts, fixed) -> np.ndarray:
        """(k, 3) nodes round each ring (r,) at equal steps of the integral of 1/h round it, ``shifts`` (r,) of a
        step on from the nodes among ``fixed`` on the cylinder's circle at height ``reference`` (r,)."""
        if not len(heights):
            return np.zeros((0, 3))
        turn = np.linspace(0.0, 2 * np.pi, RING_SAMPLES + 1)
        h = sizing(self.at(heights, radii, turn).reshape(-1, 3)).reshape(len(heights), -1)
        steps = np.array([_integral_of_inverse(turn * r, row) for r, row in zip(radii, h)]).reshape(len(h), -1)
        warps = 2 * np.pi * steps / steps[:, -1:]  # the angle mapped to 2 pi x the share of the integral so far
        counts = np.maximum(3, np.round(steps[:, -1]).astype(int))
        relative = fixed - self.cylinder.point
        angle = np.mod(np.arctan2(relative @ self.e2, relative @ self.e1), 2 * np.pi)
        circle = {height: angle[self.on_circle(fixed, height)] for height in np.unique(reference)}
        points = []
        for ring, (count, warp) in enumerate(zip(counts, warps)):
            phase = np.angle(np.exp(1j * count * np.interp(circle[reference[ring]], turn, warp)).sum()) / count
            wanted = np.mod(phase + (np.arange(count) + shifts[ring]) * 2 * np.pi / count, 2 * np.pi)
            points.append(self.at(heights[ring : ring + 1], radii[ring : ring + 1], np.interp(wanted, warp, turn))[0])
        return np.concatenate(points)

    def valid_rings(self, geometry, features, plane, height, radii, sizing, fixed, turn) -> np.ndarray:
        """The rings ``radii`` at ``height`` up to the first that leaves the patch ``plane`` or comes within
        ROW_SPACING x h of a ``fixed`` node off the cylinder's circle there."""
        if not len(radii):
            return radii
        samples = self.at(np.full(len(radii), height), radii, turn[:-1]).reshape(-1, 3)
        _, distance, face = geometry.closest_point(samples)
        h = sizing(samples)
        ok = (features.face_patch[face] == plane) & (distance < 1e-3 * h)
        off = ~self.on_circle(fixed, height)
        if off.any():
            ok &= cKDTree(fixed[off]).query(samples)[0] > ROW_SPACING * h
        whole = ok.reshape(len(radii), -1).all(axis=1)
        return radii[: int(np.argmin(whole)) if not whole.all() else len(radii)]


def _row_levels(s, frame, heights, radii, sizing, turn) -> np.ndarray:
    """Levels along ``s`` (n,) (heights up a wall or radii across a plane; the rings at ``heights``, ``radii``)
    ROW_SPACING x the smallest h round the ring apart, the first at s[0] and the last at s[-1]."""
    h = sizing(frame.at(heights, radii, turn[:-1]).reshape(-1, 3)).reshape(len(s), -1).min(axis=1)
    steps = _integral_of_inverse(np.abs(s - s[0]), ROW_SPACING * h)
    count = max(1, int(np.round(steps[-1])))
    return np.interp(np.linspace(0.0, steps[-1], count + 1), steps, s)


def _plane_at_end(geometry, features, frame, height, sizing):
    """(patch, side) of the plane at right angles to the axis at ``height`` next to the cylinder's circle there:
    side +1 outside the circle (a plate round a hole or a boss's root), -1 inside (a boss's top), or (None, 0)."""
    cylinder = frame.cylinder
    for side in (1, -1):
        h = sizing(frame.at(np.array([height]), np.array([cylinder.radius]), np.zeros(1))[0])[0]
        radius = cylinder.radius + side * 0.5 * h
        if radius <= 0:
            continue
        probe = frame.at(np.array([height]), np.array([radius]), np.linspace(0, 2 * np.pi, 8, endpoint=False))[0]
        _, distance, face = geometry.closest_point(probe)
        patch = features.face_patch[face]
        if (patch == patch[0]).all() and (distance < 1e-3 * h).all():
            candidate = features.patches[patch[0]]
            if candidate.planar and abs(candidate.normal @ frame.axis) > PLANE_SQUARE:
                return int(patch[0]), side
    return None, 0


def _on_patch(geometry, features, points, patch: int, sizing, fixed, rng) -> np.ndarray:
    """``points`` moved to the closest point of the surface, kept where that lies on ``patch``, more than
    SURFACE_EXCLUSION x h from the ``fixed`` nodes and from each other."""
    if not len(points):
        return np.zeros((0, 3))
    closest, distance, face = geometry.closest_point(points)
    h = sizing(closest)
    keep = (features.face_patch[face] == patch) & (distance < 0.5 * h)
    if len(fixed):
        keep &= cKDTree(fixed).query(closest)[0] > SURFACE_EXCLUSION * h
    closest, h = closest[keep], h[keep]
    return closest[thin(closest, SURFACE_EXCLUSION * h, rng)]


def _integral_of_inverse(s: np.ndarray, h: np.ndarray) -> np.ndarray:
    """(n,) the integral of 1 / h over ``s`` (n,) from its start, by the trapezoid rule."""
    return np.concatenate([[0.0], np.cumsum(np.diff(s) * 0.5 * (1 / h[1:] + 1 / h[:-1]))])


def random_patch_nodes(geometry, features, sizing, boundary: np.ndarray, rng, faces_mask, avoid=None, gap=0.0):
    """(k, 3) density-following random nodes on the faces of ``faces_mask`` and (k,) their patches: about
    CANDIDATES_PER_H2 samples per h^2 of their area, none within ``gap`` x h of the ``avoid`` points, thinned to
    SURFACE_EXCLUSION x h against the ``boundary`` nodes (b, 3) and each other."""
    if not faces_mask.any():
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    mesh = geometry.mesh
    leaves, owner = _subdivide(mesh.triangles[faces_mask], sizing)
    owner = np.flatnonzero(faces_mask)[owner]
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
    if avoid is not None and len(avoid) and len(candidates):
        clear = cKDTree(avoid).query(candidates)[0] >= gap * sizing(candidates)
        candidates, patch = candidates[clear], patch[clear]
    all_points = np.concatenate([boundary, candidates])
    h = sizing(all_points)
    keep = thin(all_points, SURFACE_EXCLUSION * h, rng, fixed=np.arange(len(all_points)) < len(boundary))
    keep = keep[len(boundary) :]
    return candidates[keep], patch[keep]


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
