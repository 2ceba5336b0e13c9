"""The ``delaunay`` mesher: Delaunay of all nodes, then the IN/OUT check.

All nodes are tetrahedralized with Gmsh's Delaunay kernel
(``gmsh.algorithm.tetrahedralize``); tetrahedra whose centroid lies outside
the solid, and flat ones, are dropped (the paper's method).
"""
from __future__ import annotations

import numpy as np

from ..mesh import TetMesh
from . import register_mesher

FLAT_VOLUME = 1e-9  # tets with volume below this fraction of h^3 are flat (degenerate)


def tetrahedralize(points: np.ndarray) -> np.ndarray:
    """Delaunay tetrahedra (m, 4), 0-based, of ``points`` by Gmsh's kernel."""
    import gmsh

    if not gmsh.isInitialized():
        gmsh.initialize(readConfigFiles=False)
        gmsh.option.setNumber("General.Terminal", 0)
    tets, steiner = gmsh.algorithm.tetrahedralize(np.ascontiguousarray(points, dtype=float).ravel())
    if len(steiner):
        raise RuntimeError("unconstrained Delaunay added Steiner points")
    return np.asarray(tets, dtype=np.int64).reshape(-1, 4) - 1


def orient(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tets made positive by swapping two nodes where needed, and their volumes."""
    p = points[tets]
    vol = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6.0
    tets = tets.copy()
    negative = vol < 0
    tets[negative] = tets[negative][:, [1, 0, 2, 3]]
    return tets, np.abs(vol)


def canonical(tets: np.ndarray) -> np.ndarray:
    """The same tets in a unique order: nodes sorted up to an even permutation, rows sorted.

    Gmsh's kernel returns the tetrahedra in a run-dependent order; this makes
    the mesh depend on the nodes only (orientation is kept).
    """
    order = np.argsort(tets, axis=1)
    rows = np.take_along_axis(tets, order, axis=1)
    # parity of the sorting permutation: count inversions among the 4 positions
    inversions = sum((order[:, i] > order[:, j]).astype(int) for i in range(4) for j in range(i + 1, 4))
    odd = inversions % 2 == 1
    rows[odd] = rows[odd][:, [0, 1, 3, 2]]
    return rows[np.lexsort(rows.T[::-1])]


def compact(points, tets, *node_arrays):
    """Drop nodes no tetrahedron uses; renumber."""
    used = np.zeros(len(points), bool)
    used[tets.ravel()] = True
    new_index = np.cumsum(used) - 1
    return (points[used], new_index[tets], *[a[used] for a in node_arrays])


@register_mesher("delaunay")
def mesh_delaunay(packing, geometry, features) -> TetMesh:
    points = packing.points
    tets, volume = orient(points, tetrahedralize(points))
    total = len(tets)
    h = 2 * packing.radius[tets].mean(axis=1)
    keep = volume > FLAT_VOLUME * h ** 3
    centroids = points[tets[keep]].mean(axis=1)
    keep[keep] = geometry.contains(centroids)
    tets = tets[keep]
    points, tets, level, entity = compact(points, tets, packing.level, packing.entity)
    tets = canonical(tets)
    stats = {"delaunay_tets": total, "outside_or_flat_dropped": int(total - len(tets)),
             "unused_nodes_dropped": int(len(packing) - len(points))}
    return TetMesh(points, tets, level, entity, stats)
