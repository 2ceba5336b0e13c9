"""Example fuzzymesh plug-ins (docs/plugins.md), registered by the entry points of pyproject.toml.

``pack`` keeps the Packer protocol of engine/plugins.py: the built-in lattice packer's nodes, with every
volume node moved by up to JITTER x h in a random direction drawn from the job's seed, except where that
leaves the solid or comes within h / 2 of another node's lattice place. ``mesh`` keeps the Mesher
protocol: the built-in Delaunay mesher, with the node count of each level added to the mesh's stats.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from engine.levels import NODE_LEVELS
from engine.meshing import get_mesher
from engine.packing import VOLUME, get_packer

JITTER = 0.2


def pack(geometry, features, sizing, *, seed, knowledge):
    packing = get_packer("lattice")(geometry, features, sizing, seed=seed, knowledge=knowledge)
    rng = np.random.default_rng(seed)
    volume = np.flatnonzero(packing.level == VOLUME)
    h = 2 * packing.radius[volume]
    step = rng.normal(size=(len(volume), 3))
    step *= (JITTER * h * rng.random(len(volume)) / np.linalg.norm(step, axis=1))[:, None]
    moved = packing.points[volume] + step
    distance, index = cKDTree(packing.points).query(moved, k=2)  # the nearest other node than itself
    gap = np.where(index[:, 0] == volume, distance[:, 1], distance[:, 0])
    keep = geometry.contains(moved) & (gap > h / 2)
    packing.points[volume[keep]] = moved[keep]
    packing.radius[volume[keep]] = sizing(moved[keep]) / 2
    packing.stats["jittered"] = int(keep.sum())
    return packing


def mesh(packing, geometry, features, *, seed):
    result = get_mesher("delaunay")(packing, geometry, features, seed=seed)
    result.stats["nodes_per_level"] = {
        name: int(np.count_nonzero(result.node_level == k)) for k, name in enumerate(NODE_LEVELS)
    }
    return result
