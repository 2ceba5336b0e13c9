"""The tetrahedral mesh value object."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ._numba import numba

FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])  # face k is opposite vertex k, outward


def signed_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """(m,) volume of each of ``tets`` (m, 4), positive for positively oriented ones: (b - a) . ((c - a) x (d - a))
    / 6, in numba (numpy's gather of (m, 4, 3) corners and its temporaries took 0.26 s at 1.5M tets); the terms
    summed in the order numpy's einsum of the cross product summed them, so the values are the same."""
    return _signed_volumes(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(tets, dtype=np.int64))


@numba.njit(parallel=True, cache=True)
def _signed_volumes(points, tets):
    out = np.empty(len(tets))
    for t in numba.prange(len(tets)):
        a, b, c, d = points[tets[t, 0]], points[tets[t, 1]], points[tets[t, 2]], points[tets[t, 3]]
        ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
        vx, vy, vz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
        wx, wy, wz = d[0] - a[0], d[1] - a[1], d[2] - a[2]
        out[t] = (ux * (vy * wz - vz * wy) + uz * (vx * wy - vy * wx) + uy * (vz * wx - vx * wz)) / 6.0
    return out


def distinct_pairs(pairs: np.ndarray, counts: bool = False):
    """(k, 2) the distinct rows of the integer pairs (m, 2) in ascending (a, b) order: np.unique(pairs, axis=0),
    through one int64 key a n + b per row (1-D: 3-4x faster); with ``counts``, also (k,) how often each occurs."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    n = int(pairs.max(initial=0)) + 1
    keys, seen = np.unique(pairs[:, 0] * n + pairs[:, 1], return_counts=True)
    distinct = np.column_stack(np.divmod(keys, n))
    return (distinct, seen) if counts else distinct


def triangle_edges(triangles: np.ndarray) -> np.ndarray:
    """(k, 2) the distinct edges of ``triangles`` (t, 3), each ascending, in ascending (a, b) order."""
    return distinct_pairs(np.sort(np.asarray(triangles)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1))


def single_faces(tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(owner (t,), side (t,)) of the faces of ``tets`` (m, 4) used by one tetrahedron only, in tet order:
    they are ``tets[owner, FACES[side]]``, outward for positively oriented tets. Each tet's nodes are ranked
    once, so its faces come out ascending, and :func:`_once` finds the faces that occur once, grouped by their
    smallest node (1.5M tets: 0.49 s with numpy's row argsort, gathered face array and a serial pass; 0.07 s)."""
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    rank = _ranks(tets)
    once = np.flatnonzero(_once(tets, rank, int(tets.max(initial=0)) + 1))  # face ids: 4 x tet + ranked k
    owner = once // 4
    side = rank[owner, once % 4]  # the ranked vertex a face is opposite, back in the tet's own order
    by_tet = np.argsort(owner * 4 + side)
    return owner[by_tet], side[by_tet]


@numba.njit(parallel=True, cache=True)
def _ranks(tets):
    """(m, 4) the positions of each tet's nodes in ascending order of node (ties in position order)."""
    rank = np.empty(tets.shape, np.int64)
    for t in numba.prange(len(tets)):
        for k in range(4):
            rank[t, k] = k
        for k in range(1, 4):
            j = k
            while j > 0 and tets[t, rank[t, j - 1]] > tets[t, rank[t, j]]:
                rank[t, j - 1], rank[t, j] = rank[t, j], rank[t, j - 1]
                j -= 1
    return rank


@numba.njit(cache=True, inline="always")
def _face_nodes(tets, rank, face):
    """The ascending nodes of face ``face`` = 4 t + k: tet t's face opposite its k-th smallest node."""
    t, k = face // 4, face % 4
    a = rank[t, 1] if k == 0 else rank[t, 0]
    b = rank[t, 2] if k <= 1 else rank[t, 1]
    c = rank[t, 3] if k <= 2 else rank[t, 2]
    return tets[t, a], tets[t, b], tets[t, c]


@numba.njit(parallel=True, cache=True)
def _once(tets, rank, n):
    """(4 m,) whether each face of ``tets`` (ranked by ``rank``) occurs once: the faces counting-sorted by their
    smallest node (of [0, n)), then each group's (second, third) keys sorted (a few dozen per group), the
    groups in parallel."""
    faces = 4 * len(tets)
    start = np.zeros(n + 1, np.int64)
    for f in range(faces):
        start[_face_nodes(tets, rank, f)[0] + 1] += 1
    for a in range(n):
        start[a + 1] += start[a]
    fill = start[:-1].copy()
    by_first = np.empty(faces, np.int64)
    for f in range(faces):
        a = _face_nodes(tets, rank, f)[0]
        by_first[fill[a]] = f
        fill[a] += 1
    single = np.zeros(faces, np.bool_)
    for a in numba.prange(n):
        size = start[a + 1] - start[a]
        keys = np.empty(size, np.int64)
        for j in range(size):
            _, b, c = _face_nodes(tets, rank, by_first[start[a] + j])
            keys[j] = b * n + c
        order = np.argsort(keys)
        j = 0
        while j < size:
            same = j + 1
            while same < size and keys[order[same]] == keys[order[j]]:
                same += 1
            if same == j + 1:
                single[by_first[start[a] + order[j]]] = True
            j = same
    return single


@numba.njit(cache=True)
def unique_pairs(first, second, value, n):
    """The distinct pairs of (first (k,), second (k,)), both in [0, n), each with the smallest ``value`` (k,)
    among its copies: (first, second, value) of the distinct pairs, grouped by first (ascending), in order of
    first appearance within a group. A counting sort by ``first`` and a last-seen mark per ``second``: O(k + n),
    where sorting one int64 key per pair took 3x as long (11M pairs, 275k nodes: 1.8 s against 0.54 s with
    edges of tets whose nodes are sorted)."""
    start = np.zeros(n + 1, np.int64)
    for i in range(len(first)):
        start[first[i] + 1] += 1
    for a in range(n):
        start[a + 1] += start[a]
    fill = start[:-1].copy()
    by_first = np.empty(len(first), np.int64)
    for i in range(len(first)):
        by_first[fill[first[i]]] = i
        fill[first[i]] += 1
    seen = np.full(n, -1, np.int64)
    slot = np.empty(n, np.int64)
    out_first = np.empty(len(first), np.int64)
    out_second = np.empty(len(first), np.int64)
    out_value = np.empty(len(first), value.dtype)
    k = 0
    for a in range(n):
        for j in range(start[a], start[a + 1]):
            i = by_first[j]
            b = second[i]
            if seen[b] != a:
                seen[b] = a
                slot[b] = k
                out_first[k], out_second[k], out_value[k] = a, b, value[i]
                k += 1
            elif value[i] < out_value[slot[b]]:
                out_value[slot[b]] = value[i]
    return out_first[:k], out_second[:k], out_value[:k]


@dataclass(frozen=True, kw_only=True)
class TetMesh:
    """Linear tetrahedra with node tags and, where the mesher conforms to the surface, tagged boundary faces.

    ``node_level`` is an :class:`engine.levels.Level`; ``node_entity`` is the corner / curve /
    patch index in the Features (-1 in the volume and for Steiner nodes).
    ``boundary`` triangles are outward and each lies on surface patch
    ``boundary_patch``; both are empty for a mesher that does not conform.
    ``node_bubble`` links nodes to the packing's bubbles and their population events.
    A value: a stage derives a changed one with ``dataclasses.replace``.
    """

    points: np.ndarray  # (n, 3)
    tets: np.ndarray  # (m, 4) int64, positively oriented
    node_level: np.ndarray  # (n,) int8
    node_entity: np.ndarray  # (n,) int64
    stats: dict = field(default_factory=dict)
    boundary: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    boundary_patch: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    node_bubble: np.ndarray | None = None  # (n,) the packing's bubble id of each node, -1 for added nodes
    body: np.ndarray | None = None  # (m,) the body (0-based) of each tet where the mesher knows it (an assembly)
    interfaces: dict = field(default_factory=dict)  # name -> (k, 3) triangles two bodies share (an assembly)

    def volumes(self) -> np.ndarray:
        return signed_volumes(self.points, self.tets)

    @property
    def volume(self) -> float:
        return float(self.volumes().sum())

    def boundary_faces(self) -> np.ndarray:
        """(t, 3) the faces used by one tetrahedron only, outward: the mesh's actual boundary."""
        owner, side = self.boundary_sides()
        return self.tets[owner[:, None], FACES[side]]

    def boundary_sides(self) -> tuple[np.ndarray, np.ndarray]:
        """(owner (t,), side (t,)): the faces used by one tetrahedron only are ``tets[owner, FACES[side]]``
        (found once per mesh value: the analysis stages, the gate and the FE model all ask)."""
        return self._single_faces

    @cached_property
    def _single_faces(self) -> tuple[np.ndarray, np.ndarray]:
        return single_faces(self.tets)
