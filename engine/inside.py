"""Fast inside test: a voxel grid answers most points, an exact test the rest.

Cells that the surface may cross are marked (surface samples no farther apart
than a cell, dilated by one cell). Unmarked cells form connected regions that
the surface does not cross, so each region is wholly inside or outside: one
exact test per region classifies it. A query point in an unmarked cell is
answered by a lookup; one in a marked cell by the exact test.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage


def _barycentric_grid(n: int) -> np.ndarray:
    """Barycentric coordinates of the (n+1)(n+2)/2 points of a triangle subdivided n times."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    i, j = i[keep], j[keep]
    return np.column_stack([n - i - j, i, j]).astype(float) / n


def surface_samples(vertices: np.ndarray, faces: np.ndarray, spacing: float) -> np.ndarray:
    """Points on the surface such that every surface point is within ``spacing`` of one."""
    tri = vertices[faces]
    edge = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    subdiv = np.maximum(1, np.ceil(edge / spacing)).astype(int)
    chunks = [vertices[np.unique(faces)]]
    for n in np.unique(subdiv[subdiv > 1]):
        bary = _barycentric_grid(int(n))
        chunks.append(np.einsum("bk,fkd->fbd", bary, tri[subdiv == n]).reshape(-1, 3))
    return np.concatenate(chunks)


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

        samples = surface_samples(vertices, faces, 0.9 * cell)
        marked = np.zeros(self.shape, dtype=bool)
        idx = self._cell_index(samples)
        marked[idx[:, 0], idx[:, 1], idx[:, 2]] = True
        marked = ndimage.binary_dilation(marked, structure=np.ones((3, 3, 3), bool))
        labels, count = ndimage.label(~marked)
        # one representative cell centre per free region, classified exactly
        flat = labels.ravel()
        order = np.argsort(flat, kind="stable")
        first = order[np.searchsorted(flat[order], np.arange(1, count + 1))]
        centres = self.origin + (np.column_stack(np.unravel_index(first, self.shape)) + 0.5) * cell
        region_inside = np.zeros(count + 1, dtype=bool)
        region_inside[1:] = exact(centres)
        self.labels = labels
        self.region_inside = region_inside

    def _cell_index(self, points: np.ndarray) -> np.ndarray:
        idx = np.floor((points - self.origin) / self.cell).astype(np.int64)
        return np.clip(idx, 0, np.array(self.shape) - 1)

    def contains(self, points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        raw = np.floor((points - self.origin) / self.cell)
        in_box = np.all((raw >= 0) & (raw < np.array(self.shape)), axis=1)
        result = np.zeros(len(points), dtype=bool)
        idx = raw[in_box].astype(np.int64)
        label = self.labels[idx[:, 0], idx[:, 1], idx[:, 2]]
        inside = self.region_inside[label]
        undecided = label == 0
        if undecided.any():
            inside[undecided] = self.exact(points[in_box][undecided])
        result[in_box] = inside
        return result
