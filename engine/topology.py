"""Mesh topology shared by the meshers, the output and the FE model: which tets hold a node, which tet holds
a face. Numba kernels over (m, 4) int64 tets, no geometry."""

from __future__ import annotations

import numpy as np

from ._numba import numba


def node_stars(tets: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR of the tets around each node: tets star[start[v]:start[v + 1]] contain node v."""
    return _node_stars(np.ascontiguousarray(tets, dtype=np.int64), n)


@numba.njit(cache=True)
def _node_stars(tets, n):
    start = np.zeros(n + 1, np.int64)
    for v in tets.ravel():
        start[v + 1] += 1
    start = np.cumsum(start)
    fill = start[:-1].copy()
    star = np.empty(tets.size, np.int64)
    for t in range(len(tets)):
        for k in range(4):
            v = tets[t, k]
            star[fill[v]] = t
            fill[v] += 1
    return start, star


@numba.njit(cache=True)
def find_face(tets, start, star, a, b, c, skip):
    """The tet other than ``skip`` with nodes a, b, c, and the local index of its fourth node; -1 if none."""
    lo = min(a, min(b, c))
    for s in star[start[lo] : start[lo + 1]]:
        if s == skip:
            continue
        found, other = 0, -1
        for j in range(4):
            v = tets[s, j]
            if v == a or v == b or v == c:
                found += 1
            else:
                other = j
        if found == 3:
            return s, other
    return -1, -1


def face_owners(tets: np.ndarray, n: int, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each triangle, a tet that has it as a face and that tet's local index of the opposite node
    (-1, -1 where none has)."""
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    start, star = node_stars(tets, n)
    return _face_owners(tets, start, star, np.ascontiguousarray(triangles, dtype=np.int64))


@numba.njit(cache=True)
def _face_owners(tets, start, star, triangles):
    owner = np.full(len(triangles), -1, np.int64)
    opposite = np.full(len(triangles), -1, np.int64)
    for i in range(len(triangles)):
        owner[i], opposite[i] = find_face(tets, start, star, triangles[i, 0], triangles[i, 1], triangles[i, 2], -1)
    return owner, opposite
