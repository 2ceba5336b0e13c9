"""Features of a solid: corners, feature curves and surface patches.

Feature curves are chains of sharp edges (dihedral angle between the face
normals above ``feature_angle``). Corners are where curves meet or end, or
where a curve turns sharply. Patches are the connected groups of faces
bounded by feature curves. Every feature has a stable id (``corner-3``,
``curve-0``, ``patch-5``), derived deterministically from the surface, and a
name where a shape or a recognition rule gives one. Curves are parametrised by
arc length; closed circular curves carry centre, axis and radius.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field, replace

import igl
import numpy as np
from scipy import sparse
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from .errors import GeometryError
from .fitting import (
    CIRCLE_TOLERANCE,
    Circle,
    Cylinder,
    Torus,
    cylinder_about,
    fit_circle,
    fit_cylinder,
    fit_torus,
    torus_kind,
    tube_sweep,
)
from .geometry import Geometry
from .mesh import triangle_edges

NAMES_LISTED = 12  # feature names a log line or an error lists at most
FLAT = 1e-7  # x the model size: a patch whose vertices all lie this near its mean plane is a plane (a CAD
# tessellation's plane faces: 1e-9 to 1e-8, the coordinates' precision; at 1e-9 an outside test's bracket's
# sides were "cylinders" of radius 1.8e8 and so concave fillets)


@dataclass(frozen=True, kw_only=True)
class Corner:
    id: str
    vertex: int
    point: np.ndarray
    names: list[str] = field(default_factory=list)


@dataclass(frozen=True, kw_only=True)
class Curve:
    """A polyline on (or, when given by a shape, inside) the solid."""

    id: str
    points: np.ndarray  # (n, 3) ordered; a closed curve does not repeat its first point
    closed: bool
    vertices: np.ndarray | None  # the surface vertices it runs through, in order (None for a given curve);
    # the points are these but for a smooth cut's zigzag (_unzigzagged)
    convex: bool | None = None  # None for a given curve
    dihedral: float | None = None  # median angle between the face normals along it, degrees; None for a given curve
    circle: Circle | None = None
    names: list[str] = field(default_factory=list)
    on_surface: bool = True
    sharp: bool = True  # False for borders of face groups that meet smoothly
    kinds: list[str] = field(default_factory=list)

    @property
    def polyline(self) -> np.ndarray:
        return np.vstack([self.points, self.points[:1]]) if self.closed else self.points

    @property
    def arc_length(self) -> np.ndarray:
        """Cumulative arc length at each point of :attr:`polyline`."""
        seg = np.linalg.norm(np.diff(self.polyline, axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(seg)])

    @property
    def length(self) -> float:
        return float(self.arc_length[-1])

    def parameter(self, points: np.ndarray) -> np.ndarray:
        """Arc length (k,) of the closest point on the curve to each of ``points`` (k, 3): exact (libigl AABB
        over its segments), in [0, length) on a closed curve, so a point at its seam is at 0, not at its length."""
        line = np.ascontiguousarray(self.polyline, dtype=np.float64)
        points = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        if len(points) == 0:
            return np.zeros(0)
        segments = np.column_stack([np.arange(len(line) - 1), np.arange(1, len(line))]).astype(np.int64)
        _, segment, closest = igl.point_mesh_squared_distance(points, line, segments)
        s = self.arc_length[segment] + np.linalg.norm(closest - line[segment], axis=1)
        return np.mod(s, self.length) if self.closed else s

    def point_at(self, s: np.ndarray) -> np.ndarray:
        """Points at arc lengths ``s`` (clipped to [0, length]; wrapped if closed)."""
        s = np.asarray(s, dtype=float)
        total = self.length
        s = np.mod(s, total) if self.closed else np.clip(s, 0.0, total)
        knots = self.arc_length
        seg = np.clip(np.searchsorted(knots, s, side="right") - 1, 0, len(knots) - 2)
        span = np.maximum(knots[seg + 1] - knots[seg], 1e-300)
        t = ((s - knots[seg]) / span)[..., None]
        line = self.polyline
        return (1 - t) * line[seg] + t * line[seg + 1]


@dataclass(frozen=True, kw_only=True)
class Patch:
    id: str
    faces: np.ndarray
    area: float
    normal: np.ndarray  # area-weighted mean unit normal
    centroid: np.ndarray
    vertices: np.ndarray  # (k, 3) coordinates of the patch's vertices
    planar: bool
    cylinder: Cylinder | None = None
    names: list[str] = field(default_factory=list)
    kinds: list[str] = field(default_factory=list)
    circle: Circle | None = None  # a toroidal blend's tube: its radius is the blend's
    torus: Torus | None = None  # the torus an STL patch's facets fit (a CAD face's is its exact surface)
    surface: str | None = None  # the CAD face type (Plane, Cylinder, Torus, BSpline surface on Cone, ...), CAD only


@dataclass(frozen=True, kw_only=True)
class Features:
    """The features of one solid: a value (the stages after detection derive changed ones with
    ``dataclasses.replace``: kinds by :func:`classify`, names by :func:`apply_names`, a CAD file's exact
    surfaces and assembly by engine/cad.py), never changed in place."""

    corners: list[Corner]
    curves: list[Curve]
    patches: list[Patch]
    face_patch: np.ndarray  # patch index of every surface face
    feature_angle: float
    lengths: dict = field(default_factory=dict)  # characteristic lengths given by a shape
    exact: tuple | None = None  # (per patch, per curve) exact surfaces / curves given by the input (CAD), each
    # with .project(points); None: fitted from the facets (engine/exact.py)
    assembly: object | None = None  # touching solids of a CAD file (engine/cad.py ``Assembly``): meshed body by
    # body with conforming interfaces (engine/assembly.py); None for one solid or solids apart
    charts: tuple = ()  # per patch, the chart its surface triangulation is made in when the input gives one (a
    # CAD face's own parameters: engine/facechart.py ``FaceChart``), else None; empty: none given

    def named(self, name: str) -> list:
        """All features carrying ``name``."""
        return [f for group in (self.corners, self.curves, self.patches) for f in group if name in f.names]

    @property
    def names(self) -> list[str]:
        return sorted({n for group in (self.corners, self.curves, self.patches) for f in group for n in f.names})

    def names_listed(self, near: str | None = None) -> str:
        """The feature names for a log or an error: all of up to NAMES_LISTED, else the first of them in number
        order (face-2 before face-10) or, given ``near``, those closest to it, and how many there are."""
        names = sorted(self.names, key=lambda name: [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name)])
        if len(names) <= NAMES_LISTED:
            return ", ".join(names) or "none"
        if near is not None and (close := difflib.get_close_matches(near, names, NAMES_LISTED, 0.5)):
            return f"{', '.join(close)} (the closest to '{near}' of {len(names)}: fuzzymesh features lists them)"
        return f"{', '.join(names[:NAMES_LISTED])} and {len(names) - NAMES_LISTED} more (fuzzymesh features lists them)"


def curve_sides(geometry, features) -> dict[int, tuple[int, int]]:
    """(patch on the left, patch on the right) of every surface curve, seen from outside along it."""
    faces = geometry.mesh.faces
    nv = len(geometry.mesh.vertices)
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    keys = directed[:, 0] * nv + directed[:, 1]
    order = np.argsort(keys)
    keys, owner = keys[order], (order // 3)
    sides = {}
    for index, curve in enumerate(features.curves):
        if not curve.on_surface or curve.vertices is None:
            continue
        v = np.asarray(curve.vertices)
        a, b = (v, np.roll(v, -1)) if curve.closed else (v[:-1], v[1:])
        found = []
        for edge in (a * nv + b, b * nv + a):
            at = np.clip(np.searchsorted(keys, edge), 0, len(keys) - 1)
            hit = keys[at] == edge
            patches = features.face_patch[owner[at[hit]]]
            found.append(int(np.bincount(patches).argmax()) if len(patches) else -1)
        sides[index] = tuple(found)
    return sides


def curves_meeting(features: Features) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every pair of curve ends at one corner, each pair once: (curve, end, other curve, its end), (k,) each;
    end 0 a curve's start, 1 the end of an open curve (a loop meets at the corner it starts at)."""
    corners = np.array([c.point for c in features.corners]).reshape(-1, 3)
    ends = np.array([[curve.points[0], curve.points[-1]] for curve in features.curves]).reshape(-1, 3)
    none = np.zeros(0, np.int64)
    if len(corners) == 0 or len(ends) == 0:
        return none, none, none, none
    scale = float(np.ptp(np.concatenate([corners, ends]), axis=0).max()) or 1.0
    gap, corner = cKDTree(corners).query(ends)
    on = np.flatnonzero(gap <= 1e-9 * scale)
    on = on[np.argsort(corner[on], kind="stable")]  # curve ends by corner
    first, second = [none], [none]
    for offset in range(1, len(on)):  # the ends ``offset`` apart at one corner
        same = np.flatnonzero(corner[on[offset:]] == corner[on[:-offset]])
        if len(same) == 0:
            break
        first.append(on[same])
        second.append(on[same + offset])
    first, second = np.concatenate(first), np.concatenate(second)
    return first // 2, first % 2, second // 2, second % 2


def leaving_angles(features: Features) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`curves_meeting`'s pairs of curve ends at one corner, (curve, end, other curve, its end), with (k,)
    the angle in degrees between the directions in which the two curves leave the corner (their first
    segments): under a few degrees, a cusp."""
    curve, end, other, other_end = curves_meeting(features)
    leaving = np.array([first_segment(features.curves[c], e) for c, e in zip(curve, end)]).reshape(-1, 3)
    leaving_too = np.array([first_segment(features.curves[c], e) for c, e in zip(other, other_end)]).reshape(-1, 3)
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", leaving, leaving_too), -1.0, 1.0)))
    return curve, end, other, other_end, angle


def first_segment(curve, end: int) -> np.ndarray:
    """The unit direction in which ``curve`` leaves its start (``end`` 0) or its end (1)."""
    points = curve.points
    step = points[1] - points[0] if end == 0 else points[-2] - points[-1]
    return step / (np.linalg.norm(step) or 1.0)


def detect_features(
    geometry: Geometry, feature_angle: float = 30.0, face_groups=(), whole=(), tori: bool = True
) -> Features:
    """Find corners, feature curves and patches of ``geometry`` (angles in degrees).

    ``face_groups`` are functions ``triangles (F, 3, 3) -> bool mask``; each
    marks faces that form patches of their own even where they meet their
    neighbours smoothly (e.g. a tangent fillet). Their borders become curves,
    as does the cut that halves a smooth closed patch (a sphere's surface).
    Sharp edges below CREASE x the feature angle that separate no two patches
    (a coarse faceting's creases inside one smooth surface) are not features. A smooth patch that is
    neither a plane nor a cylinder is cut into charts (see :func:`chart_pieces`):
    its planar faces, its cylinders (a fillet, a hole wall) and pieces of
    bounded normal spread, each of which can be flattened; the cuts are
    smooth (``sharp=False``) curves. ``whole``: per face group, whether it is never cut into charts (a CAD
    face on a cylinder, where a short or B-spline face's facets fit none, or triangulated in its own
    parameters).
    ``tori``: give a curved patch the torus its facets fit (:func:`fit_torus`; not for a CAD model, whose faces
    know their surfaces).
    """
    mesh = geometry.mesh
    threshold = np.radians(feature_angle)
    adjacency = mesh.face_adjacency
    sharp = mesh.face_adjacency_angles > threshold
    group = np.zeros(len(mesh.faces), dtype=int)
    for k, select in enumerate(face_groups, start=1):
        group[select(mesh.triangles)] = k
    truly_sharp = sharp.copy()
    sharp |= group[adjacency[:, 0]] != group[adjacency[:, 1]]
    patches, face_patch = _patches(geometry, adjacency[~sharp])
    crease = (face_patch[adjacency[:, 0]] == face_patch[adjacency[:, 1]]) & (
        mesh.face_adjacency_angles < CREASE * threshold
    )
    sharp &= ~crease
    truly_sharp &= ~crease
    closed = np.setdiff1d(np.arange(len(patches)), face_patch[adjacency[sharp]])
    if len(closed):  # a smooth closed patch (a sphere) is cut in two, so that every patch has a border
        for k, p in enumerate(closed, start=group.max() + 1):
            group[_half(mesh, patches[p].faces)] = k
        sharp |= group[adjacency[:, 0]] != group[adjacency[:, 1]]
        patches, face_patch = _patches(geometry, adjacency[~sharp])
    uncut = np.zeros(group.max() + 1, bool)
    uncut[1 : len(whole) + 1] = np.asarray(whole, bool)[: group.max()]
    pieces = [
        piece
        for patch in patches
        if not patch.planar and patch.cylinder is None and not uncut[group[patch.faces[0]]]
        for piece in chart_pieces(mesh, patch.faces, face_patch, ~sharp, geometry.source)
    ]
    if pieces:
        for k, piece in enumerate(pieces, start=group.max() + 1):
            group[piece] = k
        sharp |= group[adjacency[:, 0]] != group[adjacency[:, 1]]
        patches, face_patch = _patches(geometry, adjacency[~sharp])
    sharp_edges = mesh.face_adjacency_edges[sharp]
    corners, curves = _curves(
        mesh.vertices,
        sharp_edges,
        mesh.face_adjacency_convex[sharp],
        np.degrees(mesh.face_adjacency_angles[sharp]),
        truly_sharp[sharp],
        threshold,
        np.abs(mesh.vertex_defects) > threshold,
    )
    cylinders = faceted_cylinders(mesh, patches, face_patch, sharp)
    return Features(
        corners=corners,
        curves=[c if c.sharp else _unzigzagged(c, geometry) for c in curves],
        patches=_with_tori(mesh, cylinders) if tori else cylinders,
        face_patch=face_patch,
        feature_angle=feature_angle,
    )


def _with_tori(mesh, patches: list) -> list:
    """``patches`` with the torus each curved patch on no cylinder fits (:func:`fit_torus`), its tube circle and,
    concave, the kind a CAD torus face gets (:func:`torus_kind`) by the turn round the tube of all the patches
    on that torus: the charts of a bent bore's wall, each less than half a turn round it, make a 'hole'."""
    tori = [
        None
        if p.planar or p.cylinder is not None
        else fit_torus(mesh.triangles_center[p.faces], mesh.face_normals[p.faces], p.vertices)
        for p in patches
    ]
    out = list(patches)
    for k, torus in enumerate(tori):
        if torus is None:
            continue
        kinds = patches[k].kinds
        if torus.concave:
            same = [j for j, other in enumerate(tori) if other is not None and _same_torus(torus, other)]
            turn = tube_sweep(torus, np.concatenate([patches[j].vertices for j in same]))
            kinds = [*kinds, torus_kind(turn)]
        out[k] = replace(patches[k], torus=torus, circle=Circle(torus.centre, torus.axis, torus.minor), kinds=kinds)
    return out


def _same_torus(a: Torus, b: Torus) -> bool:
    """Whether two fitted tori are one surface: of one side, their centres, axes (at the circle), circles and
    tubes within SAME_TORUS x the tube radius."""
    tolerance = SAME_TORUS * min(a.minor, b.minor)
    return bool(
        a.concave == b.concave
        and np.linalg.norm(a.centre - b.centre) < tolerance
        and np.linalg.norm(np.cross(a.axis, b.axis)) * a.major < tolerance
        and abs(a.major - b.major) < tolerance
        and abs(a.minor - b.minor) < tolerance
    )


def faceted_cylinders(mesh, patches: list, face_patch: np.ndarray, sharp: np.ndarray) -> list:
    """``patches`` with the ring's cylinder given to each planar patch of a ring of at least RING_FACETS that
    closes a full turn round one axis, all its vertices on one circle: a coarse STL's polygon hole or boss (an
    OpenSCAD export's 7- or 10-sided bolt holes, whose facets turn by more than the feature angle, so that each
    is a patch of its own). They stay planar patches (charts, nodes and curves as before); the cylinder gives
    them its kinds (a concave ring: 'hole') and radius. ``sharp`` marks the mesh's face adjacencies that
    separate patches. Fewer sides make a polygon of its own (a hex socket)."""
    pairs = mesh.face_adjacency[sharp]
    a, b = face_patch[pairs[:, 0]], face_patch[pairs[:, 1]]
    planar = np.array([p.planar for p in patches], bool)
    ring = planar[a] & planar[b] & (a != b) & (mesh.face_adjacency_angles[sharp] <= np.radians(RING_TURN))
    if ring.sum() < RING_FACETS:
        return patches
    ends = mesh.vertices[mesh.face_adjacency_edges[sharp][ring]]
    direction = ends[:, 1] - ends[:, 0]
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-300)
    direction *= np.sign(direction[np.arange(len(direction)), np.argmax(np.abs(direction), axis=1)])[:, None]
    close = cKDTree(direction).query_pairs(PARALLEL, output_type="ndarray")  # edges along one axis
    count = len(direction)
    _, along = csgraph.connected_components(
        sparse.coo_matrix((np.ones(len(close)), (close[:, 0], close[:, 1])), shape=(count, count)), directed=False
    )
    a, b = a[ring], b[ring]
    out = list(patches)
    n = len(patches)
    for axis_group in np.unique(along):
        edges = along == axis_group
        if edges.sum() < RING_FACETS:
            continue
        graph = sparse.coo_matrix((np.ones(int(edges.sum())), (a[edges], b[edges])), shape=(n, n))
        _, component = csgraph.connected_components(graph, directed=False)
        members_of = np.unique(np.concatenate([a[edges], b[edges]]))
        for label in np.unique(component[members_of]):
            members = members_of[component[members_of] == label]
            if len(members) < RING_FACETS:
                continue
            faces = np.concatenate([patches[m].faces for m in members])
            vertices = mesh.vertices[np.unique(mesh.faces[faces])]
            cylinder = fit_cylinder(mesh.triangles_center[faces], mesh.face_normals[faces], vertices)
            if cylinder is not None and cylinder.full_turn:
                for m in members:
                    out[m] = replace(patches[m], cylinder=cylinder)
    return out


def _unzigzagged(curve: Curve, geometry) -> Curve:
    """A smooth cut without the teeth of its zigzag along the input's edges: a point whose neighbours lie
    nearer to each other than to it is dropped (every other one of a run), until none is left. A cut
    across a CAD tessellation's long facets runs along their diagonals, several times longer than the cut;
    bubbles spaced along that zigzag would crowd. The points left are input vertices on one side of the
    facets, and the surface points :func:`_chords_on_surface` adds where a chord between them cuts through a
    curved face; ``vertices`` still name all the input edges the cut follows (the patches' sides)."""
    points = curve.points
    for _ in range(len(points)):
        behind, ahead = np.roll(points, 1, axis=0), np.roll(points, -1, axis=0)
        across = np.linalg.norm(ahead - behind, axis=1)
        spike = across < np.minimum(np.linalg.norm(points - behind, axis=1), np.linalg.norm(ahead - points, axis=1))
        if not curve.closed:
            spike[[0, -1]] = False
        if len(points) - spike.sum() < (3 if curve.closed else 2) or not spike.any():
            break
        run_start = np.maximum.accumulate(np.where(spike & ~np.roll(spike, 1), np.arange(len(spike)), 0))
        points = points[~(spike & ((np.arange(len(spike)) - run_start) % 2 == 0))]
    if len(points) == len(curve.points):
        return curve
    return replace(curve, points=_chords_on_surface(points, curve.closed, geometry))


def _chords_on_surface(points: np.ndarray, closed: bool, geometry) -> np.ndarray:
    """``points`` (n, 3) of a polyline with the closest surface point to the middle of every chord that
    strays from the surface there by more than CHORD_ON_SURFACE x the length of the chord it came from put
    between its ends, in rounds (each halves the chords still off), at most CHORD_ROUNDS (a chord across one
    of the facets' creases strays by a share of its length that halving does not change). A cut across a
    cast housing's 4 mm base fillet, unzigzagged, ran 0.29 mm inside it on 3 mm chords, and its nodes put the
    mesh 0.28 h off the input; the corpus torus's cuts ran 0.07 inside it."""
    start, end = (points, np.roll(points, -1, axis=0)) if closed else (points[:-1], points[1:])
    allowed = CHORD_ON_SURFACE * np.linalg.norm(end - start, axis=1)  # per chord
    for _ in range(CHORD_ROUNDS):
        start, end = (points, np.roll(points, -1, axis=0)) if closed else (points[:-1], points[1:])
        closest, off, _ = geometry.closest_point(0.5 * (start + end))
        far = np.flatnonzero(off > allowed)
        if not len(far):
            break
        points = np.insert(points, far + 1, closest[far], axis=0)
        allowed = np.insert(allowed, far + 1, allowed[far])
    return points


CHORD_ON_SURFACE = 0.01  # x its length: how far a smooth cut's chord (and its halves) may stray from the surface
CHORD_ROUNDS = 6  # halvings of the chords that stray further
CREASE = 2.0  # a sharp edge inside one patch below this x the feature angle is a faceting crease
CHART_CONE = 90.0  # degrees: a curved piece is one chart if its face normals stay this close to their mean ...
MAX_STRETCH = 1.6  # ... and its conformal map stretches lengths by at most this ratio (a sphere's octant: 1.15), ...
STRETCH_SHARE = 0.01  # ... but for this share of its area at either end, ...
TIP_EXTENT = 0.1  # ... if it lies this close (x the chart's size) round one point (a cone's tip)
COPLANAR = 1e-3  # radians: faces meeting at a smaller angle lie in one plane
NARROW_REGION = 0.01  # x the model size: a coplanar region no wider than this is a strip of the surface it bends into
WIDE = 3.0  # a coplanar region this many times wider than the facets it bends into is a plane
MAX_SPLITS = 16  # halvings of a piece's normal spread before it is taken as it is
SEED_BAND = 0.25  # a halved piece's faces in this top and bottom share of their normals' spread stay apart
SMOOTHING = 4  # rounds of neighbour averaging of the normals' spread before the seeds are chosen
CREASE_TAIL = 3  # a crease continued across a smooth piece goes on the way of its last this many edges, ...
CONTINUE_TURN = 60.0  # ... each step turning by less than this (degrees) from the way so far
ISLAND = 3  # a cut's side keeps no component of fewer faces than this apart from its largest
FOLD = 3.0  # a chart's border folds where it lays two border points this many times nearer than in space
FOLD_SAMPLES = 4  # border points looked at per median border edge, ...
MAX_FOLD_SAMPLES = 200_000  # ... and at most this many per chart
RING_FACETS = 7  # planar patches round one axis, all vertices on one circle, that make a faceted cylinder ...
RING_TURN = 60.0  # ... each turning at most this (degrees) from the next
PARALLEL = 1e-3  # unit edge directions this close are one axis
SAME_TORUS = 1e-3  # x the tube radius: two patches' tori this close are one torus (fits agree to ~1e-6)
CYLINDER_AGREE = 1e-2  # two bends lie on one cylinder when their axes (sine of the angle), axis lines and radii
# (x the radius) agree this closely (exact but for rounding on a CAD tessellation's ruled cylinder)
MAX_STRIP_BENDS = 16  # a facet strip bent against more neighbours than this is no cylinder's
BAND_LENGTH = 2.0  # a cylinder next to one of its radius at an angle is a torus's band unless this x as long
MIN_SWEEP = 30.0  # degrees: a cylinder found inside a smooth patch turns at least this far round its axis (a few
# facets of a torus's irregular tessellation agree on a cylinder turning 10)


def chart_pieces(mesh, faces: np.ndarray, face_patch: np.ndarray, smooth: np.ndarray, source: str) -> list[np.ndarray]:
    """The charts a smooth patch (``faces``) is cut into; one piece when it can be flattened whole.

    First its planar regions (coplanar faces, wide against the facets they bend
    into: :func:`_wide`); then the rest is cut where a crease fades out in it
    (:func:`_continued_creases`); a connected rest that does not lie on one cylinder gives up
    the cylinders inside it (:func:`_cylinder_regions`: a hole's wall that runs into a
    tangent fillet, a block's rounds between its corner blends); then each connected rest
    is one piece if it lies on a cylinder or can be flattened (:func:`flattenable`), else
    it is halved across its widest spread of normals until every piece can.
    ``smooth`` marks the mesh's face-adjacency pairs that are not feature edges. A piece still
    neither after MAX_SPLITS halvings is refused (GeometryError naming ``source``), before any packing.
    """
    adjacency = mesh.face_adjacency
    rows = np.flatnonzero(smooth & (face_patch[adjacency[:, 0]] == face_patch[faces[0]]))  # the patch's smooth edges
    pairs = adjacency[rows]
    bent = mesh.face_adjacency_angles[rows] >= COPLANAR
    n = len(mesh.faces)
    in_patch = np.zeros(n, bool)
    in_patch[faces] = True
    region = _components(n, pairs[~bent])
    planar_regions = np.unique(region[in_patch][_wide(mesh, region, pairs[bent])[region[in_patch]]])
    planar = np.isin(region, planar_regions) & in_patch
    if not planar.any() and flattenable(mesh, faces):
        return [faces]
    pieces = [np.flatnonzero(region == r) for r in planar_regions]
    rest = in_patch & ~planar
    keep = rest[pairs[:, 0]] & rest[pairs[:, 1]]
    creases = np.flatnonzero(~smooth & in_patch[adjacency[:, 0]] & in_patch[adjacency[:, 1]])
    keep[np.flatnonzero(keep)[_continued_creases(mesh, rest, rows[keep], creases)]] = False
    labels = _components(n, pairs[keep])
    for r in np.unique(labels[rest]):
        cylinders, parts = _cylinders_apart(mesh, np.flatnonzero((labels == r) & rest), region, pairs[keep])
        pieces += cylinders
        for part in parts:
            pieces += _split_by_normals(mesh, part, pairs[keep], source)
    return pieces


def _continued_creases(mesh, rest: np.ndarray, rows: np.ndarray, creases: np.ndarray) -> np.ndarray:
    """Which of the face-adjacency ``rows`` (smooth edges between two faces of the ``rest`` mask) a crease is
    continued across, to cut the rest there. A chain of ``creases`` (sharp edges inside the patch) that comes
    in from the rest's border and ends inside it is the sharp part of a border the input's surface lost: the
    mitre between two fillets that meet at a sharp corner (a pocket's floor fillets), sharp at the walls and
    fading out towards the floor, so that the fillets make one smooth ring that no chart of one cylinder
    covers. From its end the walk goes on along the input's edges, each step the straightest on from the way
    so far (the chain's last CREASE_TAIL edges, then the steps, turning by less than CONTINUE_TURN), until it
    meets the rest's border or another crease; a walk that does not is dropped. How bent an edge is says
    nothing there: the fillets' own facet edges are as bent as the mitre's fading end."""
    cut = np.zeros(len(rows), bool)
    if not len(creases) or not len(rows):
        return cut
    edges, crease_edges = mesh.face_adjacency_edges[rows], mesh.face_adjacency_edges[creases]
    count = len(mesh.vertices)
    degree = np.bincount(crease_edges.ravel(), minlength=count)
    outside = np.zeros(count, bool)  # vertices of a face that is not in the rest
    outside[mesh.faces[~rest].ravel()] = True
    stop = outside | (degree > 0)
    chains = [_chain_from(end, crease_edges, degree, outside) for end in np.flatnonzero((degree == 1) & ~outside)]
    chains = [chain for chain in chains if chain is not None]
    if not chains:
        return cut
    # the rest's smooth edges from each vertex: CSR of (vertex -> edge index), both directions
    tail = np.concatenate([edges[:, 0], edges[:, 1]])
    order = np.argsort(tail, kind="stable")
    start = np.searchsorted(tail[order], np.arange(count + 1))
    head = np.concatenate([edges[:, 1], edges[:, 0]])[order]
    index = np.tile(np.arange(len(edges)), 2)[order]
    limit = np.cos(np.radians(CONTINUE_TURN))
    vertices = mesh.vertices
    for chain in chains:
        here = chain[0]
        way = unit(vertices[here] - vertices[chain[min(CREASE_TAIL, len(chain) - 1)]])
        walked = []
        for _ in range(len(edges)):
            ahead = unit(vertices[head[start[here] : start[here + 1]]] - vertices[here])
            turn = ahead @ way
            pick = int(np.argmax(turn)) if len(turn) else -1
            if pick < 0 or turn[pick] < limit:
                break
            walked.append(index[start[here] + pick])
            here = head[start[here] + pick]
            way = unit(way + ahead[pick])
            if stop[here]:
                cut[walked] = True
                break
    return cut


def _chain_from(end: int, chain_edges: np.ndarray, degree: np.ndarray, outside: np.ndarray) -> list[int] | None:
    """The vertices of the chain of ``chain_edges`` from its loose ``end`` to an ``outside`` vertex or a
    junction of chains; None if it ends loose there too (a mitre comes in from the walls' corner; a lone
    crease between two facets near a tessellated cone's tip is no lost border)."""
    chain = [end]
    for _ in range(len(chain_edges)):
        here = chain[-1]
        if outside[here] or degree[here] > 2:
            return chain
        step = chain_edges[(chain_edges == here).any(axis=1)].ravel()
        following = [v for v in step if v != here and (len(chain) < 2 or v != chain[-2])]
        if not following:
            return None
        chain.append(int(following[0]))
    return None


def unit(vectors: np.ndarray) -> np.ndarray:
    """``vectors`` (..., 3) scaled to length 1 along the last axis (a zero vector stays zero)."""
    return vectors / np.maximum(np.linalg.norm(vectors, axis=-1, keepdims=True), 1e-300)


def _wide(mesh, region: np.ndarray, bent: np.ndarray) -> np.ndarray:
    """Per region label: whether that coplanar region is a face of its own, not one facet strip of a curved
    surface: it is wider (its area over the length of its bending border) than WIDE x the faces it bends
    into (their height over the shared edge); a region that bends nowhere is. A CAD tessellation's flat
    wall of two triangles beside a fillet is wide; a cylinder's strip or two coplanar facets at a
    sphere's corner are not, nor is one facet alone (a long facet of a coarse cylinder between a sharp edge
    and a keyway's corner: its border is the short edge)."""
    count = int(region.max()) + 1
    ends = mesh.vertices[_shared_edges(mesh, bent)]
    length = np.linalg.norm(ends[:, 0] - ends[:, 1], axis=1)
    area = mesh.area_faces
    side, other = bent.ravel(), bent[:, ::-1].ravel()
    length = np.repeat(length, 2)  # per (face, face it bends into) of side, other
    border = np.bincount(region[side], weights=length, minlength=count)
    height = 2 * area[other] / np.maximum(length, 1e-300)
    beyond = np.bincount(region[side], weights=height * length, minlength=count) / np.maximum(border, 1e-300)
    width = np.bincount(region, weights=area, minlength=count) / np.maximum(border, 1e-300)
    return (width > WIDE * beyond) & (width > NARROW_REGION * mesh.scale) & (np.bincount(region, minlength=count) > 1)


def _cylinders_apart(mesh, piece: np.ndarray, strip: np.ndarray, pairs: np.ndarray):
    """(cylinders, parts): the cylinders inside a connected smooth ``piece`` of faces (:func:`_cylinder_regions`;
    ``strip`` and ``pairs`` as there), and the connected parts of it left over; ([piece], []) when it lies on one
    cylinder as a whole (a Gmsh-meshed fillet's triangles cross its lines and tilt: its bends agree on no axis,
    and pieces of it would)."""
    vertices = mesh.vertices[np.unique(mesh.faces[piece])]
    if fit_cylinder(mesh.triangles_center[piece], mesh.face_normals[piece], vertices) is not None:
        return [piece], []
    inside = np.zeros(len(mesh.faces), bool)
    inside[piece] = True
    cylinders = _cylinder_regions(mesh, inside, strip, pairs)
    for cylinder in cylinders:
        inside[cylinder] = False
    left = _components(len(mesh.faces), pairs[inside[pairs].all(axis=1)])
    return cylinders, [np.flatnonzero((left == k) & inside) for k in np.unique(left[inside])]


def _cylinder_regions(mesh, rest: np.ndarray, strip: np.ndarray, pairs: np.ndarray) -> list[np.ndarray]:
    """The faces of the ``rest`` mask that lie on cylinders, one array per cylinder (connected): a hole's wall
    that runs into a tangent fillet at its rim, which the patch would otherwise carry as one chart with the
    fillet and no cylinder (no 'hole' to place a pattern on). ``strip``: coplanar region label of every face;
    ``pairs``: the smooth face pairs among them.

    Each candidate of :func:`_cylinder_candidates` that is no torus band (:func:`_torus_bands`) takes every
    face of ``rest`` connected to it whose vertices lie on its cylinder and whose normal tilts off its axis
    no more than its own faces' do (at least COPLANAR): the first band of a fillet, whose facets tilt by
    half the fillet's angular step, stays out. It is kept if that makes a plain piece of a cylinder
    (:func:`_plain_cylinder`)."""
    candidates = _cylinder_candidates(mesh, rest, strip, pairs)
    band = _torus_bands(candidates, pairs, len(mesh.faces))
    in_rest = np.flatnonzero(rest)
    normals, corners = mesh.face_normals[in_rest], mesh.vertices[mesh.faces[in_rest]]
    regions = []
    taken = np.zeros(len(mesh.faces), bool)
    for (faces, cylinder, _), is_band in zip(candidates, band):
        if is_band or taken[faces].any():
            continue
        radial = corners - cylinder.point
        radial -= (radial @ cylinder.axis)[..., None] * cylinder.axis
        off = np.abs(np.linalg.norm(radial, axis=2) - cylinder.radius).max(axis=1)
        tilt = np.abs(normals @ cylinder.axis)
        on = np.zeros(len(mesh.faces), bool)
        on[in_rest] = (off <= CIRCLE_TOLERANCE * cylinder.radius) & (
            tilt <= max(COPLANAR, np.abs(mesh.face_normals[faces] @ cylinder.axis).max())
        )
        on &= ~taken
        labels = _components(len(mesh.faces), pairs[on[pairs].all(axis=1)])
        region = np.flatnonzero(on & np.isin(labels, labels[faces]))
        if _plain_cylinder(mesh, region, cylinder):
            taken[region] = True
            regions.append(region)
    return regions


def _cylinder_candidates(mesh, rest: np.ndarray, strip: np.ndarray, pairs: np.ndarray) -> list[tuple]:
    """(faces, cylinder, length along its axis) of each group of facet strips of ``rest`` that lies on one
    cylinder (arguments as :func:`_cylinder_regions`).

    Two strips bent against each other (a bend) meet along an edge that both their planes hold; on a
    cylinder every such edge runs along the axis, and the circle through the edge and the two faces' third
    vertices, seen along it, is the cylinder's. Bends are joined through the strips they share when their
    directions, axis lines and radii agree (within CYLINDER_AGREE); a joined group is a candidate when its
    bends and faces keep to one axis (a torus's rings round its own axis near the equators lean), its
    vertices lie on one circle seen along it (:func:`cylinder_about`) and it turns at least MIN_SWEEP."""
    bends = np.flatnonzero(rest[pairs[:, 0]] & rest[pairs[:, 1]] & (strip[pairs[:, 0]] != strip[pairs[:, 1]]))
    if len(bends) < 2:
        return []
    f, g = pairs[bends, 0], pairs[bends, 1]
    shared = _shared_edges(mesh, pairs[bends])
    direction = unit(mesh.vertices[shared[:, 1]] - mesh.vertices[shared[:, 0]])  # both faces' planes hold it
    direction *= np.sign(direction[np.arange(len(direction)), np.argmax(np.abs(direction), axis=1)])[:, None]
    far = [mesh.faces[side].sum(axis=1) - shared.sum(axis=1) for side in (f, g)]  # each face's third vertex
    on_axis, radius = _circumcircle(
        mesh.vertices[shared[:, 0]], mesh.vertices[far[0]], mesh.vertices[far[1]], direction
    )
    # bends meeting one strip, each with each (strips of a cylinder or a torus band have two to four)
    incident = np.concatenate([strip[f], strip[g]])
    bend = np.concatenate([np.arange(len(bends))] * 2)
    order = np.argsort(incident, kind="stable")
    incident, bend = incident[order], bend[order]
    starts = np.flatnonzero(np.r_[True, incident[1:] != incident[:-1]])
    counts = np.diff(np.r_[starts, len(incident)])
    links = [np.zeros((0, 2), np.int64)]
    for k in np.unique(counts[(counts >= 2) & (counts <= MAX_STRIP_BENDS)]):
        members = bend[starts[counts == k][:, None] + np.arange(k)]
        i, j = np.triu_indices(k, 1)
        links.append(np.column_stack([members[:, i].ravel(), members[:, j].ravel()]))
    a, b = np.concatenate(links).T
    scale = np.maximum(radius[a], radius[b])
    agree = (
        (np.linalg.norm(np.cross(direction[a], direction[b]), axis=1) < CYLINDER_AGREE)
        & (np.linalg.norm(on_axis[a] - on_axis[b], axis=1) < CYLINDER_AGREE * scale)
        & (np.abs(radius[a] - radius[b]) < CYLINDER_AGREE * scale)
    )
    group = _components(len(bends), np.column_stack([a, b])[agree])
    by_group = np.argsort(group, kind="stable")
    group_start = np.searchsorted(group[by_group], np.arange(group.max() + 2))
    in_rest = np.flatnonzero(rest)
    by_strip = in_rest[np.argsort(strip[in_rest], kind="stable")]  # the rest's faces, strip by strip
    strip_start = np.searchsorted(strip[by_strip], np.arange(strip.max() + 2))
    candidates = []
    for label in np.flatnonzero(np.diff(group_start) >= 2):
        members = by_group[group_start[label] : group_start[label + 1]]
        axis = unit(direction[members].sum(axis=0))
        if np.linalg.norm(np.cross(direction[members], axis), axis=1).max() >= CYLINDER_AGREE:
            continue
        touched = np.unique(np.concatenate([strip[f[members]], strip[g[members]]]))
        faces = np.sort(np.concatenate([by_strip[strip_start[k] : strip_start[k + 1]] for k in touched]))
        if np.abs(mesh.face_normals[faces] @ axis).max() >= CYLINDER_AGREE:
            continue
        vertices = mesh.vertices[np.unique(mesh.faces[faces])]
        cylinder = cylinder_about(axis, mesh.triangles_center[faces], mesh.face_normals[faces], vertices)
        if cylinder is not None and cylinder.sweep >= MIN_SWEEP:
            candidates.append((faces, cylinder, float(np.ptp((vertices - cylinder.point) @ cylinder.axis))))
    return candidates


def _torus_bands(candidates: list[tuple], pairs: np.ndarray, count: int) -> np.ndarray:
    """Per candidate of :func:`_cylinder_candidates`, whether it is one band of a torus's tessellation. A
    torus (a fillet round a hole's rim) is a family of candidates, each of the tube's radius with a turned
    axis: a candidate that shares or borders faces (joined by ``pairs``, of ``count`` faces in all) with
    another of its radius at an angle is a band unless it is BAND_LENGTH times as long (a straight fillet
    ending at a corner blend)."""
    band = np.zeros(len(candidates), bool)
    if not candidates:
        return band
    rows = np.concatenate([faces for faces, _, _ in candidates])
    cols = np.repeat(np.arange(len(candidates)), [len(faces) for faces, _, _ in candidates])
    member = sparse.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(count, len(candidates)))
    near = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(count, count))
    touching = sparse.triu(member.T @ (near + near.T + sparse.identity(count)) @ member, k=1).tocoo()
    for i, j in zip(touching.row, touching.col):
        (_, ci, li), (_, cj, lj) = candidates[i], candidates[j]
        if abs(ci.radius - cj.radius) < CYLINDER_AGREE * max(ci.radius, cj.radius) and (
            np.linalg.norm(np.cross(ci.axis, cj.axis)) >= CYLINDER_AGREE
        ):
            band[i] |= li < BAND_LENGTH * lj
            band[j] |= lj < BAND_LENGTH * li
    return band


def _plain_cylinder(mesh, faces: np.ndarray, cylinder: Cylinder) -> bool:
    """Whether ``faces`` (connected, on ``cylinder``) make a plain piece of it: a full turn a band (two border
    loops: Euler characteristic 0), else a disk that flattens without folding (:func:`flattenable`). A boss's
    wall that a tangent-filleted arm joins is neither: a full turn with a window whose corners are cusps,
    left to the charts, which cut it at the folds."""
    triangles = mesh.faces[faces]
    edges = triangle_edges(triangles)
    euler = len(np.unique(triangles)) - len(edges) + len(faces)
    return euler == 0 if cylinder.full_turn else euler == 1 and flattenable(mesh, faces)


def _circumcircle(p: np.ndarray, q: np.ndarray, r: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre and radius of the circle through points ``p``, ``q``, ``r`` (k, 3) seen along unit ``axis``
    (k, 3): the centre is the point of the axis line nearest the origin (inf where the three are in line)."""
    flat = lambda x: x - np.einsum("ij,ij->i", x, axis)[:, None] * axis  # noqa: E731
    p, a, b = flat(p), flat(q - p), flat(r - p)
    normal = np.cross(a, b)
    area = np.einsum("ij,ij->i", normal, normal)
    offset = np.cross((a * a).sum(axis=1)[:, None] * b - (b * b).sum(axis=1)[:, None] * a, normal)
    offset /= np.maximum(2 * area, 1e-300)[:, None]
    radius = np.where(area > 0, np.linalg.norm(offset, axis=1), np.inf)
    return p + offset, radius


def _components(n: int, pairs: np.ndarray) -> np.ndarray:
    """Connected-component label of each of ``n`` nodes joined by ``pairs``."""
    graph = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return csgraph.connected_components(graph, directed=False)[1]


def _split_by_normals(mesh, faces: np.ndarray, pairs: np.ndarray, source: str) -> list[np.ndarray]:
    """``faces`` (connected) as pieces that lie on a cylinder or can be flattened.

    A piece that is neither is halved: its faces whose normals lie in the
    upper and the lower quarter of their spread along the direction in which
    they spread most are kept apart by the shortest cut along the input's
    edges (a minimum cut of the face graph, capacities the shared edges'
    lengths). A cut along the level line of the normal instead would zigzag
    across the long facets of a CAD tessellation (a torus cut across its tube
    ran 10x its length).
    """
    normals, centres = mesh.face_normals, mesh.triangles_center
    ends = mesh.vertices[_shared_edges(mesh, pairs)]
    length = np.linalg.norm(ends[:, 0] - ends[:, 1], axis=1)
    todo, pieces = [(faces, 0)], []
    while todo:
        piece, depth = todo.pop()
        verts = mesh.vertices[np.unique(mesh.faces[piece])]
        chart = _chart(mesh, piece) if len(piece) >= 2 else None
        folds = border_folds(*chart) if chart is not None else None
        if (
            len(piece) < 2
            or (folds is not None and len(folds[0]) == 0)
            or fit_cylinder(centres[piece], normals[piece], verts) is not None
        ):
            pieces.append(piece)
            continue
        if depth >= MAX_SPLITS:
            centre = (centres[piece] * mesh.area_faces[piece, None]).sum(axis=0) / mesh.area_faces[piece].sum()
            raise GeometryError(
                f"a smooth surface around ({', '.join(f'{x:.4g}' for x in centre)}) cannot be cut "
                f"into pieces that flatten ({len(piece)} faces left after {MAX_SPLITS} halvings)",
                where=source,
                fix="lower geometry.feature_angle so that feature curves cut it, or "
                "re-export the surface with less noise",
            )
        local = np.full(len(mesh.faces), -1)
        local[piece] = np.arange(len(piece))
        inner = (local[pairs[:, 0]] >= 0) & (local[pairs[:, 1]] >= 0)
        one, other = np.zeros((2, len(piece)), bool)  # the faces the cut keeps apart
        if folds is not None:  # it flattens, but its border folds onto itself: the fold's two sides apart
            one[folds[0]], other[folds[1]] = True, True
            one, other = one & ~other, other & ~one
        if not (one.any() and other.any()):  # no fold, or one whose sides are the same faces (an ear at a cusp)
            spread = normals[piece] - normals[piece].mean(axis=0)
            along = normals[piece] @ np.linalg.svd(spread, full_matrices=False)[2][0]
            near = sparse.coo_matrix((np.ones(inner.sum()), tuple(local[pairs[inner]].T)), shape=(len(piece),) * 2)
            near = (near + near.T).tocsr()
            for _ in range(SMOOTHING):  # faceting noise (a quad's two triangles) must not interleave the seeds
                along = (along + near @ along) / (1.0 + np.asarray(near.sum(axis=1)).ravel())
            along = (along - along.min()) / max(np.ptp(along), 1e-300)
            one, other = along > 1 - SEED_BAND, along < SEED_BAND
        side = _min_cut(len(piece), local[pairs[inner]], length[inner], one, other)
        side = _without_islands(side, local[pairs[inner]])
        for half in (piece[side], piece[~side]):
            labels = _components(len(mesh.faces), pairs[inner][np.isin(pairs[inner], half).all(axis=1)])
            todo += [(half[labels[half] == r], depth + 1) for r in np.unique(labels[half])]
    return sorted(pieces, key=lambda piece: int(piece.min()))


def _without_islands(side: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """``side`` (a cut's side of each of a piece's faces, joined by ``pairs``, local indices) with every
    component of a side but its largest that has fewer than ISLAND faces given to the other side, which
    surrounds it. A minimum cut across a CAD tessellation's long facets left a single facet of a spring's
    swept face on its own: a chart of one triangle between two cuts that, unzigzagged, ran along the same
    edge (100 curve edges missing from the surface triangulation)."""
    side = side.copy()
    for half in (True, False):
        members = np.flatnonzero(side == half)
        inside = (side[pairs] == half).all(axis=1)
        labels = _components(len(side), pairs[inside])[members]
        names, sizes = np.unique(labels, return_counts=True)
        if len(names) < 2:
            continue
        small = names[(sizes < ISLAND) & (names != names[np.argmax(sizes)])]
        side[members[np.isin(labels, small)]] = not half
    return side


def _shared_edges(mesh, pairs: np.ndarray) -> np.ndarray:
    """(k, 2) vertex indices of the edge each face pair of ``pairs`` (rows of ``face_adjacency``) shares."""
    n = len(mesh.faces)
    adjacency = mesh.face_adjacency
    key = adjacency.min(axis=1) * n + adjacency.max(axis=1)
    order = np.argsort(key)
    return mesh.face_adjacency_edges[order[np.searchsorted(key[order], pairs.min(axis=1) * n + pairs.max(axis=1))]]


def _min_cut(count: int, pairs: np.ndarray, length: np.ndarray, source: np.ndarray, sink: np.ndarray) -> np.ndarray:
    """The nodes on the ``source`` side of a minimum cut (capacities ``length``) of a graph of ``count`` nodes
    joined by ``pairs`` between the ``source`` and the ``sink`` nodes (masks)."""
    unit = 1e6 / max(length.sum(), 1e-300)  # integer capacities, the whole graph at most ~1e6
    capacity = np.maximum(1, np.round(length * unit)).astype(np.int32)
    seeds = np.flatnonzero(source)
    drains = np.flatnonzero(sink)
    big = np.int32(2**30)
    rows = np.concatenate([pairs[:, 0], pairs[:, 1], np.full(len(seeds), count), drains])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0], seeds, np.full(len(drains), count + 1)])
    caps = np.concatenate([capacity, capacity, np.full(len(seeds) + len(drains), big, np.int32)])
    graph = sparse.csr_matrix((caps, (rows, cols)), shape=(count + 2, count + 2))
    graph.sum_duplicates()
    flow = csgraph.maximum_flow(graph, count, count + 1).flow
    residual = graph - flow
    residual.data[residual.data < 0] = 0
    residual.eliminate_zeros()
    reached = csgraph.breadth_first_order(residual, count, directed=True, return_predecessors=False)
    side = np.zeros(count + 2, bool)
    side[reached] = True
    return side[:count]


def flattenable(mesh, faces: np.ndarray) -> bool:
    """Whether a connected piece of surface maps to the plane without folding or much stretching: its
    normals stay within CHART_CONE of their mean, its conformal map (:func:`conformal_map`) exists and its
    border does not fold onto itself there (:func:`border_folds`)."""
    chart = _chart(mesh, faces)
    return chart is not None and len(border_folds(*chart)[0]) == 0


def _chart(mesh, faces: np.ndarray):
    """(vertices (V, 3), triangles (F, 3) local to them, uv (V, 2)) of a connected piece whose normals stay
    within CHART_CONE of their mean and whose conformal map exists; None otherwise."""
    normals, areas = mesh.face_normals[faces], mesh.area_faces[faces]
    mean = (normals * areas[:, None]).sum(axis=0)
    if np.linalg.norm(mean) < 1e-12:
        return None
    cone = np.degrees(np.arccos(np.clip((normals @ (mean / np.linalg.norm(mean))).min(), -1.0, 1.0)))
    if cone > CHART_CONE:
        return None
    used, local = np.unique(mesh.faces[faces], return_inverse=True)
    vertices, triangles = mesh.vertices[used], local.reshape(-1, 3)
    uv = conformal_map(vertices, triangles)
    return None if uv is None else (vertices, triangles, uv)


def border_folds(vertices: np.ndarray, triangles: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The triangles along the two sides of a fold of the chart ``uv``'s border (two arrays, empty when it
    has none). A fold: border edges that the chart lays FOLD times nearer than their points lie in space
    (beyond the chart's largest stretch). Of several, the one open widest in space; when one loop folds onto
    itself, its border between the two edges counts, split at the fold's tip (where the border turns back
    on itself). A patch wrapped round a zero-angle wedge of another folds so (a tangent fillet cut square
    by a flange face: the fillet's edge and the cylinder's edge leave their common corner tangent, and the
    unrolling lays both on one line); node chains along the two edges would cross in the chart, and no
    triangulation there could keep both."""
    loops = [np.asarray(loop) for loop in igl.boundary_loop_all(triangles)]
    if not loops:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    start = np.concatenate(loops)
    end = np.concatenate([np.roll(loop, -1) for loop in loops])
    loop_of = np.repeat(np.arange(len(loops)), [len(loop) for loop in loops])
    size = np.array([len(loop) for loop in loops])[loop_of]
    position = np.concatenate([np.arange(len(loop)) for loop in loops])
    span = np.linalg.norm(uv[end] - uv[start], axis=1)
    step = max(np.median(span) / FOLD_SAMPLES, span.sum() / MAX_FOLD_SAMPLES, 1e-300)
    count = np.maximum(1, np.ceil(span / step)).astype(np.int64)
    edge = np.repeat(np.arange(len(start)), count)
    t = ((np.arange(len(edge)) - np.repeat(np.cumsum(count) - count, count) + 0.5) / count[edge])[:, None]
    sample_uv = uv[start[edge]] + t * (uv[end[edge]] - uv[start[edge]])
    sample_xyz = vertices[start[edge]] + t * (vertices[end[edge]] - vertices[start[edge]])
    near = cKDTree(sample_uv).query_pairs(step, output_type="ndarray")
    a, b = edge[near[:, 0]], edge[near[:, 1]]
    apart = (start[a] != start[b]) & (start[a] != end[b]) & (end[a] != start[b]) & (end[a] != end[b])
    d_uv = np.linalg.norm(sample_uv[near[:, 0]] - sample_uv[near[:, 1]], axis=1)
    d_xyz = np.linalg.norm(sample_xyz[near[:, 0]] - sample_xyz[near[:, 1]], axis=1)
    flat, area = _chart_areas(vertices, triangles, uv)  # flat > 0 where solid: conformal_map oriented uv
    solid = area > 1e-12 * area.max()
    stretch = np.sqrt(area[solid] / np.maximum(flat[solid], 1e-300)).max()  # space length per chart length
    extent = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    fold = apart & (d_xyz > FOLD * stretch * d_uv) & (d_xyz > 1e-6 * extent)
    if not fold.any():
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    widest = np.flatnonzero(fold)[np.argmax(d_xyz[fold])]  # one fold at a time: the one open widest in space
    x, y = a[widest], b[widest]
    if loop_of[x] == loop_of[y]:  # the border between them, the short way round, split at the fold's tip
        if np.mod(position[y] - position[x], size[x]) > size[x] / 2:
            x, y = y, x
        steps = np.arange(np.mod(position[y] - position[x], size[x]) + 1)
        run = (np.cumsum([0] + [len(loop) for loop in loops]))[loop_of[x]] + np.mod(position[x] + steps, size[x])
        direction = uv[end[run]] - uv[start[run]]
        back = -np.einsum("ij,ij->i", direction[:-1], direction[1:]) / np.maximum(
            span[run[:-1]] * span[run[1:]], 1e-300
        )
        tip = int(np.argmax(back)) + 1 if len(run) > 1 else 1  # where the border turns back on itself
        first, second = run[:tip], run[tip:]
    else:  # two loops: every fold between the same two
        between = fold & np.isin(loop_of[a], loop_of[[x, y]]) & np.isin(loop_of[b], loop_of[[x, y]])
        ends = np.concatenate([a[between], b[between]])
        first, second = ends[loop_of[ends] == loop_of[x]], ends[loop_of[ends] == loop_of[y]]
    owner = _edge_owner(triangles, start, end)
    return np.unique(owner[first]), np.unique(owner[second])


def _edge_owner(triangles: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """The triangle holding each edge (start, end) (border edges: one each)."""
    n = int(triangles.max()) + 1
    ends = np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=2).reshape(-1, 2)
    key = ends.min(axis=1) * n + ends.max(axis=1)
    order = np.argsort(key, kind="stable")
    at = np.searchsorted(key[order], np.minimum(start, end) * n + np.maximum(start, end))
    return order[at] // 3


def _chart_areas(vertices: np.ndarray, triangles: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F,) signed areas of the triangles in the chart ``uv`` and (F,) their areas in space."""
    a, b, c = (uv[triangles[:, i]] for i in range(3))
    flat = 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    tri = vertices[triangles]
    return flat, 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


def conformal_map(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray | None:
    """(V, 2) least-squares conformal map (libigl LSCM) of a connected triangle set with a border,
    counter-clockwise where the triangles are, scaled so that its median length scale is 1; None when it
    folds or stretches lengths by more than MAX_STRETCH between its triangles (but at a cone's tip,
    :func:`_stretched_at_a_tip`)."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    loops = igl.boundary_loop_all(triangles) if len(triangles) else []
    if not loops:
        return None
    loop = np.asarray(max(loops, key=len))
    far = int(np.argmax(np.linalg.norm(vertices[loop] - vertices[loop[0]], axis=1)))
    pinned = np.array([loop[0], loop[far]])
    uv, _ = igl.lscm(vertices, triangles, pinned, np.array([[0.0, 0.0], [1.0, 0.0]]))
    flat, area = _chart_areas(vertices, triangles, uv)
    if np.sum(flat < 0) * 2 > len(flat):
        uv[:, 0] *= -1
        flat = -flat
    solid = area > 1e-12 * area.max()
    if not np.all(flat[solid] > 0):
        return None
    scale = np.sqrt(flat[solid] / area[solid])
    if scale.max() > MAX_STRETCH * scale.min() and not _stretched_at_a_tip(
        vertices, triangles[solid], scale, area[solid]
    ):
        return None
    return uv / np.median(scale)


def _stretched_at_a_tip(vertices: np.ndarray, triangles: np.ndarray, scale: np.ndarray, area: np.ndarray) -> bool:
    """Whether a map's lengths ``scale`` (per triangle, of ``area``) stay within MAX_STRETCH of each other but
    on the STRETCH_SHARE of the area most shrunk (or most stretched), and those triangles lie round one point,
    within TIP_EXTENT of the chart's size: a cone's tip, where its conformal map shrinks as a power of the
    distance (a drill point's by 2.1 times over a Gmsh surface mesh), not a dome's rim."""
    order = np.argsort(scale)
    share = np.cumsum(area[order]) / area.sum()
    low, high = scale[order][np.searchsorted(share, [STRETCH_SHARE, 1.0 - STRETCH_SHARE])]
    centres = vertices[triangles].mean(axis=1)
    size = np.linalg.norm(np.ptp(centres, axis=0))
    for tail, within in (
        (scale < low, scale.max() <= MAX_STRETCH * low),
        (scale > high, high <= MAX_STRETCH * scale.min()),
    ):
        tip = centres[tail]
        if within and len(tip) and np.linalg.norm(tip - tip.mean(axis=0), axis=1).max() < TIP_EXTENT * size:
            return True
    return False


def _half(mesh, faces: np.ndarray) -> np.ndarray:
    """The faces of ``faces`` on one side of the plane through their centroid across their longest extent."""
    centres = mesh.triangles_center[faces]
    centred = centres - centres.mean(axis=0)
    axis = np.linalg.svd(centred, full_matrices=False)[2][0]
    along = centred @ axis
    return faces[along > np.median(along)]


def _patches(geometry: Geometry, smooth_pairs: np.ndarray):
    mesh = geometry.mesh
    n = len(mesh.faces)
    graph = sparse.coo_matrix((np.ones(len(smooth_pairs)), (smooth_pairs[:, 0], smooth_pairs[:, 1])), shape=(n, n))
    count, labels = csgraph.connected_components(graph, directed=False)
    # renumber by lowest face index, so ids follow the surface's face order
    first_face = np.full(count, n)
    np.minimum.at(first_face, labels, np.arange(n))
    order = np.argsort(first_face)
    rank = np.empty(count, dtype=int)
    rank[order] = np.arange(count)
    labels = rank[labels]
    areas = mesh.area_faces
    normals = mesh.face_normals
    centres = mesh.triangles_center
    patches = []
    for k in range(count):
        faces = np.flatnonzero(labels == k)
        area = float(areas[faces].sum())
        normal = (normals[faces] * areas[faces, None]).sum(axis=0)
        normal /= max(np.linalg.norm(normal), 1e-300)
        centroid = (centres[faces] * areas[faces, None]).sum(axis=0) / max(area, 1e-300)
        verts = mesh.vertices[np.unique(mesh.faces[faces])]
        planar = bool(
            np.abs((verts - centroid) @ normal).max() <= FLAT * geometry.scale
            and np.all(normals[faces] @ normal > np.cos(COPLANAR))  # a float32 sliver's normal strays by 4e-4
        )
        cylinder = None if planar else fit_cylinder(centres[faces], normals[faces], verts)
        patches.append(
            Patch(
                id=f"patch-{k}",
                faces=faces,
                area=area,
                normal=normal,
                centroid=centroid,
                vertices=verts,
                planar=planar,
                cylinder=cylinder,
            )
        )
    return patches, labels


def _curves(
    vertices: np.ndarray,
    edges: np.ndarray,
    convex: np.ndarray,
    dihedral: np.ndarray,
    truly_sharp: np.ndarray,
    turn_threshold: float,
    tips: np.ndarray,
):
    """(corners, curves) of the feature ``edges`` (e, 2) into ``vertices``: a corner where other than two edges
    meet, where a sharp chain goes on as a smooth cut or turns by more than ``turn_threshold`` (radians), and at
    a ``tips`` vertex (mask over ``vertices``: the surface's angle defect there exceeds it, a cone's apex, where a
    smooth cut down a centre hole's cone to its tip and up again had no node) on any chain."""
    if len(edges) == 0:
        return [], []
    nv = len(vertices)
    degree = np.bincount(edges.ravel(), minlength=nv)
    corner_mask = (degree > 0) & (degree != 2)
    sharp_degree = np.bincount(edges[truly_sharp].ravel(), minlength=nv)
    corner_mask |= (degree == 2) & (sharp_degree == 1)  # where a sharp edge goes on as a smooth cut
    # a sharp chain turning by more than the feature angle has a corner there; a smooth cut follows
    # the input's edges, whose zigzag is no corner
    corner_mask |= _sharp_turns(vertices, edges[truly_sharp], sharp_degree, turn_threshold) & (degree == 2)
    corner_mask |= tips & (degree == 2)
    # edges belong to one curve when they share a vertex that is not a corner
    ne = len(edges)
    ends = np.concatenate([edges[:, 0], edges[:, 1]])
    edge_ids = np.concatenate([np.arange(ne), np.arange(ne)])
    inner = ~corner_mask[ends]
    order = np.argsort(ends[inner], kind="stable")
    v_sorted, e_sorted = ends[inner][order], edge_ids[inner][order]
    same = v_sorted[1:] == v_sorted[:-1]
    a, b = e_sorted[:-1][same], e_sorted[1:][same]
    graph = sparse.coo_matrix((np.ones(len(a)), (a, b)), shape=(ne, ne))
    count, edge_curve = csgraph.connected_components(graph, directed=False)

    corner_vertices = np.flatnonzero(corner_mask)
    corners = [Corner(id=f"corner-{i}", vertex=int(v), point=vertices[v].copy()) for i, v in enumerate(corner_vertices)]
    raw = []
    for k in range(count):
        members = np.flatnonzero(edge_curve == k)
        ordered, closed = _order_chain(edges[members], corner_mask)
        raw.append(
            (
                int(min(ordered)),
                ordered,
                closed,
                bool(np.mean(convex[members]) >= 0.5),
                float(np.median(dihedral[members])),
                bool(np.mean(truly_sharp[members]) >= 0.5),
            )
        )
    raw.sort(key=lambda item: item[0])
    curves = []
    for i, (_, ordered, closed, is_convex, angle, is_sharp) in enumerate(raw):
        points = vertices[ordered]
        curves.append(
            Curve(
                id=f"curve-{i}",
                points=points,
                closed=closed,
                vertices=ordered,
                convex=is_convex,
                dihedral=angle,
                sharp=is_sharp,
                circle=fit_circle(points) if closed else None,
            )
        )
    return corners, curves


def _sharp_turns(vertices, edges, degree, threshold) -> np.ndarray:
    """Degree-2 vertices where the chain turns by more than ``threshold``."""
    nv = len(vertices)
    turn = np.zeros(nv, dtype=bool)
    direction = vertices[edges[:, 1]] - vertices[edges[:, 0]]
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-300)
    # for each vertex of degree 2, the two unit vectors pointing away from it
    ends = np.concatenate([edges[:, 0], edges[:, 1]])
    away = np.concatenate([direction, -direction])
    pick = degree[ends] == 2
    ends, away = ends[pick], away[pick]
    order = np.argsort(ends, kind="stable")
    ends, away = ends[order], away[order]
    first, second = away[0::2], away[1::2]
    # the chain is straight when the two away-vectors are opposite
    cosine = -np.einsum("ij,ij->i", first, second)
    turn[ends[0::2]] = cosine < np.cos(threshold)
    return turn


def _order_chain(chain_edges: np.ndarray, corner_mask: np.ndarray):
    """Order the vertices of a chain of edges; return (vertex order, closed)."""
    local, inverse = np.unique(chain_edges.ravel(), return_inverse=True)
    inverse = inverse.reshape(-1, 2)
    n = len(local)
    graph = sparse.coo_matrix((np.ones(len(inverse)), (inverse[:, 0], inverse[:, 1])), shape=(n, n)).tocsr()
    graph = graph + graph.T
    ends = np.flatnonzero(corner_mask[local])
    local_degree = np.diff(graph.indptr)
    if len(ends) == 0:  # a loop without corners
        start, closed = int(np.argmin(local)), True
    elif len(ends) == 1 and local_degree[ends[0]] == 2:  # a loop through one corner
        start, closed = int(ends[0]), True
    else:
        start, closed = int(ends[np.argmin(local[ends])]), False
    order = csgraph.depth_first_order(graph, start, directed=False, return_predecessors=False)
    return local[order], closed


def classify(features: Features, kinds) -> Features:
    """The features with every curve and patch given the feature kinds (``FeatureKind``s) whose tests it
    passes, in the kinds' order after those it has; ``features`` is not changed."""

    def classified(feature, of: str):
        given = list(feature.kinds)
        for kind in kinds.values():
            if kind.of == of and kind.name not in given and all(_passes(feature, t, v) for t, v in kind.tests.items()):
                given.append(kind.name)
        return replace(feature, kinds=given) if len(given) > len(feature.kinds) else feature

    return replace(
        features,
        curves=[classified(c, "curve") for c in features.curves],
        patches=[classified(p, "patch") for p in features.patches],
    )


def _passes(feature, test: str, value) -> bool:
    if test == "named":
        return value in feature.names
    if test == "circular":
        return (feature.circle is not None) == value
    if test in ("dihedral_above", "dihedral_below"):
        angle = feature.dihedral
        return angle is not None and (angle > value if test == "dihedral_above" else angle < value)
    if test in ("cylindrical", "concave", "full_turn"):
        cylinder = feature.cylinder
        actual = cylinder is not None if test == "cylindrical" else bool(cylinder and getattr(cylinder, test))
        return actual == value
    if test in ("sweep_above", "sweep_below"):
        turn = feature.cylinder.sweep if feature.cylinder is not None else None
        return turn is not None and (turn > value if test == "sweep_above" else turn < value)
    return bool(getattr(feature, test)) == value


def apply_names(features: Features, rules, given_curves=()) -> Features:
    """The features named by ``rules`` (name, kind, test), in the rules' order, with ``given_curves`` added;
    ``features`` is not changed."""

    def named(feature, of: str):
        names = list(feature.names)
        for rule in rules:
            if rule.kind == of and rule.name not in names and rule.test(feature):
                names.append(rule.name)
        return replace(feature, names=names) if len(names) > len(feature.names) else feature

    curves = [named(c, "curve") for c in features.curves]
    for given in given_curves:
        points = np.asarray(given.points, float)
        curves.append(
            Curve(
                id=f"curve-{len(curves)}",
                points=points,
                closed=given.closed,
                vertices=None,
                names=[given.name],
                on_surface=False,
                circle=fit_circle(points) if given.closed else None,
            )
        )
    return replace(
        features,
        corners=[named(c, "corner") for c in features.corners],
        curves=curves,
        patches=[named(p, "patch") for p in features.patches],
    )


# ------------------------------------------------------------------ naming features in messages


def centroid(feature) -> np.ndarray:
    """A corner's point, a curve's centroid (by length along it), a patch's area centroid."""
    if isinstance(feature, Corner):
        return feature.point
    if isinstance(feature, Curve):
        line = feature.polyline
        length = np.linalg.norm(np.diff(line, axis=0), axis=1)
        middles = (line[1:] + line[:-1]) / 2
        return length @ middles / length.sum() if length.sum() > 0 else line.mean(axis=0)
    return feature.centroid


def describe(feature) -> str:
    """The feature's id and centroid, e.g. ``patch-11 (centroid 12.1, 4, 30)``, for messages."""
    point = centroid(feature)
    return f"{feature.id} (centroid {coordinates(point, np.abs(point).max())})"


def coordinates(point, scale: float) -> str:
    """A point as ``x, y, z`` (:func:`number` each), coordinates within 1e-5 x ``scale`` of 0 as 0 (below the four
    digits shown of a coordinate of size ``scale``: a float32 STL's rounding, not a position)."""
    point = np.asarray(point, dtype=float)
    return ", ".join(number(x) for x in np.where(np.abs(point) <= 1e-5 * scale, 0.0, point))


def number(x: float) -> str:
    """Four significant digits, never an exponent: 19290, 94.22, 0.001235."""
    return np.format_float_positional(x, precision=4, unique=False, fractional=False, trim="-")
