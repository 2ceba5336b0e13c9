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

from dataclasses import dataclass, replace

import igl
import igl.triangle
import numpy as np
from scipy import sparse
from scipy.sparse import csgraph
from scipy.spatial import Delaunay, cKDTree

from ..errors import GeometryError
from ..features import conformal_map, coordinates, curve_sides, describe
from ..fitting import seam
from ..packing import CORNER, CURVE, PATCH, Packing

SEAM_LAYERS = 4  # node layers copied across the seam of a full cylinder (Delaunay is local)
SEAM_TRIES = 4  # seams tried on a full cylinder, each SEAM_SHIFT of a turn on from the last
SEAM_SHIFT = 0.381966
CROWDING = 0.25  # a patch node nearer than this x h to its patch's border is left out, ...
COINCIDENT = 0.1  # x h: two open curves between the same corners this near all along are one chain (as SHORT_CURVE)
SPLIT_ROUNDS = 8  # rounds of splitting chain edges the Delaunay triangulation misses
CONSTRAINED_AFTER = 3  # ... after which a patch that still misses some is triangulated with them constrained
HOLE = 1.0  # a surface triangle whose circumradius exceeds this x h marks a missing bubble, ...
DEVIATION = 0.06  # ... and one whose chord strays this x h from its curved patch is too coarse:
REFINE_ROUNDS = 8  # both get a node at their circumcentre, in up to this many rounds
MIN_GAP = 0.5  # no node is added nearer than this x h to another
STRAY_GAP = 0.2  # ... but a point of the input the triangles pass far from (a drill point's tip, a fold between
# two facets) down to this x h from curve, corner and added nodes; it takes the place of the nearest patch node
# within MIN_GAP
NO_BUBBLE = -1  # the bubble id of a node the mesher adds
ON_EDGE = 1e-9  # barycentric roundoff within which a point on a chart's border lies on its triangle
CREASE_PROBES = (0.25, 0.5, 0.75)  # where along each input edge of a conformal chart a chord's deviation is probed


@dataclass
class BoundaryTriangulation:
    """Outward triangles on the solid's surface, indices into the packing's nodes."""

    triangles: np.ndarray  # (t, 3) int64
    patch: np.ndarray  # (t,) patch index of each triangle
    dropped: np.ndarray  # patch nodes left out because they crowd a feature curve
    nodes: Packing  # the packing's nodes, and curve nodes added where chain edges were split


def curve_chains(packing, features) -> dict[int, np.ndarray]:
    """Node indices of every surface curve, in arc-length order, its end corners included.

    A closed curve's chain does not repeat its first node. An open curve that joins the same two corner nodes
    as a curve before it and lies within COINCIDENT x h of it all along takes that curve's nodes
    (:func:`_coincident`).
    """
    corner_node = _corner_nodes(packing, features)
    corner_at_vertex = {c.vertex: corner_node[k] for k, c in enumerate(features.corners) if corner_node[k] >= 0}
    curve_nodes = np.flatnonzero(packing.level == CURVE)
    by_curve = {key: curve_nodes[packing.entity[curve_nodes] == key] for key in np.unique(packing.entity[curve_nodes])}
    chains = {}
    for index, curve in enumerate(features.curves):
        if not curve.on_surface or curve.vertices is None:
            continue
        nodes = by_curve.get(index, np.zeros(0, np.int64))
        ordered = nodes[np.argsort(curve.parameter(packing.points[nodes]), kind="stable")]
        start = corner_at_vertex.get(int(curve.vertices[0]))
        end = None if curve.closed else corner_at_vertex.get(int(curve.vertices[-1]))
        chain = np.concatenate([[start] if start is not None else [], ordered, [end] if end is not None else []])
        chains[index] = chain[np.diff(chain, prepend=-1) != 0].astype(np.int64)  # a short curve's ends: one node
    return _coincident(packing, features, chains)


def _coincident(packing, features, chains: dict) -> dict:
    """``chains`` with an open curve that runs between the same two corner nodes as an earlier one, within
    COINCIDENT x h of it all along (both ways, h the smallest at their nodes), given the earlier one's nodes.

    The patch between two such curves has collapsed: on a drafted housing's STL two smoothed cuts run 0.017 mm
    apart round a 2 mm^2 piece of fillet (4 facets), each got a node of its own at h 0.8, and the piece's own
    nodes lay beyond both in its chart: it kept triangles on one chain's side only, and the surface was left
    open along the other (both fillet recipes refused the part). With one chain the piece has no area (its
    border runs both ways: no side), its nodes go to the patch across (``_across_smooth_cuts``), and the two
    patches outside meet on the one chain."""
    by_ends: dict = {}
    for index, chain in chains.items():
        if not features.curves[index].closed and len(chain) >= 2 and chain[0] != chain[-1]:
            by_ends.setdefault(frozenset((int(chain[0]), int(chain[-1]))), []).append(index)
    for group in by_ends.values():
        for k, index in enumerate(group[1:], start=1):
            for earlier in group[:k]:
                chain, other = chains[index], chains[earlier]
                h = 2 * packing.radius[np.concatenate([chain, other])].min()
                if _curve_distance(features.curves[index], features.curves[earlier]) < COINCIDENT * h:
                    chains[index] = other if other[0] == chain[0] else other[::-1]
                    break
    return chains


def _curve_distance(a, b, samples: int = 64) -> float:
    """Two-sided Hausdorff distance between curves ``a`` and ``b`` (features.Curve), from ``samples`` points at
    equal arc lengths along each to the other (its exact closest points)."""

    def one_way(start, to):
        points = start.point_at(np.linspace(0.0, start.length, samples))
        return np.linalg.norm(points - to.point_at(to.parameter(points)), axis=1).max()

    return max(one_way(a, b), one_way(b, a))


def _corner_nodes(packing, features) -> np.ndarray:
    """(corners,) the node of each corner: its own, or for a corner that has none (its short curve joined it to
    another, engine/packing/start.py ``short_curve_groups``) the nearest corner node; -1 if there are none."""
    nodes = np.flatnonzero(packing.level == CORNER)
    node = np.full(len(features.corners), -1, np.int64)
    node[packing.entity[nodes]] = nodes
    missing = np.flatnonzero(node < 0)
    if len(missing) and len(nodes):
        points = np.array([features.corners[k].point for k in missing]).reshape(-1, 3)
        node[missing] = nodes[cKDTree(packing.points[nodes]).query(points)[1]]
    return node


def chain_edges(chain: np.ndarray, closed: bool) -> np.ndarray:
    """(k, 2) consecutive node pairs of a curve's chain, the closing pair too when the curve is closed."""
    return np.column_stack([chain, np.roll(chain, -1)]) if closed else np.column_stack([chain[:-1], chain[1:]])


def triangulate_boundary(packing, geometry, features) -> BoundaryTriangulation:
    """Constrained Delaunay triangulation of the surface nodes, patch by patch (see the module doc).

    A chain edge that a patch's Delaunay triangulation misses (other border
    nodes inside its diametral circle, at an acute corner of the patch) is
    split at its curve's midpoint, on both of its patches, until none is missed.
    Two chains that meet at a small angle encroach on each other whatever the
    splits (each midpoint lies in the other chain's circles, and the missed
    edges double each round): after CONSTRAINED_AFTER rounds a patch that
    still misses edges gets a constrained Delaunay triangulation instead
    (Shewchuk's Triangle through libigl), which keeps every chain edge.
    Holes in the packing of a patch get a node each (see ``_holes``).
    """
    sides = curve_sides(geometry, features)
    nodes = packing
    for _ in range(SPLIT_ROUNDS):  # chords that stray from their curve are split first
        chains = curve_chains(nodes, features)
        coarse = _coarse_chain_edges(nodes, features, chains)
        if len(coarse) == 0:
            break
        nodes = _split_chain_edges(nodes, features, chains, coarse)
    moved = np.zeros(len(nodes), bool)  # patch nodes given to the patch across a smooth cut
    for round in range(SPLIT_ROUNDS):
        chains = curve_chains(nodes, features)
        triangles, patch_of, dropped, missed, added = [], [], [], [], []
        next_node = len(nodes)
        for p, patch in enumerate(features.patches):
            edges = _border_edges(p, chains, sides, features)
            patch_nodes = np.flatnonzero((nodes.level == PATCH) & (nodes.entity == p))
            members = np.unique(np.concatenate([patch_nodes, edges.ravel()]))
            if len(members) < 3:
                continue
            tri, crowded, lost, new_points, new_radius = _triangulate_patch(
                PatchChart(patch, geometry, features.charts[p] if features.charts else None),
                nodes.points[members],
                nodes.radius[members],
                np.searchsorted(members, edges),
                nodes.level[members] == PATCH,
                constrained=round >= CONSTRAINED_AFTER,
            )
            index = np.concatenate([members, next_node + np.arange(len(new_points))])
            next_node += len(new_points)
            added.append(
                Packing(
                    points=new_points,
                    level=np.full(len(new_points), PATCH, np.int8),
                    entity=np.full(len(new_points), p),
                    radius=new_radius,
                    ids=np.full(len(new_points), NO_BUBBLE),
                )
            )
            triangles.append(index[tri])
            patch_of.append(np.full(len(tri), p))
            dropped.append(members[crowded])
            missed.append(members[lost])
        missed = np.unique(np.sort(np.concatenate(missed), axis=1), axis=0) if missed else np.zeros((0, 2), np.int64)
        if len(missed) == 0:
            used = np.concatenate([np.zeros(0, np.int64), *triangles, *dropped], axis=None)
            across = _across_smooth_cuts(nodes, features, chains, sides, used)
            moved = np.r_[moved, np.zeros(len(nodes) - len(moved), bool)]  # split chain edges added curve nodes
            across[moved] = -1  # a node moves once
            if (across >= 0).any() and round < SPLIT_ROUNDS - 1:  # the last round finishes as it is
                moved |= across >= 0
                nodes = replace(nodes, entity=np.where(across >= 0, across, nodes.entity))
                continue  # the patches on both sides again
            nodes = Packing.concatenate([nodes, *added], nodes.stats)
            break
        nodes = _split_chain_edges(nodes, features, chains, missed)
    else:
        where = nodes.points[missed].mean(axis=1)
        first = where[np.argmin(np.linalg.norm(where - where.mean(axis=0), axis=1))]
        ends = missed.ravel()
        on_curves = np.unique(nodes.entity[ends[nodes.level[ends] == CURVE]])
        curves = ", ".join(describe(features.curves[c]) for c in on_curves[:3])
        raise RuntimeError(
            f"{len(missed)} feature-curve edges still missing from the surface triangulation, around "
            f"({coordinates(first, np.abs(first).max())}) on {curves or 'corners'}"
        )
    triangles = np.concatenate(triangles).astype(np.int64) if triangles else np.zeros((0, 3), np.int64)
    check_closed(triangles)
    return BoundaryTriangulation(
        triangles,
        np.concatenate(patch_of) if patch_of else np.zeros(0, np.int64),
        np.concatenate(dropped).astype(np.int64) if dropped else np.zeros(0, np.int64),
        nodes,
    )


def _across_smooth_cuts(nodes, features, chains, sides, used) -> np.ndarray:
    """(n,) the patch each patch node outside its own patch's triangles (not in ``used``) belongs to when the
    chain edge nearest to it is a smooth cut's: the patch on the cut's other side; -1 for every other node.
    A smoothed cut crosses facets (``_unzigzagged``), so a strip of one patch's input faces lies beyond it:
    nodes packed there are outside their patch's chains, and the patch across has no faces to put nodes on."""
    across = np.full(len(nodes), -1)
    free = np.ones(len(nodes), bool)
    free[used[used < len(nodes)]] = False  # (the holes' added points come after the nodes)
    stranded = np.flatnonzero(free & (nodes.level == PATCH))
    if len(stranded) == 0:
        return across
    ends, curve = [], []
    for index, chain in chains.items():
        pairs = chain_edges(chain, features.curves[index].closed)
        ends.append(pairs)
        curve.append(np.full(len(pairs), index))
    if not ends:
        return across
    ends, curve = np.concatenate(ends), np.concatenate(curve)
    left_right = np.array([sides[c] for c in curve]).reshape(-1, 2)
    for p in np.unique(nodes.entity[stranded]):
        node = stranded[nodes.entity[stranded] == p]
        border = np.flatnonzero((left_right == p).any(axis=1))
        if len(border) == 0:
            continue
        a, b, x = nodes.points[ends[border, 0]], nodes.points[ends[border, 1]], nodes.points[node][:, None, :]
        span = b - a
        t = np.clip(np.sum((x - a) * span, axis=2) / np.maximum(np.sum(span * span, axis=1), 1e-300), 0, 1)
        nearest = border[np.argmin(np.linalg.norm(a + t[..., None] * span - x, axis=2), axis=1)]
        smooth = ~np.array([features.curves[c].sharp for c in curve[nearest]], dtype=bool)
        other = np.where(left_right[nearest, 0] == p, left_right[nearest, 1], left_right[nearest, 0])
        across[node[smooth & (other >= 0)]] = other[smooth & (other >= 0)]
    return across


def _border_edges(p, chains, sides, features) -> np.ndarray:
    """The chain edges around patch ``p``, directed with the patch on their left."""
    edges = []
    for index, chain in chains.items():
        left, right = sides[index]
        if p not in (left, right) or len(chain) < 2:
            continue
        pairs = chain_edges(chain, features.curves[index].closed)
        if p == left:
            edges.append(pairs)
        if p == right:
            edges.append(pairs[:, ::-1])
    return np.concatenate(edges) if edges else np.zeros((0, 2), np.int64)


def _coarse_chain_edges(nodes, features, chains) -> np.ndarray:
    """(k, 2) chain edges whose chord strays more than DEVIATION x h from their curve."""
    coarse = []
    for index, chain in chains.items():
        curve = features.curves[index]
        if len(chain) < 2:
            continue
        ends = chain_edges(chain, curve.closed)
        s = curve.parameter(nodes.points[chain])
        knots = curve.arc_length[1:-1]  # the curve's own vertices between its ends
        if curve.closed:  # the closing edge runs past the end, to the first node one turn on
            knots = np.concatenate([curve.arc_length[:-1], curve.arc_length[:-1] + curve.length])
            s = np.concatenate([s, [s[0] + curve.length]])
        edge = np.searchsorted(s, knots, side="right") - 1
        inside = (edge >= 0) & (edge < len(ends))
        edge, knots = edge[inside], knots[inside]
        if len(edge) == 0:
            continue
        a, b = nodes.points[ends[edge, 0]], nodes.points[ends[edge, 1]]
        x = curve.point_at(knots)
        t = np.clip(np.einsum("ij,ij->i", x - a, b - a) / np.maximum(np.einsum("ij,ij->i", b - a, b - a), 1e-300), 0, 1)
        stray = np.zeros(len(ends))
        np.maximum.at(stray, edge, np.linalg.norm(a + t[:, None] * (b - a) - x, axis=1))
        h = nodes.radius[ends].sum(axis=1)
        coarse.append(ends[stray > DEVIATION * h])
    return np.sort(np.concatenate(coarse), axis=1) if coarse else np.zeros((0, 2), np.int64)


def _split_chain_edges(nodes, features, chains, pairs):
    """``nodes`` with a new curve node at the arc-length middle of each chain edge in ``pairs``."""
    wanted = {tuple(pair) for pair in pairs.tolist()}
    points, entity, radius = [], [], []
    for index, chain in chains.items():
        curve = features.curves[index]
        ends = chain_edges(chain, curve.closed)
        hit = np.array([tuple(sorted(pair)) in wanted for pair in ends.tolist()], dtype=bool)
        if not hit.any():
            continue
        s = curve.parameter(nodes.points[ends[hit].ravel()]).reshape(-1, 2)
        if curve.closed:  # the edge that closes the loop runs past the start
            s[:, 1] = np.where(s[:, 1] <= s[:, 0], s[:, 1] + curve.length, s[:, 1])
        points.append(curve.point_at(s.mean(axis=1)))
        entity.append(np.full(hit.sum(), index))
        radius.append(nodes.radius[ends[hit]].mean(axis=1))
    count = sum(map(len, entity))
    added = Packing(
        points=np.vstack(points),
        level=np.full(count, CURVE, np.int8),
        entity=np.concatenate(entity).astype(np.int64),
        radius=np.concatenate(radius),
        ids=np.full(count, NO_BUBBLE),
    )
    return Packing.concatenate([nodes, added], nodes.stats)


def _triangulate_patch(chart, points, radius, constraints, droppable, constrained=False):
    """One patch's surface triangulation in its ``chart``, refined where the packing left a hole.

    Returns (triangles over the nodes then the added points, counter-clockwise
    seen from outside; ``droppable`` nodes left out for crowding the border or for a stray input point that
    took their place (``_holes``);
    constrained edges the triangulation misses; added points (k, 3) and their radii). ``constrained``: a
    Delaunay triangulation that misses constrained edges is replaced by a constrained one.
    """
    uv = chart.uv(points)
    radius = radius / chart.scale(uv)  # sizes in the chart's lengths
    added_uv, added_radius = np.zeros((0, 2)), np.zeros(0)
    displaced = np.zeros(len(uv), bool)  # packing nodes a stray point took the place of
    for round in range(REFINE_ROUNDS + 1):
        all_uv, all_radius = np.vstack([uv, added_uv]), np.concatenate([radius, added_radius])
        all_droppable = np.concatenate([droppable, np.ones(len(added_uv), bool)])
        all_displaced = np.r_[displaced, np.zeros(len(added_uv), bool)]
        tri, crowded, lost = _triangulate_chart(
            chart, all_uv, all_radius, constraints, all_droppable, constrained, all_displaced
        )
        if len(lost) or round == REFINE_ROUNDS:
            break
        new_uv, new_radius, taken = _holes(chart, all_uv, all_radius, tri, constraints, crowded, droppable)
        if len(new_uv) == 0:
            break
        added_uv, added_radius = np.vstack([added_uv, new_uv]), np.concatenate([added_radius, new_radius])
        displaced[taken] = True
    kept_added = np.setdiff1d(np.arange(len(added_uv)), crowded - len(uv))
    renumber = np.arange(len(all_uv))  # crowded added points are forgotten rather than dropped
    renumber[len(uv) + kept_added] = len(uv) + np.arange(len(kept_added))
    added_uv, added_radius = added_uv[kept_added], added_radius[kept_added]
    return (renumber[tri], crowded[crowded < len(uv)], lost, chart.lift(added_uv), added_radius * chart.scale(added_uv))


def _triangulate_chart(chart, uv, radius, constraints, droppable, constrained, displaced):
    """(triangles, crowded nodes, lost constrained edges) of one chart, the ``displaced`` nodes (a mask: a stray
    point took their place) among the crowded ones. A periodic strip whose two copies of the seam band
    triangulate a nearly co-circular set differently (roundoff decides) leaves triangles that pair with no
    neighbour, or a region on both sides of a chain (a seam through a cross bore's loop on a bore's wall): then
    the seam moves by SEAM_SHIFT of a turn and the strip is tried again."""
    if chart.turn is None:
        return _triangulate_strip(chart, uv, radius, constraints, droppable, constrained, displaced)
    result, failure = None, None
    for attempt in range(SEAM_TRIES):
        turned = uv.copy()
        turned[:, 0] = (
            np.mod(uv[:, 0] + attempt * SEAM_SHIFT * chart.turn + chart.turn / 2, chart.turn) - chart.turn / 2
        )
        try:
            result = _triangulate_strip(chart, turned, radius, constraints, droppable, constrained, displaced)
        except RuntimeError as error:  # a region on both sides of its boundary, with this seam
            failure = error
            continue
        if len(result[2]) or _paired(result[0], constraints):
            break
    if result is None:
        raise failure
    return result


def _paired(tri, constraints) -> bool:
    """Whether every directed edge of ``tri`` has its twin in ``tri`` or is a constrained (border) edge."""
    n = int(max(tri.max(initial=0), constraints.max(initial=0))) + 1
    half = np.stack([tri, np.roll(tri, -1, axis=1)], axis=2).reshape(-1, 2)
    key = half[:, 0] * n + half[:, 1]
    lone = ~np.isin(half[:, 1] * n + half[:, 0], key)
    return bool(np.isin(key[lone], constraints[:, 0] * n + constraints[:, 1]).all())


def _triangulate_strip(chart, uv, radius, constraints, droppable, constrained, displaced):
    original = np.arange(len(uv))
    copies = chart.copies(uv, radius)
    extended = np.vstack([uv] + [uv[rows] + shift for rows, shift in copies])
    original = np.concatenate([original] + [rows for rows, _ in copies])
    edges = _constraint_copies(constraints, original, extended)
    crowded = np.union1d(
        original[_crowding(extended, edges, droppable[original], 2 * radius[original])], np.flatnonzero(displaced)
    )
    if len(crowded):
        rows = ~np.isin(original, crowded)
        edges = (np.cumsum(rows) - 1)[edges]  # constrained edges join curve nodes, which stay
        extended, original = extended[rows], original[rows]
    tri = _delaunay(extended)
    inside, lost = _inside_regions(tri, edges)
    if len(lost) and constrained:
        tri = _constrained_delaunay(extended, edges)
        inside, lost = _inside_regions(tri, edges)
    if chart.turn is not None:  # one copy of each triangle: the one whose centroid lies in the unrolled turn
        u = extended[tri, 0].mean(axis=1)
        inside &= (u >= -chart.turn / 2) & (u < chart.turn / 2)
    return original[tri[inside]], crowded, original[lost].reshape(-1, 2)


def _holes(chart, uv, radius, tri, constraints, crowded, droppable):
    """Points (uv, radius) to add where the triangulation is too coarse for the surface or the size:
    triangles whose chord strays more than DEVIATION x h from the curved patch, or acute ones whose
    circumradius exceeds HOLE x h (a bubble missing), and, on a conformal chart, the input's points that lie
    more than DEVIATION x h off the triangle over them (a cone's tip inside a triangle: the vertex itself is
    the point; a fold between two facets). The point is the circumcentre where it lies in its triangle,
    else the middle of its longest edge (the centroid when that edge is on the border); one per hole, none near
    a node or the border. A stray input point takes the place of the nearest ``droppable`` packing node (a mask
    over the first nodes of ``uv``) within MIN_GAP x h of it; the third value is their indices. Kept beside it, a
    probe on a fold left edges of 0.4 h across the fold and a flat cap of four surface nodes over it."""
    a, b, c = uv[tri[:, 0]], uv[tri[:, 1]], uv[tri[:, 2]]
    if chart.turn is not None:  # a triangle across the seam: its corners within half a turn of the first
        b, c = (
            x - np.column_stack([chart.turn * np.round((x[:, 0] - a[:, 0]) / chart.turn), 0 * x[:, 1]]) for x in (b, c)
        )
    la, lb, lc = (np.linalg.norm(b - c, axis=1), np.linalg.norm(c - a, axis=1), np.linalg.norm(a - b, axis=1))
    double_area = _cross2(b - a, c - a)
    h = 2 * radius[tri].mean(axis=1)
    ba, ca = b - a, c - a
    centre = a + np.column_stack(
        [ca[:, 1] * (ba**2).sum(1) - ba[:, 1] * (ca**2).sum(1), ba[:, 0] * (ca**2).sum(1) - ca[:, 0] * (ba**2).sum(1)]
    ) / (2 * double_area[:, None])
    wb, wc = _cross2(centre - a, c - a) / double_area, _cross2(b - a, centre - a) / double_area
    in_triangle = (wb >= 0) & (wc >= 0) & (wb + wc <= 1)
    # else the middle of the longest edge, unless it is a border edge: away from the border and the nodes
    longest = np.argmax(np.column_stack([la, lb, lc]), axis=1)
    ends = np.take_along_axis(tri, np.array([[1, 2], [2, 0], [0, 1]])[longest], axis=1)
    middle = np.choose(longest[:, None], [(b + c) / 2, (c + a) / 2, (a + b) / 2])
    on_border = np.isin(np.sort(ends, axis=1) @ [len(uv), 1], np.sort(constraints, axis=1) @ [len(uv), 1])
    point = np.where(in_triangle[:, None], centre, np.where(on_border[:, None], (a + b + c) / 3, middle))
    # an acute triangle's circumcircle is an empty disk inside the triangle: a hole when wider than HOLE h
    badness = np.where(in_triangle, la * lb * lc / np.maximum(2 * double_area, 1e-300) / (HOLE * h), 0.0)
    stray = np.zeros(len(point), bool)  # which points are the input's own (_stray_points)
    if chart.kind != "plane":
        lifted = chart.lift(point)
        corners = chart.lift(np.vstack([a, b, c])).reshape(3, -1, 3)
        normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
        deviation = np.abs(np.einsum("ij,ij->i", lifted - corners[0], normal))
        badness = np.fmax(badness, deviation / (DEVIATION * h * chart.scale(point)))  # h on the patch
        badness[np.isnan(lifted[:, 0])] = 0.0  # off a conformal chart's triangles: nowhere to put a node
        if chart.kind == "conformal":  # input vertices the triangles pass far from (a drill point's tip), and
            # points of the input edges they cut across (a coarse STL's fold between two facets of a fillet)
            far_uv, far_badness, far_h = _stray_points(chart, uv, tri, corners[0], normal, h)
            point, badness, h = (
                np.concatenate([point, far_uv]),
                np.concatenate([badness, far_badness]),
                np.concatenate([h, far_h]),
            )
            stray = np.r_[stray, np.ones(len(far_uv), bool)]
    big = np.flatnonzero(badness > 1)
    if len(big) == 0:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0, np.int64)
    big = big[np.argsort(-badness[big], kind="stable")]
    point, spacing, stray = point[big], h[big], stray[big]
    index = np.setdiff1d(np.arange(len(uv)), crowded)  # the nodes present, and then their copies across a seam
    present = uv[index]
    if chart.turn is not None:  # back into the turn; nodes across the seam count as neighbours
        point[:, 0] -= chart.turn * np.round(point[:, 0] / chart.turn)
        present = np.vstack([present, present + [chart.turn, 0.0], present - [chart.turn, 0.0]])
        index = np.tile(index, 3)
        # an edge across the seam spans the whole strip here: not a border to keep off
        constraints = constraints[np.abs(np.diff(uv[constraints, 0], axis=1)[:, 0]) < chart.turn / 2]
    movable = np.zeros(len(index), bool)
    movable[index < len(droppable)] = droppable[index[index < len(droppable)]]
    nearest = cKDTree(present).query(point)[0]
    nearest_fixed = cKDTree(present[~movable]).query(point)[0] if (~movable).any() else np.full(len(point), np.inf)
    keep = np.where(stray, nearest_fixed > STRAY_GAP * spacing, nearest > MIN_GAP * spacing)
    keep[
        _crowding(np.vstack([uv, point]), constraints, np.r_[np.zeros(len(uv), bool), keep], np.r_[2 * radius, spacing])
        - len(uv)
    ] = False
    point, spacing, stray = point[keep], spacing[keep], stray[keep]
    chosen = np.ones(len(point), bool)
    neighbours = cKDTree(point).query_ball_point(point, MIN_GAP * spacing)
    for i, near in enumerate(neighbours):  # one point per hole: the worst triangle's, which come first
        if chosen[i]:
            chosen[[j for j in near if j > i]] = False
    point, spacing, stray = point[chosen], spacing[chosen], stray[chosen]
    if stray.any() and movable.any():
        gap, nearest_movable = cKDTree(present[movable]).query(point[stray])
        taken = index[movable][nearest_movable[gap < MIN_GAP * spacing[stray]]]
    else:
        taken = np.zeros(0, np.int64)
    return point, spacing / 2, np.unique(taken)


def _stray_points(chart, uv, tri, corner, normal, h):
    """(uv, badness, h) of the conformal chart's probes (its input vertices and CREASE_PROBES points along its
    input edges) lying more than DEVIATION x h off the plane of the triangle of ``tri`` (over ``uv``) whose image
    holds them; ``corner`` and ``normal`` (t, 3): a lifted corner and the unit normal of each triangle, ``h``
    (t,) its size."""
    if not len(tri) or not len(chart.probe_uv):  # libigl's distance query reads past empty arrays (a segfault)
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0)
    flat = np.ascontiguousarray(np.column_stack([uv, np.zeros(len(uv))]))
    faces = np.ascontiguousarray(tri, dtype=np.int64)
    query = np.ascontiguousarray(np.column_stack([chart.probe_uv, np.zeros(len(chart.probe_uv))]))
    squared, face, _ = igl.point_mesh_squared_distance(query, flat, faces)
    inside = np.flatnonzero(squared <= chart.flat_tolerance**2)
    face = face[inside]
    off = np.abs(np.einsum("ij,ij->i", chart.probe_xyz[inside] - corner[face], normal[face]))
    badness = np.nan_to_num(off / (DEVIATION * h[face]))
    stray = badness > 1
    return chart.probe_uv[inside[stray]], badness[stray], h[face[stray]]


def _crowding(uv, edges, candidate, h) -> np.ndarray:
    """Rows of ``candidate`` nodes that encroach on a constrained edge (inside its diametral circle,
    where they would keep it out of the Delaunay triangulation) or lie within CROWDING x h of it."""
    rows = np.flatnonzero(candidate)
    if len(rows) == 0 or len(edges) == 0:
        return np.zeros(0, np.int64)
    a, b = uv[edges[:, 0]], uv[edges[:, 1]]
    _, near = cKDTree((a + b) / 2).query(uv[rows], k=min(4, len(edges)))
    near = near.reshape(len(rows), -1)
    start, span = a[near], (b - a)[near]
    x = uv[rows][:, None, :]
    t = np.clip(np.sum((x - start) * span, axis=2) / np.maximum(np.sum(span * span, axis=2), 1e-300), 0, 1)
    distance = np.linalg.norm(start + t[..., None] * span - x, axis=2)
    encroach = np.linalg.norm(start + 0.5 * span - x, axis=2) < 0.5 * np.linalg.norm(span, axis=2)
    return rows[((distance < CROWDING * h[rows][:, None]) | encroach).any(axis=1)]


class PatchChart:
    """A patch flattened: ``uv(points)`` orientation-preserving seen from outside, ``lift(uv)`` back onto
    the patch's input triangles. A plane is projected, a cylinder unrolled, a CAD face with a ``given`` chart
    (its own parameters, engine/facechart.py ``FaceChart``) mapped by it (and lifted onto the face itself), any other
    patch mapped by a least-squares conformal map of its input triangles. A full cylinder's strip, or a given
    chart's periodic one, is periodic (``turn``)."""

    def __init__(self, patch, geometry, given=None):
        mesh = geometry.mesh
        used, local = np.unique(mesh.faces[patch.faces], return_inverse=True)
        self.vertices = np.ascontiguousarray(mesh.vertices[used], dtype=np.float64)
        self.faces = np.ascontiguousarray(local.reshape(-1, 3), dtype=np.int64)
        self.tree = igl.AABB()
        self.tree.init(self.vertices, self.faces)
        self.patch, self.turn = patch, None
        if patch.planar:
            e1 = np.cross(patch.normal, np.eye(3)[np.argmin(np.abs(patch.normal))])
            e1 /= np.linalg.norm(e1)
            self.kind, self.origin, self.frame = (
                "plane",
                patch.centroid,
                np.column_stack([e1, np.cross(patch.normal, e1)]),
            )
        elif patch.cylinder is not None:
            c = patch.cylinder
            e1 = np.cross(c.axis, np.eye(3)[np.argmin(np.abs(c.axis))])
            e1 /= np.linalg.norm(e1)
            self.kind, self.cylinder, self.e1, self.e2 = "cylinder", c, e1, np.cross(c.axis, e1)
            self.sign = -1.0 if c.concave else 1.0  # outward normal -e_r on a concave patch: mirror
            # the seam in the widest empty sector of the patch, unless a triangle crosses it there
            self.middle, goes_round = seam(self._angle(self.vertices), self.faces)
            if goes_round:  # the patch goes round: a periodic strip (a keyed bore's 330 degrees does not)
                self.turn, self.middle = 2 * np.pi * c.radius, -np.pi
        elif given is not None:
            self.kind, self.given, self.turn = "parametric", given, given.turn
        else:
            self.kind = "conformal"
            self.vertex_uv = self._conformal_map(patch, geometry.source)
            self.flat = np.ascontiguousarray(np.column_stack([self.vertex_uv, np.zeros(len(self.vertex_uv))]))
            self.flat_tree = igl.AABB()  # the chart's triangles in the plane z = 0: exact point location
            self.flat_tree.init(self.flat, self.faces)
            self.flat_tolerance = ON_EDGE * float(np.linalg.norm(np.ptp(self.vertex_uv, axis=0)))
            edges = np.unique(
                np.sort(np.concatenate([self.faces[:, [0, 1]], self.faces[:, [1, 2]], self.faces[:, [2, 0]]]), axis=1),
                axis=0,
            )
            t = np.array(CREASE_PROBES)[None, :, None]  # the vertices and points along the input edges, where
            self.probe_uv, self.probe_xyz = (  # the facets fold: where chords stray from the patch
                np.vstack([x, (x[edges[:, :1]] * (1 - t) + x[edges[:, 1:]] * t).reshape(-1, x.shape[1])])
                for x in (self.vertex_uv, self.vertices)
            )

    def _angle(self, x):
        r = x - self.cylinder.point
        return np.arctan2(r @ self.e2, r @ self.e1)

    def uv(self, points: np.ndarray) -> np.ndarray:
        if self.kind == "plane":
            return (points - self.origin) @ self.frame
        if self.kind == "cylinder":
            c = self.cylinder
            theta = np.angle(np.exp(1j * (self._angle(points) - self.middle - np.pi)))
            return np.column_stack([self.sign * c.radius * theta, (points - c.point) @ c.axis])
        if self.kind == "parametric":
            return self.given.uv(points)
        # the nearest triangle's map, extended over its plane: a smoothed cut's node just off the patch (the cut
        # crosses facets) is mapped beyond the border rather than onto its nearest border point, where nodes of
        # one chain (or of two cuts meeting at a small angle) would share uv
        points = np.ascontiguousarray(points, dtype=np.float64)
        _, face, closest = self.tree.squared_distance(self.vertices, self.faces, points)
        corners = self.vertices[self.faces[face]]
        e1, e2, rel = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], points - corners[:, 0]
        g11, g12, g22, r1, r2 = _dot(e1, e1), _dot(e1, e2), _dot(e2, e2), _dot(rel, e1), _dot(rel, e2)
        det = g11 * g22 - g12 * g12
        flat = det <= 1e-12 * np.maximum(g11 * g22, 1e-300)  # a needle or a point: the nearest point's weights
        det = np.where(flat, 1.0, det)
        b, c = (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det
        weights = np.column_stack([1 - b - c, b, c])
        if flat.any():
            weights[flat] = igl.barycentric_coordinates(
                closest[flat], *(np.ascontiguousarray(corners[flat, i]) for i in range(3))
            )
        return np.einsum("ij,ijk->ik", weights, self.vertex_uv[self.faces[face]])

    def scale(self, uv: np.ndarray) -> np.ndarray:
        """(k,) lengths on the patch per length in the chart at ``uv`` (k, 2): a given chart's own, else 1 (a
        plane's and a cylinder's are isometric, a conformal map's is fitted to the patch's lengths)."""
        return self.given.scale(uv) if self.kind == "parametric" else np.ones(len(uv))

    def lift(self, uv: np.ndarray) -> np.ndarray:
        """Points on the patch's input triangles (a given chart's: on its CAD face) at ``uv`` (NaN rows where ``uv`` is
        off a conformal chart)."""
        if self.kind == "plane":
            x = self.origin + uv @ self.frame.T
        elif self.kind == "parametric":
            return self.given.lift(uv)
        elif self.kind == "cylinder":
            c = self.cylinder
            theta = uv[:, 0] / (self.sign * c.radius) + self.middle + np.pi
            x = (
                c.point
                + c.radius * (np.cos(theta)[:, None] * self.e1 + np.sin(theta)[:, None] * self.e2)
                + uv[:, 1:2] * c.axis
            )
        else:
            return self._lift_conformal(uv)
        _, _, closest = self.tree.squared_distance(self.vertices, self.faces, np.ascontiguousarray(x))
        return closest

    def _lift_conformal(self, uv):
        """The point of the input triangle whose chart image holds ``uv`` (located exactly by an AABB tree of
        the chart's triangles; the nearest centres in uv miss the long facets of a blend), NaN off the chart."""
        out = np.full((len(uv), 3), np.nan)
        if len(uv) == 0:
            return out
        query = np.ascontiguousarray(np.column_stack([uv, np.zeros(len(uv))]), dtype=np.float64)
        squared, face, closest = self.flat_tree.squared_distance(self.flat, self.faces, query)
        hit = squared <= self.flat_tolerance**2  # a border node's roundoff counts in
        corners = self.flat[self.faces[face[hit]]]
        weights = igl.barycentric_coordinates(closest[hit], *(np.ascontiguousarray(corners[:, i]) for i in range(3)))
        weights = np.clip(weights, 0.0, None)
        weights /= weights.sum(axis=1, keepdims=True)
        out[hit] = np.einsum("ij,ijk->ik", weights, self.vertices[self.faces[face[hit]]])
        return out

    def copies(self, uv: np.ndarray, radius: np.ndarray) -> list:
        """(rows, shift) of the nodes repeated one turn to the left and to the right of a periodic strip."""
        if self.turn is None:
            return []
        half = self.turn / 2
        span = min(half, SEAM_LAYERS * 2 * radius.max())
        return [
            (np.flatnonzero(uv[:, 0] < -half + span), np.array([self.turn, 0.0])),
            (np.flatnonzero(uv[:, 0] >= half - span), np.array([-self.turn, 0.0])),
        ]

    def _conformal_map(self, patch, source) -> np.ndarray:
        uv = conformal_map(self.vertices, self.faces)
        if uv is None:
            raise GeometryError(
                f"the smooth surface patch {describe(patch)} folds over or stretches when flattened",
                where=source,
                fix="lower geometry.feature_angle so that feature curves cut it",
            )
        return uv


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def _cross2(a, b):
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]


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


def _constrained_delaunay(uv, edges) -> np.ndarray:
    """Constrained Delaunay triangles (counter-clockwise) of ``uv`` with ``edges`` (k, 2) as edges, over the
    nodes' convex hull, by Triangle (libigl); Qhull's :func:`_delaunay` when constrained edges cross (Triangle
    would add their crossings as nodes) or two nodes share a place (Triangle would crash)."""
    if len(np.unique(uv, axis=0)) < len(uv):
        return _delaunay(uv)
    points, tri = igl.triangle.triangulate(
        np.ascontiguousarray(uv, dtype=np.float64), np.ascontiguousarray(edges, dtype=np.int64), flags="pcQ"
    )[:2]
    if len(points) != len(uv):
        return _delaunay(uv)
    flip = _signed_areas(uv, tri) < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    return tri


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


def _inside_regions(tri, constraints):
    """Triangles on the left of the directed constrained edges, flooded across the other edges,
    and the constrained edges missing from ``tri`` (then nothing is flooded). An edge constrained in
    both directions (a sharp crease that ends inside the patch) stays an edge but tells no side."""
    n = int(max(tri.max(initial=0), constraints.max(initial=0))) + 1
    half = np.stack([tri, np.roll(tri, -1, axis=1)], axis=2).reshape(-1, 2)  # directed edges, 3 per triangle
    owner = np.repeat(np.arange(len(tri)), 3)
    key = half[:, 0] * n + half[:, 1]
    forward = np.isin(key, constraints[:, 0] * n + constraints[:, 1])
    backward = np.isin(key, constraints[:, 1] * n + constraints[:, 0])
    crease = forward & backward  # a sharp crease that ends inside the patch: the patch on both sides
    link_blocked = forward | backward
    forward, backward = forward & ~crease, backward & ~crease
    lost = ~np.isin(constraints[:, 0] * n + constraints[:, 1], key) & ~np.isin(
        constraints[:, 1] * n + constraints[:, 0], key
    )
    if lost.any():
        return np.zeros(len(tri), bool), constraints[lost]
    twin_key = half[:, 1] * n + half[:, 0]
    order = np.argsort(key)
    at = np.clip(np.searchsorted(key[order], twin_key), 0, len(key) - 1)
    has_twin = key[order][at] == twin_key
    twin_owner = np.where(has_twin, owner[order][at], -1)
    link = has_twin & ~link_blocked
    graph = sparse.coo_matrix((np.ones(link.sum()), (owner[link], twin_owner[link])), shape=(len(tri),) * 2)
    count, region = csgraph.connected_components(graph, directed=False)
    votes_in = np.bincount(region[owner[forward]], minlength=count)
    votes_out = np.bincount(region[owner[backward]], minlength=count)
    if np.any((votes_in > 0) & (votes_out > 0)):
        raise RuntimeError("a patch triangulation region lies on both sides of its boundary")
    return (votes_in > 0)[region], constraints[lost]


def check_closed(triangles: np.ndarray) -> None:
    """Raise unless every edge is used by exactly two triangles, once in each direction."""
    directed = np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=2).reshape(-1, 2)
    keys, counts = np.unique(directed, axis=0, return_counts=True)
    n = int(triangles.max()) + 1 if len(triangles) else 0
    code = keys[:, 0] * n + keys[:, 1]
    twin = np.isin(keys[:, 1] * n + keys[:, 0], code)
    if np.any(counts != 1) or not np.all(twin):
        raise RuntimeError(
            f"the boundary triangulation is not a closed 2-manifold: {int(np.sum(counts != 1))} "
            f"repeated and {int(np.sum(~twin))} unmatched directed edges"
        )
