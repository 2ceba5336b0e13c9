"""The ``hex-core`` mesher, for hex-dominant meshes (issue 23): the grid packer's lattice kept as boxes.

After the hex-core meshers of Yamakawa & Shimada and the "indirect" hex-dominant recipes (Botella, Lévy & Ray,
2016): hexahedra are not re-found among Delaunay tetrahedra that smoothing and sliver removal have moved, they
are built from the lattice of the ``grid`` packer (:mod:`engine.packing.grid`) directly, and only the layer
between them and the rest of the solid is tetrahedralised.

1. The surface is triangulated as the ``delaunay`` mesher does (``surface.py``).
2. The core: every box of eight nodes that follow one another along the lattice's lines (the nodes whose two
   other frame coordinates are the same, in order along the third; grid nodes and the grid rows projected onto
   aligned planes and straight curves alike), with edges at most ``MAX_EDGE`` h and at least ``MIN_ASPECT`` of
   its longest, no other node in it or on it, and each face either a face of another box, or two surface
   triangles, or a face that gets a pyramid (3). And the wall hexahedra: a box face whose four corners' next
   nodes along the lines out of it are boundary nodes (the grid packer's wall nodes on a curved patch), joined
   to them.
3. Each core face that is neither gets a pyramid outward, its apex ``APEX_HEIGHT`` x the face's edge from it
   (lower where the surface is near); apexes closer than ``APEX_MERGE`` x the edge merge (two or three
   pyramids around a concave edge or corner of the core share the centre of the missing box). A box whose
   pyramid would leave the solid, come near the surface, hold a surface node or be of scaled Jacobian below
   ``PYRAMID_FLOOR`` leaves the core, in rounds, until every pyramid fits.
4. The boxes are split into their six Kuhn tetrahedra (around the diagonal from the low corner to the high
   one: every face is split along the diagonal from its low corner, the same on both sides of a face) and the
   pyramids into two along the same diagonal; surface triangle pairs on a box face are flipped to match.
5. The layer between (the solid less the core and its pyramids) is tetrahedralised by Gmsh's constrained
   Delaunay (HXT) with its boundary (the surface triangles and the pyramids' free sides) as constrained faces,
   with the volume nodes not in the core; Gmsh's optimiser, relocation of those nodes and face swaps improve
   it, the layer's boundary kept.

So :func:`engine.recombine.recombine` finds each box as eight nodes whose tets fill it and each pyramid as the
two tets behind a quad sharing their apex. A packing without the grid's lattice (any other packer), or a core
that does not make a valid mesh, is meshed by the ``delaunay`` mesher instead, and the stats say so.
"""

from __future__ import annotations

import logging
import time

import numpy as np
from scipy.spatial import cKDTree

from ..levels import STEINER
from ..mesh import FACES, TetMesh, signed_volumes
from ..packing import PATCH, VOLUME
from . import register_mesher
from .delaunay import mesh_delaunay
from .improve import FLOOR, gmsh_optimize, min_dihedrals, relocate, swap_bad_faces
from .surface import triangulate_boundary
from .tetra import canonical, compact, inside_by_boundary, orient, tetrahedralize, unfold_flat

log = logging.getLogger(__name__)

LATTICE_TOLERANCE = 2e-3  # x the level's cell: a coordinate this near a lattice value is on it (the grid's jitter)
MAX_EDGE = 2.1  # x the larger h of its nodes: a longer box edge jumps a gap in the lattice (two layers removed)
MIN_ASPECT = 0.2  # a box's shortest edge over its longest
APEX_HEIGHT = 0.5  # x the face's mean edge: a pyramid's height
APEX_MIN = 0.2  # x the face's mean edge: the lowest pyramid (where the surface is near)
APEX_CLEARANCE = 0.45  # a pyramid's height at most this x the distance from its face's centre to the nearest
# node in front of it; CLEARANCE_NODES nearest nodes are looked at
CLEARANCE_NODES = 12
APEX_JITTER = 1e-3  # x the face's mean edge: apexes are moved at random by up to this
APEX_SURFACE = 0.1  # x the face's mean edge: an apex at least this far from the surface
APEX_MERGE = 0.35  # x the face's mean edge: apexes closer than this merge
PYRAMID_FLOOR = 0.3  # the scaled Jacobian a core pyramid must reach (the gate asks 0.2)
NODE_CLEARANCE = 0.6  # x the face's mean edge: volume nodes of the layer this near an apex are left out
LAYER_FLOOR = 8.0  # deg: a layer tet below this after the improvement takes the boxes at its nodes out of the core
WALL_JITTER = 1e-4  # x h: a curved patch's node off every box is moved by up to this (back onto the surface)
CORE_ROUNDS = 60  # rounds of dropping the boxes whose pyramids do not fit
# the box's corners: 0 low, 1 +x, 2 +x+y, 3 +y, 4 +z, 5 +x+z, 6 +x+y+z, 7 +y+z (VTK's hexahedron order)
KUHN_TETS = np.array([[0, 1, 2, 6], [0, 2, 3, 6], [0, 1, 5, 6], [0, 4, 5, 6], [0, 3, 7, 6], [0, 4, 7, 6]])
# faces, outward, each split along its nodes 0-2 (the Kuhn diagonal): -z, +z, -y, +x, +y, -x
KUHN_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [3, 7, 6, 2], [0, 4, 7, 3]])


@register_mesher("hex-core")
def mesh_hexcore(packing, geometry, features, *, seed: int = 0) -> TetMesh:
    """Module docstring. Falls back to :func:`engine.meshing.delaunay.mesh_delaunay` without a lattice."""
    lattice = packing.stats.get("grid") if packing.stats else None
    if lattice is None:
        return _fallback(packing, geometry, features, seed, "the packing has no grid lattice")
    try:
        return _mesh(packing, geometry, features, seed, lattice)
    except _NoCore as error:
        try:  # without the wall hexahedra
            mesh = _mesh(packing, geometry, features, seed, lattice, walls=False)
            mesh.stats["hex_core"]["walls_left_out"] = str(error)
            return mesh
        except _NoCore:
            pass
        return _fallback(packing, geometry, features, seed, str(error))
    except RuntimeError as error:  # Gmsh could not tetrahedralise the layer
        return _fallback(packing, geometry, features, seed, f"the layer between the core and the surface: {error}")


class _NoCore(Exception):
    pass


def _fallback(packing, geometry, features, seed, why):
    log.info("hex-core: %s; the delaunay mesher meshes the nodes", why)
    mesh = mesh_delaunay(packing, geometry, features, seed=seed)
    mesh.stats["hex_core"] = {"boxes": 0, "fallback": why}
    return mesh


def _mesh(packing, geometry, features, seed, lattice, walls=True):
    seconds = {}
    start = time.perf_counter()
    surface = triangulate_boundary(packing, geometry, features)
    nodes = surface.nodes
    keep = np.ones(len(nodes), bool)
    keep[surface.dropped] = False
    unused = np.ones(len(nodes), bool)
    unused[surface.triangles] = False
    keep[unused & (nodes.level != VOLUME)] = False
    points = nodes.points.copy()
    h = 2 * nodes.radius
    triangles = surface.triangles.copy()
    seconds["surface"] = time.perf_counter() - start

    start = time.perf_counter()
    frame = np.asarray(lattice["frame"], float)
    from ..packing.grid import Warp

    warp = Warp(lattice.get("warp", [[[], []]] * 3))
    local, on_lattice = _snap(points @ frame.T, np.asarray(lattice["origin"], float), lattice["size"], warp)
    del on_lattice  # the grid's jitter stays: the layer's Delaunay meets no four co-circular coplanar nodes
    boxes = _boxes(local, keep, h, geometry.scale)
    boxes = boxes[_empty(local, boxes, keep)]
    walls = _wall_boxes(points, local, keep, nodes.level, boxes, h, geometry.scale) if walls else boxes[:0]
    walls = walls[_empty(local, walls, keep)]
    # the curved patches' nodes off no box are moved by up to WALL_JITTER h, back onto the surface: four wall
    # nodes on two lines along a cylinder's axis are coplanar and cocircular, and the layer's constrained
    # Delaunay may split such a quad along the other diagonal
    curved = np.zeros(len(points), bool)
    planar = np.array([p.planar for p in features.patches] + [True])
    curved[(nodes.level == PATCH) & ~planar[np.where(nodes.level == PATCH, nodes.entity, -1)]] = True
    moved = np.zeros(len(points), bool)
    jitter = np.random.default_rng(seed).uniform(-WALL_JITTER, WALL_JITTER, points.shape) * h[:, None]
    found = len(boxes)
    boxes = np.unique(np.vstack([boxes, walls]), axis=0)
    core = _Core(points, local, boxes, triangles, nodes.level, keep, geometry)
    rounds, seconds["core"], seconds["layer"] = 0, 0.0, 0.0
    while True:
        rounds = _settle(core, points, rounds)
        seconds["core"] += time.perf_counter() - start
        start = time.perf_counter()
        move = curved & ~moved
        move[core.boxes.ravel()] = False
        if move.any():
            points[move] = geometry.closest_point(points[move] + jitter[move])[0]
            moved |= move
        triangles = core.flipped_triangles()
        layer_boundary, _ = core.layer_boundary(triangles)
        all_points = np.vstack([points, core.apexes])
        free = keep & (nodes.level == VOLUME)
        free[core.boxes.ravel()] = False
        free[core.crowded] = False
        free = np.concatenate([free, np.zeros(len(core.apexes), bool)])
        layer_tets, layer_points, steiner = _layer(all_points, layer_boundary, free, seed)
        seconds["layer"] += time.perf_counter() - start
        start = time.perf_counter()
        # a layer tet still below LAYER_FLOOR: the boxes and pyramids at its nodes leave the core
        worst = min_dihedrals(layer_points, layer_tets) if len(layer_tets) else np.zeros(0)
        bad = np.unique(layer_tets[worst < LAYER_FLOOR])
        drop = np.flatnonzero(np.isin(core.boxes, bad).any(axis=1))
        drop = np.union1d(drop, core.pyramid_box[np.isin(core.pyramids[:, 4], bad)])
        if len(drop) == 0 or rounds >= CORE_ROUNDS:
            break
        core.drop(drop)
        rounds += 1
    n0 = len(points)
    level = np.concatenate([nodes.level, np.full(len(core.apexes), STEINER)]).astype(np.int8)
    entity = np.concatenate([nodes.entity, np.full(len(core.apexes), -1)]).astype(np.int64)
    bubble = np.concatenate(
        [nodes.ids if nodes.ids is not None else np.full(n0, -1), np.full(len(core.apexes), -1)]
    ).astype(np.int64)
    box_tets = core.boxes[:, KUHN_TETS].reshape(-1, 4)
    pyramid_tets = core.pyramid_tets()
    fixed_tets = orient(all_points, np.vstack([box_tets, pyramid_tets]))[0]

    all_points = layer_points
    level = np.concatenate([level, np.full(steiner, STEINER)]).astype(np.int8)
    entity = np.concatenate([entity, np.full(steiner, -1)]).astype(np.int64)
    bubble = np.concatenate([bubble, np.full(steiner, -1)]).astype(np.int64)
    tets = np.vstack([fixed_tets, layer_tets])
    _check(all_points, tets, triangles)
    tets = canonical(tets)
    points_out, tets, level, entity, bubble, renumber = compact(all_points, tets, level, entity, bubble)
    boundary = renumber[triangles]
    order = np.argsort(surface.patch, kind="stable")
    stats = {
        "boundary_triangles": len(boundary),
        "crowded_surface_nodes_dropped": len(surface.dropped),
        "steiner_points": steiner,
        "hex_core": {
            "boxes": len(core.boxes),
            "lattice_boxes": found,
            "wall_boxes": len(boxes) - found,  # wall hexahedra found (not boxes of the lattice already)
            "pyramids": len(core.pyramids),
            "apexes": len(core.apexes),
            "boxes_left_out": core.left_out,
            "layer_tets": len(layer_tets),
            "layer_min_dihedral": float(min_dihedrals(all_points, layer_tets).min()) if len(layer_tets) else None,
        },
        "seconds": {k: round(v, 3) for k, v in seconds.items()},
    }
    return TetMesh(
        points=points_out,
        tets=tets,
        node_level=level,
        node_entity=entity,
        stats=stats,
        boundary=boundary[order],
        boundary_patch=surface.patch[order],
        node_bubble=bubble,
    )


def _settle(core, points, rounds) -> int:
    """Drop boxes until every pyramid fits and none crosses the surface or another (module docstring, 3)."""
    while True:
        while core.settle():
            rounds += 1
            if rounds == CORE_ROUNDS or len(core.boxes) == 0:
                raise _NoCore(f"the core did not settle in {rounds} rounds ({len(core.boxes)} boxes left)")
        if len(core.boxes) == 0:
            raise _NoCore("no lattice box fits in the solid")
        layer_boundary, owner = core.layer_boundary(core.flipped_triangles())
        crossing = _crossing(np.vstack([points, core.apexes]), layer_boundary)
        crossing = crossing[owner[crossing] >= 0]  # a pyramid's side crosses the surface or another pyramid
        if len(crossing) == 0:
            return rounds
        core.drop(np.unique(core.pyramid_box[owner[crossing]]))
        rounds += 1
        if rounds >= CORE_ROUNDS:
            raise _NoCore(f"the core's pyramids still cross after {rounds} rounds")


def _snap(local, origin, root, warp):
    """(frame coordinates with the lattice values exact, (n, 3) whether each is a lattice value)."""
    xi = warp.inverse(local)
    u = (xi - origin) / root
    out = xi.copy()
    on = np.zeros(local.shape, bool)
    for level in range(16):
        v = u * 2**level - 0.5
        near = (np.abs(v - np.round(v)) < LATTICE_TOLERANCE) & ~on
        exact = origin + (np.round(v) + 0.5) * root / 2**level
        out = np.where(near, exact, out)
        on |= near
    return np.where(on, warp(out), local), on


def _next_along(local, keep, axis, quantum):
    """(n,) the next kept node along ``axis`` on its lattice line (same other two coordinates), -1 if none."""
    other = [k for k in range(3) if k != axis]
    idx = np.flatnonzero(keep)
    key = np.round(local[idx][:, other] / quantum).astype(np.int64)
    order = np.lexsort((local[idx, axis], key[:, 1], key[:, 0]))
    sorted_idx, sorted_key = idx[order], key[order]
    same = (sorted_key[1:] == sorted_key[:-1]).all(axis=1)
    out = np.full(len(local), -1, np.int64)
    out[sorted_idx[:-1][same]] = sorted_idx[1:][same]
    return out


def _boxes(local, keep, h, scale):
    """(b, 8) the lattice boxes (module docstring, 2), corners in KUHN_TETS' order."""
    quantum = 1e-7 * scale
    nx, ny, nz = (_next_along(local, keep, axis, quantum) for axis in range(3))
    a = np.flatnonzero((nx >= 0) & (ny >= 0) & (nz >= 0))

    def step(table, at):
        out = np.full(len(at), -1, np.int64)
        ok = at >= 0
        out[ok] = table[at[ok]]
        return out

    b, d, e = nx[a], ny[a], nz[a]
    c, f, hh = step(ny, b), step(nz, b), step(nz, d)
    g = step(nz, c)
    ok = (c >= 0) & (f >= 0) & (hh >= 0) & (g >= 0)
    ok &= (step(nx, d) == c) & (step(nx, e) == f) & (step(ny, e) == hh) & (step(ny, f) == g) & (step(nx, hh) == g)
    boxes = np.column_stack([a, b, c, d, e, f, g, hh])[ok]
    extent = local[boxes[:, 6]] - local[boxes[:, 0]]  # the box's three edge lengths
    longest, shortest = extent.max(axis=1), extent.min(axis=1)
    size = h[boxes].max(axis=1)
    good = (longest <= MAX_EDGE * size) & (shortest >= MIN_ASPECT * longest)
    return boxes[good]


# a box's corners by their bits along the frame axes (KUHN_TETS' order)
BITS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
BIT_INDEX = {tuple(b): i for i, b in enumerate(BITS.tolist())}


def _wall_boxes(points, local, keep, level, boxes, h, scale):
    """(w, 8) the wall hexahedra: a box face whose four corners' next nodes along the lattice's line out of the
    box (the axis at right angles to the face) are all boundary nodes (the grid packer's wall nodes, or any
    node of a patch that the lines end on) within MAX_EDGE h, joined to them; the corners in KUHN_TETS' order by
    their bits, so the Kuhn split matches the box's. Kept when each of its Kuhn tets is oriented as in a box
    and its scaled Jacobian is at least PYRAMID_FLOOR."""
    if len(boxes) == 0:
        return np.zeros((0, 8), np.int64)
    quantum = 1e-7 * scale
    out = []
    for k in range(3):
        forward = _next_along(local, keep, k, quantum)
        backward = np.full(len(local), -1, np.int64)
        backward[forward[forward >= 0]] = np.flatnonzero(forward >= 0)
        for side, step in ((1, forward), (0, backward)):
            # the box's corners on that side, in the new hexahedron's corners on the other
            new = np.zeros((len(boxes), 8), np.int64)
            ok = np.ones(len(boxes), bool)
            for i, bits in enumerate(BITS.tolist()):
                source = list(bits)
                source[k] = side
                corner = boxes[:, BIT_INDEX[tuple(source)]]
                if bits[k] == side:  # out on the wall
                    nxt = step[corner]
                    ok &= nxt >= 0
                    nxt = np.maximum(nxt, 0)
                    ok &= level[nxt] != VOLUME
                    ok &= np.abs(local[nxt, k] - local[corner, k]) <= MAX_EDGE * h[corner]
                    new[:, i] = nxt
                else:
                    new[:, i] = corner
            out.append(new[ok])
    walls = np.unique(np.concatenate(out).reshape(-1, 8), axis=0)
    if len(walls) == 0:
        return walls
    tets = walls[:, KUHN_TETS].reshape(-1, 4)
    volume = signed_volumes(points, tets).reshape(-1, 6) * signed_volumes(BITS.astype(float), KUHN_TETS)
    positive = (volume > 0).all(axis=1)  # each Kuhn tet oriented as in the unit box: none flat or folded
    from ..recombine import HEX, cell_qualities

    good = positive & (cell_qualities(points, walls, HEX) >= PYRAMID_FLOOR)
    return walls[good]


def _empty(local, boxes, keep):
    """Whether each box holds no kept node other than its corners, in it or on its faces."""
    if len(boxes) == 0:
        return np.zeros(0, bool)
    lo, hi = local[boxes[:, 0]], local[boxes[:, 6]]
    centre, radius = 0.5 * (lo + hi), 0.5 * np.linalg.norm(hi - lo, axis=1)
    idx = np.flatnonzero(keep)
    tree = cKDTree(local[idx])
    near = tree.query_ball_point(centre, radius * (1 + 1e-9))
    counts = np.array([len(x) for x in near])
    rows = np.repeat(np.arange(len(boxes)), counts)
    nodes = idx[np.concatenate(near).astype(np.int64)] if counts.sum() else np.zeros(0, np.int64)
    tol = 1e-9 * radius[rows, None]
    inside = np.all((local[nodes] >= lo[rows] - tol) & (local[nodes] <= hi[rows] + tol), axis=1)
    inside &= ~(boxes[rows] == nodes[:, None]).any(axis=1)
    return np.bincount(rows[inside], minlength=len(boxes)) == 0


class _Core:
    """The boxes and their pyramids, settled in rounds (module docstring, 3)."""

    def __init__(self, points, local, boxes, triangles, level, keep, geometry):
        self.points, self.local, self.boxes = points, local, boxes
        self.level, self.keep, self.geometry = level, keep, geometry
        self.found = len(boxes)
        self.left_out = 0
        self.surface_keys = _keys(triangles)
        self.triangles = triangles
        self.apexes = np.zeros((0, 3))
        self.pyramids = np.zeros((0, 5), np.int64)
        self.crowded = np.zeros(0, np.int64)

    def faces(self):
        """(face nodes (6b, 4) outward Kuhn-split, box (6b,), kind (6b,): 0 shared, 1 surface as split,
        2 surface the other way, 3 open)."""
        faces = self.boxes[:, KUHN_FACES].reshape(-1, 4)
        box = np.repeat(np.arange(len(self.boxes)), 6)
        _, inverse, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
        kind = np.full(len(faces), 3, np.int8)
        kind[counts[inverse.ravel()] == 2] = 0
        for k, (first, second) in ((1, ([0, 1, 2], [0, 2, 3])), (2, ([0, 1, 3], [1, 2, 3]))):
            on = np.isin(_keys(faces[:, first]), self.surface_keys)
            on &= np.isin(_keys(faces[:, second]), self.surface_keys)
            kind[on & (kind == 3)] = k
        return faces, box, kind

    def settle(self) -> bool:
        """One round: pyramids on the open faces; drop the boxes whose pyramids do not fit. Whether any dropped."""
        faces, box, kind = self.faces()
        open_ = np.flatnonzero(kind == 3)
        if len(open_) == 0:  # the boxes fill the solid
            self.apexes, self.pyramids, self.crowded = np.zeros((0, 3)), np.zeros((0, 5), np.int64), np.zeros(0, int)
            self.pyramid_box = np.zeros(0, np.int64)
            return False
        quads = faces[open_]
        corner = self.points[quads]
        centre = corner.mean(axis=1)
        edge = np.linalg.norm(corner - np.roll(corner, 1, axis=1), axis=2).mean(axis=1)
        normal = np.cross(corner[:, 2] - corner[:, 0], corner[:, 3] - corner[:, 1])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        height = np.minimum(APEX_HEIGHT * edge, APEX_CLEARANCE * self._clearance(centre, normal, edge))
        bad = height < APEX_MIN * edge
        apex = centre + height[:, None] * normal
        _, distance, _ = self.geometry.closest_point(apex)
        bad |= ~self.geometry.contains(apex) | (distance < APEX_SURFACE * edge)
        # merge apexes closer than APEX_MERGE x the edge
        label = _clusters(apex, APEX_MERGE * edge)
        merged = np.zeros((label.max() + 1 if len(label) else 0, 3))
        np.add.at(merged, label, apex)
        merged /= np.bincount(label, minlength=len(merged))[:, None]
        # apexes off the planes of the lattice (a plate's side faces put them all at mid-thickness, with the
        # surface nodes there: flat tets in the layer); deterministic
        scale = np.zeros(len(merged))
        np.maximum.at(scale, label, edge)
        merged += APEX_JITTER * scale[:, None] * np.random.default_rng(len(merged)).uniform(-1, 1, merged.shape)
        pyramids = np.column_stack([quads, len(self.points) + label])
        work = np.vstack([self.points, merged])
        from ..recombine import PYRAMID, cell_qualities

        # VTK's pyramid: the base counter-clockwise seen from the apex, as the box's outward face is
        quality = cell_qualities(work, pyramids, PYRAMID)
        bad |= quality < PYRAMID_FLOOR
        # nodes in a pyramid, or near its apex: volume nodes are left out, anything else ends the box
        crowded, hit = self._in_pyramids(work, pyramids, edge)
        bad[hit] = True
        drop = np.unique(box[open_[bad]])
        if len(drop):
            self.drop(drop)
            return True
        self.apexes, self.pyramids, self.crowded = merged, pyramids, crowded
        self.pyramid_box = box[open_]
        return False

    def _clearance(self, centre, normal, edge):
        """(f,) the distance from each open face's centre to the nearest node in front of it (another box's
        corner too: across a change of octree level the two sides' pyramids share the gap)."""
        idx = np.flatnonzero(self.keep)
        out = np.full(len(centre), np.inf)
        if len(idx) == 0:
            return out
        distance, near = cKDTree(self.points[idx]).query(centre, k=min(CLEARANCE_NODES, len(idx)))
        distance, near = distance.reshape(len(centre), -1), near.reshape(len(centre), -1)
        ahead = np.einsum("fkj,fj->fk", self.points[idx[near]] - centre[:, None], normal) > 0.05 * edge[:, None]
        return np.where(ahead, distance, np.inf).min(axis=1)

    def _in_pyramids(self, work, pyramids, edge):
        """(volume nodes to leave out, pyramids that hold or crowd another kind of node)."""
        idx = np.flatnonzero(self.keep)
        tree = cKDTree(work[idx])
        apex = work[pyramids[:, 4]]
        near = tree.query_ball_point(apex, NODE_CLEARANCE * edge)
        counts = np.array([len(x) for x in near], np.int64)
        rows = np.repeat(np.arange(len(pyramids)), counts)
        hits = idx[np.concatenate(near).astype(np.int64)] if counts.sum() else np.zeros(0, np.int64)
        own = (pyramids[rows, :4] == hits[:, None]).any(axis=1)
        rows, hits = rows[~own], hits[~own]
        in_core = np.zeros(len(self.points), bool)
        in_core[self.boxes.ravel()] = True
        volume = (self.level[hits] == VOLUME) & ~in_core[hits]
        crowded = np.unique(hits[volume])
        # other nodes: those inside the pyramid (its five faces) end it, those merely near do not
        rows, hits = rows[~volume], hits[~volume]
        inside = np.ones(len(rows), bool)
        p = work[hits]
        base, top = pyramids[rows, :4], pyramids[rows, 4]
        centroid = (work[base].sum(axis=1) + work[top]) / 5
        for a, b, c in ((0, 1, 2), (0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)):
            nodes = np.column_stack([base, top])
            pa, pb, pc = work[nodes[:, a]], work[nodes[:, b]], work[nodes[:, c]]
            n = np.cross(pb - pa, pc - pa)
            inward = np.sign(np.einsum("ij,ij->i", n, centroid - pa))
            inside &= inward * np.einsum("ij,ij->i", n, p - pa) > -1e-9 * edge[rows] ** 2
        return crowded, np.unique(rows[inside])

    def flipped_triangles(self):
        """The surface triangles, those on a box face split along its Kuhn diagonal."""
        faces, _, kind = self.faces()
        other = faces[kind == 2]
        if len(other) == 0:
            return self.triangles
        order = np.argsort(self.surface_keys, kind="stable")
        first = order[np.searchsorted(self.surface_keys, _keys(other[:, [0, 1, 3]]), sorter=order)]
        second = order[np.searchsorted(self.surface_keys, _keys(other[:, [1, 2, 3]]), sorter=order)]
        out = self.triangles.copy()
        out[first] = other[:, [0, 1, 2]]
        out[second] = other[:, [0, 2, 3]]
        return out

    def pyramid_tets(self):
        """Two tets per pyramid along its base's Kuhn diagonal (the outward face's nodes 0-2)."""
        if len(self.pyramids) == 0:
            return np.zeros((0, 4), np.int64)
        q, apex = self.pyramids[:, :4], self.pyramids[:, 4]
        return np.vstack([np.column_stack([q[:, [0, 1, 2]], apex]), np.column_stack([q[:, [0, 2, 3]], apex])])

    def layer_boundary(self, triangles):
        """The layer's boundary, outward from it: the surface triangles not on a box, the pyramids' free sides
        (towards the pyramid)."""
        faces, _, kind = self.faces()
        on_box = faces[(kind == 1) | (kind == 2)]
        rest = ~np.isin(_keys(triangles), _keys(np.vstack([on_box[:, [0, 1, 2]], on_box[:, [0, 2, 3]]])))
        q, apex = self.pyramids[:, :4], self.pyramids[:, 4]
        sides = np.vstack([np.column_stack([q[:, i], q[:, (i + 1) % 4], apex]) for i in range(4)])
        # outward from the layer = into the pyramid: the outward quad runs (0, 1, 2, 3), so (q[i+1], q[i], apex)
        sides = sides[:, [1, 0, 2]]
        pyramid = np.tile(np.arange(len(q)), 4)
        _, inverse, counts = np.unique(np.sort(sides, axis=1), axis=0, return_inverse=True, return_counts=True)
        once = counts[inverse.ravel()] == 1
        owner = np.concatenate([np.full(int(rest.sum()), -1), pyramid[once]])
        return np.vstack([triangles[rest], sides[once]]), owner

    def drop(self, boxes) -> None:
        self.boxes = np.delete(self.boxes, boxes, axis=0)
        self.left_out += len(boxes)


def _crossing(points, triangles) -> np.ndarray:
    """The triangles that intersect another one other than along a shared edge or node (CGAL, via libigl)."""
    from igl.copyleft.cgal import remesh_self_intersections

    if len(triangles) == 0:
        return np.zeros(0, np.int64)
    used = np.unique(triangles)
    new = np.full(len(points), -1, np.int64)
    new[used] = np.arange(len(used))
    pairs = remesh_self_intersections(
        np.ascontiguousarray(points[used], float), new[triangles], detect_only=True, cutoff=len(triangles)
    )[2]
    return np.unique(pairs.ravel())


def _keys(triangles) -> np.ndarray:
    """(t,) one integer per triangle, the same for its nodes in any order (node indices below 2**21)."""
    t = np.sort(np.asarray(triangles, np.int64).reshape(-1, 3), axis=1)
    if len(t) and t.max() >= 2**21:
        raise _NoCore("more than 2**21 nodes")
    return (t[:, 0] << 42) | (t[:, 1] << 21) | t[:, 2]


def _clusters(points, radius):
    """(n,) cluster labels: points closer than the smaller of their two radii share one (transitively)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(points) == 0:
        return np.zeros(0, np.int64)
    pairs = cKDTree(points).query_pairs(float(radius.max()), output_type="ndarray")
    if len(pairs):
        d = np.linalg.norm(points[pairs[:, 0]] - points[pairs[:, 1]], axis=1)
        pairs = pairs[d < np.minimum(radius[pairs[:, 0]], radius[pairs[:, 1]])]
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(points),) * 2)
    return connected_components(graph, directed=False)[1].astype(np.int64)


def _layer(points, boundary, free, seed):
    """(tets of the layer, points with Steiner points after them, Steiner count): module docstring, 5."""
    n = len(points)
    if len(boundary) == 0:  # no layer: the core fills the solid
        return np.zeros((0, 4), np.int64), points, 0
    used = np.zeros(n, bool)
    used[boundary.ravel()] = True
    used |= free
    nodes = np.flatnonzero(used)
    new = np.full(n, -1, np.int64)
    new[nodes] = np.arange(len(nodes))
    local_boundary = new[boundary]
    tets, steiner = tetrahedralize(points[nodes], local_boundary)
    work = np.vstack([points[nodes], steiner])
    tets = unfold_flat(work, tets[inside_by_boundary(work, tets, local_boundary)])
    tets = canonical(orient(work, tets)[0])
    fixed = np.concatenate([~free[nodes], np.zeros(len(steiner), bool)])
    optimised, moved = gmsh_optimize(work, tets, fixed)
    if _faces(moved, local_boundary) and signed_volumes(optimised, moved).min() > 0:
        work, tets = optimised, canonical(moved)
    slide = np.where(fixed[:, None], np.nan, 0.0) * np.ones((1, 3))
    work, _ = relocate(work, tets, slide, seed)
    tets, _ = swap_bad_faces(work, tets, FLOOR)
    # back to the numbering of ``points``, Steiner points after them
    index = np.concatenate([nodes, n + np.arange(len(steiner))])
    out_points = np.vstack([points, work[len(nodes) :]])
    out_points[nodes] = work[: len(nodes)]
    return index[tets], out_points, len(steiner)


def _faces(tets, boundary) -> bool:
    """Whether every boundary triangle is a face of the tets, and they have no other boundary faces."""
    keys, counts = np.unique(_keys(tets[:, FACES]), return_counts=True)
    return np.array_equal(keys[counts == 1], np.unique(_keys(boundary)))


def _check(points, tets, triangles):
    """The core, its pyramids and the layer make one valid mesh bounded by the surface triangles."""
    if len(tets) == 0 or signed_volumes(points, tets).min() <= 0:
        raise _NoCore("the core and the layer have a non-positive tet")
    if not _faces(tets, triangles):
        raise _NoCore("the core and the layer do not conform to the surface triangles")
    p = points[triangles]
    enclosed = np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6
    if abs(signed_volumes(points, tets).sum() / enclosed - 1) > 1e-9:
        raise _NoCore("the core and the layer overlap")
