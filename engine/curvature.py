"""Radius of curvature of a solid's surface, per input face: the anchors of ``curvature`` patterns.

Normals at the vertices are the means of the face normals around them with Max's weights (exact on a
sphere), taken per smooth fan: faces that meet across an edge with a dihedral angle above the feature angle
(a crease, not curvature) do not share a vertex normal, so a cylinder's rim vertex has the cylinder's normal
on the cylinder's side and the end face's on the other. Each face's shape operator (2 x 2 in its plane) is
fitted by least squares to the change of those normals along its three edges (Rusinkiewicz 2004): exact on
a faceted cylinder (1 / r across the facets, 0 along them). Then smoothed: per fan, the mean of its faces'
operators (each turned into the fan's normal frame) weighted by area x shape quality; per face, the mean of
its three fans' (turned back), weighted by the fans' weights. So a sliver's ill-conditioned fit (0.06 mm
across, 15 mm long) counts for little, and a fan of slivers only for as little.

A face's radius is its chord radius: 1 / max(|k1|, |k2|, 2 |k1 + k2| / 3) of its smoothed operator's
principal curvatures k1, k2, concave (a hole, a fillet) or convex alike; planar faces, and faces curving less
than ``PLANAR`` x the model size, have none (inf). A triangle of edge h on the surface strays from it by
h^2 / (8 r) at most with r this radius: on a cylinder or a saddle it is the smaller principal radius (an edge
across the axis), on a doubly curved blend (both curvatures of one sign) up to 3/4 of it, as an equilateral
triangle's centre lies h^2 (k1 + k2) / 12 off the surface (h^2 / (6 r) on a sphere). A planar face along a
tangent fillet takes some of the fillet's curvature (about twice its radius). One radius per face: along a
cone's long facets it is the facet's, not its tip's. Measured once per geometry and feature angle
(:func:`curvature`), which gives the faces of a patch of known shape the shape's own radius instead (planes,
cylinders and tori fitted to an STL's facets; a CAD file's or built-in shape's cones, spheres and tori); the
faces are grouped in classes of like radius by :func:`engine.thickness.classes`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy import sparse
from scipy.sparse import csgraph

from .thickness import LocalPart, class_rows, classes

PLANAR = 10.0  # radii above this, times the model size, are planar (inf)
EDGE_PER_H = 1.1  # mean boundary edge / h of a packing (mean 1.07-1.11, knowledge/population.yaml calibration)
RAISE_STEP = 1.05  # per_circle is raised in steps of 5 % to meet a volume budget ...
MAX_RAISES = 2000  # ... at most this many steps over all classes


@dataclass
class Curvature:
    """The chord radius of each input face (inf where planar): the smaller principal radius, 3/4 of it on a
    sphere (see the module doc)."""

    triangles: np.ndarray  # (m, 3, 3) the input faces
    radius: np.ndarray  # (m,)
    mean: np.ndarray  # (m,) signed mean curvature (k1 + k2) / 2: > 0 convex (outward normals), 0 where planar

    def parts(self) -> list[LocalPart]:
        """The curved faces in classes of like radius, most curved first (ids ``radius-R``)."""
        return classes(self.triangles, self.radius, "radius")

    def raised_per_circle(self, volume: float, budget: float, per_circle: float, finest: float, size: float):
        """Elements per circle for each class of :meth:`parts` (by id) so that the predicted volume change of
        the chords on the faces the rule sizes is within ``budget`` x ``volume``, raised where it pays most;
        with the relative change before and after (signed).

        A straight-sided triangle of edge e inscribed in a surface of mean curvature k lies k e^2 / 8 inside it
        on average (exact on a sphere), so a class of radius L meshed at h = 2 pi L / n (within [finest, size];
        e = EDGE_PER_H h) changes the volume by -e^2 / 8 x the sum of area x k over its faces: convex faces lose
        volume, concave ones (holes, fillets) gain it. While the sum over the classes exceeds the budget, the
        class whose next step of RAISE_STEP removes the most change per added surface element (area / h^2) is
        raised: large convex radii first, small fillets last (they change the volume little for many
        elements). The rule answers for the classes it sizes (2 pi L / per_circle below ``size``): a face of
        larger radius is sized by ``size``, and so is a plane's faceting noise next to a fillet."""
        rows = class_rows(self.radius)
        if not rows:
            return {}, 0.0, 0.0
        ids = [part.id for part in self.parts()]
        length = np.array([r[0] for r in rows])
        weighted = np.array([(self.area[r[2]] * self.mean[r[2]]).sum() for r in rows])  # sum of area x k
        area = np.array([self.area[r[2]].sum() for r in rows])
        active = 2 * np.pi * length / per_circle < size  # the classes the rule sizes
        edge = lambda n: np.clip(2 * np.pi * length / n, finest, size) * EDGE_PER_H  # noqa: E731
        change = lambda n: -(np.where(active, weighted, 0.0) * edge(n) ** 2).sum() / 8 / volume  # noqa: E731
        n = np.full(len(rows), float(per_circle))
        before = change(n)
        for _ in range(MAX_RAISES):
            now = change(n)
            if abs(now) <= budget:
                break
            step = n[None, :] * np.where(np.eye(len(n), dtype=bool), RAISE_STEP, 1.0)  # one class raised per row
            gain = abs(now) - np.abs([change(row) for row in step])
            cost = area * (1 / edge(step.diagonal()) ** 2 - 1 / edge(n) ** 2)
            best = int(np.argmax(np.where(active & (cost > 0), gain / np.maximum(cost, 1e-300), -np.inf)))
            if not active[best] or gain[best] <= 0 or cost[best] <= 0:
                break  # no class left whose raise helps (each at its finest size, or the change from others)
            n[best] *= RAISE_STEP
        n = np.where(n > per_circle, np.ceil(n), per_circle)
        return {i: float(k) for i, k in zip(ids, n) if k > per_circle}, float(before), float(change(n))

    @property
    def area(self) -> np.ndarray:
        """(m,) area of each input face."""
        T = self.triangles
        return np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1) / 2


def curvature(geometry, features) -> Curvature:
    """The geometry's radius of curvature: measured (:func:`measure`) where its ``features`` know no shape, the
    shape's own on the faces of a patch that is planar or lies on a known cylinder, cone, sphere or torus (a CAD
    face's, a shape's, a cylinder or torus fitted to an STL's facets: the measure smears a narrow fillet's strip of long
    facets, r 1.5 read as 0.6 to 3.8); made on the first call per feature angle and kept with the geometry. Of
    an assembly (engine/cad.py ``Assembly``, whose union ``geometry`` is): every body's surface, each face
    once per body, the interfaces included: a bolt's shank in a plate's hole is no face of the union (its
    two sides' chords change the bodies' volumes, not the union's: their mean curvatures cancel)."""
    if features.assembly is not None:
        bodies = [curvature(body, body_features) for body, body_features in features.assembly.bodies]
        return Curvature(
            triangles=np.concatenate([b.triangles for b in bodies]),
            radius=np.concatenate([b.radius for b in bodies]),
            mean=np.concatenate([b.mean for b in bodies]),
        )
    cache = geometry.__dict__.setdefault("_curvature", {})
    if features.feature_angle not in cache:
        cache[features.feature_angle] = _known_shapes(
            measure(geometry.mesh, features.feature_angle), geometry, features
        )
    return cache[features.feature_angle]


def _known_shapes(measured: Curvature, geometry, features) -> Curvature:
    """``measured`` with the radius and mean curvature of every face of a patch of known shape replaced by the
    shape's at the face's centre (the mean's sign: convex where the face's outward normal leaves the shape's
    centre or axis)."""
    from .exact import CylinderSurface, Plane, Torus

    radius, mean = measured.radius.copy(), measured.mean.copy()
    mesh = geometry.mesh
    given = features.exact[0] if features.exact is not None else [None] * len(features.patches)
    for patch, surface in zip(features.patches, given):
        if not hasattr(surface, "curvatures"):  # a B-spline face's own closest point, or an STL's patch
            if patch.planar:
                surface = Plane(patch.centroid, patch.normal)
            elif patch.cylinder is not None:
                surface = CylinderSurface(patch.cylinder.point, patch.cylinder.axis, patch.cylinder.radius)
            elif patch.torus is not None:
                surface = Torus(patch.torus.centre, patch.torus.axis, patch.torus.major, patch.torus.minor)
            else:
                continue
        centres = mesh.triangles_center[patch.faces]
        k = surface.curvatures(centres)
        outward = np.sign(np.einsum("ij,ij->i", mesh.face_normals[patch.faces], surface.normals(centres)))
        chord = np.maximum(np.abs(k).max(axis=1), 2.0 / 3.0 * np.abs(k.sum(axis=1)))
        with np.errstate(divide="ignore"):
            radius[patch.faces] = np.where(chord * PLANAR * geometry.scale > 1, 1.0 / chord, np.inf)
        mean[patch.faces] = np.where(np.isfinite(radius[patch.faces]), outward * k.sum(axis=1) / 2, 0.0)
    return Curvature(measured.triangles, radius, mean)


def measure(mesh: trimesh.Trimesh, feature_angle: float = 30.0) -> Curvature:
    """Radius of curvature per face of the closed, outward-oriented surface ``mesh``; edges with a dihedral
    angle above ``feature_angle`` (degrees) are creases."""
    V, F = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)
    scale = float(np.linalg.norm(np.ptp(V, axis=0)))
    T = V[F]
    edges = np.roll(T, -1, axis=1) - T  # edges[:, i] = p[i + 1] - p[i]
    cross = np.cross(edges[:, 0], edges[:, 1])
    area = np.linalg.norm(cross, axis=1) / 2
    good = area > 1e-12 * scale**2
    normal = cross / np.where(good, 2 * area, 1.0)[:, None]
    fan, fans = _fans(mesh, feature_angle)  # fan of each corner (3 f + i)
    fan_normal = _fan_normals(fan, fans, edges, normal)
    corner_normal = fan_normal[fan].reshape(-1, 3, 3)
    t1 = edges[:, 0] / np.maximum(np.linalg.norm(edges[:, 0], axis=1), 1e-300)[:, None]
    frame = np.stack([t1, np.cross(normal, t1)], axis=2)  # (m, 3, 2): the face's plane
    own = np.zeros((len(F), 2, 2))
    own[good] = _fit(
        edges[good] @ frame[good], (np.roll(corner_normal, -1, axis=1) - corner_normal)[good] @ frame[good]
    )
    face = np.repeat(np.arange(len(F)), 3)
    turn = _rotations(normal[face], fan_normal[fan])  # per corner: face frame -> fan frame
    quality = 4 * np.sqrt(3) * area / np.maximum(np.einsum("fij,fij->f", edges, edges), 1e-300)  # 1: equilateral
    weight = np.repeat(np.where(good, area * quality, 0.0), 3)
    gather = sparse.csr_matrix((np.ones(len(fan)), (fan, np.arange(len(fan)))), shape=(fans, len(fan)))
    fan_weight = gather @ weight
    turned = weight[:, None, None] * (turn @ (frame @ own @ frame.transpose(0, 2, 1))[face] @ turn.transpose(0, 2, 1))
    fan_operator = (gather @ turned.reshape(-1, 9)).reshape(-1, 3, 3) / np.maximum(fan_weight, 1e-300)[:, None, None]
    corner_weight = fan_weight[fan].reshape(-1, 3, 1, 1)
    back = (turn.transpose(0, 2, 1) @ fan_operator[fan] @ turn).reshape(-1, 3, 3, 3)
    smooth = (back * corner_weight).sum(axis=1) / np.maximum(corner_weight.sum(axis=1), 1e-300)
    operator = frame.transpose(0, 2, 1) @ smooth @ frame
    with np.errstate(divide="ignore"):
        radius = np.where(good, 1.0 / _chord_curvature(operator), np.inf)
    radius[radius > PLANAR * scale] = np.inf
    mean = np.where(np.isfinite(radius), (operator[:, 0, 0] + operator[:, 1, 1]) / 2, 0.0)
    return Curvature(T, radius, mean)


def _fans(mesh: trimesh.Trimesh, feature_angle: float):
    """Label of every face corner (3 f + i): corners of one vertex joined across edges that are not creases."""
    F = mesh.faces
    smooth = mesh.face_adjacency_angles <= np.radians(feature_angle)
    a, b = mesh.face_adjacency[smooth].T
    shared = mesh.face_adjacency_edges[smooth]

    def corner(f, v):
        return 3 * f + np.argmax(F[f] == v[:, None], axis=1)

    rows = np.concatenate([corner(a, shared[:, 0]), corner(a, shared[:, 1])])
    cols = np.concatenate([corner(b, shared[:, 0]), corner(b, shared[:, 1])])
    n = 3 * len(F)
    fans, fan = csgraph.connected_components(
        sparse.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)), directed=False
    )
    return fan, fans


def _fan_normals(fan, fans, edges, normal):
    """Mean face normal of each fan with Max's weights (sin of the corner's angle over its two edges' lengths:
    exact at the vertices of triangles inscribed in a sphere), unit length."""
    before = -np.roll(edges, 1, axis=1)  # from corner i to p[i - 1]
    weight = (
        np.linalg.norm(np.cross(edges, before), axis=2)
        / np.maximum(np.einsum("fij,fij->fi", edges, edges) * np.einsum("fij,fij->fi", before, before), 1e-300)
    ).ravel()
    total = np.stack([np.bincount(fan, weight * np.repeat(normal[:, j], 3), minlength=fans) for j in range(3)], 1)
    return total / np.maximum(np.linalg.norm(total, axis=1), 1e-300)[:, None]


def _fit(edges: np.ndarray, change: np.ndarray) -> np.ndarray:
    """Symmetric S (m, 2, 2) with S e = dn in least squares over the three edges e (m, 3, 2) and normal
    changes dn (m, 3, 2): unknowns (S00, S01, S11)."""
    eu, ev = edges[..., 0], edges[..., 1]
    A = np.zeros((len(edges), 6, 3))
    A[:, :3, 0], A[:, :3, 1], A[:, 3:, 1], A[:, 3:, 2] = eu, ev, eu, ev
    y = np.concatenate([change[..., 0], change[..., 1]], axis=1)
    s = np.linalg.solve(A.transpose(0, 2, 1) @ A, (A.transpose(0, 2, 1) @ y[..., None]))[..., 0]
    return np.stack([s[:, [0, 1]], s[:, [1, 2]]], axis=1)


def _rotations(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotations (m, 3, 3) taking unit vectors a to b (Rodrigues)."""
    v = np.cross(a, b)
    K = np.zeros((len(a), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    K -= K.transpose(0, 2, 1)
    return np.eye(3) + K + K @ K / np.maximum(1.0 + np.einsum("ij,ij->i", a, b), 1e-12)[:, None, None]


def _chord_curvature(operator: np.ndarray) -> np.ndarray:
    """max(|k1|, |k2|, 2 |k1 + k2| / 3) of symmetric 2 x 2 matrices with eigenvalues k1, k2: the curvature whose
    h^2 / 8 bounds how far a triangle of edge h strays from the surface (the module doc)."""
    mean = (operator[:, 0, 0] + operator[:, 1, 1]) / 2
    largest = np.abs(mean) + np.hypot((operator[:, 0, 0] - operator[:, 1, 1]) / 2, operator[:, 0, 1])
    return np.maximum(largest, 4.0 / 3.0 * np.abs(mean))
