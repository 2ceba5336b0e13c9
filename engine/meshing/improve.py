"""Quality improvement after connection: Gmsh's tetrahedral optimiser, then targeted node relocation.

1. Gmsh's optimiser (edge and face swaps, node relocation) on the mesh loaded
   as discrete entities: boundary nodes sit on the boundary entity and are
   never moved; elements below ``Mesh.OptimizeThreshold`` (gamma, the radius
   ratio) are worked on.
2. What is left under the target is fixed by moving the nodes of each bad
   tetrahedron to the best of a few candidate places (star centroid,
   deterministic perturbations), judged by the worst element quality of the
   node's star, q = min(radius ratio, min dihedral / 70.53 deg) (1 for the
   regular tetrahedron); a move is kept only if it improves it. Volume nodes
   move freely, nodes of planar patches slide in their plane, curve and corner
   nodes stay. Nodes of curved patches stay too, but for a last pass on what
   is still under the target, where they slide in the plane of their input
   face and then go back onto the surface (sliding changes the surface's
   chords, so it is kept for the few elements single moves inside could not
   fix: on the 1M junction with the cylinder at the centre, a tet of three
   cylinder nodes and one volume node stayed at 14.0 deg without it).

The settings were chosen by measurement on the junction benchmark (bench/run.py cases,
10k, 100k and 1M tets, both cylinder positions), against Gmsh 4.15.2 HXT on the same
solid and sizes (min dihedral 13.7-15.7 deg, 1st percentile about 20 deg):

| Gmsh threshold | target | min dihedral (10k / 100k / 1M) | 1st pct, 1M | improvement s, 1M |
|---|---|---|---|---|
| 0.3 | 14 deg / 0.2 | 14.0 / 14.0 / 14.0 | 19.5 | 2.6 |
| 0.3 | 20 deg | 18.5-19.7 / 18.1 / 18.2-18.4 | 23.0 | 12.1-12.5 |
| 0.4 | 20 deg | 20.0 / 20.0 / 20.0 | 23.9 | 4.1-5.3 |
| 0.5 | 20 deg | 20.1 / 20.1 / 20.0 | 26.9-27.0 | 4.2-4.7 |

A wider Gmsh threshold lets its swaps repair what single-node moves cannot (at 0.3 the
relocation stalls short of 20 deg and takes three times longer).
"""
from __future__ import annotations

import numpy as np

from .._numba import numba
from ..mesh import FACES
from .tetra import gmsh_session, node_stars

GMSH_THRESHOLD = 0.5        # Gmsh optimises tets with gamma below this
REGULAR_DIHEDRAL = 70.528779365509308
TARGET = 20.0 / REGULAR_DIHEDRAL   # relocation works on tets with q below: min dihedral < 20 deg or radius ratio < 0.284
FLOOR = min(10.0 / REGULAR_DIHEDRAL, 0.15)   # the quality every element must reach
RELOCATION_PASSES = 6
CANDIDATES = 24             # perturbation directions per node and pass
STEPS = np.array([0.04, 0.12, 0.25])   # perturbation lengths, x the mean edge length of the star


def gmsh_optimize(points: np.ndarray, tets: np.ndarray, fixed: np.ndarray):
    """Gmsh's optimiser on the mesh; nodes with ``fixed`` set stay where they are.

    Returns (points, tets): node indices are kept; Gmsh may relocate free nodes.
    """
    import gmsh

    gmsh_session()
    gmsh.option.setNumber("Mesh.OptimizeThreshold", GMSH_THRESHOLD)
    gmsh.option.setNumber("Mesh.Renumber", 0)    # keep our node numbers as Gmsh's tags
    previous = gmsh.model.getCurrent() if gmsh.model.list() else None
    gmsh.model.add("fuzzymesh-optimize")
    try:
        surface = gmsh.model.addDiscreteEntity(2)
        volume = gmsh.model.addDiscreteEntity(3, -1, [surface])
        used = np.zeros(len(points), bool)
        used[tets.ravel()] = True
        for entity, dim, select in ((surface, 2, used & fixed), (volume, 3, used & ~fixed)):
            nodes = np.flatnonzero(select)
            gmsh.model.mesh.addNodes(dim, entity, (nodes + 1).tolist(), points[nodes].ravel().tolist())
        gmsh.model.mesh.addElementsByType(volume, 4, [], (tets + 1).ravel().tolist())
        gmsh.model.mesh.optimize("", force=True)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        _, nodes = gmsh.model.mesh.getElementsByType(4)
    finally:
        gmsh.model.remove()
        if previous:
            gmsh.model.setCurrent(previous)
    tags = np.asarray(tags, dtype=np.int64)
    if tags.max() > len(points):
        raise RuntimeError("Gmsh's optimiser added nodes")
    points = points.copy()
    points[tags - 1] = np.asarray(coords).reshape(-1, 3)
    return points, np.asarray(nodes, dtype=np.int64).reshape(-1, 4) - 1


def relocate(points: np.ndarray, tets: np.ndarray, slide: np.ndarray, seed: int = 0,
             target: float | None = None) -> tuple[np.ndarray, int]:
    """Move nodes of tets below the ``target`` quality (default TARGET) where that improves their stars.

    ``slide`` (n, 3) per node: NaN for a fixed node, zeros for a free one, a
    unit normal for a node that slides in a plane. Returns (points, number of
    moves). Deterministic for a seed.
    """
    points = np.ascontiguousarray(points, dtype=np.float64).copy()
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    slide = np.ascontiguousarray(slide, dtype=np.float64)
    star_start, star_tets = node_stars(tets, len(points))
    directions = np.random.default_rng(seed).normal(size=(CANDIDATES, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    movable = ~np.isnan(slide[:, 0])
    target = TARGET if target is None else target
    check = np.arange(len(tets))
    moves = 0
    for _ in range(RELOCATION_PASSES):
        bad = check[_below_quality(points, tets, check, target)]
        if len(bad) == 0:
            break
        candidates = np.unique(tets[bad].ravel())
        candidates = candidates[movable[candidates]]
        moved = _relocate_nodes(points, tets, star_start, star_tets, candidates, slide, directions, STEPS)
        moves += moved
        if moved == 0:
            break
        # only the stars of the nodes just worked on can have changed
        counts = star_start[candidates + 1] - star_start[candidates]
        offsets = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        check = np.unique(star_tets[np.repeat(star_start[candidates], counts) + offsets])
    return points, moves


def quality_below(points, tets, quality: float) -> np.ndarray:
    """Which tets have min(radius ratio, min dihedral / 70.53 deg) below ``quality``."""
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    return _below_quality(np.ascontiguousarray(points, dtype=np.float64), tets, np.arange(len(tets)), quality)


def peel_boundary_slivers(points, tets, boundary, patch, quality: float, removable=None):
    """Remove the tets below ``quality`` that lie flat between two boundary faces of one patch (or of
    two, across an edge of ``removable`` nodes: a smooth cut's), and those that lie flat under three
    boundary faces around a ``removable`` node.

    The first fills the fold between two surface triangles that share an edge; its two
    other faces become boundary instead (a surface edge flip across a flat tet, so the
    surface moves by less than the tet's thickness and every node stays on the boundary).
    A removal that would make an edge non-manifold (the flipped edge already on the
    boundary) is skipped. The second is the whole star of a surface node (three
    consecutive nodes of a smooth cut and a patch node beside them): its fourth face
    becomes boundary and the node leaves the mesh. Returns (tets, boundary, patch,
    removed count); the number of bad tets is small, so they are taken one by one.
    """
    bad = np.flatnonzero(quality_below(points, tets, quality))
    if not len(bad):
        return tets, boundary, patch, 0
    faces = {tuple(sorted(f)): k for k, f in enumerate(boundary.tolist())}
    edges = {}
    for f in boundary.tolist():
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            edges[(min(a, b), max(a, b))] = edges.get((min(a, b), max(a, b)), 0) + 1
    drop, gone, added, added_patch = [], set(), [], []
    degree = np.bincount(boundary.ravel(), minlength=len(points))
    for t in bad:
        own = tets[t][FACES]                              # outward faces of the tet
        on_boundary = [faces.get(tuple(sorted(f))) for f in own.tolist()]
        hits = [k for k in on_boundary if k is not None]
        if len(hits) == 3 and removable is not None and max(hits) < len(boundary) and not gone & set(hits):
            opposite = [k is None for k in on_boundary].index(True)
            apex = tets[t][opposite]                      # the node all three boundary faces share
            if removable[apex] and degree[apex] == 3:
                drop.append(t)
                gone.update(hits)
                face = own[opposite][::-1]
                np.subtract.at(degree, boundary[hits].ravel(), 1)
                np.add.at(degree, face, 1)
                faces[tuple(sorted(face.tolist()))] = len(boundary) + len(added)
                added.append(face)
                added_patch.append(np.bincount(patch[hits]).argmax())
            continue
        if len(hits) != 2 or max(hits) >= len(boundary) or gone & set(hits):
            continue                                      # (faces made boundary or gone here are left alone)
        inner = own[[k is None for k in on_boundary]]     # the two faces that become boundary
        shared = set(boundary[hits[0]].tolist()) & set(boundary[hits[1]].tolist())
        across_cut = removable is not None and all(removable[v] for v in shared)   # a smooth cut's edge
        if patch[hits[0]] != patch[hits[1]] and not across_cut:
            continue
        flipped = tuple(sorted(set(tets[t].tolist()) - shared))
        if len(shared) != 2 or edges.get(flipped, 0):
            continue
        drop.append(t)
        gone.update(hits)
        edges[flipped] = 2
        edges[tuple(sorted(shared))] = 0
        np.subtract.at(degree, boundary[hits].ravel(), 1)
        np.add.at(degree, inner.ravel(), 1)
        for f in inner[:, ::-1]:                          # reversed: outward for the remaining mesh
            faces[tuple(sorted(f.tolist()))] = len(boundary) + len(added)
            added.append(f)
            added_patch.append(patch[hits[0]])
    if not drop:
        return tets, boundary, patch, 0
    keep = np.ones(len(boundary), bool)
    keep[list(gone)] = False
    boundary = np.vstack([boundary[keep], np.array(added, dtype=boundary.dtype)])
    patch = np.concatenate([patch[keep], np.array(added_patch, dtype=patch.dtype)])
    return np.delete(tets, drop, axis=0), boundary, patch, len(drop)


def min_dihedrals(points, tets) -> np.ndarray:
    """Minimum dihedral angle (degrees) of every tet; -1 for inverted or flat ones."""
    return _min_dihedrals(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(tets, dtype=np.int64))


@numba.njit(parallel=True, cache=True, error_model="numpy")
def _min_dihedrals(points, tets):
    out = np.empty(len(tets))
    for t in numba.prange(len(tets)):
        out[t] = _min_dihedral(points[tets[t, 0]], points[tets[t, 1]], points[tets[t, 2]], points[tets[t, 3]])
    return out


@numba.njit(parallel=True, cache=True, error_model="numpy")
def _below_quality(points, tets, rows, quality):
    """Which of the tets ``rows`` have _quality below ``quality``."""
    out = np.empty(len(rows), dtype=np.bool_)
    for i in numba.prange(len(rows)):
        t = rows[i]
        out[i] = _quality(points[tets[t, 0]], points[tets[t, 1]], points[tets[t, 2]], points[tets[t, 3]]) < quality
    return out


@numba.njit(inline="always", error_model="numpy")
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@numba.njit(cache=True, error_model="numpy")
def _shape(a, b, c, d):
    """(6 x volume, the largest cosine between outward face normals' opposites, radius ratio)."""
    ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    vx, vy, vz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    wx, wy, wz = d[0] - a[0], d[1] - a[1], d[2] - a[2]
    vw = _cross(vx, vy, vz, wx, wy, wz)
    six_volume = ux * vw[0] + uy * vw[1] + uz * vw[2]
    if six_volume <= 0.0:
        return six_volume, 1.0, 0.0
    # outward normals (area x 2) of the faces opposite a, b, c, d
    n0 = _cross(d[0] - b[0], d[1] - b[1], d[2] - b[2], c[0] - b[0], c[1] - b[1], c[2] - b[2])
    n1 = vw
    n2 = _cross(wx, wy, wz, ux, uy, uz)
    n3 = _cross(ux, uy, uz, vx, vy, vz)
    normals = (n0, n1, n2, n3)
    lengths = (np.sqrt(n0[0] ** 2 + n0[1] ** 2 + n0[2] ** 2), np.sqrt(n1[0] ** 2 + n1[1] ** 2 + n1[2] ** 2),
               np.sqrt(n2[0] ** 2 + n2[1] ** 2 + n2[2] ** 2), np.sqrt(n3[0] ** 2 + n3[1] ** 2 + n3[2] ** 2))
    largest = -1.0
    for i in range(4):
        for j in range(i + 1, 4):
            cosine = -(normals[i][0] * normals[j][0] + normals[i][1] * normals[j][1]
                       + normals[i][2] * normals[j][2]) / (lengths[i] * lengths[j])
            largest = max(largest, cosine)
    area2 = lengths[0] + lengths[1] + lengths[2] + lengths[3]        # twice the surface area
    r_in = six_volume / area2
    uu, vv, ww = ux * ux + uy * uy + uz * uz, vx * vx + vy * vy + vz * vz, wx * wx + wy * wy + wz * wz
    wu = _cross(wx, wy, wz, ux, uy, uz)
    uv = n3
    cx = uu * vw[0] + vv * wu[0] + ww * uv[0]
    cy = uu * vw[1] + vv * wu[1] + ww * uv[1]
    cz = uu * vw[2] + vv * wu[2] + ww * uv[2]
    r_circ = np.sqrt(cx * cx + cy * cy + cz * cz) / (2 * six_volume)
    return six_volume, largest, 3 * r_in / r_circ


@numba.njit(cache=True, error_model="numpy")
def _min_dihedral(a, b, c, d):
    """Minimum dihedral angle in degrees, -1 when the tet is inverted or flat."""
    six_volume, largest, _ = _shape(a, b, c, d)
    if six_volume <= 0.0:
        return -1.0
    return np.degrees(np.arccos(min(1.0, largest)))


@numba.njit(cache=True, error_model="numpy")
def _quality(a, b, c, d):
    """min(radius ratio, min dihedral / regular dihedral): 1 for the regular tet, -1 for an inverted one."""
    six_volume, largest, radius_ratio = _shape(a, b, c, d)
    if six_volume <= 0.0:
        return -1.0
    return min(radius_ratio, np.degrees(np.arccos(min(1.0, largest))) / REGULAR_DIHEDRAL)


@numba.njit(cache=True, error_model="numpy")
def _star_quality(points, tets, star, node, position):
    worst = 1.0
    q = np.empty((4, 3))
    for t in star:
        for k in range(4):
            v = tets[t, k]
            q[k] = position if v == node else points[v]
        worst = min(worst, _quality(q[0], q[1], q[2], q[3]))
    return worst


@numba.njit(cache=True, error_model="numpy")
def _relocate_nodes(points, tets, star_start, star_tets, nodes, slide, directions, steps):
    moved = 0
    for node in nodes:
        star = star_tets[star_start[node]:star_start[node + 1]]
        here = points[node].copy()
        normal = slide[node]
        best = _star_quality(points, tets, star, node, here)
        centre = np.zeros(3)
        count = 0
        edge = 0.0
        for t in star:
            for k in range(4):
                v = tets[t, k]
                if v != node:
                    centre += points[v]
                    edge += np.sqrt(np.sum((points[v] - here) ** 2))
                    count += 1
        centre /= count
        edge /= count
        best_position = here.copy()
        trial = centre - np.dot(centre - here, normal) * normal
        q = _star_quality(points, tets, star, node, trial)
        if q > best:
            best, best_position = q, trial
        for s in steps:
            for k in range(len(directions)):
                step = directions[k] - np.dot(directions[k], normal) * normal
                trial = here + s * edge * step
                q = _star_quality(points, tets, star, node, trial)
                if q > best:
                    best, best_position = q, trial
        if np.any(best_position != here):
            points[node] = best_position
            moved += 1
    return moved
