"""Features of a solid: corners, feature curves and surface patches.

Feature curves are chains of sharp edges (dihedral angle between the face
normals above ``feature_angle``). Corners are where curves meet or end, or
where a curve turns sharply. Patches are the connected groups of faces
bounded by feature curves. Every feature has a stable id (``corner-3``,
``curve-0``, ``patch-5``), derived deterministically from the surface, and a
name where a shape or a recognition rule gives one. Curves are parametrised by
arc length; closed circular curves carry centre, axis and radius.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from .geometry import Geometry

CIRCLE_TOLERANCE = 2e-3  # max radial deviation / radius for a curve to count as a circle


@dataclass(frozen=True)
class Circle:
    centre: np.ndarray
    axis: np.ndarray
    radius: float


@dataclass(frozen=True)
class Cylinder:
    """A patch that lies on a cylinder; ``concave`` when the material is outside it."""

    point: np.ndarray
    axis: np.ndarray
    radius: float
    concave: bool
    full_turn: bool


@dataclass
class Corner:
    id: str
    vertex: int
    point: np.ndarray
    names: list[str] = field(default_factory=list)


@dataclass
class Curve:
    """A polyline on (or, when given by a shape, inside) the solid."""

    id: str
    points: np.ndarray              # (n, 3) ordered; a closed curve does not repeat its first point
    closed: bool
    vertices: np.ndarray | None     # surface vertex index of each point, None for a given curve
    convex: bool | None = None      # None for a given curve
    circle: Circle | None = None
    names: list[str] = field(default_factory=list)
    on_surface: bool = True
    sharp: bool = True              # False for borders of face groups that meet smoothly
    kinds: list[str] = field(default_factory=list)

    @property
    def polyline(self) -> np.ndarray:
        return np.vstack([self.points, self.points[:1]]) if self.closed else self.points

    @property
    def arc_length(self) -> np.ndarray:
        """Cumulative arc length at each point of :attr:`polyline`."""
        seg = np.linalg.norm(np.diff(self.polyline, axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(seg)])

    @property
    def length(self) -> float:
        return float(self.arc_length[-1])

    def point_at(self, s: np.ndarray) -> np.ndarray:
        """Points at arc lengths ``s`` (clipped to [0, length]; wrapped if closed)."""
        s = np.asarray(s, dtype=float)
        total = self.length
        s = np.mod(s, total) if self.closed else np.clip(s, 0.0, total)
        knots = self.arc_length
        seg = np.clip(np.searchsorted(knots, s, side="right") - 1, 0, len(knots) - 2)
        span = np.maximum(knots[seg + 1] - knots[seg], 1e-300)
        t = ((s - knots[seg]) / span)[..., None]
        line = self.polyline
        return (1 - t) * line[seg] + t * line[seg + 1]


@dataclass
class Patch:
    id: str
    faces: np.ndarray
    area: float
    normal: np.ndarray     # area-weighted mean unit normal
    centroid: np.ndarray
    vertices: np.ndarray   # (k, 3) coordinates of the patch's vertices
    planar: bool
    cylinder: Cylinder | None = None
    names: list[str] = field(default_factory=list)
    kinds: list[str] = field(default_factory=list)


@dataclass
class Features:
    corners: list[Corner]
    curves: list[Curve]
    patches: list[Patch]
    face_patch: np.ndarray   # patch index of every surface face
    feature_angle: float
    lengths: dict = field(default_factory=dict)   # characteristic lengths given by a shape

    def named(self, name: str) -> list:
        """All features carrying ``name``."""
        return [f for group in (self.corners, self.curves, self.patches) for f in group if name in f.names]

    @property
    def names(self) -> list[str]:
        return sorted({n for group in (self.corners, self.curves, self.patches) for f in group for n in f.names})


def detect_features(geometry: Geometry, feature_angle: float = 30.0, face_groups=()) -> Features:
    """Find corners, feature curves and patches of ``geometry`` (angles in degrees).

    ``face_groups`` are functions ``triangles (F, 3, 3) -> bool mask``; each
    marks faces that form patches of their own even where they meet their
    neighbours smoothly (e.g. a tangent fillet). Their borders become curves,
    as does the cut that halves a smooth closed patch (a sphere's surface).
    """
    mesh = geometry.mesh
    threshold = np.radians(feature_angle)
    adjacency = mesh.face_adjacency
    sharp = mesh.face_adjacency_angles > threshold
    group = np.zeros(len(mesh.faces), dtype=int)
    for k, select in enumerate(face_groups, start=1):
        group[select(mesh.triangles)] = k
    truly_sharp = sharp.copy()
    sharp |= group[adjacency[:, 0]] != group[adjacency[:, 1]]
    patches, face_patch = _patches(geometry, adjacency[~sharp])
    closed = np.setdiff1d(np.arange(len(patches)), face_patch[adjacency[sharp]])
    if len(closed):   # a smooth closed patch (a sphere) is cut in two, so that every patch has a border
        for k, p in enumerate(closed, start=group.max() + 1):
            group[_half(mesh, patches[p].faces)] = k
        sharp |= group[adjacency[:, 0]] != group[adjacency[:, 1]]
        patches, face_patch = _patches(geometry, adjacency[~sharp])
    sharp_edges = mesh.face_adjacency_edges[sharp]
    corners, curves = _curves(mesh.vertices, sharp_edges, mesh.face_adjacency_convex[sharp],
                              truly_sharp[sharp], threshold)
    return Features(corners, curves, patches, face_patch, feature_angle)


def _half(mesh, faces: np.ndarray) -> np.ndarray:
    """The faces of ``faces`` on one side of the plane through their centroid across their longest extent."""
    centres = mesh.triangles_center[faces]
    centred = centres - centres.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    along = centred @ axis
    return faces[along > np.median(along)]


def _patches(geometry: Geometry, smooth_pairs: np.ndarray):
    mesh = geometry.mesh
    n = len(mesh.faces)
    graph = sparse.coo_matrix((np.ones(len(smooth_pairs)), (smooth_pairs[:, 0], smooth_pairs[:, 1])), shape=(n, n))
    count, labels = csgraph.connected_components(graph, directed=False)
    # renumber by lowest face index, so ids follow the surface's face order
    first_face = np.full(count, n)
    np.minimum.at(first_face, labels, np.arange(n))
    order = np.argsort(first_face)
    rank = np.empty(count, dtype=int)
    rank[order] = np.arange(count)
    labels = rank[labels]
    areas = mesh.area_faces
    normals = mesh.face_normals
    centres = mesh.triangles_center
    patches = []
    for k in range(count):
        faces = np.flatnonzero(labels == k)
        area = float(areas[faces].sum())
        normal = (normals[faces] * areas[faces, None]).sum(axis=0)
        normal /= max(np.linalg.norm(normal), 1e-300)
        centroid = (centres[faces] * areas[faces, None]).sum(axis=0) / max(area, 1e-300)
        verts = mesh.vertices[np.unique(mesh.faces[faces])]
        planar = bool(np.abs((verts - centroid) @ normal).max() <= 1e-9 * geometry.scale
                      and np.all(normals[faces] @ normal > 1 - 1e-9))
        cylinder = None if planar else fit_cylinder(centres[faces], normals[faces], verts)
        patches.append(Patch(f"patch-{k}", faces, area, normal, centroid, verts, planar, cylinder))
    return patches, labels


def _curves(vertices: np.ndarray, edges: np.ndarray, convex: np.ndarray, truly_sharp: np.ndarray,
            turn_threshold: float):
    if len(edges) == 0:
        return [], []
    nv = len(vertices)
    degree = np.bincount(edges.ravel(), minlength=nv)
    corner_mask = (degree > 0) & (degree != 2)
    corner_mask |= _sharp_turns(vertices, edges, degree, turn_threshold)
    # edges belong to one curve when they share a vertex that is not a corner
    ne = len(edges)
    ends = np.concatenate([edges[:, 0], edges[:, 1]])
    edge_ids = np.concatenate([np.arange(ne), np.arange(ne)])
    inner = ~corner_mask[ends]
    order = np.argsort(ends[inner], kind="stable")
    v_sorted, e_sorted = ends[inner][order], edge_ids[inner][order]
    same = v_sorted[1:] == v_sorted[:-1]
    a, b = e_sorted[:-1][same], e_sorted[1:][same]
    graph = sparse.coo_matrix((np.ones(len(a)), (a, b)), shape=(ne, ne))
    count, edge_curve = csgraph.connected_components(graph, directed=False)

    corner_vertices = np.flatnonzero(corner_mask)
    corners = [Corner(f"corner-{i}", int(v), vertices[v].copy()) for i, v in enumerate(corner_vertices)]
    raw = []
    for k in range(count):
        members = np.flatnonzero(edge_curve == k)
        ordered, closed = _order_chain(edges[members], corner_mask)
        raw.append((int(min(ordered)), ordered, closed, bool(np.mean(convex[members]) >= 0.5),
                    bool(np.mean(truly_sharp[members]) >= 0.5)))
    raw.sort(key=lambda item: item[0])
    curves = []
    for i, (_, ordered, closed, is_convex, is_sharp) in enumerate(raw):
        points = vertices[ordered]
        curve = Curve(f"curve-{i}", points, closed, ordered, convex=is_convex, sharp=is_sharp)
        if closed:
            curve.circle = fit_circle(points)
        curves.append(curve)
    return corners, curves


def _sharp_turns(vertices, edges, degree, threshold) -> np.ndarray:
    """Degree-2 vertices where the chain turns by more than ``threshold``."""
    nv = len(vertices)
    turn = np.zeros(nv, dtype=bool)
    direction = vertices[edges[:, 1]] - vertices[edges[:, 0]]
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-300)
    # for each vertex of degree 2, the two unit vectors pointing away from it
    ends = np.concatenate([edges[:, 0], edges[:, 1]])
    away = np.concatenate([direction, -direction])
    pick = degree[ends] == 2
    ends, away = ends[pick], away[pick]
    order = np.argsort(ends, kind="stable")
    ends, away = ends[order], away[order]
    first, second = away[0::2], away[1::2]
    # the chain is straight when the two away-vectors are opposite
    cosine = -np.einsum("ij,ij->i", first, second)
    turn[ends[0::2]] = cosine < np.cos(threshold)
    return turn


def _order_chain(chain_edges: np.ndarray, corner_mask: np.ndarray):
    """Order the vertices of a chain of edges; return (vertex order, closed)."""
    local, inverse = np.unique(chain_edges.ravel(), return_inverse=True)
    inverse = inverse.reshape(-1, 2)
    n = len(local)
    graph = sparse.coo_matrix((np.ones(len(inverse)), (inverse[:, 0], inverse[:, 1])), shape=(n, n)).tocsr()
    graph = graph + graph.T
    ends = np.flatnonzero(corner_mask[local])
    local_degree = np.diff(graph.indptr)
    if len(ends) == 0:                 # a loop without corners
        start, closed = int(np.argmin(local)), True
    elif len(ends) == 1 and local_degree[ends[0]] == 2:   # a loop through one corner
        start, closed = int(ends[0]), True
    else:
        start, closed = int(ends[np.argmin(local[ends])]), False
    order = csgraph.depth_first_order(graph, start, directed=False, return_predecessors=False)
    return local[order], closed


def fit_circle(points: np.ndarray) -> Circle | None:
    """Least-squares circle through ``points`` if they lie on one, else None."""
    centre0 = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre0)
    axis = vt[2]
    u, v = vt[0], vt[1]
    xy = np.column_stack([(points - centre0) @ u, (points - centre0) @ v])
    if np.abs((points - centre0) @ axis).max() > CIRCLE_TOLERANCE * np.ptp(xy):
        return None
    A = np.column_stack([2 * xy, np.ones(len(xy))])
    rhs = (xy ** 2).sum(axis=1)
    (cx, cy, c), *_ = np.linalg.lstsq(A, rhs, rcond=None)
    radius = float(np.sqrt(c + cx ** 2 + cy ** 2))
    deviation = np.abs(np.linalg.norm(xy - [cx, cy], axis=1) - radius).max()
    if len(points) < 6 or deviation > CIRCLE_TOLERANCE * radius:
        return None
    if axis[np.argmax(np.abs(axis))] < 0:
        axis = -axis
    return Circle(centre0 + cx * u + cy * v, axis, radius)


def fit_cylinder(face_centres: np.ndarray, face_normals: np.ndarray, vertices: np.ndarray) -> Cylinder | None:
    """The cylinder a patch lies on (normals perpendicular to one axis, points on one circle), or None."""
    if len(face_normals) < 3:
        return None
    _, singular, vt = np.linalg.svd(face_normals, full_matrices=False)
    axis = vt[2]
    if singular[2] > 1e-3 * singular[0]:
        return None
    circle = fit_circle_projected(vertices, axis)
    if circle is None:
        return None
    centre, radius = circle
    radial = face_centres - centre
    radial -= np.outer(radial @ axis, axis)
    concave = bool(np.mean(np.einsum("ij,ij->i", radial, face_normals)) < 0)
    angles = np.sort(np.arctan2(radial @ np.cross(axis, _any_perpendicular(axis)), radial @ _any_perpendicular(axis)))
    gaps = np.diff(np.concatenate([angles, angles[:1] + 2 * np.pi]))
    if axis[np.argmax(np.abs(axis))] < 0:
        axis = -axis
    return Cylinder(centre, axis, radius, concave, bool(gaps.max() < np.radians(30)))


def _any_perpendicular(axis: np.ndarray) -> np.ndarray:
    helper = np.eye(3)[np.argmin(np.abs(axis))]
    v = np.cross(axis, helper)
    return v / np.linalg.norm(v)


def fit_circle_projected(points: np.ndarray, axis: np.ndarray):
    """Centre (a point on the axis) and radius of the circle the points make seen along ``axis``."""
    u = _any_perpendicular(axis)
    v = np.cross(axis, u)
    origin = points.mean(axis=0)
    xy = np.column_stack([(points - origin) @ u, (points - origin) @ v])
    A = np.column_stack([2 * xy, np.ones(len(xy))])
    (cx, cy, c), *_ = np.linalg.lstsq(A, (xy ** 2).sum(axis=1), rcond=None)
    radius = float(np.sqrt(max(c + cx ** 2 + cy ** 2, 0.0)))
    if radius == 0 or np.abs(np.linalg.norm(xy - [cx, cy], axis=1) - radius).max() > CIRCLE_TOLERANCE * radius:
        return None
    return origin + cx * u + cy * v, radius


def classify(features: Features, kinds) -> Features:
    """Give every curve and patch the feature kinds (``FeatureKind``s) whose tests it passes."""
    for kind in kinds.values():
        group = features.curves if kind.of == "curve" else features.patches
        for feature in group:
            if kind.name not in feature.kinds and all(_passes(feature, t, v) for t, v in kind.tests.items()):
                feature.kinds.append(kind.name)
    return features


def _passes(feature, test: str, value) -> bool:
    if test == "named":
        return value in feature.names
    if test == "circular":
        return (feature.circle is not None) == value
    if test in ("cylindrical", "concave", "full_turn"):
        cylinder = feature.cylinder
        actual = cylinder is not None if test == "cylindrical" else bool(cylinder and getattr(cylinder, test))
        return actual == value
    return bool(getattr(feature, test)) == value


def apply_names(features: Features, rules, given_curves=()) -> Features:
    """Name detected features by ``rules`` (name, kind, test) and add ``given_curves``."""
    groups = {"curve": features.curves, "patch": features.patches, "corner": features.corners}
    for rule in rules:
        for feature in groups[rule.kind]:
            if rule.name not in feature.names and rule.test(feature):
                feature.names.append(rule.name)
    for given in given_curves:
        curve = Curve(f"curve-{len(features.curves)}", np.asarray(given.points, float), given.closed, None,
                      names=[given.name], on_surface=False)
        if given.closed:
            curve.circle = fit_circle(curve.points)
        features.curves.append(curve)
    return features
