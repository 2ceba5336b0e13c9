"""The boundary triangulation: the surface nodes of a packing joined into a closed, conforming surface.

Each patch is flattened (a plane by projection, a cylinder by unrolling, any
other patch by a least-squares conformal map of its input triangles) and its
nodes are triangulated there by constrained Delaunay, with the node chains of
its bounding feature curves as constrained edges. The chains are shared by the
patches on both sides of a curve, so the patch triangulations meet edge to
edge and feature curves stay mesh edges. Which triangles lie on the patch is
decided exactly, without tolerances: the surface's winding tells on which side
of every chain edge its patch lies, and that side is flooded across the
unconstrained edges. Triangles come out oriented outward.
"""
from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np
from scipy import sparse
from scipy.sparse import csgraph
from scipy.spatial import Delaunay, cKDTree

from ..errors import GeometryError
from ..packing import CORNER, CURVE, PATCH

SEAM_LAYERS = 4   # node layers copied across the seam of a full cylinder (Delaunay is local)
CROWDING = 0.25   # a patch node nearer than this x h to its patch's border is left out


@dataclass
class BoundaryTriangulation:
    """Outward triangles on the solid's surface, indices into the packing's nodes."""

    triangles: np.ndarray   # (t, 3) int64
    patch: np.ndarray       # (t,) patch index of each triangle
    dropped: np.ndarray     # patch nodes left out because they crowd a feature curve


def curve_chains(packing, features) -> dict[int, np.ndarray]:
    """Node indices of every surface curve, in arc-length order, its end corners included.

    A closed curve's chain does not repeat its first node.
    """
    corner_node = {int(packing.entity[i]): i for i in np.flatnonzero(packing.level == CORNER)}
    corner_at_vertex = {c.vertex: corner_node[k] for k, c in enumerate(features.corners) if k in corner_node}
    curve_nodes = np.flatnonzero(packing.level == CURVE)
    by_curve = {key: curve_nodes[packing.entity[curve_nodes] == key] for key in np.unique(packing.entity[curve_nodes])}
    chains = {}
    for index, curve in enumerate(features.curves):
        if not curve.on_surface or curve.vertices is None:
            continue
        nodes = by_curve.get(index, np.zeros(0, np.int64))
        ordered = nodes[np.argsort(arc_parameter(curve, packing.points[nodes]), kind="stable")]
        start = corner_at_vertex.get(int(curve.vertices[0]))
        end = None if curve.closed else corner_at_vertex.get(int(curve.vertices[-1]))
        chains[index] = np.concatenate([[start] if start is not None else [], ordered,
                                        [end] if end is not None else []]).astype(np.int64)
    return chains


def arc_parameter(curve, points: np.ndarray) -> np.ndarray:
    """Arc length along ``curve`` of the closest point to each of ``points``."""
    line = curve.polyline
    start, direction = line[:-1], np.diff(line, axis=0)
    length2 = np.maximum(np.einsum("ij,ij->i", direction, direction), 1e-300)
    _, nearest = cKDTree(line).query(points)
    best_s, best_d = np.zeros(len(points)), np.full(len(points), np.inf)
    for segment in (nearest - 1, nearest):   # the two segments at the nearest polyline vertex
        segment = np.clip(segment, 0, len(start) - 1)
        t = np.clip(np.einsum("ij,ij->i", points - start[segment], direction[segment]) / length2[segment], 0, 1)
        d = np.linalg.norm(start[segment] + t[:, None] * direction[segment] - points, axis=1)
        better = d < best_d
        best_d[better] = d[better]
        best_s[better] = (curve.arc_length[segment] + t * np.sqrt(length2[segment]))[better]
    return best_s


def curve_sides(geometry, features) -> dict[int, tuple[int, int]]:
    """(patch on the left, patch on the right) of every surface curve, seen from outside along it."""
    faces = geometry.mesh.faces
    nv = len(geometry.mesh.vertices)
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    keys = directed[:, 0] * nv + directed[:, 1]
    order = np.argsort(keys)
    keys, owner = keys[order], (order // 3)
    sides = {}
    for index, curve in enumerate(features.curves):
        if not curve.on_surface or curve.vertices is None:
            continue
        v = np.asarray(curve.vertices)
        a, b = (v, np.roll(v, -1)) if curve.closed else (v[:-1], v[1:])
        found = []
        for edge in (a * nv + b, b * nv + a):
            at = np.clip(np.searchsorted(keys, edge), 0, len(keys) - 1)
            hit = keys[at] == edge
            patches = features.face_patch[owner[at[hit]]]
            found.append(int(np.bincount(patches).argmax()) if len(patches) else -1)
        sides[index] = tuple(found)
    return sides


def triangulate_boundary(packing, geometry, features) -> BoundaryTriangulation:
    """Constrained Delaunay triangulation of the surface nodes, patch by patch (see the module doc)."""
    chains = curve_chains(packing, features)
    sides = curve_sides(geometry, features)
    patch_nodes = np.flatnonzero(packing.level == PATCH)
    triangles, patch_of, dropped = [], [], []
    for p, patch in enumerate(features.patches):
        edges = []
        for index, chain in chains.items():
            left, right = sides[index]
            if p not in (left, right) or len(chain) < 2:
                continue
            curve = features.curves[index]
            pairs = np.column_stack([chain, np.roll(chain, -1)]) if curve.closed else np.column_stack([chain[:-1], chain[1:]])
            if p == left:
                edges.append(pairs)
            if p == right:
                edges.append(pairs[:, ::-1])
        edges = np.concatenate(edges) if edges else np.zeros((0, 2), np.int64)
        nodes = np.unique(np.concatenate([patch_nodes[packing.entity[patch_nodes] == p], edges.ravel()]))
        if len(nodes) < 3:
            continue
        local = np.searchsorted(nodes, edges)
        tri, crowded = _triangulate_patch(patch, geometry, packing.points[nodes], packing.radius[nodes], local,
                                          packing.level[nodes] == PATCH)
        triangles.append(nodes[tri])
        patch_of.append(np.full(len(tri), p))
        dropped.append(nodes[crowded])
    triangles = np.concatenate(triangles) if triangles else np.zeros((0, 3), np.int64)
    result = BoundaryTriangulation(triangles.astype(np.int64),
                                   np.concatenate(patch_of) if patch_of else np.zeros(0, np.int64),
                                   np.concatenate(dropped).astype(np.int64) if dropped else np.zeros(0, np.int64))
    check_closed(result.triangles)
    return result


def _triangulate_patch(patch, geometry, points, radius, constraints, droppable):
    """Triangles (local indices, counter-clockwise seen from outside) of one patch's nodes,
    and the local indices of the ``droppable`` nodes left out for crowding the border."""
    uv, copies = flatten(patch, geometry, points, radius)
    extended = uv if copies is None else np.vstack([uv] + [uv[rows] + shift for rows, shift in copies])
    original = np.arange(len(uv)) if copies is None else np.concatenate([np.arange(len(uv))] + [rows for rows, _ in copies])
    edges = _constraint_copies(constraints, original, extended)
    crowded = np.unique(original[_crowding(extended, edges, droppable[original], 2 * radius[original])])
    if len(crowded):
        rows = ~np.isin(original, crowded)
        edges = (np.cumsum(rows) - 1)[edges]   # constrained edges join curve nodes, which stay
        extended, original = extended[rows], original[rows]
    tri = _delaunay(extended)
    inside = _inside_regions(tri, edges)
    if copies is not None:   # one copy of each triangle: the one whose centroid lies in the unrolled turn
        u = extended[tri, 0].mean(axis=1)
        inside &= (u >= -np.pi * patch.cylinder.radius) & (u < np.pi * patch.cylinder.radius)
    return original[tri[inside]], crowded


def _crowding(uv, edges, candidate, h) -> np.ndarray:
    """Rows of ``candidate`` nodes nearer than CROWDING x h to a constrained edge."""
    rows = np.flatnonzero(candidate)
    if len(rows) == 0 or len(edges) == 0:
        return np.zeros(0, np.int64)
    a, b = uv[edges[:, 0]], uv[edges[:, 1]]
    _, near = cKDTree((a + b) / 2).query(uv[rows], k=min(4, len(edges)))
    near = near.reshape(len(rows), -1)
    start, span = a[near], (b - a)[near]
    x = uv[rows][:, None, :]
    t = np.clip(np.sum((x - start) * span, axis=2) / np.maximum(np.sum(span * span, axis=2), 1e-300), 0, 1)
    distance = np.linalg.norm(start + t[..., None] * span - x, axis=2).min(axis=1)
    return rows[distance < CROWDING * h[rows]]


def flatten(patch, geometry, points, radius):
    """2-D coordinates of points on ``patch``, orientation-preserving seen from outside.

    Returns (uv, copies): for a full cylinder, ``copies`` lists (rows, shift)
    of nodes repeated one turn to the left and right of the unrolled strip.
    """
    mesh = geometry.mesh
    if patch.planar:
        e1 = np.cross(patch.normal, np.eye(3)[np.argmin(np.abs(patch.normal))])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(patch.normal, e1)
        return (points - patch.centroid) @ np.column_stack([e1, e2]), None
    if patch.cylinder is not None:
        c = patch.cylinder
        e1 = np.cross(c.axis, np.eye(3)[np.argmin(np.abs(c.axis))])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(c.axis, e1)
        sign = -1.0 if c.concave else 1.0    # outward normal -e_r on a concave patch: mirror

        def angle(x):
            r = x - c.point
            return np.arctan2(r @ e2, r @ e1)

        if c.full_turn:
            theta = angle(points)
        else:   # turn the largest empty sector of the patch to the seam
            vertex_angles = np.sort(angle(mesh.vertices[np.unique(mesh.faces[patch.faces])]))
            gaps = np.diff(np.concatenate([vertex_angles, vertex_angles[:1] + 2 * np.pi]))
            k = int(np.argmax(gaps))
            middle = vertex_angles[k] + gaps[k] / 2
            theta = np.angle(np.exp(1j * (angle(points) - middle - np.pi)))
        uv = np.column_stack([sign * c.radius * theta, (points - c.point) @ c.axis])
        if not c.full_turn:
            return uv, None
        span = c.radius * min(np.pi, SEAM_LAYERS * 2 * radius.max() / c.radius)
        turn = 2 * np.pi * c.radius
        half = np.pi * c.radius
        copies = [(np.flatnonzero(uv[:, 0] < -half + span), np.array([turn, 0.0])),
                  (np.flatnonzero(uv[:, 0] >= half - span), np.array([-turn, 0.0]))]
        return uv, copies
    return _conformal_map(patch, geometry, points), None


def _conformal_map(patch, geometry, points) -> np.ndarray:
    """Least-squares conformal map of the patch's input triangles, carried to ``points`` barycentrically."""
    mesh = geometry.mesh
    used, local = np.unique(mesh.faces[patch.faces], return_inverse=True)
    vertices = np.ascontiguousarray(mesh.vertices[used], dtype=np.float64)
    faces = np.ascontiguousarray(local.reshape(-1, 3), dtype=np.int64)
    loops = igl.boundary_loop_all(faces) if len(faces) else []
    if not len(loops):
        raise GeometryError(f"surface patch '{patch.id}' is closed and smooth and cannot be flattened",
                            fix="split it by feature curves (lower geometry.feature_angle) or mesh a solid whose "
                                "smooth faces have borders")
    loop = np.asarray(max(loops, key=len))
    pinned = np.array([loop[0], loop[len(loop) // 2]])
    anchor = vertices[pinned]
    span = np.linalg.norm(anchor[1] - anchor[0])
    uv_vertices, _ = igl.lscm(vertices, faces, pinned, np.array([[0.0, 0.0], [span, 0.0]]))
    area = _signed_areas(uv_vertices, faces)
    if np.sum(area < 0) * 2 > len(area):
        uv_vertices[:, 0] *= -1
        area = -area
    if np.any(area <= 0):
        raise GeometryError(f"surface patch '{patch.id}' folds over when flattened",
                            fix="split it by feature curves (lower geometry.feature_angle)")
    tree = igl.AABB()
    tree.init(vertices, faces)
    _, face, closest = tree.squared_distance(vertices, faces, np.ascontiguousarray(points, dtype=np.float64))
    corners = vertices[faces[face]]
    weights = igl.barycentric_coordinates(closest, *(np.ascontiguousarray(corners[:, i]) for i in range(3)))
    return np.einsum("ij,ijk->ik", weights, uv_vertices[faces[face]])


def _signed_areas(uv, tri) -> np.ndarray:
    a, b, c = uv[tri[:, 0]], uv[tri[:, 1]], uv[tri[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def _constraint_copies(edges, original, extended) -> np.ndarray:
    """Constrained edges between node copies: each pair of copies less than half a turn apart."""
    if len(original) == len(np.unique(original)):
        return edges
    copies_of = {}
    for row, node in enumerate(original):
        copies_of.setdefault(int(node), []).append(row)
    out = []
    for a, b in edges:
        for ra in copies_of[int(a)]:
            for rb in copies_of[int(b)]:
                out.append((ra, rb))
    out = np.array(out, dtype=np.int64).reshape(-1, 2)
    # keep the short versions (an edge across the seam spans the whole turn between the originals)
    length = np.linalg.norm(extended[out[:, 0]] - extended[out[:, 1]], axis=1)
    half_turn = (extended[:, 0].max() - extended[:, 0].min()) / 4
    return out[length < half_turn]


def _delaunay(uv) -> np.ndarray:
    """Delaunay triangles (0-based, counter-clockwise) of ``uv`` by Qhull, inside a frame of far points.

    The frame makes the nodes' own hull interior, so straight borders of
    collinear nodes are triangulated like any other edge.
    """
    low, high = uv.min(axis=0), uv.max(axis=0)
    centre, reach = (low + high) / 2, 2 * (high - low).max() + 1e-12
    frame = centre + reach * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    tri = Delaunay(np.vstack([uv, frame]), qhull_options="Qbb Qc Qz Q12").simplices.astype(np.int64)
    tri = tri[np.all(tri < len(uv), axis=1)]
    flip = _signed_areas(uv, tri) < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    return tri


def _inside_regions(tri, constraints) -> np.ndarray:
    """Triangles on the left of the directed constrained edges, flooded across the other edges."""
    n = int(tri.max()) + 1 if len(tri) else 0
    half = np.stack([tri, np.roll(tri, -1, axis=1)], axis=2).reshape(-1, 2)   # directed edges, 3 per triangle
    owner = np.repeat(np.arange(len(tri)), 3)
    key = half[:, 0] * n + half[:, 1]
    twin_key = half[:, 1] * n + half[:, 0]
    order = np.argsort(key)
    at = np.clip(np.searchsorted(key[order], twin_key), 0, len(key) - 1)
    has_twin = key[order][at] == twin_key
    twin_owner = np.where(has_twin, owner[order][at], -1)
    lo, hi = np.minimum(half[:, 0], half[:, 1]), np.maximum(half[:, 0], half[:, 1])
    cons = np.sort(constraints, axis=1)
    constrained = np.isin(lo * n + hi, cons[:, 0] * n + cons[:, 1])
    link = has_twin & ~constrained
    graph = sparse.coo_matrix((np.ones(link.sum()), (owner[link], twin_owner[link])), shape=(len(tri),) * 2)
    count, region = csgraph.connected_components(graph, directed=False)
    forward = np.isin(key, constraints[:, 0] * n + constraints[:, 1])
    backward = np.isin(key, constraints[:, 1] * n + constraints[:, 0])
    votes_in = np.bincount(region[owner[forward]], minlength=count)
    votes_out = np.bincount(region[owner[backward]], minlength=count)
    if np.any((votes_in > 0) & (votes_out > 0)):
        raise RuntimeError("a patch triangulation region lies on both sides of its boundary")
    missing = len(constraints) - int(forward.sum())
    if missing:
        raise RuntimeError(f"{missing} constrained boundary edges are missing from a patch triangulation")
    return (votes_in > 0)[region]


def check_closed(triangles: np.ndarray) -> None:
    """Raise unless every edge is used by exactly two triangles, once in each direction."""
    directed = np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=2).reshape(-1, 2)
    keys, counts = np.unique(directed, axis=0, return_counts=True)
    n = int(triangles.max()) + 1 if len(triangles) else 0
    code = keys[:, 0] * n + keys[:, 1]
    twin = np.isin(keys[:, 1] * n + keys[:, 0], code)
    if np.any(counts != 1) or not np.all(twin):
        raise RuntimeError(f"the boundary triangulation is not a closed 2-manifold: {int(np.sum(counts != 1))} "
                           f"repeated and {int(np.sum(~twin))} unmatched directed edges")
