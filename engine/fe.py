"""What an FE analyst needs beyond the elements: named groups of the model's features, and
quadratic tetrahedra whose boundary follows the surface.

Groups: ``solid`` (every tetrahedron), ``solid-1``, ``solid-2``, ... (the tetrahedra of each body,
where the surface holds several; an assembly's bodies named from the CAD file where it names them), an
assembly's interfaces ``interface-<a>-<b>`` (the triangles two bodies share), one per surface patch (its
name, or its id such as ``patch-3``) with its boundary triangles, one per named or unnamed feature curve with
its mesh edges, one per named corner. They become physical groups in ``.msh``, node sets, element sets and
element-face surfaces in Abaqus ``.inp``, and element groups (the solids only) in ``.med``.

Every boundary face is a face of exactly one tetrahedron (:func:`tet_boundary`), outward, with that
tet's edge mid-nodes; its patch is the mesher's for the same triangle, so a group never names a
triangle the tets split along the other diagonal.
"""

from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from .exact import ExactSurfaces, fit_exact, onto_intersection
from .levels import CORNER, CURVE
from .mesh import FACES, TetMesh
from .quadratic import QUADRATIC_FLOOR, scaled_jacobian

TET10_EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])  # VTK / meshio / Abaqus C3D10 order
# (4, 6) per side k of a tet (FACES[k]): its corners and its edges' mid-nodes, 10-node local indices in triangle6 order
SIDE_NODES = np.array(
    [[*f, *(4 + TET10_EDGES.tolist().index(sorted((f[i], f[(i + 1) % 3]))) for i in range(3))] for f in FACES.tolist()]
)
BISECTION_STEPS = 8  # the fraction of its curving a mid-edge node keeps is found to 1 / 2**8


@dataclass
class Group:
    """A named set of mesh entities: tets (dim 3), boundary triangles (2), curve edges (1) or corner nodes (0)."""

    name: str
    dim: int
    cells: np.ndarray  # (k,) tet indices for dim 3; (k, 3), (k, 2), (k, 1) node indices below

    @property
    def nodes(self) -> np.ndarray:
        return np.unique(self.cells) if self.dim < 3 else np.array([], np.int64)


def tet_bodies(mesh: TetMesh, geometry) -> np.ndarray:
    """The body (0-based, as ``geometry.face_body``) of every tet: the mesher's (``mesh.body``, an assembly's)
    where it knows it.

    Else tets joined through shared nodes form one piece; a piece belongs to the body whose surface is
    closest to the centroid of its largest tet (a point inside a body is closer to that body's own
    surface than to any other).
    """
    if mesh.body is not None:
        return np.asarray(mesh.body, np.int64)
    if geometry.bodies == 1:
        return np.zeros(len(mesh.tets), np.int64)
    n, first = len(mesh.points), np.repeat(mesh.tets[:, 0], 3)
    graph = sparse.coo_matrix((np.ones(len(first)), (first, mesh.tets[:, 1:].ravel())), shape=(n, n))
    piece = csgraph.connected_components(graph, directed=False)[1][mesh.tets[:, 0]]
    order = np.lexsort((-mesh.volumes(), piece))
    largest = order[np.r_[0, np.flatnonzero(np.diff(piece[order])) + 1]]  # per piece, ascending
    face = geometry.closest_point(mesh.points[mesh.tets[largest]].mean(axis=1))[2]
    return geometry.face_body[face][np.searchsorted(piece[largest], piece)]


def feature_groups(mesh: TetMesh, features, body: np.ndarray | None = None) -> list[Group]:
    """The solid, its bodies (``body``: 0-based per tet, from :func:`tet_bodies`; named as an assembly names
    them, else ``solid-N``), an assembly's interfaces (``mesh.interfaces``: the triangles two bodies share),
    patches, curves and corners as groups (see the module doc); patches, curves and corners only where the
    mesh has a tagged boundary."""
    groups = [Group("solid", 3, np.arange(len(mesh.tets)))]
    if body is not None and body.max(initial=0) > 0:
        assembly = getattr(features, "assembly", None)
        names = assembly.names if assembly is not None else [f"solid-{b + 1}" for b in range(body.max() + 1)]
        groups += [Group(names[b], 3, np.flatnonzero(body == b)) for b in range(body.max() + 1)]
    groups += [Group(name, 2, np.asarray(t, np.int64)) for name, t in mesh.interfaces.items() if len(t)]
    if len(mesh.boundary) == 0:
        return groups
    owner, side, face_patch = tet_boundary(mesh)
    faces = side_cells(mesh.tets, owner, side)
    for p, patch in enumerate(features.patches):
        if (face_patch == p).any():
            for name in _names(patch):
                groups.append(Group(name, 2, faces[face_patch == p]))
    edges, curve = curve_edges(mesh, features, faces)
    for c, feature in enumerate(features.curves):
        if (curve == c).any():
            for name in _names(feature):
                groups.append(Group(name, 1, edges[curve == c]))
    corner_nodes = np.flatnonzero(mesh.node_level == CORNER)
    for node in corner_nodes:
        feature = features.corners[mesh.node_entity[node]]
        if feature.names:
            for name in feature.names:
                groups.append(Group(name, 0, np.array([[node]])))
    return _merge_same_names(groups)


def _names(feature) -> list[str]:
    return list(feature.names) or [feature.id]


def _merge_same_names(groups: list[Group]) -> list[Group]:
    """One group per (name, dim): a name on several features of one kind unites them."""
    merged: dict = {}
    for group in groups:
        key = (group.name, group.dim)
        merged[key] = (
            group
            if key not in merged
            else Group(group.name, group.dim, np.concatenate([merged[key].cells, group.cells]))
        )
    names = [name for name, _ in merged]
    return [
        g
        if names.count(g.name) == 1
        else Group(f"{g.name}-{('corner', 'curve', 'surface', 'solid')[g.dim]}", g.dim, g.cells)
        for g in merged.values()
    ]


def tet_boundary(mesh: TetMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The faces of one tet only, (owner (t,), side (t,), patch (t,)), sorted by patch: face k is
    ``mesh.tets[owner[k], FACES[side[k]]]``, outward.

    Its patch is the mesher's (``mesh.boundary_patch``) for the same triangle, else, where the tets split a
    quad of the surface along the other diagonal than the mesher's triangles, that of the mesher's
    triangle nearest its centroid; -1 where the mesh has no tagged boundary.
    """
    owner, side = mesh.boundary_sides()
    faces = side_cells(mesh.tets, owner, side)
    if len(mesh.boundary) == 0:
        return owner, side, np.full(len(owner), -1, np.int64)
    row = row_index(np.sort(mesh.boundary, axis=1), np.sort(faces, axis=1))
    patch = mesh.boundary_patch[row]
    other = np.flatnonzero(row < 0)
    if len(other):
        centroids = mesh.points[faces[other]].mean(axis=1)
        nearest = igl.point_mesh_squared_distance(centroids, mesh.points, mesh.boundary.astype(np.int64))[1]
        patch[other] = mesh.boundary_patch[nearest]
    order = np.argsort(patch, kind="stable")
    return owner[order], side[order], patch[order]


def side_cells(tets: np.ndarray, owner: np.ndarray, side: np.ndarray) -> np.ndarray:
    """The boundary cells (t, 3) of 4-node ``tets`` or (t, 6) triangle6 of 10-node ``tets`` (m, 10) on
    sides ``side`` of tets ``owner`` (from :func:`tet_boundary`), outward."""
    return tets[owner[:, None], SIDE_NODES[side, : 3 if tets.shape[1] == 4 else 6]]


def curve_edges(mesh: TetMesh, features, faces: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Boundary edges that lie on feature curves, and the curve index of each; ``faces`` (t, 3) the
    tets' boundary faces if already at hand."""
    if len(mesh.boundary) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64)
    faces = mesh.boundary_faces() if faces is None else faces
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    edges = directed[directed[:, 0] < directed[:, 1]]
    on_curve = np.isin(mesh.node_level[edges], (CORNER, CURVE)).all(axis=1)
    edges = edges[on_curve]
    level, entity = mesh.node_level[edges], mesh.node_entity[edges]
    curve = np.where(level[:, 0] == CURVE, entity[:, 0], np.where(level[:, 1] == CURVE, entity[:, 1], -1))
    # an edge from corner to corner belongs to the curve that runs between those two corners
    corner_vertex = np.array([c.vertex for c in features.corners], dtype=np.int64)
    ends = {}
    for index, c in enumerate(features.curves):
        if c.vertices is not None and not c.closed and len(c.vertices) > 1:
            ends.setdefault(tuple(sorted((int(c.vertices[0]), int(c.vertices[-1])))), index)
    for row in np.flatnonzero(curve < 0):
        key = tuple(sorted(corner_vertex[entity[row]].tolist()))
        curve[row] = ends.get(key, -1)
    # both nodes on the same curve, a corner only where it ends the curve: a chord of the curve, not a
    # diagonal across a patch from a corner that ends another curve
    corner_of_vertex = {int(v): k for k, v in enumerate(corner_vertex)}
    curves = len(features.curves)
    end_keys = np.array(
        [
            corner_of_vertex[int(v)] * curves + index
            for index, c in enumerate(features.curves)
            if c.vertices is not None and len(c.vertices)
            for v in (c.vertices[0], c.vertices[-1])
            if int(v) in corner_of_vertex
        ],
        dtype=np.int64,
    )
    ends_curve = np.isin(entity * curves + curve[:, None], end_keys)
    same = np.where(level == CURVE, entity == curve[:, None], ends_curve)
    keep = (curve >= 0) & same.all(axis=1)
    return edges[keep], curve[keep]


def quadratic(
    mesh: TetMesh,
    geometry,
    features,
    floor: float = QUADRATIC_FLOOR,
    boundary: tuple | None = None,
    exact: ExactSurfaces | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ten-node tetrahedra: (points, tets10 in TET10_EDGES order, boundary triangle6 (t, 6) of :func:`tet_boundary`;
    ``boundary``: its (owner, side, patch) if already at hand, else computed; ``exact``: the solid's fitted exact
    surfaces (:func:`engine.exact.fit_exact`, as the pipeline's exact stage returns them), else fitted here).

    Mid-edge nodes of boundary edges are moved onto the exact surface of their patch where it has one
    (:mod:`engine.exact`: a plane, cylinder, sphere or cone), else onto the input surface; a curve's chords onto
    the exact intersection of the patches it borders, else onto the curve; a smooth cut's chords as a patch's.
    Where an element's scaled Jacobian would fall below ``floor`` its mid-edge nodes move
    only part of the way (:func:`limit_curving`).
    """
    owner, side, patch = boundary if boundary is not None else tet_boundary(mesh)
    unique, tets10, triangles6 = quadratic_elements(mesh, (owner, side))
    straight = mesh.points[unique].mean(axis=1)
    curved = straight.copy()
    on_boundary = np.unique(triangles6[:, 3:]) - len(mesh.points)
    if len(on_boundary):
        curved[on_boundary] = geometry.closest_point(straight[on_boundary])[0]
    surfaces, along = fit_exact(geometry, features) if exact is None else exact
    for p in np.unique(patch[patch >= 0]):
        if surfaces[p] is not None:
            rows = np.unique(triangles6[patch == p, 3:]) - len(mesh.points)
            curved[rows] = surfaces[p].project(straight[rows])
    chords, curve = curve_edges(mesh, features, triangles6[:, :3])
    chord_row = row_index(unique, np.sort(chords, axis=1))
    for c in np.unique(curve):
        if not features.curves[c].sharp:  # a smooth cut's chords stay curved onto a patch's surface, as its nodes
            continue  # (engine/exact.py: they slide over the surface, off the curve)
        rows = chord_row[(curve == c) & (chord_row >= 0)]
        if along[c]:
            curved[rows] = onto_intersection(along[c], straight[rows])
        else:
            curved[rows] = features.curves[c].point_at(features.curves[c].parameter(straight[rows]))
    points = limit_curving(np.vstack([mesh.points, straight]), np.vstack([mesh.points, curved]), tets10, floor)
    return points, tets10, triangles6


def quadratic_elements(mesh: TetMesh, boundary: tuple | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 10-node connectivity of a linear mesh: (unique edges (e, 2), tets10 (m, 10), boundary triangle6
    (t, 6) on the sides ``boundary`` = (owner, side) of :func:`tet_boundary`, computed if not given).

    Mid-edge node k of the quadratic mesh is ``len(mesh.points) + k``, on edge ``unique[k]``.
    """
    edges = np.sort(mesh.tets[:, TET10_EDGES].reshape(-1, 2), axis=1)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    tets10 = np.hstack([mesh.tets, len(mesh.points) + inverse.reshape(-1, 6)])
    owner, side = boundary if boundary is not None else tet_boundary(mesh)[:2]
    return unique, tets10, side_cells(tets10, owner, side)


def limit_curving(
    straight: np.ndarray, curved: np.ndarray, tets10: np.ndarray, floor: float = QUADRATIC_FLOOR
) -> np.ndarray:
    """Node positions (n, 3) from ``straight`` (n, 3) toward ``curved`` (n, 3) that keep every element of
    ``tets10`` (m, 10) at a scaled Jacobian of at least ``floor`` (straight elements have 1).

    Each moved node goes the fraction of the way found by bisection (BISECTION_STEPS): the last one at which
    every element around it was at the floor; a node still in an element below it ends straight.
    """
    moved = np.flatnonzero((curved != straight).any(axis=1))
    local = np.full(len(straight), -1)
    local[moved] = np.arange(len(moved))
    lo, hi, fraction = np.zeros(len(moved)), np.ones(len(moved)), np.ones(len(moved))

    def placed(fraction):
        points = straight.copy()
        points[moved] += fraction[:, None] * (curved[moved] - straight[moved])
        return points

    def below(fraction, elements):
        """(len(moved),) which moved nodes are in one of ``elements`` under the floor."""
        bad = local[tets10[elements[scaled_jacobian(placed(fraction), tets10[elements]) < floor]]]
        mask = np.zeros(len(moved), bool)
        mask[bad[bad >= 0]] = True
        return mask

    near = np.flatnonzero((local[tets10] >= 0).any(axis=1))  # the elements whose shape changes
    bad = below(fraction, near)
    if not bad.any():
        return curved.copy()
    around = local[tets10[near]]
    near = near[((around >= 0) & bad[around]).any(axis=1)]  # from here on, only those around nodes cut back
    for _ in range(BISECTION_STEPS):
        hi, lo = np.where(bad, fraction, hi), np.where(bad, lo, fraction)
        fraction = (lo + hi) / 2
        bad = below(fraction, near)
    fraction = np.where(bad, lo, fraction)
    while (bad := below(fraction, near)).any():
        fraction[bad] = 0
    return placed(fraction)


def row_index(table: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Index into ``table`` of each of ``rows`` (node tuples, each sorted the same way), -1 where absent."""
    if len(table) == 0 or len(rows) == 0:
        return np.full(len(rows), -1, np.int64)
    n = int(max(table.max(), rows.max())) + 1

    def key(a):
        k = np.zeros(len(a), np.int64)
        for column in a.T:
            k = k * n + column
        return k

    table_keys = key(table)
    order = np.argsort(table_keys)
    at = np.clip(np.searchsorted(table_keys[order], key(rows)), 0, len(table) - 1)
    return np.where(table_keys[order][at] == key(rows), order[at], -1)
