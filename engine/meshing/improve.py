"""Quality improvement after connection: Gmsh's tetrahedral optimiser, then targeted node relocation.

1. Gmsh's optimiser (edge and face swaps, node relocation) on the mesh loaded
   as discrete entities: boundary nodes sit on the boundary entity and are
   never moved; elements below ``Mesh.OptimizeThreshold`` (gamma, the radius
   ratio) are worked on.
2. What is left under the target is fixed by moving the nodes of each bad
   tetrahedron to the best of a few candidate places (star centroid,
   deterministic perturbations), judged by the worst element quality of the
   node's star, q = min(radius ratio, min dihedral / 70.53 deg) (1 for the
   regular tetrahedron; ``engine/tetmetrics.py``, the kernel the quality
   report measures with); a move is kept only if it improves it. Volume nodes
   move freely, nodes of planar patches slide in their plane, curve and corner
   nodes stay. Nodes of curved patches stay too, but for a last pass on what
   is still under the target, where they slide in the plane of their input
   face and then go back onto the surface (sliding changes the surface's
   chords, so it is kept for the few elements single moves inside could not
   fix: on the 1M junction with the cylinder at the centre, a tet of three
   cylinder nodes and one volume node stayed at 14.0 deg without it).

3. A flat cap (a tet under the target whose four nodes are all on the boundary:
   the fold of two surface triangles on a convex patch, 10-16 deg at 24 nodes
   per circle) gets a new node beneath it (``fill_flat_caps``): no swap mends it,
   as the rings around its inner edges have no node under the fold, and a peel
   would dent the surface by more than the repairs' tolerance.

4. What is still under the floor (10 deg / radius ratio 0.15) is repaired by
   topology (``peel_boundary_slivers``, ``collapse_bad_nodes``, ``swap_bad_faces``):
   flat tets between boundary faces peeled, crowded nodes collapsed into a
   neighbour, inner faces and edges swapped; sharp curves stay element edges and
   the boundary stays within a tolerance of the input surface. The mesher then
   runs Gmsh's optimiser and the relocation once more where tets under the floor
   are left (relocation and the repairs give its swaps new tets to work on), and
   repairs again.

5. What is still under the target gets the same flips at the target and relocation
   once more (``mend_below_target``): on the junction at 10M tets a volume tet of 14.0
   deg with two cylinder nodes was left where relocation had stopped (19.5 deg after).

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
from ..tetmetrics import REGULAR_DIHEDRAL, min_dihedral, shape_quality
from ..topology import node_stars
from .tetra import gmsh_session

GMSH_THRESHOLD = 0.5  # Gmsh optimises tets with gamma below this
TARGET = 20.0 / REGULAR_DIHEDRAL  # relocation works on tets with q below: min dihedral < 20 deg or radius ratio < 0.284
FLOOR = min(10.0 / REGULAR_DIHEDRAL, 0.15)  # the quality every element must reach
RELOCATION_PASSES = 6
RING = 7  # the largest ring of tets around an edge that is retriangulated (42 ways)
PEEL_ROUNDS = 8  # rounds of each repair (peels, collapses, swaps): one can lay the next bad tet open
CANDIDATES = 24  # perturbation directions per node and pass
STEPS = np.array([0.04, 0.12, 0.25])  # perturbation lengths, x the mean edge length of the star
CAP_PLACES = np.linspace(0.0, 1.0, 11)  # where a flat cap's new node is tried: edge midpoint (0) to ring centre (1)


def gmsh_optimize(points: np.ndarray, tets: np.ndarray, fixed: np.ndarray):
    """Gmsh's optimiser on the mesh; nodes with ``fixed`` set stay where they are.

    Returns (points, tets): node indices are kept; Gmsh may relocate free nodes.
    """
    import gmsh

    gmsh_session()
    gmsh.option.setNumber("Mesh.OptimizeThreshold", GMSH_THRESHOLD)
    gmsh.option.setNumber("Mesh.Renumber", 0)  # keep our node numbers as Gmsh's tags
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


def relocate(
    points: np.ndarray, tets: np.ndarray, slide: np.ndarray, seed: int = 0, target: float | None = None
) -> tuple[np.ndarray, int]:
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


def mend_below_target(points: np.ndarray, tets: np.ndarray, slide: np.ndarray, seed: int = 0):
    """The last step for the tets still under TARGET after the repairs: flips at TARGET (:func:`swap_bad_faces`)
    open stars that relocation could not mend, then relocation (``slide`` as for :func:`relocate`) goes on from
    there. Returns (points, tets, flips, moves). On the junction at 10M tets a tet of 14.0 deg was left among
    10 under 20 deg: relocation alone had stopped at it."""
    tets, flips = swap_bad_faces(points, tets, TARGET)
    points, moves = relocate(points, tets, slide, seed)
    return points, tets, flips, moves


def quality_below(points, tets, quality: float) -> np.ndarray:
    """Which tets have min(radius ratio, min dihedral / 70.53 deg) below ``quality``."""
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    return _below_quality(np.ascontiguousarray(points, dtype=np.float64), tets, np.arange(len(tets)), quality)


def peel_boundary_slivers(points, tets, boundary, patch, quality: float, removable=None, surface=None, tolerance=None):
    """Remove the tets below ``quality`` that lie flat between two boundary faces of one patch (or of
    two, across a smooth cut's edge: one with a ``removable`` node), and those that lie flat under three
    boundary faces around a ``removable`` node; in rounds, as a peel can lay the next flat tet open.

    The first fills the fold between two surface triangles that share an edge; its two
    other faces become boundary instead (a surface edge flip across a flat tet, so the
    surface moves by less than the tet's thickness and every node stays on the boundary).
    An edge between two patches is a curve's; one with a ``removable`` node (a patch node
    or a smooth cut's) is a smooth cut's, where the cut may end at a corner of a sharp
    curve; an edge of two curve or corner nodes between two patches is a sharp curve's and
    stays. A removal that would make an edge non-manifold (the flipped edge already on the
    boundary) is skipped. The second is the whole star of a surface node (three
    consecutive nodes of a smooth cut and a patch node beside them): its fourth face
    becomes boundary and the node leaves the mesh.

    With ``surface`` (points (k, 3) -> their distances to the input surface and its outward
    unit normals there) a removal is kept only if the faces it makes boundary face outward
    as the input surface does and are no farther from it (at their centroids and edge
    midpoints) than the faces it removes, or than the smallest ``tolerance`` (per node) of
    their nodes. Returns (tets, boundary, patch, removed count); the number of bad tets is
    small, so they are taken one by one, the worst first.
    """
    return _in_rounds(
        lambda tets, boundary, patch: _peel_round(
            points, tets, boundary, patch, quality, removable, surface, tolerance
        ),
        (tets, boundary, patch),
    )


def _in_rounds(step, state: tuple, rounds: int = PEEL_ROUNDS) -> tuple:
    """The round loop of the repairs: ``step(*state)`` returns the new state and a count of changes, with the
    count last; rounds run until one changes nothing, at most ``rounds``. Returns (*state, total count)."""
    total = 0
    for _ in range(rounds):
        *state, count = step(*state)
        total += count
        if not count:
            break
    return (*state, total)


def _peel_round(points, tets, boundary, patch, quality, removable, surface, tolerance):
    bad = np.flatnonzero(quality_below(points, tets, quality))
    if not len(bad):
        return tets, boundary, patch, 0
    bad = bad[np.argsort(min_dihedrals(points, tets[bad]), kind="stable")]  # the worst first
    faces = {tuple(sorted(f)): k for k, f in enumerate(boundary.tolist())}
    edges = {}
    for f in boundary.tolist():
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            edges[(min(a, b), max(a, b))] = edges.get((min(a, b), max(a, b)), 0) + 1
    degree = np.bincount(boundary.ravel(), minlength=len(points))
    proposals = []  # (tet, removed faces, new faces, new patch, flip, apex)
    for t in bad:
        own = tets[t][FACES]  # outward faces of the tet
        on_boundary = [faces.get(tuple(sorted(f))) for f in own.tolist()]
        hits = [k for k in on_boundary if k is not None]
        if len(hits) == 3 and removable is not None:
            opposite = [k is None for k in on_boundary].index(True)
            apex = tets[t][opposite]  # the node all three boundary faces share
            if removable[apex] and degree[apex] == 3:
                proposals.append((t, hits, own[opposite][None, ::-1], np.bincount(patch[hits]).argmax(), None, apex))
            continue
        if len(hits) != 2:
            continue
        shared = set(boundary[hits[0]].tolist()) & set(boundary[hits[1]].tolist())
        across_cut = removable is not None and any(removable[v] for v in shared)  # a smooth cut's edge
        if len(shared) != 2 or (patch[hits[0]] != patch[hits[1]] and not across_cut):
            continue
        flipped = tuple(sorted(set(tets[t].tolist()) - shared))
        if edges.get(flipped, 0):
            continue
        inner = own[[k is None for k in on_boundary]][:, ::-1]  # reversed: outward for the remaining mesh
        proposals.append((t, hits, inner, patch[hits[0]], (tuple(sorted(shared)), flipped), None))
    if surface is not None and proposals:
        ok = _stays_on_surface(
            points, surface, tolerance, [boundary[p[1]] for p in proposals], [p[2] for p in proposals]
        )
        proposals = [p for p, keep in zip(proposals, ok) if keep]
    drop, gone, added, added_patch = [], set(), [], []
    for t, hits, new, new_patch, flip, apex in proposals:
        if gone & set(hits):  # a face this round already removed
            continue
        if flip is not None:
            shared, flipped = flip
            if edges.get(flipped, 0):
                continue
            edges[flipped] = 2
            edges[shared] = 0
        elif degree[apex] != 3:
            continue
        drop.append(t)
        gone.update(hits)
        np.subtract.at(degree, boundary[hits].ravel(), 1)
        np.add.at(degree, new.ravel(), 1)
        added.extend(new)
        added_patch.extend([new_patch] * len(new))
    if not drop:
        return tets, boundary, patch, 0
    keep = np.ones(len(boundary), bool)
    keep[list(gone)] = False
    boundary = np.vstack([boundary[keep], np.array(added, dtype=boundary.dtype).reshape(-1, 3)])
    patch = np.concatenate([patch[keep], np.array(added_patch, dtype=patch.dtype)])
    return np.delete(tets, drop, axis=0), boundary, patch, len(drop)


def _stays_on_surface(points, surface, tolerance, old, new) -> np.ndarray:
    """Per change (the surface triangles ``old[i]`` replaced by ``new[i]``): every new triangle faces outward
    as the input surface does at its centroid, and the new ones are no farther from the input surface than
    the old ones, or than their nodes' smallest ``tolerance``, at their centroids and edge midpoints."""
    count = len(new)
    old_owner = np.repeat(np.arange(count), [len(o) for o in old])
    new_owner = np.repeat(np.arange(count), [len(n) for n in new])
    old, new = np.vstack(old).reshape(-1, 3), np.vstack(new).reshape(-1, 3)

    def samples(triangles):
        corners = points[triangles]
        return np.concatenate([corners.mean(axis=1)[:, None], 0.5 * (corners + np.roll(corners, 1, axis=1))], axis=1)

    distance, normal = surface(np.vstack([samples(old), samples(new)]).reshape(-1, 3))
    allowed = np.zeros(count)
    np.maximum.at(allowed, old_owner, distance[: 4 * len(old)].reshape(-1, 4).max(axis=1))
    if tolerance is not None:
        smallest = np.full(count, np.inf)
        np.minimum.at(smallest, new_owner, tolerance[new].min(axis=1))
        np.maximum(allowed, smallest, out=allowed)
    far = np.zeros(count)
    np.maximum.at(far, new_owner, distance[4 * len(old) :].reshape(-1, 4).max(axis=1))
    corners = points[new]
    outward = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    agree = np.einsum("ij,ij->i", outward, normal[4 * len(old) :].reshape(-1, 4, 3)[:, 0]) > 0
    facing = np.ones(count, bool)
    np.logical_and.at(facing, new_owner, agree)
    return facing & (far <= allowed)


def collapse_bad_nodes(points, tets, boundary, patch, quality: float, collapsible, surface=None, tolerance=None):
    """Take out, by an edge collapse, a ``collapsible`` node of a tet below ``quality`` where that makes the
    worst tet around it better: the node merges into a neighbour (a surface node only into a surface
    neighbour along a boundary edge, so the boundary stays a closed two-manifold with its nodes on the
    input surface), the tets on that edge go and its other tets take the neighbour instead; of all its
    neighbours and all the tet's collapsible nodes, the collapse with the best worst tet is taken.

    Crowded nodes leave so: two smooth cuts meeting at a sharp curve at a small angle put their nodes, and
    the flat tets between them, closer together than the sizing asks. Nodes of sharp curves and corners are
    never ``collapsible``, so every sharp curve stays a chain of element edges. A collapse is kept only if
    every new tet is positive, no face gets more than two tets, the tets' free faces are the old ones but
    for the merged node's boundary faces, every boundary edge keeps two faces, and (with ``surface``, see
    ``peel_boundary_slivers``) the moved boundary faces stay as close to the input surface. The node is
    left unused (``tetra.compact`` drops it). In rounds; returns (tets, boundary, patch, collapsed count)."""
    return _in_rounds(
        lambda tets, boundary, patch: _collapse_round(
            points, tets, boundary, patch, quality, collapsible, surface, tolerance
        ),
        (tets, boundary, patch),
    )


def _collapse_round(points, tets, boundary, patch, quality, collapsible, surface, tolerance):
    bad = np.flatnonzero(quality_below(points, tets, quality))
    if not len(bad):
        return tets, boundary, patch, 0
    bad = bad[np.argsort(min_dihedrals(points, tets[bad]), kind="stable")]
    star_start, star_tets = node_stars(tets, len(points))
    tets = tets.copy()
    boundary = boundary.copy()
    faces = {tuple(sorted(f)): k for k, f in enumerate(boundary.tolist())}
    edges = {}
    for f in boundary.tolist():
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            edges[(min(a, b), max(a, b))] = edges.get((min(a, b), max(a, b)), 0) + 1
    on_boundary = np.zeros(len(points), bool)
    on_boundary[boundary.ravel()] = True
    touched = np.zeros(len(tets), bool)
    dead_faces = np.zeros(len(boundary), bool)
    dead, collapses = [], 0
    for t in bad:
        if touched[t]:
            continue
        options = []
        for v in tets[t]:
            if not collapsible[v]:
                continue
            star_v = star_tets[star_start[v] : star_start[v + 1]]
            for w in np.unique(tets[star_v]):  # into any neighbour
                if w == v or (on_boundary[v] and edges.get((min(v, w), max(v, w)), 0) != 2):
                    continue
                star_w = star_tets[star_start[w] : star_start[w + 1]]
                if touched[star_v].any() or touched[star_w].any():
                    continue
                option = _collapse(points, tets, boundary, faces, edges, star_v, star_w, v, w)
                if option is not None:
                    options.append(option)
        options.sort(key=lambda o: -o["worst"])
        if surface is not None and any(len(o["new_faces"]) for o in options):
            moving = [o for o in options if len(o["new_faces"])]
            ok = _stays_on_surface(
                points,
                surface,
                tolerance,
                [boundary[o["removed_faces"] + o["old_faces"]] for o in moving],
                [o["new_faces"] for o in moving],
            )
            rejected = {id(o) for o, keep in zip(moving, ok) if not keep}
            options = [o for o in options if id(o) not in rejected]
        if not options:
            continue
        best = options[0]
        touched[best["star_v"]] = touched[best["star_w"]] = True
        tets[best["changed"]] = best["rows"]
        dead.extend(best["gone"].tolist())
        collapses += 1
        for k in best["removed_faces"]:
            dead_faces[k] = True
            faces.pop(tuple(sorted(boundary[k].tolist())), None)
        for k, f in zip(best["old_faces"], best["new_faces"]):
            boundary[k] = f
            faces[tuple(sorted(f.tolist()))] = k
        edges.update(best["edges"])
    if not dead:
        return tets, boundary, patch, 0
    keep = np.ones(len(tets), bool)
    keep[dead] = False
    return tets[keep], boundary[~dead_faces], patch[~dead_faces], collapses


def _collapse(points, tets, boundary, faces, edges, star_v, star_w, v, w):
    """The collapse of node v into node w (the changes as a dict), or None where it is not valid or does not
    make the worst tet of v's star better."""
    old_rows = tets[star_v]
    has_w = (old_rows == w).any(axis=1)
    rows = np.where(old_rows[~has_w] == v, w, old_rows[~has_w])
    if len(rows) == 0:
        return None
    new_q = _qualities(points, rows)
    old_worst = _qualities(points, old_rows).min()
    if new_q.min() <= max(old_worst, 0.0):
        return None
    other = star_w[~np.isin(star_w, star_v)]
    region_old = np.vstack([old_rows, tets[other]])
    region_new = np.vstack([rows, tets[other]])
    if len(np.unique(np.sort(region_new, axis=1), axis=0)) != len(region_new):
        return None
    old_once = _free_faces(region_old)
    new_once = _free_faces(region_new)
    if new_once is None:
        return None
    # boundary faces of v: those with w go, the others take w
    old_faces, new_faces, removed = [], [], []
    candidates = set()
    for row in old_rows.tolist():
        for f in (row[1:], [row[0], row[2], row[3]], [row[0], row[1], row[3]], row[:3]):
            key = tuple(sorted(f))
            if v in key and key in faces:
                candidates.add(faces[key])
    for k in sorted(candidates):
        f = boundary[k]
        if (f == w).any():
            removed.append(k)
        else:
            old_faces.append(k)
            new_faces.append(np.where(f == v, w, f))
    expected = {f for f in old_once if v not in f} | {tuple(sorted(f.tolist())) for f in new_faces}
    if new_once != expected:
        return None
    changes = {}
    for f in [boundary[k] for k in removed + old_faces]:
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            key = (min(a, b), max(a, b))
            changes[key] = changes.get(key, edges.get(key, 0)) - 1
    for f in new_faces:
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            key = (min(a, b), max(a, b))
            changes[key] = changes.get(key, edges.get(key, 0)) + 1
    if any(c not in (0, 2) for c in changes.values()):
        return None
    return {
        "worst": float(new_q.min()),
        "star_v": star_v,
        "star_w": star_w,
        "changed": star_v[~has_w],
        "rows": rows,
        "gone": star_v[has_w],
        "removed_faces": removed,
        "old_faces": old_faces,
        "new_faces": np.array(new_faces, dtype=boundary.dtype).reshape(-1, 3),
        "edges": changes,
    }


def swap_bad_faces(points, tets, quality: float):
    """Flips at the tets below ``quality`` (edge and face swaps, boundary faces never among them): a 2-3
    flip of the bad tet and its neighbour across an inner face into three tets around the edge joining
    their opposite nodes, and the removal of an inner edge of the bad tet, its ring of k tets retriangulated
    into 2k - 4 (k <= RING, every triangulation of the ring tried); the best is kept where every new tet is
    positive and the worst of them is better than the worst of the tets they replace. A flat tet of four
    surface nodes so gets a volume node as its fourth. In rounds; returns (tets, flips)."""
    return _in_rounds(lambda tets: _swap_round(points, tets, quality), (tets,))


def _swap_round(points, tets, quality):
    bad = np.flatnonzero(quality_below(points, tets, quality))
    if not len(bad):
        return tets, 0
    bad = bad[np.argsort(min_dihedrals(points, tets[bad]), kind="stable")]
    star_start, star_tets = node_stars(tets, len(points))

    def star(v):
        return star_tets[star_start[v] : star_start[v + 1]]

    touched = np.zeros(len(tets), bool)
    added, gone = [], []
    for t in bad:
        if touched[t]:
            continue
        options = []  # (worst new quality, replaced tets, new rows)
        for k in range(4):
            face = tets[t][FACES[k]]  # outward from t
            neighbour = np.setdiff1d(np.intersect1d(np.intersect1d(star(face[0]), star(face[1])), star(face[2])), [t])
            if len(neighbour) != 1:
                continue  # a boundary face
            apex = tets[neighbour[0]][~np.isin(tets[neighbour[0]], face)][0]
            rows = np.array(
                [
                    [tets[t][k], face[1], face[2], apex],
                    [face[0], tets[t][k], face[2], apex],
                    [face[0], face[1], tets[t][k], apex],
                ]
            )
            options.append((np.array([t, neighbour[0]]), rows))
        for i, j in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)):
            a, b = tets[t][i], tets[t][j]
            ring = _edge_ring(star_start, star_tets, a, b)
            if len(ring) > RING:
                continue
            polygon = _ring(tets[ring], a, b)
            if polygon is None:
                continue  # a boundary edge
            for triangles in _triangulations(len(polygon)):
                tri = polygon[np.array(triangles)]
                options.append(
                    (
                        ring,
                        np.vstack(
                            [
                                np.column_stack([tri[:, ::-1], np.full(len(tri), a)]),
                                np.column_stack([tri, np.full(len(tri), b)]),
                            ]
                        ),
                    )
                )
        best = None
        for replaced, rows in options:
            if touched[replaced].any():
                continue
            q = _qualities(points, rows)
            if q.min() > max(_qualities(points, tets[replaced]).min(), 0.0) and (best is None or q.min() > best[0]):
                best = (q.min(), replaced, rows)
        if best is None:
            continue
        _, replaced, rows = best
        touched[replaced] = True
        gone.extend(replaced.tolist())
        added.append(rows)
    if not gone:
        return tets, 0
    keep = np.ones(len(tets), bool)
    keep[gone] = False
    return np.vstack([tets[keep]] + added), len(added)


def fill_flat_caps(points, tets, boundary, quality: float):
    """Give a node beneath each flat cap: a tet below ``quality`` whose four nodes are all on the boundary
    (over the fold of two surface triangles on a convex patch, where a peel would dent the surface and no
    swap helps, as its rings have no node beneath the fold). The ring of tets around one of its inner
    edges becomes the star of a new node at the best of CAP_PLACES places between the edge's midpoint
    and the ring's centre, if every new tet is positive and the worst of them is better than the worst of
    the ring's. In rounds; returns (points (n + added, 3), tets, added count): the new nodes come last."""
    return _in_rounds(lambda points, tets: _cap_round(points, tets, boundary, quality), (points, tets))


def _cap_round(points, tets, boundary, quality):
    on_boundary = np.zeros(len(points), bool)
    on_boundary[boundary.ravel()] = True
    capping = np.flatnonzero(on_boundary[tets].all(axis=1))  # few: only these are judged
    bad = capping[_below_quality(points, np.ascontiguousarray(tets, dtype=np.int64), capping, quality)]
    if not len(bad):
        return points, tets, 0
    bad = bad[np.argsort(min_dihedrals(points, tets[bad]), kind="stable")]  # the worst first
    star_start, star_tets = node_stars(tets, len(points))
    touched = np.zeros(len(tets), bool)
    gone, added, new_points = [], [], []
    for t in bad:
        best = None  # (worst new quality, ring, rows, place)
        for i, j in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)):
            a, b = tets[t][i], tets[t][j]
            ring = _edge_ring(star_start, star_tets, a, b)
            if touched[ring].any() or _ring(tets[ring], a, b) is None:  # a boundary edge's ring is open
                continue
            nodes, local = np.unique(tets[ring], return_inverse=True)  # the ring's tets on its own nodes
            local = local.reshape(-1, 4)
            here = len(nodes)  # the new node, last of the ring's
            a_local, b_local = np.searchsorted(nodes, [a, b])
            rows = np.vstack([np.where(local == b_local, here, local), np.where(local == a_local, here, local)])
            middle = (points[a] + points[b]) / 2
            centre = points[nodes].mean(axis=0)
            for place in middle + CAP_PLACES[:, None] * (centre - middle):
                q = _qualities(np.vstack([points[nodes], place]), rows)
                if best is None or q.min() > best[0]:
                    best = (q.min(), ring, np.append(nodes, len(points) + len(new_points))[rows], place)
        if best is None or best[0] <= max(_qualities(points, tets[best[1]]).min(), 0.0):
            continue
        _, ring, rows, place = best
        touched[ring] = True
        gone.extend(ring.tolist())
        added.append(rows)
        new_points.append(place[None])
    if not gone:
        return points, tets, 0
    keep = np.ones(len(tets), bool)
    keep[gone] = False
    return np.vstack([points, *new_points]), np.vstack([tets[keep]] + added), len(new_points)


def _edge_ring(star_start, star_tets, a, b) -> np.ndarray:
    """The tets round edge (a, b): those in both nodes' stars (``node_stars``)."""
    return np.intersect1d(star_tets[star_start[a] : star_start[a + 1]], star_tets[star_start[b] : star_start[b + 1]])


def _ring(rows, a, b):
    """The nodes around edge (a, b), in the order that makes (ring[i], ring[i + 1], b, a) positive when
    the tets ``rows`` (all around the edge, positive) close around it; None for an open ring."""
    pairs = {}
    for row in rows.tolist():
        k = row.index(a), row.index(b)
        rest = [v for v in row if v != a and v != b]
        # (a, b, c, d) positive and its even permutations: c -> d is the ring's direction
        perm = [k[0], k[1]] + [row.index(v) for v in rest]
        even = sum(perm[x] > perm[y] for x in range(4) for y in range(x + 1, 4)) % 2 == 0
        c, d = rest if even else rest[::-1]
        if c in pairs:
            return None
        pairs[c] = d
    ring = [next(iter(pairs))]
    while len(ring) <= len(pairs):
        following = pairs.get(ring[-1])
        if following is None:
            return None
        if following == ring[0]:
            break
        ring.append(following)
    return np.array(ring) if len(ring) == len(pairs) and pairs.get(ring[-1]) == ring[0] else None


def _triangulations(k, first=0, last=None):
    """Every triangulation of the polygon first..last (indices), as lists of (i, j, l)."""
    last = k - 1 if last is None else last
    if last - first < 2:
        return [[]]
    out = []
    for m in range(first + 1, last):
        for left in _triangulations(k, first, m):
            for right in _triangulations(k, m, last):
                out.append(left + [(first, m, last)] + right)
    return out


def _free_faces(rows):
    """The faces (sorted tuples) of one tet only among ``rows``; None where a face has more than two."""
    own = np.sort(rows[:, FACES].reshape(-1, 3), axis=1)
    unique, count = np.unique(own, axis=0, return_counts=True)
    if (count > 2).any():
        return None
    return {tuple(f) for f in unique[count == 1].tolist()}


def min_dihedrals(points, tets) -> np.ndarray:
    """Minimum dihedral angle (degrees) of every tet; -1 for inverted or flat ones."""
    return _min_dihedrals(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(tets, dtype=np.int64))


@numba.njit(parallel=True, cache=True, error_model="numpy")
def _min_dihedrals(points, tets):
    out = np.empty(len(tets))
    for t in numba.prange(len(tets)):
        out[t] = min_dihedral(points[tets[t, 0]], points[tets[t, 1]], points[tets[t, 2]], points[tets[t, 3]])
    return out


def _qualities(points, tets) -> np.ndarray:
    return _quality_values(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(tets, dtype=np.int64))


@numba.njit(cache=True, error_model="numpy")
def _quality_values(points, tets):
    out = np.empty(len(tets))
    for t in range(len(tets)):
        out[t] = shape_quality(points[tets[t, 0]], points[tets[t, 1]], points[tets[t, 2]], points[tets[t, 3]])
    return out


@numba.njit(parallel=True, cache=True, error_model="numpy")
def _below_quality(points, tets, rows, quality):
    """Which of the tets ``rows`` have shape_quality below ``quality``."""
    out = np.empty(len(rows), dtype=np.bool_)
    for i in numba.prange(len(rows)):
        t = rows[i]
        out[i] = shape_quality(points[tets[t, 0]], points[tets[t, 1]], points[tets[t, 2]], points[tets[t, 3]]) < quality
    return out


@numba.njit(cache=True, error_model="numpy")
def _star_quality(points, tets, star, node, position):
    worst = 1.0
    q = np.empty((4, 3))
    for t in star:
        for k in range(4):
            v = tets[t, k]
            q[k] = position if v == node else points[v]
        worst = min(worst, shape_quality(q[0], q[1], q[2], q[3]))
    return worst


@numba.njit(cache=True, error_model="numpy")
def _relocate_nodes(points, tets, star_start, star_tets, nodes, slide, directions, steps):
    moved = 0
    for node in nodes:
        star = star_tets[star_start[node] : star_start[node + 1]]
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
