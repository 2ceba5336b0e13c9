"""Fast inside test: a voxel grid answers most points, an exact test the rest.

Cells that the surface may touch are marked: every cell of a triangle's
bounding box that the triangle's plane passes through (the exact plane/box
overlap test on the closed cell, so a superset of the cells the triangle
touches). Unmarked cells form face-connected regions that the surface does not
touch, so each region is wholly inside or outside: one exact test per region
classifies it. A query point in an unmarked cell is answered by a lookup; one
in a marked cell by the exact test.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ._numba import numba


class InsideGrid:
    """Inside test for a closed surface, accelerated by a voxel grid.

    ``exact(points) -> bool array`` is the slow, exact test used for the
    points the grid cannot decide.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, exact, max_cells: int = 2_000_000):
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        extent = np.maximum(hi - lo, 1e-9 * float((hi - lo).max()))
        cell = float(np.cbrt(np.prod(extent) / max_cells))
        cell = max(cell, float(extent.max()) / 1024)
        self.cell = cell
        self.origin = lo - cell
        self.shape = tuple(np.ceil(extent / cell).astype(int) + 2)
        self.exact = exact

        marked = np.zeros(self.shape, dtype=bool)
        _mark_cells(
            np.ascontiguousarray(vertices, dtype=np.float64),
            np.ascontiguousarray(faces, dtype=np.int64),
            self.origin,
            cell,
            marked,
        )
        labels, count = ndimage.label(~marked)
        # one representative cell centre per free region, classified exactly (any of its cells will do)
        representative = np.zeros(count + 1, dtype=np.int64)
        representative[labels.ravel()] = np.arange(labels.size)
        centres = self.origin + (np.column_stack(np.unravel_index(representative[1:], self.shape)) + 0.5) * cell
        region_inside = np.zeros(count + 1, dtype=bool)
        region_inside[1:] = exact(centres)
        self.labels = labels
        self.region_inside = region_inside

    def region(self, points: np.ndarray) -> np.ndarray:
        """The free region of each point's cell: 0 in a cell the surface may touch, -1 outside the grid."""
        raw = np.floor((np.asarray(points, dtype=float).reshape(-1, 3) - self.origin) / self.cell)
        in_box = np.all((raw >= 0) & (raw < np.array(self.shape)), axis=1)
        region = np.full(len(raw), -1, dtype=np.int64)
        idx = raw[in_box].astype(np.int64)
        region[in_box] = self.labels[idx[:, 0], idx[:, 1], idx[:, 2]]
        return region

    def contains(self, points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        region = self.region(points)
        result = self.region_inside[np.maximum(region, 0)]  # region 0 is not inside: decided below
        undecided = region == 0
        if undecided.any():
            result[undecided] = self.exact(points[undecided])
        return result


@numba.njit(cache=True)
def _mark_cells(vertices, faces, origin, cell, marked):
    """Mark every cell (closed cube of side ``cell`` from ``origin``) that the plane of a triangle crosses
    inside the triangle's bounding box. The plane's dominant axis is scanned as an interval per column,
    so the work per triangle is its bounding box's footprint across that axis, a few cells deep."""
    shape = marked.shape
    slack = 1e-9 * cell
    for f in range(len(faces)):
        a, b, c = vertices[faces[f, 0]], vertices[faces[f, 1]], vertices[faces[f, 2]]
        n = np.cross(b - a, c - a)
        length = np.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2)
        if length == 0.0:
            continue
        n = n / length
        lo = np.empty(3, np.int64)
        hi = np.empty(3, np.int64)
        for k in range(3):
            low = min(a[k], b[k], c[k])
            high = max(a[k], b[k], c[k])
            lo[k] = max(0, int(np.floor((low - slack - origin[k]) / cell)))
            hi[k] = min(shape[k] - 1, int(np.floor((high + slack - origin[k]) / cell)))
        axis = np.argmax(np.abs(n))
        u, v = (axis + 1) % 3, (axis + 2) % 3
        # |n . (centre - a)| <= reach: the plane crosses the closed cell
        reach = 0.5 * cell * (abs(n[0]) + abs(n[1]) + abs(n[2])) + slack
        offset = n[0] * a[0] + n[1] * a[1] + n[2] * a[2]
        for i in range(lo[u], hi[u] + 1):
            cu = origin[u] + (i + 0.5) * cell
            for j in range(lo[v], hi[v] + 1):
                cv = origin[v] + (j + 0.5) * cell
                # centres along the axis with |n_axis * c + rest - offset| <= reach
                middle = (offset - n[u] * cu - n[v] * cv) / n[axis]
                half = reach / abs(n[axis])
                first = max(lo[axis], int(np.ceil((middle - half - origin[axis]) / cell - 0.5)))
                last = min(hi[axis], int(np.floor((middle + half - origin[axis]) / cell - 0.5)))
                for k in range(first, last + 1):
                    if axis == 0:
                        marked[k, i, j] = True
                    elif axis == 1:
                        marked[j, k, i] = True
                    else:
                        marked[i, j, k] = True
