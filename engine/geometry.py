"""The solid to mesh: a validated, closed, consistently oriented surface.

:func:`load_surface` reads STL, OBJ, PLY, OFF or GLB through trimesh and
refuses anything that is not a valid solid with one clear line.
:class:`Geometry` answers the vectorised queries the other stages need:
inside test, closest point on the surface, signed distance (positive inside).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import igl
import numpy as np
import trimesh

from .errors import GeometryError
from .inside import InsideGrid

log = logging.getLogger(__name__)

SURFACE_FORMATS = {".stl": "stl", ".obj": "obj", ".ply": "ply", ".off": "off", ".glb": "glb"}
TOUCH = 1e-9  # two shells closer than this times the model size touch
FLIP_ROUNDS = 8  # rounds of swapping zero-area faces' long edges (needles next to needles wait a round)


@dataclass(frozen=True, kw_only=True)
class Geometry:
    """A valid solid bounded by a closed, outward-oriented triangle surface. A frozen value whose measures are
    cached in its ``__dict__`` (``cached_property``; the wall thickness and curvature of engine/thickness.py and
    engine/curvature.py): no ``slots``, and a ``dataclasses.replace`` copy starts with no caches."""

    mesh: trimesh.Trimesh
    source: str
    face_body: np.ndarray  # the body (separate solid, 0-based) each face bounds; a cavity's is the solid around it
    notes: list[str] = field(default_factory=list)
    chord: float = 0.0  # how far the surface may lie from the true one it stands for (a CAD tessellation's
    # sagitta, engine/cad.py); 0 where the surface is the input itself (an STL)
    exact_volume: float | None = None  # the solid's volume from its exact definition (a CAD file's, by
    # OpenCASCADE; a built-in shape's formula); None where the surface is the definition (an STL)

    @property
    def bodies(self) -> int:
        return int(self.face_body.max()) + 1

    @property
    def vertices(self) -> np.ndarray:
        return self.mesh.vertices

    @property
    def faces(self) -> np.ndarray:
        return self.mesh.faces

    @property
    def bounds(self) -> np.ndarray:
        return self.mesh.bounds

    @property
    def volume(self) -> float:
        return float(self.mesh.volume)

    @property
    def area(self) -> float:
        return float(self.mesh.area)

    @property
    def scale(self) -> float:
        """Length of the bounding-box diagonal: the model size."""
        return float(np.linalg.norm(self.bounds[1] - self.bounds[0]))

    @cached_property
    def _igl_arrays(self):
        return (
            np.ascontiguousarray(self.mesh.vertices, dtype=np.float64),
            np.ascontiguousarray(self.mesh.faces, dtype=np.int64),
        )

    def _query(self, points: np.ndarray):
        points = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        V, F = self._igl_arrays
        if len(points) == 0:
            return np.zeros(0), np.zeros(0, np.int64), np.zeros((0, 3))
        dist, face, closest, _ = igl.signed_distance(points, V, F, sign_type=igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)
        return -dist, face, closest

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Distance to the surface, positive inside the solid."""
        return self._query(points)[0]

    def __getstate__(self) -> dict:
        """Pickled without the AABB tree (it cannot be; it is built again on use)."""
        return {key: value for key, value in self.__dict__.items() if key != "_tree"}

    @cached_property
    def _tree(self) -> igl.AABB:
        """An AABB tree of the faces, built once: ``igl.signed_distance`` builds one per call (0.2 s on a lofted
        blade's 150k facets, asked once per curve)."""
        tree = igl.AABB()
        tree.init(*self._igl_arrays)
        return tree

    def closest_point(self, points: np.ndarray):
        """Closest surface point (k, 3), its distance (k,) and the face it lies on (k,) to each of ``points``."""
        points = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        if len(points) == 0:
            return np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int64)
        squared, face, closest = self._tree.squared_distance(*self._igl_arrays, points)
        return closest, np.sqrt(squared), face

    def _exact_contains(self, points: np.ndarray) -> np.ndarray:
        return self._query(points)[0] > 0

    @cached_property
    def _inside_grid(self) -> InsideGrid:
        V, F = self._igl_arrays
        return InsideGrid(V, F, self._exact_contains)

    def contains(self, points: np.ndarray) -> np.ndarray:
        """True for points strictly inside the solid (vectorised, grid-accelerated)."""
        return self._inside_grid.contains(points)


def load_surface(path: str | Path, *, allow_multiple_solids: bool = False) -> Geometry:
    """Read a surface file and validate it as a solid (see :func:`validate_surface`)."""
    path = Path(path)
    source = str(path)
    suffix = path.suffix.lower()
    if suffix not in SURFACE_FORMATS:
        raise GeometryError(
            f"unknown surface format '{path.suffix or '(none)'}'",
            where=source,
            fix=f"give one of: {', '.join(sorted(SURFACE_FORMATS))}",
        )
    if not path.is_file():
        raise GeometryError("file not found", where=source, fix="check the path")
    if path.stat().st_size == 0:
        raise GeometryError("the file is empty", where=source, fix="export the solid again")
    try:
        loaded = trimesh.load(str(path), file_type=SURFACE_FORMATS[suffix], force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for broken files
        detail = "" if isinstance(exc, ImportError) else f" ({exc.__class__.__name__}: {exc})"
        raise GeometryError(
            f"not a readable {suffix[1:].upper()} surface{detail}",
            where=source,
            fix="check that the file is a valid surface mesh",
        ) from None
    if not isinstance(loaded, trimesh.Trimesh):
        raise GeometryError(
            "the file holds no triangle surface", where=source, fix="export the solid's boundary as triangles"
        )
    return validate_surface(loaded.vertices, loaded.faces, source, allow_multiple_solids=allow_multiple_solids)


def validate_surface(
    vertices, faces, source: str, *, allow_multiple_solids: bool = False, check_self_intersections: bool = True
) -> Geometry:
    """Build a :class:`Geometry` from raw arrays, or raise a one-line GeometryError.

    Refused: no triangles, NaN/inf coordinates, open or non-manifold surface,
    non-orientable surface, shells that touch or overlap, self-intersections,
    zero volume, several solids (unless allowed). Fixed and noted: inconsistent
    or inside-out orientation, duplicate vertices, degenerate faces.
    """
    vertices = np.asarray(vertices, dtype=float)
    faces = np.asarray(faces, dtype=np.int64)
    notes: list[str] = []
    if faces.ndim != 2 or len(faces) == 0:
        raise GeometryError("the surface has no triangles", where=source, fix="export the solid's boundary")
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise GeometryError(
            f"{int(bad.sum())} vertices have NaN or infinite coordinates (first: vertex {first})",
            where=source,
            fix="repair or re-export the surface",
        )
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    mesh.merge_vertices()
    notes += _without_degenerate_faces(mesh)
    if len(mesh.faces) == 0:
        raise GeometryError(
            "the surface has no triangles of non-zero area", where=source, fix="export the solid's boundary"
        )
    _check_closed(mesh, source)
    notes += _make_consistent(mesh, source)
    face_shell, depth, shell_body = _shells(mesh, source)
    if check_self_intersections:
        _check_self_intersections(mesh, source, face_shell, shell_body)
    notes += _orient(mesh, source, face_shell, depth, allow_multiple_solids)
    with np.errstate(divide="ignore", invalid="ignore"):
        volume = float(mesh.volume)
    if not volume > 1e-9 * mesh.scale**3:
        raise GeometryError(
            f"the surface encloses no volume ({volume:.3g})",
            where=source,
            fix="give a solid body, not a sheet or a degenerate surface",
        )
    for note in notes:
        log.warning("%s: %s", source, note)
    return Geometry(mesh=mesh, source=source, face_body=shell_body[face_shell], notes=notes)


def _without_degenerate_faces(mesh: trimesh.Trimesh) -> list[str]:
    """Remove or fix ``mesh``'s zero-area faces in place; the notes saying what was done. A face with a repeated
    vertex (two vertices merged) is removed; a needle whose third vertex lies on its longest edge (a T-junction
    of an OpenSCAD or CAD export: removing it would open the surface) swaps that edge with the face across it,
    in rounds (FLIP_ROUNDS) while needles meet needles; what is still degenerate is removed."""
    faces = mesh.faces
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    faces, flipped = faces[~repeated], 0
    for _ in range(FLIP_ROUNDS):
        needle = _degenerate(mesh.vertices, faces, mesh.scale)
        if len(needle) == 0:
            break
        faces, done = _flip_needles(mesh.vertices, faces, needle)
        flipped += done
        if done == 0:
            break
    else:
        needle = _degenerate(mesh.vertices, faces, mesh.scale)
    mesh.faces = np.delete(faces, needle, axis=0)
    mesh.remove_unreferenced_vertices()
    removed = int(repeated.sum()) + len(needle)
    notes = [f"removed {removed} degenerate (zero-area) faces"] if removed else []
    if flipped:
        notes.append(f"swapped the long edge of {flipped} zero-area faces whose third vertex lies on it (T-junctions)")
    return notes


def _degenerate(vertices: np.ndarray, faces: np.ndarray, scale: float) -> np.ndarray:
    """Indices of ``faces`` of zero area (no corner farther than 1e-12 x ``scale`` from the opposite side)."""
    surface = trimesh.Trimesh(vertices, faces, process=False)
    return np.flatnonzero(~surface.nondegenerate_faces(height=1e-12 * max(scale, 1e-300)))


def _flip_needles(vertices: np.ndarray, faces: np.ndarray, needle: np.ndarray) -> tuple[np.ndarray, int]:
    """(faces, how many needles were fixed): each of the ``needle`` faces (a, b, c), its longest edge a -> b, and
    the face (b, a, d) across it become (a, d, c) and (d, b, c); needles across from needles, or edges not
    shared by exactly two faces, wait for a later round (at most one flip per face per round)."""
    corners = vertices[faces[needle]]
    length = np.linalg.norm(corners - np.roll(corners, -1, axis=1), axis=2)  # edge k: corner k -> k + 1
    k = np.argmax(length, axis=1)
    a, b, c = faces[needle, k], faces[needle, (k + 1) % 3], faces[needle, (k + 2) % 3]
    directed = np.stack([faces, np.roll(faces, -1, axis=1)], axis=2).reshape(-1, 2)
    n = len(vertices)
    keys = directed[:, 0] * n + directed[:, 1]
    order = np.argsort(keys, kind="stable")
    ordered, across = keys[order], b * n + a
    at = np.clip(np.searchsorted(ordered, across), 0, len(keys) - 1)
    single = np.searchsorted(ordered, across, side="right") - np.searchsorted(ordered, across) == 1
    other = order[at] // 3
    is_needle = np.zeros(len(faces), bool)
    is_needle[needle] = True
    ok = single & ~is_needle[other]
    candidates = np.flatnonzero(ok)
    _, first, count = np.unique(other[candidates], return_index=True, return_counts=True)
    ok[:] = False
    ok[candidates[first[count == 1]]] = True  # one flip per face across
    slot = order[at] % 3  # the edge b -> a of the other face starts at its corner slot
    d = faces[other, (slot + 2) % 3]
    ok &= (d != c) & (d != a) & (d != b)
    faces = faces.copy()
    faces[needle[ok]] = np.column_stack([a, d, c])[ok]
    faces[other[ok]] = np.column_stack([d, b, c])[ok]
    return faces, int(ok.sum())


def _check_closed(mesh: trimesh.Trimesh, source: str) -> None:
    edges = np.sort(mesh.edges, axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    open_edges = int((counts == 1).sum())
    nonmanifold = int((counts > 2).sum())
    if open_edges:
        raise GeometryError(
            f"the surface is not closed (not watertight): {open_edges} edges bound a hole",
            where=source,
            fix="close the holes in the CAD tool or a mesh repair tool",
        )
    if nonmanifold:
        raise GeometryError(
            f"the surface is not manifold: {nonmanifold} edges are shared by more than two faces",
            where=source,
            fix="repair the surface so that each edge joins exactly two faces "
            "(bodies that touch along an edge share it: move them apart)",
        )


def _check_self_intersections(
    mesh: trimesh.Trimesh, source: str, face_shell: np.ndarray, shell_body: np.ndarray
) -> None:
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=mesh.vertices, face_matrix=mesh.faces.astype(np.int32)))
    ms.compute_selection_by_self_intersections_per_face()
    selected = ms.current_mesh().face_selection_array().astype(bool)
    if selected.any():
        selected = _crossing(np.asarray(mesh.vertices), np.asarray(mesh.faces), selected)
    shells = np.unique(face_shell[selected])
    if len(shells) > 1:
        raise _touch_error(source, shell_body, shells[0], shells[1])
    if len(shells):
        raise GeometryError(
            f"the surface intersects itself ({int(selected.sum())} faces cross other faces)",
            where=source,
            fix="union the overlapping bodies or repair the surface",
        )


def _crossing(vertices: np.ndarray, faces: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """Per face, whether it crosses or touches another of the ``candidates`` (per face: pymeshlab's selection),
    by CGAL's exact predicates (libigl). pymeshlab's test of a pair is not symmetric (two coplanar triangles 1 mm
    apart "cross" when the later one is tested first) and which orders it tests depends on the process: after a
    few calls of its get_topological_measures (engine/quality.py, once per mesh; four on a tetrahedron, three
    meshes of test_cad.py) it tests both, for good. Its selection alone thus depended on the faces' order and on
    what the process had run before (issue 17: a CAD assembly's tessellation refused after other meshes in one
    process, the faces meshed by Gmsh instead and the assembly rejected, met in a fresh process)."""
    from igl.copyleft.cgal import remesh_self_intersections

    index = np.flatnonzero(candidates)
    pairs = remesh_self_intersections(vertices, faces[index].astype(np.int64), detect_only=True)[2]
    out = np.zeros(len(faces), bool)
    out[index[pairs.ravel()]] = True
    return out


def _make_consistent(mesh: trimesh.Trimesh, source: str) -> list[str]:
    """Orient every face consistently with its neighbours. Mutates ``mesh``."""
    if mesh.is_winding_consistent:
        return []
    trimesh.repair.fix_winding(mesh)
    if not mesh.is_winding_consistent:
        raise GeometryError(
            "the surface cannot be oriented consistently (non-orientable)", where=source, fix="repair the surface"
        )
    return ["fixed inconsistent face orientation"]


def _shells(mesh: trimesh.Trimesh, source: str):
    """The closed shells of a consistently wound surface: (shell of every face, numbered by lowest face;
    depth of every shell inside the others; body of every shell, 0-based in shell order).

    A shell at even depth bounds a body of its own, one at odd depth is a cavity of the body around it.
    Shells whose bounding boxes overlap are tested against each other, vertex by vertex (by the inside
    grid; exactly only near the other shell): a vertex on the other shell (a shared one too) or some but
    not all vertices inside it make them touch or overlap, which is refused.
    """
    n = len(mesh.faces)
    labels = trimesh.graph.connected_component_labels(mesh.face_adjacency, node_count=n)
    count = int(labels.max()) + 1
    first = np.full(count, n)
    np.minimum.at(first, labels, np.arange(n))
    rank = np.empty(count, dtype=np.int64)
    rank[np.argsort(first)] = np.arange(count)
    face_shell = rank[labels]
    V = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    F = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    tol = TOUCH * mesh.scale
    lo, hi = np.full((count, 3), np.inf), np.full((count, 3), -np.inf)
    np.minimum.at(lo, face_shell, V[F].min(axis=1))
    np.maximum.at(hi, face_shell, V[F].max(axis=1))
    boxes_meet = ((lo[:, None] <= hi[None] + tol) & (lo[None] <= hi[:, None] + tol)).all(axis=2)
    pairs = np.argwhere(np.triu(boxes_meet, 1))
    shells = {k: _Shell(V, F[face_shell == k]) for k in np.unique(pairs)}
    inside = np.zeros((count, count), dtype=bool)  # inside[a, b]: shell a lies inside shell b
    touching = []
    for i, j in pairs:
        for a, b in ((i, j), (j, i)):
            within, on = shells[b].classify(shells[a].points, tol)
            inside[a, b] = within.all()
            if on.any() or within.any() != within.all():
                touching.append((i, j))
    depth = inside.sum(axis=1)
    outer = depth % 2 == 0
    around = np.argmax(inside & (depth[None, :] == depth[:, None] - 1), axis=1)  # a cavity's shell around it
    shell_body = (np.cumsum(outer) - 1)[np.where(outer, np.arange(count), around)]
    if touching:
        raise _touch_error(source, shell_body, *touching[0])
    return face_shell, depth, shell_body


class _Shell:
    """One closed shell, either way round: its vertices, and an inside test that also finds points on it."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        used = np.unique(faces)
        self.points = vertices[used]
        self.faces = np.searchsorted(used, faces)
        tri = self.points[self.faces]
        self.sign = -1.0 if np.einsum("ij,ij->", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])) > 0 else 1.0
        # the grid's few free regions by winding number: a region's cell centre may lie far from every face,
        # where the closest-point search would visit them all (the centre of a sphere)
        self.grid = InsideGrid(
            self.points,
            self.faces,
            lambda centres: np.abs([winding_number(self.points[self.faces], centre) for centre in centres]) > 0.5,
        )

    def classify(self, points: np.ndarray, tol: float):
        """(inside or on, on: within ``tol``) for every point; exact (signed distance) in the grid's cells
        that the shell may touch, by the cell's free region elsewhere."""
        region = self.grid.region(points)
        within = self.grid.region_inside[np.maximum(region, 0)]
        on = np.zeros(len(points), dtype=bool)
        near = np.flatnonzero(region == 0)
        if len(near):
            distance = (
                self.sign
                * igl.signed_distance(
                    np.ascontiguousarray(points[near]),
                    self.points,
                    self.faces,
                    sign_type=igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL,
                )[0]
            )
            within[near] = distance > -tol
            on[near] = np.abs(distance) <= tol
        return within, on


def winding_number(triangles: np.ndarray, point: np.ndarray) -> float:
    """How often the triangles (t, 3, 3) wind around ``point``: the sum of their solid angles over 4 pi."""
    a, b, c = (triangles[:, k] - point for k in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    dot = (
        la * lb * lc
        + np.einsum("ij,ij->i", a, b) * lc
        + np.einsum("ij,ij->i", b, c) * la
        + np.einsum("ij,ij->i", c, a) * lb
    )
    return float(np.arctan2(det, dot).sum() / (2 * np.pi))


def _touch_error(source: str, shell_body: np.ndarray, i: int, j: int) -> GeometryError:
    """The error for shells ``i`` and ``j`` that touch or overlap, naming their bodies (1-based)."""
    count = int(shell_body.max()) + 1
    held = f"the surface holds {count} {'body' if count == 1 else 'bodies'}"
    a, b = sorted((int(shell_body[i]) + 1, int(shell_body[j]) + 1))
    if a == b:
        return GeometryError(
            f"{held} and two shells of body {a} (its outer surface and a cavity, or two cavities) touch or overlap",
            where=source,
            fix="move the cavity clear of the other shell",
        )
    return GeometryError(
        f"{held} and bodies {a} and {b} touch or overlap",
        where=source,
        fix="move them apart, or unite them into one solid in the CAD tool",
    )


def _orient(
    mesh: trimesh.Trimesh, source: str, face_shell: np.ndarray, depth: np.ndarray, allow_multiple_solids: bool
) -> list[str]:
    """Orient every shell outward (cavities, at odd depth, inward); count solids. Mutates ``mesh``."""
    notes = []
    tri = np.asarray(mesh.vertices, dtype=np.float64)[mesh.faces]
    signed_volume = np.bincount(face_shell, np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])))
    flip = (signed_volume > 0) != (depth % 2 == 0)
    if flip.any():
        faces = mesh.faces.copy()
        faces[flip[face_shell]] = faces[flip[face_shell]][:, ::-1]
        mesh.faces = faces
        notes.append(f"turned {int(flip.sum())} inside-out shell(s) the right way round")
    solids = int((depth % 2 == 0).sum())
    if solids > 1 and not allow_multiple_solids:
        raise GeometryError(
            f"the surface holds {solids} disconnected solids",
            where=source,
            fix="mesh them one at a time, or set 'allow_multiple_solids: true' in the job's geometry",
        )
    return notes
