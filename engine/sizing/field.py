"""The sizing field h(x): the placed patterns composed by membership dominance (the highest mu wins, ties to
the smaller h), capped by the gradation limit on a background grid graded exactly; audit arrays on request."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from .._numba import numba
from ..errors import KnowledgeError
from .counts import ExpectedCounts, estimate_counts

if TYPE_CHECKING:
    from ..features import Features
    from ..geometry import Geometry
    from .binding import PlacedPattern

GRID_NODES = 400_000  # background grid for the gradation
GRADED_THRESHOLD = 0.01  # an element counts as graded when the gradation limit lowered its h by more than this share


@dataclass
class SizingAudit:
    """Why each point got its size."""

    h: np.ndarray  # final size
    raw: np.ndarray  # size of the winning pattern, before gradation and bounds
    winner: np.ndarray  # index of the winning placed pattern
    runner_up: np.ndarray  # index of the best other pattern (-1 if none reaches)
    zone: np.ndarray  # zone index of the winner
    mu: np.ndarray  # (n, patterns) membership of every placed pattern
    sizes: np.ndarray  # (n, patterns) size every placed pattern asks for (inf where mu = 0)

    @property
    def graded(self) -> np.ndarray:
        """Where the gradation limit lowered the size by more than GRADED_THRESHOLD of the raw size (the graded grid
        holds a lower bound of the raw size over each cell, so wherever the raw size varies h is a fraction of a
        percent below it: that is not the gradation acting, docs/rules.md section 4)."""
        return self.h < self.raw * (1 - GRADED_THRESHOLD)


@dataclass(frozen=True, kw_only=True, eq=False)
class SizingField:
    """h(x) from placed patterns by membership dominance, with the gradation limit and bounds. A frozen value
    built complete by :meth:`build` (its graded grid included); ``expected_counts`` is cached in its
    ``__dict__`` (``cached_property``), so no ``slots``. Compared by identity (``eq=False``): it holds arrays."""

    placed: tuple[PlacedPattern, ...]
    geometry: Geometry
    gradation: float
    global_size: float
    min_size: float | None = None
    max_size: float | None = None
    features: Features | None = None
    grid: np.ndarray = field(repr=False)  # graded node sizes of the background grid
    reach: np.ndarray = field(repr=False)  # (patterns, cells) bool: whether a pattern's mu can be > 0 in a cell
    origin: np.ndarray
    cell: float
    shape: tuple[int, int, int]
    h_min: float  # smallest and largest size of the grid, within the bounds
    h_max: float

    @classmethod
    def build(
        cls,
        *,
        placed,
        geometry,
        gradation: float,
        global_size: float,
        min_size: float | None = None,
        max_size: float | None = None,
        features=None,
    ) -> SizingField:
        """The field of ``placed`` on ``geometry``, its graded grid built (:func:`_graded_grid`)."""
        if not placed:
            raise KnowledgeError("no pattern is placed", fix="place the base pattern 'uniform-domain'")
        placed = tuple(placed)
        grid, reach, origin, cell, shape = _graded_grid(placed, geometry, gradation, global_size)
        h_min, h_max = float(grid.min()), float(grid.max())
        if min_size is not None:
            h_min = max(h_min, min_size)
        if max_size is not None:
            h_max = min(h_max, max_size)
        return cls(
            placed=placed,
            geometry=geometry,
            gradation=gradation,
            global_size=global_size,
            min_size=min_size,
            max_size=max_size,
            features=features,
            grid=grid,
            reach=reach,
            origin=origin,
            cell=cell,
            shape=shape,
            h_min=h_min,
            h_max=h_max,
        )

    # -- raw composition
    def _raw(self, points: np.ndarray):
        """Raw size, winner, runner-up, winner's zone, and (n, patterns) memberships and sizes."""
        n, count = len(points), len(self.placed)
        mu, size, zone = np.zeros((count, n)), np.full((count, n), np.inf), np.full((count, n), -1, dtype=np.int64)
        cells = np.floor((points - self.origin) / self.cell).astype(np.int64)
        in_grid = np.all((cells >= 0) & (cells < np.array(self.reach_shape)), axis=1)
        cell = np.ravel_multi_index(tuple(np.clip(cells, 0, np.array(self.reach_shape) - 1).T), self.reach_shape)
        for k, placed in enumerate(self.placed):  # each pattern only where its mu can be > 0 (its grid cells)
            rows = np.flatnonzero(self.reach[k, cell] | ~in_grid)
            mu[k, rows], size[k, rows], zone[k, rows] = placed.evaluate(points[rows])
        _tie(mu, np.array([placed.ties for placed in self.placed]))
        winner, runner_up = _dominance(mu, size)
        rows = np.arange(n)
        safe = np.maximum(winner, 0)
        raw = np.where(winner >= 0, size[safe, rows], self.global_size)
        return raw, winner, runner_up, zone[safe, rows], mu.T, size.T

    @property
    def reach_shape(self) -> tuple[int, int, int]:
        """The grid's cells along each axis (one fewer than its nodes)."""
        return tuple(n - 1 for n in self.shape)

    def _graded(self, points: np.ndarray) -> np.ndarray:
        """Trilinear interpolation of the graded grid."""
        return _trilinear(self.grid, self.origin, self.cell, np.ascontiguousarray(points, dtype=np.float64))

    # -- public
    def evaluate(self, points: np.ndarray) -> SizingAudit:
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        raw, winner, runner_up, zone, mu, sizes = self._raw(points)
        h = np.minimum(raw, self._graded(points))
        if self.min_size is not None or self.max_size is not None:
            h = np.clip(h, self.min_size or 0.0, self.max_size or np.inf)
        return SizingAudit(h, raw, winner, runner_up, zone, mu, sizes)

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """h at ``points``: the graded grid alone, since it never exceeds the raw size (no audit)."""
        h = self._graded(np.asarray(points, dtype=float).reshape(-1, 3))
        if self.min_size is not None or self.max_size is not None:
            h = np.clip(h, self.min_size or 0.0, self.max_size or np.inf)
        return h

    def legend(self) -> list[dict]:
        return [p.legend() for p in self.placed]

    @cached_property
    def expected_counts(self) -> ExpectedCounts:
        """The nodes and tetrahedra a packing of this field should have (:func:`estimate_counts`), computed once."""
        return estimate_counts(self.geometry, self, self.features)


def _graded_grid(placed_patterns, geometry, gradation: float, global_size: float):
    """Graded background grid G with G <= raw everywhere, so h = G is exactly Lipschitz.

    Each cell gets a lower bound of the raw size over the whole cell (interval
    bounds of every pattern's mu and h over the cell, keeping only patterns
    that can win somewhere in it; a pattern is bounded only on the cells
    its anchor's box grown by its reach holds, elsewhere its mu is 0); each
    node the minimum over its 8 cells;
    then the nodes are graded exactly in the L1 metric at (g - 1)/sqrt(3).
    Trilinear interpolation of such a grid is Euclidean-Lipschitz with g - 1
    and never exceeds the raw size. Also returned: (patterns, cells) whether each pattern's mu can be
    above 0 somewhere in each cell (its upper bound there), so an evaluation skips it elsewhere.
    """
    lo, hi = geometry.bounds
    extent = hi - lo
    cell = float(np.cbrt(np.prod(extent) / GRID_NODES))
    cell = max(cell, float(extent.max()) / 512)
    shape = tuple(int(np.ceil(e / cell)) + 3 for e in extent)
    origin = lo - cell
    cells_shape = tuple(n - 1 for n in shape)
    half_diagonal = 0.5 * math.sqrt(3.0) * cell
    bounded = []  # (cells, mu low, mu high, h low) per placed pattern
    for placed in placed_patterns:
        index = _cells_near(placed.distance, placed.reach + 2 * half_diagonal, origin, cell, cells_shape)
        centres = origin + cell * (np.column_stack(np.unravel_index(index, cells_shape)) + 0.5)
        bounded.append((index, *placed.bounds(centres, half_diagonal)))
    best_low = np.zeros(math.prod(cells_shape))
    for index, m_lo, _, _ in bounded:
        best_low[index] = np.maximum(best_low[index], m_lo)
    cell_low = np.full(len(best_low), np.inf)
    reach = np.zeros((len(bounded), len(best_low)), bool)
    for k, (index, _, m_hi, h_lo) in enumerate(bounded):
        reach[k, index[m_hi > 0]] = True
        can_win = (m_hi > 0) & (m_hi >= best_low[index])
        cell_low[index[can_win]] = np.minimum(cell_low[index[can_win]], h_lo[can_win])
    cell_low = np.where(best_low > 0, cell_low, np.minimum(cell_low, global_size))
    cells = cell_low.reshape(cells_shape)
    padded = np.pad(cells, 1, mode="edge")
    nodes = np.full(shape, np.inf)
    for corner in np.ndindex(2, 2, 2):
        nodes = np.minimum(
            nodes,
            padded[
                corner[0] : corner[0] + shape[0], corner[1] : corner[1] + shape[1], corner[2] : corner[2] + shape[2]
            ],
        )
    rate = (gradation - 1.0) / math.sqrt(3.0)
    grid = nodes
    for axis in range(3):
        grid = _grade_along(grid, axis, rate * cell)
    return np.ascontiguousarray(grid), reach, origin, cell, shape


@numba.njit(parallel=True, cache=True)
def _trilinear(grid, origin, cell, points):
    """(n,) the grid (nodes at ``origin`` + ``cell`` x index) interpolated trilinearly at ``points`` (n, 3), the edge
    values held outside it: scipy.ndimage.map_coordinates(order=1, mode="nearest") bit for bit (its weights
    1 - |start - u + k| and its order of summation), without its generic spline machinery (4-6x faster)."""
    nx, ny, nz = grid.shape
    out = np.empty(len(points))
    for p in numba.prange(len(points)):
        ux = (points[p, 0] - origin[0]) / cell
        uy = (points[p, 1] - origin[1]) / cell
        uz = (points[p, 2] - origin[2]) / cell
        fx, fy, fz = np.floor(ux), np.floor(uy), np.floor(uz)
        ix, iy, iz = int(fx), int(fy), int(fz)
        wx = (1.0 - abs(fx - ux), 1.0 - abs(fx - ux + 1.0))
        wy = (1.0 - abs(fy - uy), 1.0 - abs(fy - uy + 1.0))
        wz = (1.0 - abs(fz - uz), 1.0 - abs(fz - uz + 1.0))
        total = 0.0
        for a in range(2):
            i = min(max(ix + a, 0), nx - 1)
            for b in range(2):
                j = min(max(iy + b, 0), ny - 1)
                for c in range(2):
                    k = min(max(iz + c, 0), nz - 1)
                    total += grid[i, j, k] * wx[a] * wy[b] * wz[c]
        out[p] = total
    return out


def _cells_near(distance, bound: float, origin: np.ndarray, cell: float, shape: tuple) -> np.ndarray:
    """Flat indices (ascending) of the grid cells whose centres lie in the anchor's box grown by ``bound``;
    every cell for an unbounded reach or an anchor without a box (the domain)."""
    if not math.isfinite(bound) or not hasattr(distance, "lo"):
        return np.arange(math.prod(shape))
    first = np.maximum(np.ceil((distance.lo - bound - origin) / cell - 0.5), 0).astype(np.int64)
    last = np.minimum(np.floor((distance.hi + bound - origin) / cell - 0.5), np.array(shape) - 1).astype(np.int64)
    return np.ravel_multi_index(np.ix_(*[np.arange(a, b + 1) for a, b in zip(first, last)]), shape).ravel()


def _tie(mu: np.ndarray, ties: np.ndarray) -> None:
    """Where a tying pattern reaches (mu > 0), its mu becomes the highest mu of the other patterns (its own
    where none reaches), so it ties with the winner and wins only with the smaller size. In place."""
    if not ties.any():
        return
    top = mu[~ties].max(axis=0) if (~ties).any() else np.zeros(mu.shape[1])
    mu[ties] = np.where(mu[ties] > 0, np.where(top > 0, top, mu[ties]), 0.0)


@numba.njit(parallel=True, cache=True)
def _dominance(mu, size):
    """Per point: the pattern with the highest mu (ties: smaller h), and the best other one; -1 if none."""
    count, n = mu.shape
    winner = np.full(n, -1, dtype=np.int64)
    runner_up = np.full(n, -1, dtype=np.int64)
    for i in numba.prange(n):
        best = -1
        for k in range(count):
            if mu[k, i] > 0 and (
                best < 0 or mu[k, i] > mu[best, i] or (mu[k, i] == mu[best, i] and size[k, i] < size[best, i])
            ):
                best = k
        second = -1
        for k in range(count):
            if k != best and mu[k, i] > 0 and (second < 0 or mu[k, i] > mu[second, i]):
                second = k
        winner[i] = best
        runner_up[i] = second
    return winner, runner_up


def _grade_along(grid: np.ndarray, axis: int, step: float) -> np.ndarray:
    """Exact 1-D min-plus convolution with step*|i - j| along ``axis`` (forward and backward)."""
    g = np.moveaxis(grid, axis, 0)
    ramp = (step * np.arange(g.shape[0])).reshape(-1, *([1] * (g.ndim - 1)))
    forward = np.minimum.accumulate(g - ramp, axis=0) + ramp
    backward = (np.minimum.accumulate((forward + ramp)[::-1], axis=0)[::-1]) - ramp
    return np.moveaxis(np.minimum(forward, backward), 0, axis)
