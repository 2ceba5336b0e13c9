"""The ``grid`` packer: nodes on a locally regular grid aligned with a direction frame, for hex-dominant meshes
(issue 23; the packer ``output: {elements: hex-dominant}`` uses unless the job names one).

The direction field of this first version is one frame for the whole solid (:func:`direction_frame`): the
normal of the largest planar patch, then the normal of the largest planar patch at right angles to it (within
~6 deg), and their cross product; a solid without two such patches takes the principal axes of its
area-weighted normal tensor. So the grid follows box-like solids (plates, brackets, blocks) and not curved
ones: there is no smoothing of a frame field through the volume, no alignment with a curve's tangent, and a
cylinder's wall meets the grid at every angle (its layer of elements is hexahedra only where the wall is within
28 deg of a frame axis, the rest tetrahedra and pyramids).

Nodes: corners; curves at equal steps of the integral of 1/h (:mod:`engine.packing.start`), except straight
curves along a frame axis, whose nodes are the grid's columns projected onto them; planar patches at right
angles to a frame axis get the grid's rows projected onto their plane (so that the boundary layer is boxes of
the grid); curved patches a wall node where a lattice line meets them within 28 deg of their normal
(:func:`_wall_nodes`: the hex-core mesher's wall hexahedra), and around those the start's thinned random nodes,
as other patches; the volume the centres of an octree in the frame,
graded by h (a cell of size s emits where s <= 2^(1/3) h, as the lattice start, but jittered by 1e-4 h only),
whose coarse islands and one-cell inlets among finer cells are split (:func:`_smooth_levels`: fewer level steps).
The octree lives in lattice coordinates that :func:`plane_warp` maps piecewise linearly onto the frame's, so
that the aligned planes lie on cell boundaries and the grid's nearest layer is half a cell from each of them;
grid nodes are kept ``LATTICE_EXCLUSION`` h from the boundary nodes on the lattice's lines and
``GRID_EXCLUSION`` h from the others. Between octree levels (a factor 2) the grid is not regular and the
hex-core mesher (engine/meshing/hexcore.py) leaves tetrahedra and pyramids there.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from . import CURVE, LEVELS, PATCH, VOLUME, Packing, register_packer
from .start import SPACING_SLACK, corner_nodes, curve_nodes, random_patch_nodes

ALIGNED = np.cos(np.radians(6.0))  # a normal within 6 deg of a frame axis is aligned with it
GRID_EXCLUSION = 0.45  # x h kept free between grid nodes and the boundary nodes (a boundary layer of >= 0.5 s)
GRID_JITTER = 1e-4  # x h: the grid nodes' random offsets, so that Delaunay meets no eight co-spherical nodes
EDGE_EXCLUSION = 0.75  # x h kept free between grid nodes and the curve and corner nodes (> CURVE_EXCLUSION x 2^0.5)
LATTICE_EXCLUSION = 0.2  # x h kept free between grid nodes and boundary nodes on the lattice's lines (the
# nearest layer is half a cell from an aligned plane: its boxes are half boxes)
THIN = 0.6  # x h: volume nodes closer than this are thinned (two octree levels side by side)
CURVE_EXCLUSION = 0.5  # x h kept free between projected grid nodes and the curve and corner nodes
WALL_ALIGNED = np.cos(np.radians(28.0))  # a curved wall's normal within this of a frame axis gets that axis's
# lattice lines projected onto it (the hex-core mesher's wall hexahedra; beyond ~30 deg the hexahedron's corner
# angles leave the recombination's 60-120 deg)
WALL_MIN = 0.4  # x h: a wall hexahedron at least this thick (a grid node nearer the wall along the line goes)
WALL_GAP = 0.5  # x h: wall nodes closer than this to one another: the less aligned goes
WALL_CLEAR = 1.0  # x h: random patch nodes kept this far from the wall nodes (no node inside a wall quad)
SMOOTH_FINER = 2  # a leaf with at least this many face neighbours in the solid of a finer level, and no fewer
# than of its own or a coarser one, is split (:func:`_smooth_levels`)
SMOOTH_ROUNDS = 50  # at most (the junction-edge example at size 12 settles in 10)
WALL_TRACE = 24  # sphere-tracing steps along a lattice line to the wall
WALL_SPAN = 0.9  # near a cylinder along a frame axis, octree cells at most this x the widest chord of radius R
# that stays within the surface mesher's DEVIATION h of its arc, sqrt(8 DEVIATION h R): a wider wall quad gets a
# node in its middle, and its wall hexahedron goes
WALL_BAND = 2.0  # x the root cell: how far into (and out of) a cylinder's wall the WALL_SPAN bound holds (a
# narrower band leaves a coarse core in a thin cylinder, and level steps round it)


def direction_frame(features) -> np.ndarray:
    """(3, 3) rows: the grid's axes (orthonormal, right-handed), see the module docstring."""
    planar = sorted((p for p in features.patches if p.planar), key=lambda p: -p.area)
    normals = [p.normal / np.linalg.norm(p.normal) for p in planar if np.linalg.norm(p.normal) > 0]
    if normals:
        first = normals[0]
        second = next((n for n in normals[1:] if abs(n @ first) < np.sin(np.radians(6.0))), None)
        if second is not None:
            second = second - (second @ first) * first
            second /= np.linalg.norm(second)
            return np.array([first, second, np.cross(first, second)])
    tensor = np.zeros((3, 3))
    for patch in features.patches:
        n = patch.normal / max(np.linalg.norm(patch.normal), 1e-300)
        tensor += patch.area * np.outer(n, n)
    _, vectors = np.linalg.eigh(tensor)
    frame = vectors.T[::-1].copy()
    frame[2] = np.cross(frame[0], frame[1])
    return frame


class Warp:
    """Per frame axis a monotone piecewise-linear map from lattice coordinates (xi) to frame coordinates, slope 1
    beyond its knots: ``knots[k] = (xi values, frame values)``. The aligned planes of an axis lie on root-cell
    boundaries: between two planes ``d`` apart there are ceil(d / root) root cells, shrunk to fit."""

    def __init__(self, knots):
        self.knots = [(np.asarray(a, float), np.asarray(b, float)) for a, b in knots]

    @staticmethod
    def _map(u, a, b):
        if len(a) == 0:
            return u.copy()
        out = np.interp(u, a, b)
        out = np.where(u < a[0], b[0] + (u - a[0]), out)
        return np.where(u > a[-1], b[-1] + (u - a[-1]), out)

    def __call__(self, xi):
        return np.column_stack([self._map(xi[:, k], *self.knots[k]) for k in range(3)])

    def inverse(self, x):
        return np.column_stack([self._map(x[:, k], self.knots[k][1], self.knots[k][0]) for k in range(3)])

    def slope(self, xi):
        """(n, 3) the map's slope at each point (the shrink of a cell there)."""
        out = np.ones((len(xi), 3))
        for k, (a, b) in enumerate(self.knots):
            if len(a) > 1:
                i = np.clip(np.searchsorted(a, xi[:, k], side="right") - 1, 0, len(a) - 2)
                inside = (xi[:, k] >= a[0]) & (xi[:, k] <= a[-1])
                out[inside, k] = ((b[1:] - b[:-1]) / (a[1:] - a[:-1]))[i[inside]]
        return out


def plane_warp(features, frame, root) -> Warp:
    """The Warp that puts the aligned planar patches' planes on root-cell boundaries (a plane closer than half a
    root cell to a larger one of the same axis is left off them)."""
    knots = []
    for k in range(3):
        levels = []
        for patch in sorted(features.patches, key=lambda p: -p.area):
            if not patch.planar:
                continue
            n = patch.normal / max(np.linalg.norm(patch.normal), 1e-300)
            if abs(frame[k] @ n) < ALIGNED:
                continue
            level = float(np.mean(patch.vertices @ frame[k]))
            if all(abs(level - other) >= 0.5 * root for other in levels):
                levels.append(level)
        levels = np.sort(levels)
        xi = levels[:1].copy()
        for gap in np.diff(levels):
            xi = np.append(xi, xi[-1] + np.ceil(gap / root - 1e-9) * root)
        knots.append((xi, levels))
    return Warp(knots)


def _wall_limit(features, frame, root):
    """A function (points, h) -> the largest octree cell there: WALL_SPAN sqrt(8 DEVIATION h R) within
    WALL_BAND root cells of a convex cylindrical patch of radius R along a frame axis (over the patch's length), inf
    elsewhere."""
    from ..meshing.surface import DEVIATION

    walls = []
    for patch in features.patches:
        c = patch.cylinder
        if c is None or patch.planar or c.concave:  # a fillet or hole: measured, no wall hexahedra, +31 % nodes
            continue
        axis = np.asarray(c.axis, float) / np.linalg.norm(c.axis)
        if np.abs(frame @ axis).max() < ALIGNED:
            continue
        along = (patch.vertices - c.point) @ axis
        walls.append((np.asarray(c.point, float), axis, float(c.radius), along.min(), along.max()))

    def limit(points, h):
        out = np.full(len(points), np.inf)
        for point, axis, radius, low, high in walls:
            d = points - point
            t = d @ axis
            r = np.linalg.norm(d - np.outer(t, axis), axis=1)
            near = (np.abs(r - radius) < WALL_BAND * root) & (t > low - 0.5 * root) & (t < high + 0.5 * root)
            out[near] = np.minimum(out[near], WALL_SPAN * np.sqrt(8 * DEVIATION * h[near] * radius))
        return out

    return limit


def _octree_centres(lo, hi, sizing, frame, warp, limit=None, relevant=None):
    """(centres (k, 3) in frame coordinates, cell sizes (k, 3) along each axis, the root cells' corner (3,) in
    lattice coordinates, their size): the octree cells, in the lattice coordinates of ``warp``, whose size
    matches h. A cell of level l (size ``size / 2**l``) has its centre at ``origin + (i + 1/2) size / 2**l`` on
    each lattice axis: the levels' coordinates are disjoint sets."""
    size = sizing.h_max * SPACING_SLACK * (1 - 1e-9)
    lo, hi = warp.inverse(lo[None])[0], warp.inverse(hi[None])[0]
    counts = np.maximum(1, np.ceil((hi - lo) / size)).astype(int)
    lo = 0.5 * (lo + hi) - 0.5 * counts * size  # centred on the solid's box, or from a plane on root boundaries
    for k, (xi, _) in enumerate(warp.knots):
        if len(xi):
            lo[k] = xi[0] - size * np.ceil((xi[0] - lo[k]) / size - 1e-9)
            counts[k] = max(1, int(np.ceil((hi[k] - lo[k]) / size - 1e-9)))
    origin, root = lo.copy(), size
    axes = [lo[k] + (np.arange(counts[k]) + 0.5) * size for k in range(3)]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    octants = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    leaves, level = [], 0
    while len(centres):
        cell = size * warp.slope(centres)
        world = warp(centres) @ frame
        h = sizing(world)
        done = cell.max(axis=1) <= h * SPACING_SLACK
        if limit is not None:
            done &= cell.max(axis=1) <= limit(world, h)
        leaves.append((level, centres[done]))
        size /= 2
        level += 1
        centres = (centres[~done][:, None, :] + 0.5 * size * octants[None]).reshape(-1, 3)
    if relevant is not None:
        leaves = _smooth_levels(leaves, origin, root, warp, frame, relevant)
    out = [c for _, c in leaves]
    sizes = [(root / 2**lv) * warp.slope(c) for lv, c in leaves]
    return warp(np.concatenate(out)), np.concatenate(sizes), origin, root


def _smooth_levels(leaves, origin, root, warp, frame, relevant):
    """The octree's leaves with coarse islands and inlets filled: a leaf (of the solid, ``relevant``) at least
    half of whose face neighbours in the solid are of a finer level is split, in rounds. Only splits: no cell
    gets larger than h asks. Each level step costs a layer of tetrahedra and pyramids ~0.75 coarse cells wide
    between the boxes of the two levels; a coarse cell among finer ones (a coarse island, a one-cell inlet of
    the staircase) is such a layer on most of its sides."""
    octants = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    steps = np.vstack([np.eye(3), -np.eye(3)])
    depth = len(leaves)
    for _ in range(SMOOTH_ROUNDS):
        by_level = {lv: c for lv, c in leaves if len(c)}
        keys = {}
        for lv, c in by_level.items():
            index = np.floor((c - origin) / (root / 2**lv)).astype(np.int64)
            keys[lv] = {tuple(i) for i in index.tolist()}
        split = {}
        for lv, c in by_level.items():
            inside = relevant(warp(c) @ frame)
            finer = np.zeros(len(c), int)
            other = np.zeros(len(c), int)
            s = root / 2**lv
            for step in steps:
                probe = c + step * (0.5 * s + 0.25 * root / 2 ** (depth - 1))
                ok = relevant(warp(probe) @ frame)
                found = np.full(len(c), -1)
                for m in range(depth):
                    if m not in keys:
                        continue
                    index = np.floor((probe - origin) / (root / 2**m)).astype(np.int64)
                    hit = np.array([tuple(i) in keys[m] for i in index.tolist()], bool) & (found < 0)
                    found[hit] = m
                finer += ok & (found > lv)
                other += ok & (found >= 0) & (found <= lv)
            split[lv] = inside & (finer >= SMOOTH_FINER) & (finer >= other)
        if not any(v.any() for v in split.values()):
            break
        new = {lv: [c[~split[lv]]] for lv, c in by_level.items()}
        for lv, c in by_level.items():
            if split[lv].any():
                children = (c[split[lv]][:, None, :] + 0.25 * root / 2**lv * octants[None]).reshape(-1, 3)
                new.setdefault(lv + 1, []).append(children)
        depth = max(depth, max(new) + 1)
        leaves = sorted((lv, np.concatenate(parts)) for lv, parts in new.items())
    return leaves


def _on_faces(points, vertices, faces, tolerance) -> np.ndarray:
    import igl

    if len(points) == 0:
        return np.zeros(0, bool)
    d2, _, _ = igl.point_mesh_squared_distance(
        np.ascontiguousarray(points, float),
        np.ascontiguousarray(vertices, float),
        np.ascontiguousarray(faces, np.int64),
    )
    return d2 <= tolerance**2


def _straight_axis(curve, frame, tolerance):
    """The frame axis a straight curve runs along, or None."""
    if curve.closed or len(curve.points) < 2 or not curve.on_surface:
        return None
    a, b = curve.points[0], curve.points[-1]
    chord = b - a
    length = np.linalg.norm(chord)
    if length == 0:
        return None
    d = chord / length
    off = curve.points - a - np.outer((curve.points - a) @ d, d)
    if np.abs(off).max() > tolerance:
        return None
    k = int(np.argmax(np.abs(frame @ d)))
    return k if abs(frame[k] @ d) >= ALIGNED else None


@register_packer("grid")
def pack_grid(geometry, features, sizing, *, seed: int = 0, knowledge=None) -> Packing:
    rng = np.random.default_rng(seed)
    frame = direction_frame(features)
    vertices = np.asarray(geometry.mesh.vertices, float)
    local = vertices @ frame.T
    root = sizing.h_max * SPACING_SLACK * (1 - 1e-9)
    warp = plane_warp(features, frame, root)
    limit = _wall_limit(features, frame, root)
    centres, cells, origin, root = _octree_centres(
        local.min(axis=0), local.max(axis=0), sizing, frame, warp, limit, geometry.contains
    )
    cell = cells.max(axis=1)
    tolerance = 1e-6 * geometry.scale

    def on_planes(points, axes=(0, 1, 2)):
        """Whether each point's frame coordinates on ``axes`` are all levels of aligned planes (the warp's)."""
        x = points @ frame.T
        ok = np.ones(len(points), bool)
        for k in axes:
            levels = warp.knots[k][1]
            ok &= np.abs(x[:, k, None] - levels[None]).min(axis=1, initial=np.inf) < tolerance
        return ok

    parts = [corner_nodes(features, sizing)]
    # a corner where three aligned planes meet is on the lattice's lines; the others are kept clear of
    lattice_corner = on_planes(parts[0].points)
    # straight curves along an axis: the grid's columns projected onto them; the others as the start has them
    straight = {i: _straight_axis(c, frame, tolerance) for i, c in enumerate(features.curves)}
    points, entity = [], []
    for index, axis in straight.items():
        if axis is None:
            continue
        curve = features.curves[index]
        a, b = curve.points[0] @ frame.T, curve.points[-1] @ frame.T
        other = [k for k in range(3) if k != axis]
        near = np.all(np.abs(centres[:, other] - a[other]) < 0.75 * cells[:, other], axis=1)  # the nearest columns
        low, high = sorted((a[axis], b[axis]))
        column = np.unique(centres[near, axis])
        h = sizing(np.outer(column - a[axis], frame[axis]) + curve.points[0])
        ends = np.array([curve.points[0], curve.points[-1]])[np.argsort([a[axis], b[axis]])]
        clear = np.where(on_planes(ends), LATTICE_EXCLUSION, CURVE_EXCLUSION)  # from the low end, the high end
        keep = (column - low > clear[0] * h) & (high - column > clear[1] * h)
        on = np.repeat(a[None], int(keep.sum()), axis=0)
        on[:, axis] = column[keep]
        points.append(on @ frame)
        entity.append(np.full(len(on), index))
    curved = curve_nodes(_Only(features, [i for i, k in straight.items() if k is None]), sizing, parts[0].points)
    straight_points = np.concatenate(points).reshape(-1, 3) if points else np.zeros((0, 3))
    straight_nodes = Packing(
        points=straight_points,
        level=np.full(len(straight_points), CURVE, np.int8),
        entity=np.concatenate(entity).astype(np.int64) if entity else np.zeros(0, np.int64),
        radius=sizing(straight_points) / 2 if len(straight_points) else np.zeros(0),
    )
    parts += [curved, straight_nodes]
    boundary = Packing.concatenate(parts)
    # the corner and curve nodes off the lattice (kept clear of by EDGE_EXCLUSION and CURVE_EXCLUSION) and on it
    edges = np.vstack([parts[0].points[~lattice_corner], curved.points])
    lattice_edges = np.vstack([parts[0].points[lattice_corner], straight_points])
    # planar patches at right angles to an axis: the grid's rows projected onto them
    aligned = np.zeros(len(features.patches), bool)
    projected, owner = [], []
    for index, patch in enumerate(features.patches):
        if not patch.planar:
            continue
        n = patch.normal / max(np.linalg.norm(patch.normal), 1e-300)
        axis = int(np.argmax(np.abs(frame @ n)))
        if abs(frame[axis] @ n) < ALIGNED:
            continue
        aligned[index] = True
        level = float(np.mean(patch.vertices @ frame[axis]))
        inward = -np.sign(frame[axis] @ n)  # from the plane into the solid, along the axis
        depth = (centres[:, axis] - level) * inward
        near = (depth > 0) & (depth <= 0.75 * cells[:, axis])  # the nearest layer inside (half a cell in): the
        # columns the boxes under it follow
        on = centres[near].copy()
        on[:, axis] = level
        world = on @ frame
        faces = geometry.mesh.faces[features.face_patch == index]
        world = world[_on_faces(world, vertices, faces, tolerance)]
        projected.append(world)
        owner.append(np.full(len(world), index))
    projected = np.concatenate(projected).reshape(-1, 3) if projected else np.zeros((0, 3))
    owner = np.concatenate(owner).astype(np.int64) if owner else np.zeros(0, np.int64)
    if len(projected):
        h = sizing(projected)
        keep = _gap(edges, projected) > CURVE_EXCLUSION * h
        keep &= _gap(lattice_edges, projected) > LATTICE_EXCLUSION * h
        projected, owner = projected[keep], owner[keep]
    parts.append(
        Packing(
            points=projected,
            level=np.full(len(projected), PATCH, np.int8),
            entity=owner,
            radius=sizing(projected) / 2,
        )
    )
    # curved (non-aligned) walls: the lattice's lines that meet them nearly square end on them (wall nodes)
    wall, wall_owner, too_near = _wall_nodes(geometry, features, sizing, frame, centres, cells, aligned)
    if len(wall):
        h = sizing(wall)
        keep = (_gap(edges, wall) > CURVE_EXCLUSION * h) & (_gap(lattice_edges, wall) > LATTICE_EXCLUSION * h)
        keep &= _gap(projected, wall) > WALL_GAP * h
        wall, wall_owner = wall[keep], wall_owner[keep]
    parts.append(
        Packing(points=wall, level=np.full(len(wall), PATCH, np.int8), entity=wall_owner, radius=sizing(wall) / 2)
    )
    centres, cell = centres[~too_near], cell[~too_near]
    boundary = Packing.concatenate(parts)
    on_lattice = np.vstack([lattice_edges, projected, wall])
    parts.append(
        _random_patch_nodes(geometry, features, sizing, boundary, rng, ~aligned[features.face_patch], avoid=wall)
    )
    off_lattice = np.vstack([edges, parts[-1].points])  # kept GRID_EXCLUSION from, the lattice's LATTICE_EXCLUSION
    # the volume: the octree's centres inside, away from the boundary nodes
    world = centres @ frame
    inside = geometry.contains(world)
    world, size = world[inside], cell[inside]
    h = sizing(world)
    away = (_gap(off_lattice, world) >= GRID_EXCLUSION * h) & (_gap(on_lattice, world) >= LATTICE_EXCLUSION * h)
    # near an edge off the lattice, the rows that would join a node to both planes are gone: so is the node
    away &= _gap(edges, world) >= EDGE_EXCLUSION * h
    world, h, size = world[away], h[away], size[away]
    world += rng.uniform(-GRID_JITTER, GRID_JITTER, world.shape) * h[:, None]  # no co-spherical eights
    inside = geometry.contains(world)
    world, size = world[inside], size[inside]
    h = sizing(world)
    # only where octree levels meet (a level's own spacing s is > 0.63 h: its parent, 2 s, was > 1.26 h), and
    # the finer node goes: a node of the coarser level is a corner of eight boxes eight times as large
    keep = np.zeros(len(world), bool)
    for level_size in np.unique(size)[::-1]:
        new = np.flatnonzero(size == level_size)
        if keep.any():
            gap, _ = cKDTree(world[keep]).query(world[new])
            new = new[gap >= THIN * h[new]]
        keep[new] = True
    world, h = world[keep], h[keep]
    parts.append(
        Packing(points=world, level=np.full(len(world), VOLUME, np.int8), entity=np.full(len(world), -1), radius=h / 2)
    )
    packing = Packing.concatenate(parts)
    return replace(
        packing,
        stats={
            "nodes": len(packing),
            **{f"{name}_nodes": int((packing.level == k).sum()) for k, name in enumerate(LEVELS)},
            "aligned_patches": int(aligned.sum()),
            "frame": np.round(frame, 6).tolist(),
            # the lattice, for the hex-core mesher (engine/meshing/hexcore.py): frame rows, the root cells'
            # corner in frame coordinates and their size (module docstring of _octree_centres)
            "grid": {
                "frame": frame.tolist(),
                "origin": origin.tolist(),
                "size": float(root),
                "warp": [[a.tolist(), b.tolist()] for a, b in warp.knots],
            },
        },
    )


def _gap(nodes, points) -> np.ndarray:
    """(n,) the distance from each point to the nearest of ``nodes`` (inf without nodes)."""
    if len(nodes) == 0:
        return np.full(len(points), np.inf)
    return cKDTree(nodes).query(points)[0]


class _Only:
    """Features with only some curves (for :func:`curve_nodes`), keeping the curves' indices."""

    def __init__(self, features, indices):
        keep = set(indices)
        self.curves = [c if i in keep else _Skipped() for i, c in enumerate(features.curves)]


class _Skipped:
    on_surface = False


def _wall_nodes(geometry, features, sizing, frame, centres, cells, aligned):
    """(wall nodes (w, 3), their patch (w,), (k,) the octree centres to drop): where a lattice line (frame axis k,
    either way) from an octree centre inside meets a non-aligned patch whose normal is within WALL_ALIGNED of the
    axis, at a distance t from the centre with WALL_MIN h <= t < its cell + WALL_MIN h (so the centre is the
    line's last before the wall), the meeting point is a wall node; a centre nearer than WALL_MIN h to such a
    wall along a line goes. The hex-core mesher joins a core face to its four wall nodes (a wall hexahedron)."""
    none = (np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(len(centres), bool))
    if aligned.all() or len(centres) == 0:
        return none
    world = centres @ frame
    inside = geometry.contains(world)
    reach = 1.0 + WALL_MIN + 0.5
    candidates = np.flatnonzero(inside)
    sd, _, _ = geometry._query(world[candidates])
    candidates = candidates[sd < reach * cells[candidates].max(axis=1)]
    if len(candidates) == 0:
        return none
    h = sizing(world[candidates])
    vertices = np.asarray(geometry.mesh.vertices, float)
    faces = np.asarray(geometry.mesh.faces, np.int64)
    normals = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    points, owner, score = [], [], []
    drop = np.zeros(len(centres), bool)
    for k in range(3):
        for sign in (-1.0, 1.0):
            direction = sign * frame[k]
            limit = reach * cells[candidates, k]
            t = np.zeros(len(candidates))
            for _ in range(WALL_TRACE):  # sphere tracing: a step of the distance to the surface never crosses it
                d, _, _ = geometry._query(world[candidates] + t[:, None] * direction)
                t = np.minimum(t + np.maximum(d, 0.0), limit)
            d, face, _ = geometry._query(world[candidates] + t[:, None] * direction)
            hit = (t < limit) & (np.abs(d) < 1e-6 * geometry.scale)
            patch = features.face_patch[face]
            cosine = normals[face] @ direction  # outward normal along the line
            hit &= ~aligned[patch] & (cosine >= WALL_ALIGNED)
            near = hit & (t < WALL_MIN * h)
            drop[candidates[near]] = True
            ends = hit & ~near & (t < cells[candidates, k] + WALL_MIN * h)
            local = centres[candidates[ends]].copy()
            local[:, k] += sign * t[ends]
            points.append(local @ frame)
            owner.append(patch[ends])
            score.append(cosine[ends])
    points, owner, score = np.concatenate(points), np.concatenate(owner), np.concatenate(score)
    # two wall nodes closer than WALL_GAP h (two lines' ends, or one end seen from two levels): the better
    # aligned stays
    order = np.argsort(-score, kind="stable")
    points, owner = points[order], owner[order]
    radius = WALL_GAP * sizing(points)
    keep = np.ones(len(points), bool)
    if len(points):
        pairs = cKDTree(points).query_pairs(float(radius.max()), output_type="ndarray")
        if len(pairs):
            pairs = np.sort(pairs, axis=1)
            close = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1) < radius[pairs[:, 1]]
            for a, b in pairs[close][np.argsort(pairs[close][:, 0], kind="stable")]:
                if keep[a]:
                    keep[b] = False
    return points[keep], owner[keep].astype(np.int64), drop


def _random_patch_nodes(geometry, features, sizing, boundary: Packing, rng, faces_mask, avoid=None) -> Packing:
    """The start's random patch nodes (:func:`engine.packing.start.random_patch_nodes`) on the faces of
    ``faces_mask`` only, none within WALL_CLEAR h of the ``avoid`` points (the wall nodes)."""
    points, patch = random_patch_nodes(
        geometry, features, sizing, boundary.points, rng, faces_mask, avoid=avoid, gap=WALL_CLEAR
    )
    return Packing(points=points, level=np.full(len(points), PATCH, np.int8), entity=patch, radius=sizing(points) / 2)
