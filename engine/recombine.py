"""Tetrahedra recombined into hexahedra, prisms and pyramids: the hex-dominant mesh (issue 23).

After Yamakawa & Shimada (IJNME 57, 2003) and Botella, Lévy & Ray ("Indirect unstructured hex-dominant mesh
generation using tetrahedra recombination", 2016): every set of 8 nodes that makes a cube-like hexahedron from
the tet mesh's edges is a candidate, whatever the tets inside it (the 5- and 6-tet patterns and any other,
slivers included); so is every 6-node prism. A candidate is kept when

- its tets (those whose four nodes are all its nodes) fill it exactly: their faces used once are two
  triangles on each quad face (meeting along a diagonal of it) and one on each triangular face, and
- it is valid: the scaled Jacobian at every corner (the determinant of the three unit edge vectors there,
  x 2/sqrt(3) for a prism's corners, as Verdict) is at least the floor ``min_quality``.

Hexahedra are then taken greedily by quality (each tet in one element), then prisms among the tets left. The
mesh stays conforming: a quad face of a hexahedron or prism is a face of two of them with the same four nodes,
or on the boundary, or the base of a pyramid made of the two tets behind it (they must share their fourth node
and belong to nothing else); where none of these holds the element is dissolved back into its tets, until no
quad face is left hanging. The rest stays tetrahedra.

Candidates come from each node's edges: three edges at a corner, roughly at right angles (the cosines of
their angles within ``CORNER_COSINE``), give the hexahedron's other corners as the common neighbours nearest to
where a parallelepiped would put them. Kernels are numba (one pass over the nodes for the candidates, one over
the candidates for the checks); selection and the conformity rounds are numpy.

Node orders are meshio's (VTK's hexahedron and pyramid, Gmsh's prism: the first triangle's normal points to
the second, as Abaqus' C3D6).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ._numba import numba
from .mesh import FACES, signed_volumes

CORNER_COSINE = 0.5  # |cos| of the angle between two of a candidate corner's edges (60-120 deg)
PLANAR = 1e-9  # a boundary quad's warp (6 x the volume of its four nodes) over its diagonal cubed
REGULAR = 0.9  # cells of scaled Jacobian above this are chosen first (a lattice's boxes)
MAX_TETS = 16  # tets in one candidate at most (5-7 in practice)
HEX, PRISM, PYRAMID, TET = 0, 1, 2, 3
CELL_TYPES = ("hexahedron", "wedge", "pyramid", "tetra")
SIZES = (8, 6, 5, 4)

# corners: (node, its three edge neighbours in right-handed order)
HEX_CORNERS = np.array(
    [[0, 1, 3, 4], [1, 2, 0, 5], [2, 3, 1, 6], [3, 0, 2, 7], [4, 7, 5, 0], [5, 4, 6, 1], [6, 5, 7, 2], [7, 6, 4, 3]]
)
PRISM_CORNERS = np.array([[0, 1, 2, 3], [1, 2, 0, 4], [2, 0, 1, 5], [3, 5, 4, 0], [4, 3, 5, 1], [5, 4, 3, 2]])
PYRAMID_CORNERS = np.array([[0, 1, 3, 4], [1, 2, 0, 4], [2, 3, 1, 4], [3, 0, 2, 4]])
# faces, outward (meshio / VTK order): quads as 4 nodes, triangles with -1 last
HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
PRISM_FACES = np.array([[0, 2, 1, -1], [3, 4, 5, -1], [0, 1, 4, 3], [1, 2, 5, 4], [2, 0, 3, 5]])
PYRAMID_FACES = np.array([[0, 3, 2, 1], [0, 1, 4, -1], [1, 2, 4, -1], [2, 3, 4, -1], [3, 0, 4, -1]])
TET_FACES = np.c_[FACES, np.full(4, -1)]
CELL_FACES = (HEX_FACES, PRISM_FACES, PYRAMID_FACES, TET_FACES)
TET_CORNERS = np.array([[0, 1, 2, 3], [1, 2, 0, 3], [2, 0, 1, 3], [3, 0, 2, 1]])
CORNERS = (HEX_CORNERS, PRISM_CORNERS, PYRAMID_CORNERS, TET_CORNERS)
SCALE = (1.0, 2.0 / np.sqrt(3.0), np.sqrt(2.0), np.sqrt(2.0))  # corner determinants of the ideal cell -> 1


@dataclass
class MixedMesh:
    """Cells of four types: ``cells[k]`` (c, SIZES[k]) of type CELL_TYPES[k] (meshio's names and node orders), over
    the tet mesh's nodes and, after them, one centre node per element split to its centroid; ``parents[k]`` (c,)
    the tet of the tet mesh each cell takes its audit row from (its largest tet, or the largest of the element
    it was split from)."""

    points: np.ndarray
    cells: list
    parents: list
    stats: dict = field(default_factory=dict)

    def volumes(self) -> list[np.ndarray]:
        return [cell_volumes(self.points, c, k) for k, c in enumerate(self.cells)]

    def qualities(self) -> list[np.ndarray]:
        return [cell_qualities(self.points, c, k) for k, c in enumerate(self.cells)]


@numba.njit(cache=True)
def _common_nearest(start, adjacency, a, b, exclude, target, points):
    """The common neighbour of nodes a and b (not in ``exclude``) nearest to ``target``, or -1."""
    best, best_d = -1, np.inf
    for i in range(start[a], start[a + 1]):
        c = adjacency[i]
        skip = False
        for e in exclude:
            if c == e:
                skip = True
        if skip:
            continue
        found = False
        for j in range(start[b], start[b + 1]):
            if adjacency[j] == c:
                found = True
                break
        if not found:
            continue
        d = (points[c, 0] - target[0]) ** 2 + (points[c, 1] - target[1]) ** 2 + (points[c, 2] - target[2]) ** 2
        if d < best_d:
            best, best_d = c, d
    return best


@numba.njit(cache=True)
def _adjacent(start, adjacency, a, b):
    for j in range(start[a], start[a + 1]):
        if adjacency[j] == b:
            return True
    return False


@numba.njit(cache=True)
def _corner_det(points, o, a, b, c):
    """det of the unit vectors o->a, o->b, o->c."""
    u = points[a] - points[o]
    v = points[b] - points[o]
    w = points[c] - points[o]
    nu, nv, nw = np.sqrt((u * u).sum()), np.sqrt((v * v).sum()), np.sqrt((w * w).sum())
    if nu == 0 or nv == 0 or nw == 0:
        return -1.0
    det = u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) + u[2] * (v[0] * w[1] - v[1] * w[0])
    return det / (nu * nv * nw)


@numba.njit(cache=True)
def cell_quality(points, nodes, corners, scale):
    """The smallest scaled corner Jacobian of one cell (``corners`` its table, e.g. HEX_CORNERS)."""
    q = np.inf
    for k in range(corners.shape[0]):
        d = scale * _corner_det(
            points, nodes[corners[k, 0]], nodes[corners[k, 1]], nodes[corners[k, 2]], nodes[corners[k, 3]]
        )
        q = min(q, min(d, 1.0))
    return q


@numba.njit(cache=True)
def _hex_candidates(points, start, adjacency, cosine):
    n = len(start) - 1
    capacity = 4 * n + 16
    out = np.empty((capacity, 8), np.int64)
    count = 0
    exclude = np.empty(4, np.int64)
    for v in range(n):
        lo, hi = start[v], start[v + 1]
        for i in range(lo, hi):
            p = adjacency[i]
            if p < v:
                continue
            ep = points[p] - points[v]
            ep /= np.sqrt((ep * ep).sum())
            for j in range(i + 1, hi):
                q = adjacency[j]
                if q < v:
                    continue
                eq = points[q] - points[v]
                eq /= np.sqrt((eq * eq).sum())
                if abs((ep * eq).sum()) > cosine:
                    continue
                for k in range(j + 1, hi):
                    r = adjacency[k]
                    if r < v:
                        continue
                    er = points[r] - points[v]
                    er /= np.sqrt((er * er).sum())
                    if abs((ep * er).sum()) > cosine or abs((eq * er).sum()) > cosine:
                        continue
                    det = ep[0] * (eq[1] * er[2] - eq[2] * er[1]) - ep[1] * (eq[0] * er[2] - eq[2] * er[0])
                    det += ep[2] * (eq[0] * er[1] - eq[1] * er[0])
                    a, b, c = p, q, r
                    if det < 0:
                        b, c = r, q
                    exclude[0], exclude[1], exclude[2], exclude[3] = v, a, b, c
                    ab = _common_nearest(start, adjacency, a, b, exclude, points[a] + points[b] - points[v], points)
                    ac = _common_nearest(start, adjacency, a, c, exclude, points[a] + points[c] - points[v], points)
                    bc = _common_nearest(start, adjacency, b, c, exclude, points[b] + points[c] - points[v], points)
                    if ab < v or ac < v or bc < v or ab == ac or ab == bc or ac == bc:
                        continue
                    far = _common_nearest(
                        start, adjacency, ab, ac, exclude, points[a] + points[b] + points[c] - 2 * points[v], points
                    )
                    if far < v or far == bc or not _adjacent(start, adjacency, far, bc):
                        continue
                    if count == capacity:
                        grown = np.empty((2 * capacity, 8), np.int64)
                        grown[:count] = out[:count]
                        out, capacity = grown, 2 * capacity
                    out[count, 0], out[count, 1], out[count, 2], out[count, 3] = v, a, ab, b
                    out[count, 4], out[count, 5], out[count, 6], out[count, 7] = c, ac, far, bc
                    count += 1
    return out[:count]


@numba.njit(cache=True)
def _prism_candidates(points, start, adjacency, cosine):
    n = len(start) - 1
    capacity = 4 * n + 16
    out = np.empty((capacity, 6), np.int64)
    count = 0
    exclude = np.empty(4, np.int64)
    for v in range(n):
        lo, hi = start[v], start[v + 1]
        for i in range(lo, hi):
            p = adjacency[i]
            if p < v:
                continue
            for j in range(i + 1, hi):
                q = adjacency[j]
                if q < v or not _adjacent(start, adjacency, p, q):
                    continue
                normal = np.cross(points[p] - points[v], points[q] - points[v])
                size = np.sqrt((normal * normal).sum())
                if size == 0:
                    continue
                normal /= size
                for k in range(lo, hi):
                    r = adjacency[k]
                    if r < v or r == p or r == q:
                        continue
                    er = points[r] - points[v]
                    er /= np.sqrt((er * er).sum())
                    along = (er * normal).sum()
                    if abs(along) < 1 - cosine:
                        continue
                    a, b = p, q
                    if along < 0:
                        a, b = q, p
                    exclude[0], exclude[1], exclude[2], exclude[3] = v, a, b, r
                    ar = _common_nearest(start, adjacency, a, r, exclude, points[a] + points[r] - points[v], points)
                    br = _common_nearest(start, adjacency, b, r, exclude, points[b] + points[r] - points[v], points)
                    if ar < v or br < v or ar == br or not _adjacent(start, adjacency, ar, br):
                        continue
                    if count == capacity:
                        grown = np.empty((2 * capacity, 6), np.int64)
                        grown[:count] = out[:count]
                        out, capacity = grown, 2 * capacity
                    out[count, 0], out[count, 1], out[count, 2] = v, a, b
                    out[count, 3], out[count, 4], out[count, 5] = r, ar, br
                    count += 1
    return out[:count]


@numba.njit(cache=True)
def _fill(candidates, tets, free, node_start, node_tets, faces, corners, scale, points, floor):
    """For each candidate: its quality (-inf where its free tets do not fill it exactly) and its tets."""
    c, size = candidates.shape
    quality = np.full(c, -np.inf)
    members = np.full((c, MAX_TETS), -1, np.int64)
    local_faces = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    for e in range(c):
        nodes = candidates[e]
        q = cell_quality(points, nodes, corners, scale)
        if q < floor:
            continue
        found = np.empty(MAX_TETS, np.int64)
        k = 0
        ok = True
        for corner in range(size):
            v = nodes[corner]
            for s in range(node_start[v], node_start[v + 1]):
                t = node_tets[s]
                inside = True
                for m in range(4):
                    w = tets[t, m]
                    hit = False
                    for x in range(size):
                        if nodes[x] == w:
                            hit = True
                    if not hit:
                        inside = False
                        break
                if not inside:
                    continue
                seen = False
                for x in range(k):
                    if found[x] == t:
                        seen = True
                if seen:
                    continue
                if not free[t] or k == MAX_TETS:
                    ok = False
                    break
                found[k] = t
                k += 1
            if not ok:
                break
        if not ok or k == 0:
            continue
        # faces used once, sorted triples
        tri = np.empty((4 * k, 3), np.int64)
        for x in range(k):
            for f in range(4):
                a = tets[found[x], local_faces[f, 0]]
                b = tets[found[x], local_faces[f, 1]]
                d = tets[found[x], local_faces[f, 2]]
                lo3 = min(a, min(b, d))
                hi3 = max(a, max(b, d))
                tri[4 * x + f, 0], tri[4 * x + f, 1], tri[4 * x + f, 2] = lo3, a + b + d - lo3 - hi3, hi3
        covered = np.zeros(faces.shape[0], np.int64)
        missing = np.full((faces.shape[0], 2), -1, np.int64)
        for x in range(4 * k):
            twice = False
            for y in range(4 * k):
                if y != x and tri[y, 0] == tri[x, 0] and tri[y, 1] == tri[x, 1] and tri[y, 2] == tri[x, 2]:
                    twice = True
                    break
            if twice:
                continue
            placed = False
            for f in range(faces.shape[0]):
                quad = faces[f, 3] >= 0
                width = 4 if quad else 3
                hits = 0
                out_node = -1
                for g in range(width):
                    node = nodes[faces[f, g]]
                    if node == tri[x, 0] or node == tri[x, 1] or node == tri[x, 2]:
                        hits += 1
                    else:
                        out_node = g
                if hits == 3:
                    if covered[f] < 2:
                        missing[f, covered[f]] = out_node
                    covered[f] += 1
                    placed = True
                    break
            if not placed:
                ok = False
                break
        if not ok:
            continue
        for f in range(faces.shape[0]):
            if faces[f, 3] >= 0:
                if covered[f] != 2 or (missing[f, 0] - missing[f, 1]) % 2 != 0:
                    ok = False  # two triangles meeting along a diagonal
            elif covered[f] != 1:
                ok = False
        if ok:
            quality[e] = q
            members[e, :k] = found[:k]
    return quality, members


def _csr(keys: np.ndarray, values: np.ndarray, n: int):
    order = np.argsort(keys, kind="stable")
    start = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(keys, minlength=n), out=start[1:])
    return start, values[order].astype(np.int64)


def _adjacency(tets: np.ndarray, n: int):
    pairs = tets[:, [0, 0, 0, 1, 1, 2, 1, 2, 3, 2, 3, 3]].reshape(-1, 2, 6).transpose(0, 2, 1).reshape(-1, 2)
    pairs = np.unique(np.sort(pairs, axis=1), axis=0)
    both = np.vstack([pairs, pairs[:, ::-1]])
    both = both[np.lexsort(both.T[::-1])]
    return _csr(both[:, 0], both[:, 1], n)


def _select(quality, members, candidates, faces, free, tets):
    """Greedy by quality: the candidates kept, each tet in one. A flat tet on a quad face (a sliver between two
    cells, its four nodes on the face) is in both candidates' sets: the first cell keeps it, the second
    conforms along the same quad without it."""
    quads = faces[faces[:, 3] >= 0]
    nodes = candidates[:, quads]  # (c, quads, 4)
    tet_nodes = np.where(members[..., None] >= 0, tets[np.maximum(members, 0)], -2)  # (c, MAX_TETS, 4)
    on_face = (tet_nodes[:, :, None, :, None] == nodes[:, None, :, None, :]).any(axis=-1).all(axis=-1).any(axis=-1)
    members = members.copy()
    keep = _greedy(np.argsort(-quality, kind="stable"), quality, members, on_face & (members >= 0), free.copy())
    return keep, members


@numba.njit(cache=True)
def _greedy(order, quality, members, optional, free):
    keep = np.zeros(len(order), np.bool_)
    for e in order:
        if not np.isfinite(quality[e]):
            break
        ok = True
        for i in range(members.shape[1]):
            t = members[e, i]
            if t >= 0 and not free[t] and not optional[e, i]:
                ok = False
        if ok:
            keep[e] = True
            for i in range(members.shape[1]):
                t = members[e, i]
                if t >= 0:
                    if free[t]:
                        free[t] = False
                    else:
                        members[e, i] = -1  # a face sliver the neighbour took
    return keep


def _opposite(tets: np.ndarray) -> np.ndarray:
    """(m, 4) the tet across each face (FACES order), -1 on the boundary."""
    faces = np.sort(tets[:, FACES].reshape(-1, 3), axis=1)
    order = np.lexsort(faces.T[::-1])
    same = np.flatnonzero((faces[order[1:]] == faces[order[:-1]]).all(axis=1))
    opposite = np.full(len(faces), -1, np.int64)
    opposite[order[same]] = order[same + 1] // 4
    opposite[order[same + 1]] = order[same] // 4
    return opposite.reshape(-1, 4)


def _quads(cells: np.ndarray, faces: np.ndarray):
    """(cell (k,), quad nodes (k, 4)) of every quad face of ``cells``."""
    quads = faces[faces[:, 3] >= 0]
    return np.repeat(np.arange(len(cells)), len(quads)), cells[:, quads].reshape(-1, 4)


def cell_qualities(points: np.ndarray, cells: np.ndarray, kind: int) -> np.ndarray:
    """The smallest scaled corner Jacobian of each cell of type ``kind`` (1 for the ideal cell, <= 0 invalid)."""
    if len(cells) == 0:
        return np.zeros(0)
    return _qualities(
        np.ascontiguousarray(points, float), np.ascontiguousarray(cells, np.int64), CORNERS[kind], SCALE[kind]
    )


@numba.njit(cache=True)
def _qualities(points, cells, corners, scale):
    out = np.empty(len(cells))
    for c in range(len(cells)):
        out[c] = cell_quality(points, cells[c], corners, scale)
    return out


def cell_volumes(points: np.ndarray, cells: np.ndarray, kind: int) -> np.ndarray:
    """Each cell's volume, from its centroid and its faces (a quad as four triangles to its centre): where two
    cells share a face they count it the same way, so the sum over a conforming mesh is the volume its boundary
    faces enclose (exact for planar faces)."""
    p = points[cells]
    centre = p.mean(axis=1)
    volume = np.zeros(len(cells))
    for face in CELL_FACES[kind]:
        face = face[face >= 0]
        corners = p[:, face]
        if len(face) == 3:
            fans = [(corners[:, 0], corners[:, 1], corners[:, 2])]
        else:
            middle = corners.mean(axis=1)
            fans = [(corners[:, i], corners[:, (i + 1) % 4], middle) for i in range(4)]
        for a, b, c in fans:
            volume += np.einsum("ij,ij->i", a - centre, np.cross(b - centre, c - centre)) / 6.0
    return volume


def recombine(points: np.ndarray, tets: np.ndarray, min_quality: float = 0.2, prisms: bool = True) -> MixedMesh:
    """The hex-dominant mesh of the tet mesh (``tets`` positively oriented): module docstring."""
    import time

    seconds = {}
    start_time = time.perf_counter()
    points = np.ascontiguousarray(points, float)
    tets = np.ascontiguousarray(tets, np.int64)
    n, m = len(points), len(tets)
    start, adjacency = _adjacency(tets, n)
    node_start, node_tets = _csr(tets.ravel(), np.repeat(np.arange(m), 4), n)
    opposite = _opposite(tets)
    tet_volume = signed_volumes(points, tets)
    seconds["topology"] = time.perf_counter() - start_time
    kinds = [(HEX, HEX_CORNERS, HEX_FACES)] + ([(PRISM, PRISM_CORNERS, PRISM_FACES)] if prisms else [])
    chosen, found = {}, {}
    free = np.ones(m, bool)
    reserved = np.zeros(m, bool)  # the pyramids the chosen cells' open quads will need
    for kind, corners, faces in kinds:
        t0 = time.perf_counter()
        generate = _hex_candidates if kind == HEX else _prism_candidates
        candidates = generate(points, start, adjacency, CORNER_COSINE)
        generated = len(candidates)
        touched = np.zeros(n, bool)  # a cell of free tets has every node on one
        touched[tets[free & ~reserved].ravel()] = True
        candidates = candidates[touched[candidates].all(axis=1)]
        quality, members = _fill(
            candidates, tets, free & ~reserved, node_start, node_tets, faces, corners, SCALE[kind], points, min_quality
        )
        keep = np.zeros(len(candidates), bool)
        # in tiers: the near-regular cells first, then the pyramids on their open quads are kept from the rest
        for tier in (REGULAR, min_quality):
            later = quality < tier
            tier_quality = np.where(later | keep, -np.inf, quality)
            tier_keep, tier_members = _select(tier_quality, members, candidates, faces, free & ~reserved, tets)
            members[tier_keep] = tier_members[tier_keep]
            keep |= tier_keep
            chosen[kind] = (candidates[keep], members[keep], quality[keep])
            used = members[keep].ravel()
            free[used[used >= 0]] = False
            reserved |= _pyramid_tets(points, tets, opposite, chosen, min_quality)
        found[CELL_TYPES[kind]] = {
            "candidates": generated,
            "valid": int(np.isfinite(quality).sum()),
            "chosen": int(keep.sum()),
        }
        seconds[CELL_TYPES[kind]] = time.perf_counter() - t0
    t0 = time.perf_counter()
    cells, parents, centres, counts = _conform(points, tets, opposite, chosen, tet_volume, min_quality)
    seconds["conformity"] = time.perf_counter() - t0
    mixed = MixedMesh(np.vstack([points, centres]).reshape(-1, 3), cells, parents)
    mixed.stats = {
        "candidates": found,
        **counts,
        "seconds": {k: round(v, 3) for k, v in seconds.items()},
    }
    return mixed


def _pyramid_tets(points, tets, opposite, chosen, floor) -> np.ndarray:
    """(m,) the tets that make valid pyramids on the quads of the ``chosen`` cells that no other chosen cell
    shares: the two tets behind such a quad, sharing their fourth node."""
    m = len(tets)
    owner_kind, owner = np.full(m, -1, np.int64), np.full(m, -1, np.int64)
    quad_cell, quad_kind, quad_nodes = [], [], []
    for kind, (nodes, members, _) in chosen.items():
        rows = np.repeat(np.arange(len(members)), MAX_TETS).reshape(members.shape)
        owner_kind[members[members >= 0]] = kind
        owner[members[members >= 0]] = rows[members >= 0]
        cell, quads = _quads(nodes, CELL_FACES[kind])
        quad_cell.append(cell)
        quad_kind.append(np.full(len(cell), kind))
        quad_nodes.append(quads)
    out = np.zeros(m, bool)
    quad_cell, quad_kind = np.concatenate(quad_cell), np.concatenate(quad_kind)
    quad_nodes = np.concatenate(quad_nodes).reshape(-1, 4)
    if len(quad_cell) == 0:
        return out
    _, inverse, counts = np.unique(np.sort(quad_nodes, axis=1), axis=0, return_inverse=True, return_counts=True)
    single = counts[inverse.ravel()] == 1
    behind = _behind(tets, opposite, owner_kind, owner, quad_kind, quad_cell, quad_nodes, single)
    t1, t2 = behind[:, 0], behind[:, 1]
    idx = np.flatnonzero(single & (t1 >= 0) & (t2 >= 0) & (t1 != t2))
    idx = idx[(owner_kind[t1[idx]] == -1) & (owner_kind[t2[idx]] == -1)]
    apex = _fourth(tets[t1[idx]], quad_nodes[idx])
    same = (apex == _fourth(tets[t2[idx]], quad_nodes[idx])) & (apex >= 0)
    idx, apex = idx[same], apex[same]
    good = cell_qualities(points, np.column_stack([quad_nodes[idx], apex]), PYRAMID) >= floor
    out[t1[idx[good]]] = out[t2[idx[good]]] = True
    return out


def _largest(members: np.ndarray, tet_volume: np.ndarray) -> np.ndarray:
    v = np.where(members >= 0, tet_volume[np.maximum(members, 0)], -np.inf)
    return members[np.arange(len(members)), v.argmax(axis=1)]


def _star_ok(points, nodes, kind, floor) -> np.ndarray:
    """Whether each element (nodes (k, size)) splits validly into pieces to its centroid: on every quad face a
    pyramid of quality >= ``floor`` and both two-tet splits positive, on every triangle a positive tet."""
    if len(nodes) == 0:
        return np.zeros(0, bool)
    centre = points[nodes].mean(axis=1)
    work = np.vstack([points, centre])
    c = len(points) + np.arange(len(nodes))
    ok = np.ones(len(nodes), bool)
    for face in CELL_FACES[kind]:
        f = nodes[:, face[face >= 0]]
        if f.shape[1] == 4:
            ok &= cell_qualities(work, np.column_stack([f[:, ::-1], c]), PYRAMID) >= floor  # base seen from c
            for a, b, d in ((0, 1, 2), (0, 2, 3), (0, 1, 3), (1, 2, 3)):
                ok &= cell_qualities(work, np.column_stack([c, f[:, a], f[:, b], f[:, d]]), TET) >= floor
        else:
            ok &= cell_qualities(work, np.column_stack([c, f]), TET) >= floor
    return ok


def _conform(points, tets, opposite, chosen, tet_volume, floor):
    """Make every quad face of the chosen hexahedra and prisms conform (module docstring). An element with a
    quad face that cannot (the tets behind it make no valid pyramid, or another quad takes them) is split into
    pieces to a node at its centroid (``starred``: a pyramid on each quad face it shares with another element,
    else two tets matching the triangles on the other side, and a tet on each triangle), which conforms with
    whatever is around it; where that split would not be valid it goes back to its tets (``dissolved``).

    Returns (cells per type, parents per type, new centre nodes (k, 3), counts)."""
    m, n = len(tets), len(points)
    state = {kind: np.zeros(len(v[0]), np.int8) for kind, v in chosen.items()}  # 0 kept, 1 starred, 2 dissolved
    rounds = 0
    while True:
        rounds += 1
        owner_kind = np.full(m, -1, np.int64)
        owner = np.full(m, -1, np.int64)
        quad_cell, quad_kind, quad_nodes, quad_quality, quad_state = [], [], [], [], []
        for kind, (nodes, members, quality) in chosen.items():
            live = np.flatnonzero(state[kind] < 2)
            mem = members[live]
            rows = np.repeat(live, MAX_TETS).reshape(mem.shape)
            owner_kind[mem[mem >= 0]] = kind
            owner[mem[mem >= 0]] = rows[mem >= 0]
            cell, quads = _quads(nodes[live], CELL_FACES[kind])
            quad_cell.append(live[cell])
            quad_kind.append(np.full(len(cell), kind))
            quad_nodes.append(quads)
            quad_quality.append(quality[live[cell]])
            quad_state.append(state[kind][live[cell]])
        quad_cell = np.concatenate(quad_cell)
        quad_kind = np.concatenate(quad_kind)
        quad_nodes = np.concatenate(quad_nodes).reshape(-1, 4)
        quad_quality = np.concatenate(quad_quality)
        quad_state = np.concatenate(quad_state)
        if len(quad_cell):
            _, inverse, counts = np.unique(np.sort(quad_nodes, axis=1), axis=0, return_inverse=True, return_counts=True)
            shared = counts[inverse.ravel()] == 2
        else:
            shared = np.zeros(0, bool)
        single = ~shared & (quad_state == 0)
        behind = _behind(tets, opposite, owner_kind, owner, quad_kind, quad_cell, quad_nodes, single)
        boundary = single & (behind[:, 0] == -1) & (behind[:, 1] == -1)
        need = single & ~(boundary & _planar(points, quad_nodes))  # a boundary quad must be flat
        t1, t2 = behind[:, 0], behind[:, 1]
        ok = need & (t1 >= 0) & (t2 >= 0) & (t1 != t2)
        ok[ok] &= (owner_kind[t1[ok]] == -1) & (owner_kind[t2[ok]] == -1)
        apex = np.full(len(quad_cell), -1, np.int64)
        idx = np.flatnonzero(ok)
        a1 = _fourth(tets[t1[idx]], quad_nodes[idx])
        a2 = _fourth(tets[t2[idx]], quad_nodes[idx])
        same = (a1 == a2) & (a1 >= 0)
        ok[idx[~same]] = False
        apex[idx[same]] = a1[same]
        idx = np.flatnonzero(ok)
        if len(idx):
            ok[idx] = cell_qualities(points, np.column_stack([quad_nodes[idx], apex[idx]]), PYRAMID) >= floor
        request = np.flatnonzero(ok)  # a tet in two pyramids: the better cell's quad keeps it
        order = request[np.argsort(-quad_quality[request], kind="stable")]
        claimed = np.column_stack([t1[order], t2[order]]).ravel()  # in the quads' order, both tets of each
        firsts = np.zeros(len(claimed), bool)
        firsts[np.unique(claimed, return_index=True)[1]] = True
        ok[order[~firsts.reshape(-1, 2).all(axis=1)]] = False
        bad = need & ~ok
        if not bad.any():
            break
        for kind in chosen:
            drop = np.unique(quad_cell[bad & (quad_kind == kind)])
            star = _star_ok(points, chosen[kind][0][drop], kind, floor)
            state[kind][drop] = np.where(star, 1, 2)
    # the cells
    pyramid_quads = np.flatnonzero(ok)
    cells = [[], [], [np.column_stack([quad_nodes[pyramid_quads], apex[pyramid_quads]])], []]
    parents = [[], [], [t1[pyramid_quads]], []]
    used = np.zeros(m, bool)
    used[t1[pyramid_quads]] = used[t2[pyramid_quads]] = True
    centres = []
    counts = {"starred": {}, "dissolved": {}, "conformity_rounds": rounds}
    shared_key = {tuple(k) for k in np.sort(quad_nodes[shared], axis=1).tolist()}
    for kind, (nodes, members, _) in chosen.items():
        kept = state[kind] == 0
        cells[kind].append(nodes[kept])
        parents[kind].append(_largest(members[kept], tet_volume))
        mem = members[state[kind] < 2]
        used[mem[mem >= 0]] = True
        starred = np.flatnonzero(state[kind] == 1)
        counts["starred"][CELL_TYPES[kind]] = len(starred)
        counts["dissolved"][CELL_TYPES[kind]] = int((state[kind] == 2).sum())
        if not len(starred):
            continue
        snodes, smembers = nodes[starred], members[starred]
        centre_index = n + sum(len(c) for c in centres) + np.arange(len(starred))
        centres.append(points[snodes].mean(axis=1))
        parent = _largest(smembers, tet_volume)
        # quad faces shared with another element: pyramids to the centre
        for face in CELL_FACES[kind]:
            if face[3] < 0:
                continue
            f = snodes[:, face]
            pyramid = np.array([tuple(k) in shared_key for k in np.sort(f, axis=1).tolist()], bool)
            cells[PYRAMID].append(np.column_stack([f[pyramid][:, ::-1], centre_index[pyramid]]))
            parents[PYRAMID].append(parent[pyramid])
        # every other face of the element: its tets' faces there, each a tet to the centre
        rows = np.repeat(np.arange(len(starred)), MAX_TETS)
        flat = smembers.ravel()
        rows, flat = rows[flat >= 0], flat[flat >= 0]
        tri_rows = np.repeat(rows, 4)
        tri = tets[flat][:, FACES].reshape(-1, 3)
        across = opposite[flat].ravel()
        inside = np.zeros(len(tri), bool)
        valid = across >= 0
        inside[valid] = (owner_kind[across[valid]] == kind) & (owner[across[valid]] == starred[tri_rows[valid]])
        outer = ~inside
        on_pyramid = np.zeros(len(tri), bool)
        for face in CELL_FACES[kind]:
            if face[3] < 0:
                continue
            f = snodes[tri_rows][:, face]
            is_shared = np.array([tuple(k) in shared_key for k in np.sort(f, axis=1).tolist()], bool)
            within = (tri[:, :, None] == f[:, None, :]).any(axis=2).all(axis=1)
            on_pyramid |= within & is_shared
        pick = outer & ~on_pyramid
        cells[TET].append(np.column_stack([centre_index[tri_rows[pick]], tri[pick]]))
        parents[TET].append(parent[tri_rows[pick]])
    alone = np.flatnonzero(~used)
    cells[TET].append(tets[alone])
    parents[TET].append(alone)
    cells = [
        np.concatenate(c).reshape(-1, SIZES[k]).astype(np.int64) if c else np.zeros((0, SIZES[k]), np.int64)
        for k, c in enumerate(cells)
    ]
    parents = [np.concatenate(p).astype(np.int64) if p else np.zeros(0, np.int64) for p in parents]
    centres = np.concatenate(centres).reshape(-1, 3) if centres else np.zeros((0, 3))
    return cells, parents, centres, counts


def _planar(points, quads) -> np.ndarray:
    """Whether each quad's four nodes lie in a plane, to rounding (PLANAR of its size cubed)."""
    p = points[quads]
    u, v, w = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    size = np.linalg.norm(v, axis=1) ** 3
    return np.abs(np.einsum("ij,ij->i", u, np.cross(v, w))) <= PLANAR * size


def _fourth(tet_nodes: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """The node of each tet not on its quad (-1 when not exactly one)."""
    off = ~(tet_nodes[:, :, None] == quads[:, None, :]).any(axis=2)
    return np.where(off.sum(axis=1) == 1, tet_nodes[np.arange(len(tet_nodes)), off.argmax(axis=1)], -1)


def _behind(tets, opposite, owner_kind, owner, quad_kind, quad_cell, quad_nodes, single):
    """(k, 2) the tets across the two faces of each single quad from its cell's tets (-1: the mesh boundary;
    -2 for a face not found)."""
    out = np.full((len(quad_cell), 2), -2, np.int64)
    idx = np.flatnonzero(single)
    if len(idx) == 0:
        return out
    # candidate tets: those of the quad's cell; their faces lying on the quad
    cell_key = quad_kind * (len(tets) + 1) + quad_cell
    tet_key = owner_kind * (len(tets) + 1) + owner
    has = owner_kind >= 0
    t_sorted = np.flatnonzero(has)[np.argsort(tet_key[has], kind="stable")]
    keys_sorted = tet_key[t_sorted]
    lo = np.searchsorted(keys_sorted, cell_key[idx], "left")
    hi = np.searchsorted(keys_sorted, cell_key[idx], "right")
    width = int((hi - lo).max())
    slot = lo[:, None] + np.arange(width)[None]
    valid = slot < hi[:, None]
    cand = np.where(valid, t_sorted[np.minimum(slot, len(t_sorted) - 1)], -1)  # (k, width)
    faces = tets[np.maximum(cand, 0)][:, :, FACES]  # (k, width, 4, 3)
    on = (faces[..., None] == quad_nodes[idx][:, None, None, None, :]).any(axis=-1).all(axis=-1) & valid[:, :, None]
    across = opposite[np.maximum(cand, 0)]  # (k, width, 4)
    flat_on = on.reshape(len(idx), -1)
    flat_across = across.reshape(len(idx), -1)
    first = np.argmax(flat_on, axis=1)
    rest = flat_on.copy()
    rest[np.arange(len(idx)), first] = False
    second = np.argmax(rest, axis=1)
    two = flat_on.sum(axis=1) == 2
    out[idx[two], 0] = flat_across[two, first[two]]
    out[idx[two], 1] = flat_across[two, second[two]]
    return out
