"""The ``qhull`` mesher: the paper's method as written, kept for comparison.

Unconstrained Delaunay of all nodes by Qhull (scipy), then the IN/OUT check:
tets whose centroid is outside the solid are dropped, and so are flat ones.
No boundary recovery and no quality improvement: the boundary can miss
surface triangles or bridge concave regions, and slivers stay. Its stats count
the boundary defects (free faces through the volume, non-manifold boundary
edges) and the log shows them with the slivers; use the default ``delaunay``
mesher for analysis.

Qhull options, chosen by measurement on 166,865 junction nodes (this
machine): the defaults took 106-133 s and 13-16 GB; ``QJ`` (joggled input,
every facet simplicial) 6.6 s and 0.45 GB.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from scipy.spatial import Delaunay

from ..mesh import TetMesh
from ..packing import VOLUME
from . import register_mesher
from .tetra import canonical, compact, orient

QHULL_OPTIONS = "QJ Qbb"
FLAT_VOLUME = 1e-9  # tets below this fraction of h^3 are flat (Qhull's joggle leaves some on the hull)


@register_mesher("qhull")
def mesh_qhull(packing, geometry, features, *, seed: int = 0) -> TetMesh:
    start = time.perf_counter()
    points = packing.points
    tets, volume = orient(points, Delaunay(points, qhull_options=QHULL_OPTIONS).simplices.astype(np.int64))
    total = len(tets)
    h = 2 * packing.radius[tets].mean(axis=1)
    keep = volume > FLAT_VOLUME * h**3
    keep[keep] = geometry.contains(points[tets[keep]].mean(axis=1))
    bubble = packing.ids if packing.ids is not None else np.full(len(packing), -1)
    points, tets, level, entity, bubble, _ = compact(points, tets[keep], packing.level, packing.entity, bubble)
    mesh = TetMesh(
        points=points, tets=canonical(tets), node_level=level.astype(np.int8), node_entity=entity, node_bubble=bubble
    )
    stats = {
        "delaunay_tets": total,
        "outside_or_flat_dropped": int(total - len(tets)),
        "unused_nodes_dropped": int(len(packing) - len(points)),
        **boundary_defects(mesh),
        "seconds": {"connect": round(time.perf_counter() - start, 3)},
    }
    return replace(mesh, stats=stats)


def boundary_defects(mesh: TetMesh) -> dict:
    """What keeps the free faces from being the solid's surface: faces through the volume (a node
    inside the solid) and edges shared by more than two free faces (a non-manifold boundary)."""
    free = mesh.boundary_faces()
    through_volume = (mesh.node_level[free] == VOLUME).any(axis=1)
    edges = np.sort(free[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    return {
        "boundary_faces": len(free),
        "boundary_faces_through_volume": int(through_volume.sum()),
        "non_manifold_boundary_edges": int((uses > 2).sum()),
    }
