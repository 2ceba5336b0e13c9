"""Point sets shared by the packers: their k-d trees (:func:`point_tree`), and thinning, a maximal conflict-free
subset chosen greedily by seeded random priority, holding each conflict once as two int32 (not every conflict's
distances and both directions).

Two points conflict when they are closer than the mean of their exclusion radii. :func:`thin` keeps the
``fixed`` points, then every other point in descending random priority unless it conflicts with one already
kept: the maximal independent set a parallel (Luby) thinning with the same priorities gives. Conflicts are
found a block of CHUNK spatially close points at a time (the surface start of a fin-heavy part has 8
candidates per h^2 and millions of conflicts).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ._numba import numba

CHUNK = 1 << 15  # points whose conflicts are searched at once


def point_tree(points: np.ndarray) -> cKDTree:
    """A k-d tree of ``points`` (n, 3) split at sliding midpoints instead of medians (``balanced_tree=False``):
    built in half the time (275k bubbles: 0.10 -> 0.05 s), queried as fast on a packing's near-uniform points,
    with the same answers. The packer builds one per population round, mostly for a few queries."""
    return cKDTree(points, balanced_tree=False)


def thin(
    points: np.ndarray, radius: np.ndarray, rng: np.random.Generator, fixed: np.ndarray | None = None
) -> np.ndarray:
    """(n,) boolean mask of a maximal subset of ``points`` (n, 3) with no two closer than the mean of their
    ``radius`` (n,) that contains every ``fixed`` point (fixed points may conflict with each other)."""
    n = len(points)
    fixed = np.zeros(n, bool) if fixed is None else fixed
    priority = rng.random(n)
    order = np.lexsort((-priority, ~fixed))  # fixed first, then by descending priority
    rank = np.empty(n, np.int64)
    rank[order] = np.arange(n)
    later, earlier = _earlier_conflicts(points, radius, rank)
    by_later = np.argsort(later, kind="stable")
    first = np.concatenate([[0], np.cumsum(np.bincount(later, minlength=n))])
    kept = fixed.copy()
    _keep_unless_conflicting(order[int(fixed.sum()) :], first, earlier[by_later], kept)
    return kept


def _earlier_conflicts(points: np.ndarray, radius: np.ndarray, rank: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(i, j) int32: every conflicting pair once, j the one of higher priority (lower ``rank``). Points are
    grouped by radius in factors of 2, so that a fine region does not search with the coarse regions' radius,
    and each group's points are taken in blocks of CHUNK in its k-d tree's order (spatially close)."""
    if not len(points):
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    _, bucket = np.unique(np.floor(np.log2(radius / radius.min())).astype(int), return_inverse=True)
    groups = [np.flatnonzero(bucket == b) for b in range(bucket.max() + 1)]
    trees = [point_tree(points[g]) for g in groups]
    reach = [float(radius[g].max()) for g in groups]
    found_i, found_j = [], []
    for u, tree in enumerate(trees):
        for block in np.array_split(groups[u][tree.indices], -(-len(tree.indices) // CHUNK)):
            block_tree = point_tree(points[block])
            for v, others in enumerate(groups):
                found = block_tree.sparse_distance_matrix(trees[v], 0.5 * (reach[u] + reach[v]), output_type="ndarray")
                i, j = block[found["i"]], others[found["j"]]
                conflict = (found["v"] < 0.5 * (radius[i] + radius[j])) & (rank[j] < rank[i])
                found_i.append(i[conflict].astype(np.int32))
                found_j.append(j[conflict].astype(np.int32))
    return np.concatenate(found_i), np.concatenate(found_j)


@numba.njit(cache=True)
def _keep_unless_conflicting(order, first, earlier, kept):
    """Keep each point of ``order`` (descending priority) unless one of its higher-priority conflicts
    ``earlier[first[i]:first[i + 1]]`` is kept (``kept`` updated in place)."""
    for i in order:
        keep = True
        for p in range(first[i], first[i + 1]):
            if kept[earlier[p]]:
                keep = False
                break
        kept[i] = keep
