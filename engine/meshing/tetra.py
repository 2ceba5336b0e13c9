"""Tetrahedralization kernels shared by the meshers: Gmsh's Delaunay, orientation, IN/OUT, ordering."""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager

import numpy as np

from .._numba import numba
from ..mesh import FACES, signed_volumes
from ..tetmetrics import shape_quality
from ..topology import find_face, node_stars

FLAT = 1e-10  # |6 x volume| below this x (edge length)^3: a flat tetrahedron


def gmsh_session() -> None:
    """Initialise Gmsh once, quietly, with HXT as the 3-D kernel (the one that takes constraints).

    Not ``interruptible``: Gmsh would set SIGINT's handler, which only the main thread may (a Dask worker meshes
    in a thread), and Ctrl-C would then kill the process before the output's temporary files are removed."""
    import gmsh

    if not gmsh.isInitialized():
        gmsh.initialize(readConfigFiles=False, interruptible=False)
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.Verbosity", 0)
    gmsh.option.setNumber("Mesh.Algorithm3D", 10)


@contextmanager
def quiet_stdout():
    """Silence what native code writes to the process's standard output."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def tetrahedralize(points: np.ndarray, triangles: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Delaunay tetrahedra (m, 4), 0-based, of ``points`` by Gmsh, with ``triangles`` as constrained faces.

    Returns (tets, steiner points); the tets cover the convex hull, and
    indices at and beyond len(points) are Steiner points.
    """
    import gmsh

    gmsh_session()
    faces = [] if triangles is None else (np.asarray(triangles, dtype=np.int64) + 1).ravel().tolist()
    with quiet_stdout():  # HXT prints "Info : Recover Delaunay" whatever the verbosity
        tets, steiner = gmsh.algorithm.tetrahedralize(np.ascontiguousarray(points, dtype=float).ravel(), faces)
    return np.asarray(tets, dtype=np.int64).reshape(-1, 4) - 1, np.asarray(steiner, dtype=float).reshape(-1, 3)


def orient(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tets made positive by swapping two nodes where needed, and their volumes."""
    vol = signed_volumes(points, tets)
    tets = tets.copy()
    negative = vol < 0
    tets[negative] = tets[negative][:, [1, 0, 2, 3]]
    return tets, np.abs(vol)


def inside_by_boundary(points: np.ndarray, tets: np.ndarray, boundary: np.ndarray) -> np.ndarray:
    """Which tets lie inside the closed, outward-oriented ``boundary`` triangulation (faces of the tets).

    The outside is flooded, through faces that are not boundary triangles,
    from the tets in front of (on the outer side of) a boundary triangle;
    every outside region of the hull touches the boundary, so what is not
    reached is inside. Exact: no inside tests on the curved solid, whose
    chords the boundary triangles are; reaching a tet that lies behind a
    boundary triangle is an error. A flat tet is inside only if it has a
    neighbour across each face and no boundary triangle (:func:`unfold_flat`
    takes it out); on a boundary or the hull it is not.
    """
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    start, star = node_stars(tets, len(points))
    inside, conflicts = _inside_by_boundary(
        np.ascontiguousarray(points, dtype=np.float64),
        tets,
        np.ascontiguousarray(boundary, dtype=np.int64),
        start,
        star,
        FACES,
    )
    if conflicts:
        raise RuntimeError("a region of tetrahedra lies on both sides of the boundary")
    return inside


@numba.njit(cache=True)
def _inside_by_boundary(points, tets, boundary, start, star, faces):
    m = len(tets)
    blocked = np.zeros((m, 4), np.bool_)
    vote = np.zeros(m, np.int8)  # +1: behind a boundary triangle, -1: in front of one
    for i in range(len(boundary)):
        a, b, c = boundary[i, 0], boundary[i, 1], boundary[i, 2]
        ab, ac = points[b] - points[a], points[c] - points[a]
        normal = np.cross(ab, ac)
        skip = -1
        for _ in range(2):
            t, k = find_face(tets, start, star, a, b, c, skip)
            if t < 0:
                break
            blocked[t, k] = True
            side = np.dot(points[tets[t, k]] - points[a], normal)
            scale = np.dot(normal, normal) ** 0.75  # ~ |ab|^3: a flat tet on a flat hull votes nothing
            if side < -FLAT * scale:
                vote[t] = 1
            elif side > FLAT * scale:
                vote[t] = -1
            skip = t
    # flood the outside from the tets in front of the boundary; every outside region touches the boundary
    outside = np.zeros(m, np.bool_)
    stack = np.empty(m, np.int64)
    top = 0
    for t in range(m):
        if vote[t] < 0:
            outside[t] = True
            stack[top] = t
            top += 1
    conflicts = 0
    while top:
        top -= 1
        t = stack[top]
        for k in range(4):
            if blocked[t, k]:
                continue
            f = faces[k]
            s, _ = find_face(tets, start, star, tets[t, f[0]], tets[t, f[1]], tets[t, f[2]], t)
            if s >= 0 and not outside[s]:
                if vote[s] > 0:
                    conflicts += 1
                outside[s] = True
                stack[top] = s
                top += 1
    inside = ~outside
    for t in range(m):  # a flat tet on the hull (HXT fills a flat hull face with them) is not inside
        if inside[t] and _is_flat(points, tets[t]):
            for k in range(4):
                f = faces[k]
                s, _ = find_face(tets, start, star, tets[t, f[0]], tets[t, f[1]], tets[t, f[2]], t)
                if blocked[t, k] or s < 0:
                    inside[t] = False
    return inside, conflicts


def unfold_flat(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """``tets`` (all inside the solid) with their flat tetrahedra unfolded where their sides are two pyramids.

    Four coplanar nodes on one sphere (a thin plate's edges packed alike on its top and bottom, a rectangle of
    four nodes across a corner) have two Delaunay diagonals; HXT may split the quad by one for the pyramid on
    one side and by the other for the pyramid on the other side, with a zero-volume tet between them, which
    the IN/OUT pass could only drop (a hole in the solid: the boundary is not a two-manifold). The pyramid
    whose apex sees the quad from one side is re-split by the other side's diagonal, whichever of the two
    re-splits leaves the better worst tet. A flat tet whose sides are not two such pyramids (each side's two
    triangles in tets of different apexes: a rectangle through a 10 mm ligament, rim to plate edge, at h 11)
    stays, for the mesher's swaps to take out (``improve.swap_bad_faces``; dropping it left the same hole there).
    """
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    flat = np.flatnonzero(flat_tets(points, tets))
    if not len(flat):
        return tets
    start, star = node_stars(tets, len(points))
    taken = np.zeros(len(tets), bool)  # flat, or re-split already
    taken[flat] = True
    gone = np.zeros(len(tets), bool)
    added = []
    for t in flat:
        own = np.sort(tets[t, FACES], axis=1)
        across = [find_face(tets, start, star, *face, t)[0] for face in own]
        if min(across) < 0 or taken[across].any():
            continue
        apex = [int(np.setdiff1d(tets[s], tets[t])[0]) for s in across]
        sides = [(k, j) for k in range(4) for j in range(k + 1, 4) if apex[k] == apex[j]]
        if len(sides) != 2 or sorted(sides[0] + sides[1]) != [0, 1, 2, 3]:
            continue
        best = None  # (worst new quality, the pyramid re-split, its new tets)
        for keep, redo in (sides, sides[::-1]):  # the pyramid 'redo' takes the triangles of the pyramid 'keep'
            new, _ = orient(points, np.array([[apex[redo[0]], *own[k]] for k in keep]))
            worst = min(shape_quality(*points[row]) for row in new)
            if worst > 0 and (best is None or worst > best[0]):
                best = (worst, [across[k] for k in redo], new)
        if best is not None:
            gone[[t, *best[1]]] = taken[best[1]] = True
            added.append(best[2])
    return np.concatenate([tets[~gone], *added]) if added else tets[~gone]


@numba.njit(cache=True)
def _is_flat(points, tet):
    """Whether the tet is flat: |6 x volume| at most FLAT x (its first edge's length)^3."""
    a = points[tet[0]]
    bx, by, bz = points[tet[1], 0] - a[0], points[tet[1], 1] - a[1], points[tet[1], 2] - a[2]
    cx, cy, cz = points[tet[2], 0] - a[0], points[tet[2], 1] - a[1], points[tet[2], 2] - a[2]
    dx, dy, dz = points[tet[3], 0] - a[0], points[tet[3], 1] - a[1], points[tet[3], 2] - a[2]
    six_volume = bx * (cy * dz - cz * dy) + by * (cz * dx - cx * dz) + bz * (cx * dy - cy * dx)
    return abs(six_volume) <= FLAT * (bx * bx + by * by + bz * bz) ** 1.5


def flat_tets(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """(m,) whether each of ``tets`` (m, 4) is flat: |6 x volume| at most FLAT x (its first edge's length)^3."""
    return _flat(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(tets, dtype=np.int64))


@numba.njit(cache=True)
def _flat(points, tets):
    """(m,) whether each tet is flat (:func:`_is_flat`)."""
    flat = np.zeros(len(tets), np.bool_)
    for t in range(len(tets)):
        flat[t] = _is_flat(points, tets[t])
    return flat


def canonical(tets: np.ndarray) -> np.ndarray:
    """The same tets in a unique order: nodes sorted up to an even permutation, rows sorted.

    Gmsh returns tetrahedra in a run-dependent order; this makes the mesh
    depend on the nodes only (orientation is kept).
    """
    rows = _sorted_rows(np.ascontiguousarray(tets, dtype=np.int64))
    if len(rows) and rows.max() < 2**21:  # three nodes in one int64 key
        order = np.lexsort((rows[:, 3], (rows[:, 0] << 42) | (rows[:, 1] << 21) | rows[:, 2]))
    else:
        order = np.lexsort(rows.T[::-1])
    return rows[order]


@numba.njit(cache=True)
def _sorted_rows(tets):
    """Each row's nodes in increasing order, the last two swapped where that takes an odd permutation."""
    out = tets.copy()
    for t in range(len(out)):
        row = out[t]
        odd = False
        for i in range(1, 4):  # insertion sort, counting swaps
            j = i
            while j > 0 and row[j - 1] > row[j]:
                row[j - 1], row[j] = row[j], row[j - 1]
                odd = not odd
                j -= 1
        if odd:
            row[2], row[3] = row[3], row[2]
    return out


def compact(points, tets, *node_arrays):
    """Drop nodes no tetrahedron uses; renumber. Returns (points, tets, *node_arrays, new index of old)."""
    used = np.zeros(len(points), bool)
    used[tets.ravel()] = True
    new_index = np.where(used, np.cumsum(used) - 1, -1)
    return (points[used], new_index[tets], *[a[used] for a in node_arrays], new_index)
