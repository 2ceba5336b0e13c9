"""Exact surfaces: the plane, cylinder or sphere that a patch's input vertices lie on, and nodes moved onto them.

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

import numpy as np

from .mesh import NODE_LEVELS, signed_volumes

EXACT_TOLERANCE = 1e-6   # x the model size: a float32 STL's vertices lie within ~1e-7 of their surface
ROUNDS = 8               # alternating projections onto the surfaces a curve borders


@dataclass(frozen=True)
class Plane:
    point: np.ndarray
    normal: np.ndarray

    def project(self, x: np.ndarray) -> np.ndarray:
        """Closest points (k, 3) on the plane."""
        return x - np.outer((x - self.point) @ self.normal, self.normal)


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


@dataclass(frozen=True)
class Sphere:
    centre: np.ndarray
    radius: float

    def project(self, x: np.ndarray) -> np.ndarray:
        """Closest points (k, 3) on the sphere; its centre stays."""
        rel = x - self.centre
        length = np.linalg.norm(rel, axis=1, keepdims=True)
        return np.where(length > 0, self.centre + self.radius * rel / np.where(length > 0, length, 1), x)


def fit_surface(vertices: np.ndarray, planar: bool, cylinder, tolerance: float):
    """The Plane, CylinderSurface or Sphere all ``vertices`` (k, 3) lie on within ``tolerance``, or None.
    ``cylinder`` is the patch's fitted :class:`engine.features.Cylinder` (its axis), if any."""
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
        solution, *_ = np.linalg.lstsq(matrix, (vertices ** 2).sum(axis=1), rcond=None)
        centre = solution[:3]
        candidates.append(Sphere(centre, float(np.sqrt(max(solution[3] + centre @ centre, 0.0)))))
    for surface in candidates:
        if np.abs(surface.project(vertices) - vertices).max() <= tolerance:
            return surface
    return None


def exact_surfaces(geometry, features) -> list:
    """Per patch of ``features``, the analytic surface its input vertices lie on (:func:`fit_surface`) or None."""
    tolerance = EXACT_TOLERANCE * geometry.scale
    return [fit_surface(p.vertices, p.planar, p.cylinder, tolerance) for p in features.patches]


def curve_surfaces(geometry, features, surfaces: list) -> list[list]:
    """Per curve, the exact surfaces of the patches on either side of it; [] unless every such patch has one
    (a curve along a freeform patch keeps its polyline) or for a curve inside the solid."""
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


def onto_intersection(surfaces: list, x: np.ndarray) -> np.ndarray:
    """Points (k, 3) moved onto the common line of ``surfaces`` by alternating projections (one surface:
    its closest points)."""
    for _ in range(ROUNDS if len(surfaces) > 1 else 1):
        for surface in surfaces:
            x = surface.project(x)
    return x


def on_exact_surfaces(mesh, geometry, features):
    """The mesh with its curve and patch nodes on their exact surfaces (module docstring); nodes of a tet
    the move would leave with a non-positive volume stay where they were. Returns (mesh, stats)."""
    surfaces = exact_surfaces(geometry, features)
    along = curve_surfaces(geometry, features, surfaces)
    points = mesh.points.copy()
    for level, table in (("patch", [[s] if s is not None else [] for s in surfaces]), ("curve", along)):
        nodes = np.flatnonzero((mesh.node_level == NODE_LEVELS.index(level)) & (mesh.node_entity >= 0))
        for entity in np.unique(mesh.node_entity[nodes]):
            if table[entity]:
                mine = nodes[mesh.node_entity[nodes] == entity]
                points[mine] = onto_intersection(table[entity], points[mine])
    kept = np.zeros(len(points), bool)
    while (bad := signed_volumes(points, mesh.tets) <= 0).any():   # ends: the input mesh has none
        back = np.unique(mesh.tets[bad])
        points[back], kept[back] = mesh.points[back], True
    distance = np.linalg.norm(points - mesh.points, axis=1)
    stats = {"exact_patches": sum(s is not None for s in surfaces), "patches": len(surfaces),
             "exact_curves": sum(bool(a) for a in along), "curves": len(along),
             "nodes_moved": int((distance > 0).sum()), "largest_move": float(distance.max(initial=0.0)),
             "nodes_kept_for_validity": int(kept.sum())}
    return dataclasses.replace(mesh, points=points), stats
