"""Point-set thinning shared by the packers: a vectorised maximal independent set.

Two points conflict when they are closer than the mean of their exclusion
radii. :func:`thin` keeps a maximal set of points with no conflicts, always
keeping the ``fixed`` ones, preferring higher random priority (seeded).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def conflict_pairs(points: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ordered pairs (i, j), i != j, with |p_i - p_j| < (r_i + r_j) / 2 (both directions).

    Points are bucketed by radius (factors of 2) so that a fine region does not
    search with the coarse regions' radius.
    """
    if len(points) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    bucket = np.floor(np.log2(radius / radius.min())).astype(int)
    groups = [np.flatnonzero(bucket == b) for b in np.unique(bucket)]
    trees = [cKDTree(points[g]) for g in groups]
    reach = [float(radius[g].max()) for g in groups]
    found_i, found_j = [], []
    for u in range(len(groups)):
        for v in range(u, len(groups)):
            limit = 0.5 * (reach[u] + reach[v])
            if u == v:
                pairs = trees[u].query_pairs(limit, output_type="ndarray")
                i, j = groups[u][pairs[:, 0]], groups[u][pairs[:, 1]]
            else:
                found = trees[u].sparse_distance_matrix(trees[v], limit, output_type="ndarray")
                i, j = groups[u][found["i"]], groups[v][found["j"]]
            close = np.linalg.norm(points[i] - points[j], axis=1) < 0.5 * (radius[i] + radius[j])
            found_i.append(i[close])
            found_j.append(j[close])
    i, j = np.concatenate(found_i), np.concatenate(found_j)
    return np.concatenate([i, j]), np.concatenate([j, i])


def thin(
    points: np.ndarray, radius: np.ndarray, rng: np.random.Generator, fixed: np.ndarray | None = None
) -> np.ndarray:
    """Boolean mask of a maximal conflict-free subset that contains every fixed point."""
    n = len(points)
    fixed = np.zeros(n, bool) if fixed is None else fixed
    a, b = conflict_pairs(points, radius)
    state = np.zeros(n, dtype=np.int8)  # 0 undecided, 1 kept, -1 dropped
    state[fixed] = 1
    state[b[fixed[a] & ~fixed[b]]] = -1
    priority = rng.random(n)
    while True:
        undecided = state == 0
        if not undecided.any():
            return state == 1
        live = undecided[a] & undecided[b]
        is_max = undecided.copy()
        lose = live & (priority[a] < priority[b])
        is_max[a[lose]] = False
        state[is_max] = 1
        state[b[is_max[a] & (state[b] == 0)]] = -1
