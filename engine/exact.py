"""Exact surfaces: the plane, cylinder, sphere or cone that a patch's input vertices lie on, and nodes moved
onto them.

A faceted input (a built-in shape's faceting, an STL exported from CAD) puts its vertices on the true
surface and its facets' insides off it, by up to the faceting's sagitta. A patch whose vertices all fit one
analytic surface to within EXACT_TOLERANCE x the model size is that surface; its mesh nodes, and the
10-node mid-edge nodes of its faces, belong on it, not on the facets (a hole drawn as a polygon has stress
peaks at the polygon's corners that refinement never removes). Curve nodes go onto the intersection of
the exact surfaces of the patches the curve borders (alternating projections); corners stay where the
input has them. Patches that fit no analytic surface (freeform, or blends of several) keep the facets.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .levels import Level
from .mesh import signed_volumes

EXACT_TOLERANCE = 1e-6  # x the model size: a float32 STL's vertices lie within ~1e-7 of their surface
ROUNDS = 8  # alternating projections onto the surfaces a curve borders


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

    def distances(x):
        apex, axis, angle = unpack(x)
        rel = vertices - apex
        along = rel @ axis
        across = np.linalg.norm(rel - np.outer(along, axis), axis=1)
        return across * np.cos(angle) - along * np.sin(angle)

    start = np.r_[
        cone.apex, np.arccos(np.clip(cone.axis[2], -1, 1)), np.arctan2(cone.axis[1], cone.axis[0]), cone.angle
    ]
    apex, axis, angle = unpack(least_squares(distances, start, method="lm").x)
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


def fit_surface(
    vertices: np.ndarray,
    planar: bool,
    cylinder,
    tolerance: float,
    normals: np.ndarray | None = None,
    centres: np.ndarray | None = None,
):
    """The Plane, CylinderSurface, Sphere or Cone all ``vertices`` (k, 3) lie on within ``tolerance``, or
    None. ``cylinder`` is the patch's fitted :class:`engine.features.Cylinder` (its axis), if any; the
    faces' ``normals`` and ``centres`` (f, 3), if given, allow a cone."""
    if len(vertices) < 4:
        return None
    candidates = []
    if planar:
        centre = vertices.mean(axis=0)
        normal = np.linalg.svd(vertices - centre, full_matrices=False)[2][2]
        candidates.append(Plane(centre, normal))
    elif cylinder is not None:
        from .features import fit_circle_projected

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
        fit_surface(p.vertices, p.planar, p.cylinder, tolerance, normals[p.faces], centres[p.faces])
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


def on_exact_surfaces(mesh, geometry, features):
    """The mesh with its curve and patch nodes on their exact surfaces (module docstring); nodes of a tet
    the move would leave with a non-positive volume stay where they were. Returns (mesh, stats, exact):
    ``exact`` the fitted surfaces (:func:`fit_exact`), for the stages after this one (the 10-node elements)."""
    exact = fit_exact(geometry, features)
    surfaces, along = exact
    points = mesh.points.copy()
    for level, table in (("patch", [[s] if s is not None else [] for s in surfaces]), ("curve", along)):
        nodes = np.flatnonzero((mesh.node_level == Level[level.upper()]) & (mesh.node_entity >= 0))
        for entity in np.unique(mesh.node_entity[nodes]):
            if table[entity]:
                mine = nodes[mesh.node_entity[nodes] == entity]
                points[mine] = onto_intersection(table[entity], points[mine])
    kept = np.zeros(len(points), bool)
    while (bad := signed_volumes(points, mesh.tets) <= 0).any():  # ends: the input mesh has none
        back = np.unique(mesh.tets[bad])
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
    }
    return dataclasses.replace(mesh, points=points), stats, exact


def fit_analytic(points: np.ndarray, normals: np.ndarray, tolerance: float, tube_radii=()):
    """The simplest Plane, Sphere, CylinderSurface, Cone or Torus that all ``points`` (k, 3) lie on within
    ``tolerance``, or None; for a CAD face's own points (a B-spline or other non-analytic face evaluated by
    the kernel: no faceting error) with their unit ``normals`` (k, 3, either sign). A cylinder's axis is
    the direction its normals all miss; a cone's tangent planes all hold its apex (:func:`fit_cone`); a
    torus's tube centres are the points moved along their normals by its tube radius, one of
    ``tube_radii`` (the reciprocals of the face's principal curvatures), and make one circle."""
    points, normals = np.asarray(points, float), np.asarray(normals, float)
    if len(points) < 9:
        return None

    def fits(surface) -> bool:
        return bool(np.linalg.norm(surface.project(points) - points, axis=1).max() <= tolerance)

    centre = points.mean(axis=0)
    plane = Plane(centre, np.linalg.svd(points - centre, full_matrices=False)[2][2])
    if fits(plane):
        return plane
    matrix = np.column_stack([2 * points, np.ones(len(points))])
    solution, *_ = np.linalg.lstsq(matrix, (points**2).sum(axis=1), rcond=None)
    sphere = Sphere(solution[:3], float(np.sqrt(max(solution[3] + solution[:3] @ solution[:3], 0.0))))
    if fits(sphere):
        return sphere
    axis = np.linalg.svd(normals, full_matrices=False)[2][2]
    circle = _circle_across(points, axis)
    if circle is not None and fits(cylinder := CylinderSurface(circle[0], axis, circle[1])):
        return cylinder
    cone = fit_cone(points, normals, points)
    if cone is not None and fits(cone):
        return cone
    for radius in tube_radii:
        if not np.isfinite(radius) or radius <= 0:
            continue
        for sign in (1.0, -1.0):
            tube = points + sign * radius * normals
            middle = tube.mean(axis=0)
            spread, vt = np.linalg.svd(tube - middle, full_matrices=False)[1:]
            if spread[1] <= tolerance:  # the tube centres are one point: a sphere
                continue
            ring = _circle_across(tube, vt[2])
            if ring is not None and fits(torus := Torus(ring[0], vt[2], ring[1], float(radius))):
                return torus
    return None


def _circle_across(points: np.ndarray, axis: np.ndarray):
    """(centre, radius) of the least-squares circle of ``points`` seen along ``axis``, or None."""
    u = np.cross(axis, np.eye(3)[np.argmin(np.abs(axis))])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    origin = points.mean(axis=0)
    xy = np.column_stack([(points - origin) @ u, (points - origin) @ v])
    matrix = np.column_stack([2 * xy, np.ones(len(xy))])
    (cx, cy, c), *_ = np.linalg.lstsq(matrix, (xy**2).sum(axis=1), rcond=None)
    radius = c + cx**2 + cy**2
    return (origin + cx * u + cy * v, float(np.sqrt(radius))) if radius > 0 else None
