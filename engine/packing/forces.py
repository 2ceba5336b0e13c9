"""Interbubble forces (numba kernels) and the neighbour lists they use.

Shimada's proximity force between bubbles i and j at distance l, with the
stable distance r0 = (d_i + d_j) / 2 (d = h, the bubble diameter) and w = l / r0:
    f(w) = 1.25 w^3 - 2.375 w^2 + 1.125   for w < 1.5, 0 beyond,
repulsive (> 0) below w = 1, attractive between 1 and 1.5. The force is
scaled by r0 so that bubbles of every size move at the same relative pace
(k0 = 1 per unit of r0, m = 1).
"""

from __future__ import annotations

import numpy as np

from .._numba import numba
from ..sampling import point_tree

CUTOFF = 1.5  # w beyond which the force vanishes


@numba.njit(cache=True, inline="always")
def shimada(w):
    return 1.25 * w * w * w - 2.375 * w * w + 1.125


@numba.njit(cache=True, inline="always")
def separation(a, i, b, j):
    """Vector from point ``b[j]`` to point ``a[i]`` (rows of (n, 3) arrays), and its length."""
    dx = a[i, 0] - b[j, 0]
    dy = a[i, 1] - b[j, 1]
    dz = a[i, 2] - b[j, 2]
    return dx, dy, dz, np.sqrt(dx * dx + dy * dy + dz * dz)


@numba.njit(parallel=True, cache=True)
def forces(x, frozen, h, neighbours):
    """Net force on the bubbles ``x`` (n, 3) from their listed neighbours (n, k): an index j < n is ``x[j]``, one
    at or beyond n is ``frozen[j - n]`` (the lower levels' bubbles, kept apart so that no step copies them);
    ``h`` holds the diameters of both in that order; -1 entries are empty."""
    n = len(x)
    out = np.zeros((n, 3))
    for i in numba.prange(n):
        fx = 0.0
        fy = 0.0
        fz = 0.0
        for k in range(neighbours.shape[1]):
            j = neighbours[i, k]
            if j < 0:
                continue
            dx, dy, dz, length = separation(x, i, x, j) if j < n else separation(x, i, frozen, j - n)
            r0 = 0.5 * (h[i] + h[j])
            w = length / r0
            if w < CUTOFF and length > 0.0:
                scale = shimada(w) * r0 / length
                fx += scale * dx
                fy += scale * dy
                fz += scale * dz
        out[i, 0] = fx
        out[i, 1] = fy
        out[i, 2] = fz
    return out


@numba.njit(parallel=True, cache=True)
def proximity(x, h, neighbours, movable, count_radius):
    """Per movable bubble: overlap p = max_j r0 / l, and the count of neighbours within count_radius * r0."""
    overlap = np.ones(movable)
    count = np.zeros(movable, dtype=np.int64)
    for i in numba.prange(movable):
        best = 0.0
        c = 0
        for k in range(neighbours.shape[1]):
            j = neighbours[i, k]
            if j < 0:
                continue
            length = separation(x, i, x, j)[3]
            r0 = 0.5 * (h[i] + h[j])
            if length < count_radius * r0:
                c += 1
            ratio = r0 / max(length, 1e-300)
            if ratio > best:
                best = ratio
        overlap[i] = best
        count[i] = c
    return overlap, count


@numba.njit(parallel=True, cache=True)
def deletions(x, h, neighbours, movable, candidate, priority):
    """Candidates to delete: those with no closer-than-r0 candidate neighbour of higher priority.

    So of two overlapping candidates only the one with the higher priority goes in a round.
    """
    out = np.zeros(movable, dtype=np.bool_)
    for i in numba.prange(movable):
        if not candidate[i]:
            continue
        keep_me = False
        for k in range(neighbours.shape[1]):
            j = neighbours[i, k]
            if j < 0:
                continue
            if j >= movable or not candidate[j] or priority[j] <= priority[i]:
                continue
            if separation(x, i, x, j)[3] < 0.5 * (h[i] + h[j]):
                keep_me = True
                break
        out[i] = not keep_me
    return out


@numba.njit(cache=True)
def adopt(neighbours, x, first_new, movable):
    """Enter each new bubble (rows first_new..movable) into the lists of the movable bubbles it lists,
    in an empty slot or in place of a farther neighbour, so forces stay mutual between rebuilds."""
    for b in range(first_new, movable):
        for k in range(neighbours.shape[1]):
            j = neighbours[b, k]
            if j < 0 or j >= movable or j == b:
                continue
            d = (x[j, 0] - x[b, 0]) ** 2 + (x[j, 1] - x[b, 1]) ** 2 + (x[j, 2] - x[b, 2]) ** 2
            worst, worst_d = -1, -1.0
            for m in range(neighbours.shape[1]):
                o = neighbours[j, m]
                if o == b:
                    worst = -2
                    break
                if o < 0:
                    worst, worst_d = m, np.inf
                    continue
                e = (x[j, 0] - x[o, 0]) ** 2 + (x[j, 1] - x[o, 1]) ** 2 + (x[j, 2] - x[o, 2]) ** 2
                if e > worst_d:
                    worst, worst_d = m, e
            if worst >= 0 and d < worst_d:
                neighbours[j, worst] = b


def update_neighbours(
    neighbours: np.ndarray, keep: np.ndarray, everything: np.ndarray, movable: int, k: int
) -> np.ndarray:
    """Neighbour lists after a population change, without a full rebuild.

    ``keep`` marks the surviving old movable bubbles (their lists are renumbered,
    deleted entries emptied); the bubbles after them up to ``movable`` are new and
    get their own k nearest, then enter their neighbours' lists (:func:`adopt`).
    """
    old = len(keep)
    survivors = int(keep.sum())
    frozen = len(everything) - movable
    remap = np.full(old + frozen, -1, dtype=np.int64)
    remap[:old][keep] = np.arange(survivors)
    remap[old:] = movable + np.arange(frozen)
    rows = neighbours[keep]
    rows = np.where(rows >= 0, remap[np.maximum(rows, 0)], -1)
    fresh = movable - survivors
    if fresh:
        kk = min(k, len(everything) - 1, rows.shape[1])
        _, idx = point_tree(everything).query(everything[survivors:movable], k=kk + 1, workers=-1)
        idx = idx.astype(np.int64)
        own = idx == np.arange(survivors, movable)[:, None]
        keep_cols = ~own
        keep_cols[own.sum(axis=1) == 0, -1] = False
        new_rows = np.full((fresh, rows.shape[1]), -1, dtype=np.int64)
        new_rows[:, :kk] = idx[keep_cols].reshape(fresh, kk)
        rows = np.concatenate([rows, new_rows])
        adopt(rows, everything, survivors, movable)
    return np.ascontiguousarray(rows)


def morton_order(x: np.ndarray, bits: int = 10) -> np.ndarray:
    """A permutation that puts spatially close points close in memory (Z-order curve)."""
    if len(x) == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = x.min(axis=0), x.max(axis=0)
    cells = ((x - lo) / np.maximum(hi - lo, 1e-300) * (2**bits - 1)).astype(np.uint64)
    key = np.zeros(len(x), dtype=np.uint64)
    for bit in range(bits):
        for axis in range(3):
            key |= ((cells[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return np.argsort(key, kind="stable")


def neighbour_lists(x: np.ndarray, movable: int, k: int) -> np.ndarray:
    """The k nearest other bubbles of each movable bubble, as an (movable, k) int array."""
    k = min(k, len(x) - 1)
    if movable == 0 or k <= 0:
        return np.full((movable, 0), -1, dtype=np.int64)
    _, idx = point_tree(x).query(x[:movable], k=k + 1, workers=-1)
    idx = idx.astype(np.int64)
    own = idx == np.arange(movable)[:, None]
    # drop each row's own index (usually the first column; duplicates may swap places)
    keep = ~own
    keep[own.sum(axis=1) == 0, -1] = False
    return idx[keep].reshape(movable, k)
