"""Exact surfaces: the plane, cylinder, sphere, cone or torus that a patch's input vertices lie on, and nodes
moved onto them.

A faceted input (a built-in shape's faceting, an STL exported from CAD) puts its vertices on the true
surface and its facets' insides off it, by up to the faceting's sagitta. A patch whose vertices all fit one
analytic surface to within EXACT_TOLERANCE x the model size is that surface; its mesh nodes, and the
10-node mid-edge nodes of its faces, belong on it, not on the facets (a hole drawn as a polygon has stress
peaks at the polygon's corners that refinement never removes). Curve nodes go onto the intersection of
the exact surfaces of the patches the curve borders (alternating projections), but those of a smooth cut
(faces meeting tangentially: the mesher slides them over the surface) onto the surface of the patch they lie
on; corners stay where the input has them. Patches that fit no analytic surface (freeform, or blends of
several) keep the facets.

An STL's vertices lie on the surface but its facets do not: moving the nodes onto the exact surface moves the
mesh off the input by up to the facets' sagitta. Where the mesh is finer than the faceting (a 15 degree export,
a small local size) that is more than the boundary may stray from the input (the acceptance gate's Hausdorff
bound is a fraction of h), and where only one side of a thin wall fits a surface it changes the wall's
thickness and the solid's volume. So a fitted surface is used only where the input's facets lie within
FAITHFUL x the local element size of it, or within the mesh's own chordal deviation there (its element size
squared over 8 radii: where the mesh is the coarser faceting, nodes on the surface bring it nearer the
input, not further) (:func:`faithful`). Patches of one surface (a sphere cut into several patches) are
judged together: all of them move or none. The exact surfaces a CAD model gives are used as they are.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .fitting import fit_circle_projected
from .levels import Level
from .mesh import triangle_edges
from .quality import tet_quality

EXACT_TOLERANCE = 1e-6  # x the model size: a float32 STL's vertices lie within ~1e-7 of their surface
ROUNDS = 8  # alternating projections onto the surfaces a curve borders
FAITHFUL = 0.05  # x the local element size: how far the input's facets may lie from the surface nodes go onto
SAME_SURFACE = 1e-4  # x the model size, and radians: two patches' fitted surfaces this close are one surface
FLAT_AFTER_MOVE = 10.0  # deg: a tet the move onto the exact surfaces would leave flatter than this keeps its nodes
CONE_STEPS = 30  # evaluations refining a cone fit: a cone's take 3-9, a face on none (an involute flank) wanders
CLOSER = 10.0  # a simpler surface that fits a face is taken over a closer one if its error is within this factor
EXACT_FIT = 1e-6  # ... or below this x the tolerance (roundoff: every surface that holds the face fits it exactly)
# barycentric points of a facet where its distance from the surface is sampled: centroid, edge midpoints, and
# between them (the facet's deepest point on a cylinder, sphere or cone lies inside it or on an edge)
FACET_SAMPLES = np.array(
    [[1 / 3, 1 / 3, 1 / 3], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]]
    + [[2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]]
)


@dataclass(frozen=True)
class Plane:
    point: np.ndarray
    normal: np.ndarray

    def project(self, x: np.ndarray) -> np.ndarray:
        """Closest points (k, 3) on the plane."""
        return x - np.outer((x - self.point) @ self.normal, self.normal)

    def normals(self, x: np.ndarray) -> np.ndarray:
        """Unit normals (k, 3) at the closest points, up to sign."""
        return np.broadcast_to(self.normal, x.shape)

    def curvatures(self, x: np.ndarray) -> np.ndarray:
        """Principal curvatures (k, 2) at the closest points: none."""
        return np.zeros((len(x), 2))


@dataclass(frozen=True)
class CylinderSurface:
    point: np.ndarray
    axis: np.ndarray
    radius: float

    def project(self, x: np.ndarray) -> np.ndarray:
        """Closest points (k, 3) on the cylinder; points on its axis stay."""
        rel = x - self.point
        foot = self.point + np.outer(rel @ self.axis, self.axis)
        radial = x - foot
        length = np.linalg.norm(radial, axis=1, keepdims=True)
        return np.where(length > 0, foot + self.radius * radial / np.where(length > 0, length, 1), x)

    def normals(self, x: np.ndarray) -> np.ndarray:
        """Unit normals (k, 3) at the closest points, up to sign."""
        rel = x - self.point
        radial = rel - np.outer(rel @ self.axis, self.axis)
        return radial / np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-300)

    def curvatures(self, x: np.ndarray) -> np.ndarray:
        """Principal curvatures (k, 2) at the closest points, > 0 bending away from :meth:`normals` (which point
        away from the axis): 1 / radius across the axis, 0 along it."""
        return np.tile([1.0 / self.radius, 0.0], (len(x), 1))


@dataclass(frozen=True)
class Sphere:
    centre: np.ndarray
    radius: float

    def project(self, x: np.ndarray) -> np.ndarray:
        """Closest points (k, 3) on the sphere; its centre stays."""
        rel = x - self.centre
        length = np.linalg.norm(rel, axis=1, keepdims=True)
        return np.where(length > 0, self.centre + self.radius * rel / np.where(length > 0, length, 1), x)

    def normals(self, x: np.ndarray) -> np.ndarray:
        """Unit normals (k, 3) at the closest points, up to sign."""
        rel = x - self.centre
        return rel / np.maximum(np.linalg.norm(rel, axis=1, keepdims=True), 1e-300)

    def curvatures(self, x: np.ndarray) -> np.ndarray:
        """Principal curvatures (k, 2) at the closest points, > 0 bending away from :meth:`normals` (outward)."""
        return np.full((len(x), 2), 1.0 / self.radius)


@dataclass(frozen=True)
class Cone:
    apex: np.ndarray
    axis: np.ndarray  # unit, from the apex into the cone
    angle: float  # half-angle, radians

    def project(self, x: np.ndarray) -> np.ndarray:
        """Closest points (k, 3) on the cone's nappe (the apex for points behind it); points on the axis
        go to the generator in the direction of the first perpendicular."""
        rel = x - self.apex
        along = rel @ self.axis
        radial = rel - np.outer(along, self.axis)
        length = np.linalg.norm(radial, axis=1, keepdims=True)
        fallback = np.cross(self.axis, np.eye(3)[np.argmin(np.abs(self.axis))])
        unit = np.where(length > 0, radial / np.where(length > 0, length, 1), fallback / np.linalg.norm(fallback))
        generator = np.cos(self.angle) * self.axis + np.sin(self.angle) * unit
        t = np.maximum(np.einsum("ij,ij->i", rel, generator), 0.0)
        return self.apex + t[:, None] * generator

    def normals(self, x: np.ndarray) -> np.ndarray:
        """Unit normals (k, 3) at the closest points, up to sign: the generator turned by 90 degrees."""
        rel = x - self.apex
        radial = rel - np.outer(rel @ self.axis, self.axis)
        unit = radial / np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-300)
        return np.cos(self.angle) * unit - np.sin(self.angle) * self.axis

    def curvatures(self, x: np.ndarray) -> np.ndarray:
        """Principal curvatures (k, 2) at the closest points, > 0 bending away from :meth:`normals` (which point
        away from the axis): cos(half-angle) / the distance from the axis round it, 0 along the generator."""
        rel = self.project(x) - self.apex
        around = np.linalg.norm(rel - np.outer(rel @ self.axis, self.axis), axis=1)
        return np.column_stack([np.cos(self.angle) / np.maximum(around, 1e-300), np.zeros(len(x))])


def fit_cone(vertices: np.ndarray, normals: np.ndarray, centres: np.ndarray) -> Cone | None:
    """The cone through a patch's ``vertices`` (k, 3), from its faces' ``normals`` and ``centres`` (f, 3), or
    None. Every facet of a faceted cone spans two generators, so its plane holds the apex: the apex is the
    least-squares point of the face planes. Seen from the apex the vertices make one angle with the axis:
    their unit directions lie on a circle, whose plane's normal is the axis."""
    spread = normals - normals.mean(axis=0)
    singular = np.linalg.svd(spread, compute_uv=False)
    if len(normals) < 6 or singular[1] < 1e-3 * len(normals) ** 0.5 or singular[2] > 0.05 * singular[0]:
        return None  # one normal (a plane), or normals all round (a sphere): no cone
    apex, *_ = np.linalg.lstsq(normals, np.einsum("ij,ij->i", normals, centres), rcond=None)
    rel = vertices - apex
    distance = np.linalg.norm(rel, axis=1)
    directions = rel[distance > 0] / distance[distance > 0, None]
    if len(directions) < 3:
        return None
    axis = np.linalg.svd(directions - directions.mean(axis=0), full_matrices=False)[2][2]
    if (directions @ axis).mean() < 0:
        axis = -axis
    angle = float(np.arccos(np.clip(np.median(directions @ axis), -1, 1)))
    if not 0 < angle < np.pi / 2:
        return None
    return _refined(Cone(apex, axis, angle), vertices)


def _refined(cone: Cone, vertices: np.ndarray) -> Cone:
    """The cone's apex, axis and angle adjusted by least squares (scipy) to the vertices' distances from it:
    a tessellation whose triangles do not each span two generators puts the planes' apex a little off."""
    from scipy.optimize import least_squares

    def unpack(x):
        axis = np.array([np.sin(x[3]) * np.cos(x[4]), np.sin(x[3]) * np.sin(x[4]), np.cos(x[3])])
        return x[:3], axis, x[5]

    def parts(x):
        apex, axis, angle = unpack(x)
        rel = vertices - apex
        along = rel @ axis
        across = np.maximum(np.linalg.norm(rel - np.outer(along, axis), axis=1), 1e-300)
        return rel, along, across, axis, angle

    def distances(x):
        _, along, across, _, angle = parts(x)
        return across * np.cos(angle) - along * np.sin(angle)

    def jacobian(x):  # (k, 6): d distance / d (apex, polar and azimuth of the axis, angle)
        rel, along, across, axis, angle = parts(x)
        radial = rel - np.outer(along, axis)
        by_apex = -np.cos(angle) * radial / across[:, None] + np.sin(angle) * axis
        by_axis = -(np.cos(angle) * along / across + np.sin(angle))[:, None] * rel
        turns = np.array(
            [
                [np.cos(x[3]) * np.cos(x[4]), np.cos(x[3]) * np.sin(x[4]), -np.sin(x[3])],
                [-np.sin(x[3]) * np.sin(x[4]), np.sin(x[3]) * np.cos(x[4]), 0.0],
            ]
        )
        by_angle = -across * np.sin(angle) - along * np.cos(angle)
        return np.column_stack([by_apex, by_axis @ turns.T, by_angle])

    start = np.r_[
        cone.apex, np.arccos(np.clip(cone.axis[2], -1, 1)), np.arctan2(cone.axis[1], cone.axis[0]), cone.angle
    ]
    apex, axis, angle = unpack(least_squares(distances, start, jac=jacobian, method="lm", max_nfev=CONE_STEPS).x)
    return Cone(apex, axis, float(angle)) if 0 < angle < np.pi / 2 else cone


@dataclass(frozen=True)
class Torus:
    centre: np.ndarray
    axis: np.ndarray
    major: float
    minor: float

    def tube_centre(self, x: np.ndarray) -> np.ndarray:
        """(k, 3) the points of the tube's centre circle nearest ``x`` (k, 3)."""
        rel = x - self.centre
        radial = rel - np.outer(rel @ self.axis, self.axis)
        length = np.linalg.norm(radial, axis=1, keepdims=True)
        fallback = np.cross(self.axis, np.eye(3)[np.argmin(np.abs(self.axis))])
        return self.centre + self.major * np.where(length > 0, radial / np.where(length > 0, length, 1), fallback)

    def project(self, x: np.ndarray) -> np.ndarray:
        """Closest points (k, 3) on the torus; points on the tube's centre circle stay."""
        tube = self.tube_centre(x)
        rel = x - tube
        length = np.linalg.norm(rel, axis=1, keepdims=True)
        return np.where(length > 0, tube + self.minor * rel / np.where(length > 0, length, 1), x)

    def normals(self, x: np.ndarray) -> np.ndarray:
        """Unit normals (k, 3) at the closest points, up to sign: out of the tube."""
        rel = x - self.tube_centre(x)
        return rel / np.maximum(np.linalg.norm(rel, axis=1, keepdims=True), 1e-300)

    def curvatures(self, x: np.ndarray) -> np.ndarray:
        """Principal curvatures (k, 2) at the closest points, > 0 bending away from the normal pointing out of the
        tube: 1 / minor round the tube, cos(phi) / (distance from the axis) round the axis (phi the angle round
        the tube from its outer equator: < 0 on the inner, saddle side)."""
        on = self.project(x)
        rel = on - self.centre
        around = np.linalg.norm(rel - np.outer(rel @ self.axis, self.axis), axis=1)
        cos_phi = (around - self.major) / self.minor
        return np.column_stack([np.full(len(x), 1.0 / self.minor), cos_phi / np.maximum(around, 1e-300)])


def fit_surface(
    vertices: np.ndarray,
    planar: bool,
    cylinder,
    tolerance: float,
    normals: np.ndarray | None = None,
    centres: np.ndarray | None = None,
    torus=None,
):
    """The Plane, CylinderSurface, Sphere, Cone or Torus all ``vertices`` (k, 3) lie on within ``tolerance``,
    or None. ``cylinder`` and ``torus`` are the patch's fitted :class:`engine.fitting.Cylinder` (its axis) and
    :class:`engine.fitting.Torus`, if any; the faces' ``normals`` and ``centres`` (f, 3), if given, allow a
    cone."""
    if len(vertices) < 4:
        return None
    candidates = []
    if torus is not None:
        candidates.append(Torus(torus.centre, torus.axis, torus.major, torus.minor))
    elif planar:
        centre = vertices.mean(axis=0)
        normal = np.linalg.svd(vertices - centre, full_matrices=False)[2][2]
        candidates.append(Plane(centre, normal))
    elif cylinder is not None:
        circle = fit_circle_projected(vertices, cylinder.axis)
        if circle is not None:
            candidates.append(CylinderSurface(circle[0], cylinder.axis, circle[1]))
    else:
        # algebraic sphere fit: |x|^2 = 2 c.x + (r^2 - |c|^2)
        matrix = np.column_stack([2 * vertices, np.ones(len(vertices))])
        solution, *_ = np.linalg.lstsq(matrix, (vertices**2).sum(axis=1), rcond=None)
        centre = solution[:3]
        candidates.append(Sphere(centre, float(np.sqrt(max(solution[3] + centre @ centre, 0.0)))))
        cone = fit_cone(vertices, normals, centres) if normals is not None else None
        if cone is not None:
            candidates.append(cone)
    fitting = [c for c in candidates if np.abs(c.project(vertices) - vertices).max() <= tolerance]
    if len(fitting) < 2 or normals is None:
        return fitting[0] if fitting else None
    # two rings of vertices lie on a sphere and on a cone alike: the one whose normals the facets follow
    return min(fitting, key=lambda c: np.mean(1 - np.abs(np.einsum("ij,ij->i", c.normals(centres), normals))))


def exact_surfaces(geometry, features) -> list:
    """Per patch of ``features``, the exact surface the input gives (CAD: ``features.exact``) or the analytic
    surface its input vertices lie on (:func:`fit_surface`) or None."""
    if features.exact is not None:
        return list(features.exact[0])
    tolerance = EXACT_TOLERANCE * geometry.scale
    normals, centres = geometry.mesh.face_normals, geometry.mesh.triangles_center
    return [
        fit_surface(p.vertices, p.planar, p.cylinder, tolerance, normals[p.faces], centres[p.faces], p.torus)
        for p in features.patches
    ]


def curve_surfaces(geometry, features, surfaces: list) -> list[list]:
    """Per curve, the exact surfaces of the patches on either side of it; [] unless every such patch has one
    (a curve along a freeform patch keeps its polyline) or for a curve inside the solid; the input's exact
    curve where it gives one (CAD: ``features.exact``)."""
    if features.exact is not None:
        return [[c] if c is not None else [] for c in features.exact[1]]
    mesh = geometry.mesh
    n = len(mesh.vertices)
    shared = np.sort(mesh.face_adjacency_edges, axis=1)
    keys = shared[:, 0] * n + shared[:, 1]
    order = np.argsort(keys)
    out = []
    for curve in features.curves:
        if curve.vertices is None or not curve.on_surface:
            out.append([])
            continue
        ends = np.column_stack([curve.vertices, np.roll(curve.vertices, -1)])
        ends = np.sort(ends if curve.closed else ends[:-1], axis=1)
        wanted = ends[:, 0] * n + ends[:, 1]
        at = np.clip(np.searchsorted(keys, wanted, sorter=order), 0, len(keys) - 1)
        found = order[at][keys[order[at]] == wanted]
        patches = np.unique(features.face_patch[mesh.face_adjacency[found]])
        chosen = [surfaces[p] for p in patches]
        out.append(chosen if len(found) and all(s is not None for s in chosen) else [])
    return out


class ExactSurfaces(NamedTuple):
    """A solid's exact surfaces, fitted once (:func:`fit_exact`) and passed on from stage to stage."""

    patches: list  # per patch: its exact surface or None (exact_surfaces)
    curves: list[list]  # per curve: the exact surfaces it lies on, or [] (curve_surfaces)


def fit_exact(geometry, features) -> ExactSurfaces:
    """The exact surfaces of the patches and of the curves of ``features``."""
    surfaces = exact_surfaces(geometry, features)
    return ExactSurfaces(surfaces, curve_surfaces(geometry, features, surfaces))


def onto_intersection(surfaces: list, x: np.ndarray) -> np.ndarray:
    """Points (k, 3) moved onto the common line of ``surfaces`` by alternating projections (one surface:
    its closest points)."""
    for _ in range(ROUNDS if len(surfaces) > 1 else 1):
        for surface in surfaces:
            x = surface.project(x)
    return x


def facet_deviation(surface, corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(f,) how far each facet (``corners`` (f, 3, 3)) strays from ``surface`` (the largest distance of its
    FACET_SAMPLES from it: the sagitta, for a facet whose corners lie on the surface) and (f, 3) the point
    where."""
    points = np.einsum("kj,fjd->fkd", FACET_SAMPLES, corners)
    flat = points.reshape(-1, 3)
    distance = np.linalg.norm(surface.project(flat) - flat, axis=1).reshape(len(corners), -1)
    deepest = distance.argmax(axis=1)
    return distance[np.arange(len(corners)), deepest], points[np.arange(len(corners)), deepest]


def element_size(mesh, points: np.ndarray) -> np.ndarray:
    """(k,) the mesh's element size at ``points`` (k, 3) on its boundary: the mean length of the boundary edges
    at the nearest boundary node (the mesh's own h there; inf for a mesh without boundary faces)."""
    from scipy.spatial import cKDTree

    if len(mesh.boundary) == 0:
        return np.full(len(points), np.inf)
    edges = triangle_edges(mesh.boundary)
    length = np.linalg.norm(mesh.points[edges[:, 0]] - mesh.points[edges[:, 1]], axis=1)
    total = np.bincount(edges.ravel(), np.repeat(length, 2), len(mesh.points))
    count = np.bincount(edges.ravel(), minlength=len(mesh.points))
    nodes = np.flatnonzero(count)
    return (total[nodes] / count[nodes])[cKDTree(mesh.points[nodes]).query(points)[1]]


def same_surface(a, b, tolerance: float) -> bool:
    """Whether the curved surfaces ``a`` and ``b`` (fitted to two patches) are one surface: positions and
    radii within ``tolerance``, directions within SAME_SURFACE radians."""
    if type(a) is not type(b):
        return False
    if isinstance(a, Sphere):
        return bool(np.linalg.norm(a.centre - b.centre) <= tolerance and abs(a.radius - b.radius) <= tolerance)
    if isinstance(a, CylinderSurface):
        offset = b.point - a.point
        return bool(
            np.linalg.norm(np.cross(a.axis, b.axis)) <= SAME_SURFACE
            and np.linalg.norm(offset - (offset @ a.axis) * a.axis) <= tolerance
            and abs(a.radius - b.radius) <= tolerance
        )
    if isinstance(a, Cone):
        return bool(
            np.linalg.norm(a.apex - b.apex) <= tolerance
            and a.axis @ b.axis >= 1 - SAME_SURFACE**2 / 2
            and abs(a.angle - b.angle) <= SAME_SURFACE
        )
    return False


def radius_across(surface, points: np.ndarray) -> np.ndarray:
    """(k,) the smallest radius of curvature of ``surface`` at (the closest points to) ``points`` (k, 3)."""
    if isinstance(surface, Sphere | CylinderSurface):
        return np.full(len(points), surface.radius)
    if isinstance(surface, Cone):  # across the generators: the distance from the axis over cos(half-angle)
        rel = points - surface.apex
        across = np.linalg.norm(rel - np.outer(rel @ surface.axis, surface.axis), axis=1)
        return across / np.cos(surface.angle)
    return np.full(len(points), np.inf)


def faithful(surfaces: list, geometry, features, mesh) -> tuple[list, dict]:
    """``surfaces`` (per patch) with None for every curved surface the input's facets stray from
    (:func:`facet_deviation`) by more than both FAITHFUL x the mesh's element size L there
    (:func:`element_size`) and the mesh's own chordal deviation L^2 / (8 R) (R: :func:`radius_across`);
    patches whose surfaces coincide (:func:`same_surface`) are judged as one, by the worst of them. Planes
    stay (their facets lie on them). Also returns what it found: how many patches were left on the facets,
    and the largest ratio of the facets' deviation to that allowance among the patches kept and among those
    left."""
    curved = [p for p, s in enumerate(surfaces) if s is not None and not isinstance(s, Plane)]
    corners = geometry.vertices[geometry.faces]
    found = [facet_deviation(surfaces[p], corners[features.patches[p].faces]) for p in curved]
    where = [x for _, x in found]
    sizes = element_size(mesh, np.vstack(where)) if curved else np.zeros(0)  # one lookup for all patches
    ratio = {}
    for p, (deviation, x), size in zip(curved, found, np.split(sizes, np.cumsum([len(x) for x in where])[:-1])):
        allowed = np.maximum(FAITHFUL * size, size**2 / (8 * radius_across(surfaces[p], x)))
        ratio[p] = float((deviation / allowed).max(initial=0.0))
    tolerance = SAME_SURFACE * geometry.scale
    group = {p: p for p in curved}
    for i, p in enumerate(curved):
        for q in curved[:i]:
            if group[q] == q and same_surface(surfaces[p], surfaces[q], tolerance):
                group[p] = q
                break
    worst = {}
    for p in curved:
        worst[group[p]] = max(worst.get(group[p], 0.0), ratio[p])
    left = [p for p in curved if worst[group[p]] > 1]
    out = [None if p in left else s for p, s in enumerate(surfaces)]
    stats = {
        "patches_left_on_facets": len(left),
        "facet_deviation_kept": max((ratio[p] for p in curved if p not in left), default=0.0),
        "facet_deviation_left": max((ratio[p] for p in left), default=0.0),
    }
    return out, stats


def on_exact_surfaces(mesh, geometry, features):
    """The mesh with its curve and patch nodes on their exact surfaces (module docstring); nodes of a tet
    the move would leave with a non-positive volume, or flattened (:func:`_flattened`), stay where they were.
    Returns (mesh, stats, exact): ``exact`` the surfaces used (those of :func:`fit_exact`, less the ones an
    input faceting strays from, :func:`faithful`), for the stages after this one (the 10-node elements)."""
    surfaces = exact_surfaces(geometry, features)
    faithful_stats = {}
    if features.exact is None:  # an input faceting, not a CAD model's surfaces
        surfaces, faithful_stats = faithful(surfaces, geometry, features, mesh)
    exact = ExactSurfaces(surfaces, curve_surfaces(geometry, features, surfaces))
    surfaces, along = exact
    points = mesh.points.copy()
    level, entity = _surface_or_curve(mesh, geometry, features)
    for which, table in ((Level.PATCH, [[s] if s is not None else [] for s in surfaces]), (Level.CURVE, along)):
        nodes = np.flatnonzero((level == which) & (entity >= 0))
        for key in np.unique(entity[nodes]):
            if table[key]:
                mine = nodes[entity[nodes] == key]
                points[mine] = onto_intersection(table[key], points[mine])
    kept = np.zeros(len(points), bool)
    touched = mesh.tets[np.any(points != mesh.points, axis=1)[mesh.tets].any(axis=1)]  # the others are as they were
    before = tet_quality(mesh.points, touched).min_dihedral
    while (bad := _flattened(points, touched, before)).any():  # ends: the input mesh's tets are as they were
        back = np.unique(touched[bad])
        points[back], kept[back] = mesh.points[back], True
    distance = np.linalg.norm(points - mesh.points, axis=1)
    stats = {
        "exact_patches": sum(s is not None for s in surfaces),
        "patches": len(surfaces),
        "exact_curves": sum(bool(a) for a in along),
        "curves": len(along),
        "nodes_moved": int((distance > 0).sum()),
        "largest_move": float(distance.max(initial=0.0)),
        "nodes_kept_for_validity": int(kept.sum()),
        **faithful_stats,
    }
    return dataclasses.replace(mesh, points=points), stats, exact


def _flattened(points: np.ndarray, tets: np.ndarray, before: np.ndarray) -> np.ndarray:
    """(t,) whether each tet is not positive at ``points``, or flatter than FLAT_AFTER_MOVE degrees where its
    minimum dihedral angle was ``before`` above that: four surface nodes of a spring's swept face, moved up to
    0.12 onto it from its tessellation, made three tets of 1-3 deg, which the gate refused."""
    quality = tet_quality(points, tets)
    return (quality.volume <= 0) | ((quality.min_dihedral < FLAT_AFTER_MOVE) & (before >= FLAT_AFTER_MOVE))


def _surface_or_curve(mesh, geometry, features) -> tuple[np.ndarray, np.ndarray]:
    """(n,) level and entity of each node as the move onto exact surfaces takes them: a node of a smooth cut
    (a curve between faces that meet tangentially) slides over the surface in the mesher's improvement
    (engine/meshing/delaunay.py), up to about h off its curve, so it goes onto the surface of the patch it lies
    on, not back onto its curve (a move of h that flattens its tets)."""
    level, entity = mesh.node_level.copy(), mesh.node_entity.copy()
    smooth = np.array([not c.sharp for c in features.curves] + [False], dtype=bool)
    on_cut = np.flatnonzero((level == Level.CURVE) & smooth[np.where(level == Level.CURVE, entity, -1)])
    if len(on_cut):
        level[on_cut] = Level.PATCH
        entity[on_cut] = features.face_patch[geometry.closest_point(mesh.points[on_cut])[2]]
    return level, entity


def fit_analytic(points: np.ndarray, normals: np.ndarray, tolerance: float, tube_radii=()):
    """The simplest Plane, Sphere, CylinderSurface, Cone or Torus that all ``points`` (k, 3) lie on within
    ``tolerance`` and about as closely as the closest of them (within CLOSER x its error, or EXACT_FIT x
    ``tolerance``: a cylinder's narrow band, 0.4 x 5 mm on a bolt's washer face, lies within 0.004 of a sphere
    too), or None; for a CAD face's own points (a B-spline or other non-analytic face evaluated by
    the kernel: no faceting error) with their unit ``normals`` (k, 3, either sign). A cylinder's axis is
    the direction its normals all miss; a cone's tangent planes all hold its apex (:func:`fit_cone`); a
    torus's tube centres are the points moved along their normals by its tube radius, one of
    ``tube_radii`` (the reciprocals of the face's principal curvatures), and make one circle."""
    points, normals = np.asarray(points, float), np.asarray(normals, float)
    if len(points) < 9:
        return None

    def candidates():  # the simplest first
        centre = points.mean(axis=0)
        yield Plane(centre, np.linalg.svd(points - centre, full_matrices=False)[2][2])
        matrix = np.column_stack([2 * points, np.ones(len(points))])
        solution, *_ = np.linalg.lstsq(matrix, (points**2).sum(axis=1), rcond=None)
        yield Sphere(solution[:3], float(np.sqrt(max(solution[3] + solution[:3] @ solution[:3], 0.0))))
        axis = np.linalg.svd(normals, full_matrices=False)[2][2]
        circle = fit_circle_projected(points, axis, tolerance=np.inf)
        if circle is not None:
            yield CylinderSurface(circle[0], axis, circle[1])
        cone = fit_cone(points, normals, points)
        if cone is not None:
            yield cone
        for radius in tube_radii:
            if not np.isfinite(radius) or radius <= 0:
                continue
            for sign in (1.0, -1.0):
                tube = points + sign * radius * normals
                middle = tube.mean(axis=0)
                spread, vt = np.linalg.svd(tube - middle, full_matrices=False)[1:]
                if spread[1] <= tolerance:  # the tube centres are one point: a sphere
                    continue
                ring = fit_circle_projected(tube, vt[2], tolerance=np.inf)
                if ring is not None:
                    yield Torus(ring[0], vt[2], ring[1], float(radius))

    fitting = [
        (surface, error)
        for surface in candidates()
        if (error := float(np.linalg.norm(surface.project(points) - points, axis=1).max())) <= tolerance
    ]
    if not fitting:
        return None
    best = min(error for _, error in fitting)
    return next(surface for surface, error in fitting if error <= max(CLOSER * best, EXACT_FIT * tolerance))
