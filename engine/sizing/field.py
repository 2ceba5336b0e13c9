"""The sizing field h(x): the placed patterns composed by membership dominance (the highest mu wins, ties to
the smaller h), capped by the gradation limit on a background grid graded exactly (with finer grids of its own
where sizes fall far below its cells); audit arrays on request."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage

from .._numba import numba
from ..errors import KnowledgeError
from .counts import ExpectedCounts, estimate_counts

if TYPE_CHECKING:
    from ..features import Features
    from ..geometry import Geometry
    from .binding import PlacedPattern

GRID_NODES = 400_000  # background grid for the gradation
FINER_BELOW = 0.25  # a cell whose size bound is under this x its width gets a finer grid (a box round such cells) ...
FINER_MARGIN = 2  # ... reaching this many cells beyond them, ...
FINER_NODES = 200_000  # ... of at most about this many nodes, the finer grids within it included, ...
FINER_TOTAL = GRID_NODES  # ... and this many in all (a finer grid costs what the background grid does per node), ...
FINER_DEPTH = 3  # ... and finer again within it, at most this many times, ...
FINER_STEP = 0.5  # ... each time with cells at most this x as wide
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
    graded: GradedGrid = field(repr=False)  # the background grid, graded
    reach: np.ndarray = field(repr=False)  # (patterns, cells) bool: whether a pattern's mu can be > 0 in a cell
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
        lo, hi = geometry.bounds
        cell = max(float(np.cbrt(np.prod(hi - lo) / GRID_NODES)), float((hi - lo).max()) / 512)
        graded, reach = _graded_grid(placed, lo, hi, cell, gradation, global_size, FINER_TOTAL)
        h_min, h_max = graded.extremes()
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
            graded=graded,
            reach=reach,
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
    def grid(self) -> np.ndarray:
        """The background grid's graded node sizes (its finer grids aside)."""
        return self.graded.values

    @property
    def origin(self) -> np.ndarray:
        return self.graded.origin

    @property
    def cell(self) -> float:
        return self.graded.cell

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.graded.values.shape

    @property
    def reach_shape(self) -> tuple[int, int, int]:
        """The grid's cells along each axis (one fewer than its nodes)."""
        return tuple(n - 1 for n in self.shape)

    def _graded(self, points: np.ndarray) -> np.ndarray:
        """The graded grid at ``points``."""
        return self.graded(np.ascontiguousarray(points, dtype=np.float64))

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


@dataclass(frozen=True, eq=False)
class GradedGrid:
    """Sizes graded exactly on the nodes of a grid of cubic cells (``values`` (nx, ny, nz) at ``origin`` + ``cell``
    x index), interpolated trilinearly, and ``finer`` grids (box lo, box hi, grid) that cover the boxes where
    sizes fall far below its cells: inside a box h is the smaller of the two."""

    values: np.ndarray
    origin: np.ndarray
    cell: float
    finer: tuple[tuple[np.ndarray, np.ndarray, GradedGrid], ...] = ()

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """(n,) h at ``points`` (n, 3) float64, C-contiguous."""
        h = _trilinear(self.values, self.origin, self.cell, points)
        for lo, hi, grid in self.finer:
            inside = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))
            if len(inside):
                h[inside] = np.minimum(h[inside], grid(np.ascontiguousarray(points[inside])))
        return h

    def lowest_near(self, points: np.ndarray, reach: float, axis: int) -> np.ndarray:
        """(k,) a lower bound of the sizes on the square of half-width ``reach`` round each of ``points`` (k, 3) at
        right angles to ``axis``: the smallest node value of the cells that reach there, and of its finer grids'
        where they do."""
        span = np.full(3, int(np.ceil(reach / self.cell)) + 1)
        span[axis] = 1
        lowest = ndimage.minimum_filter(self.values, size=tuple(2 * span + 1), mode="nearest")
        nearest = np.rint((points - self.origin) / self.cell).astype(np.int64)
        low = lowest[tuple(np.clip(nearest, 0, np.array(self.values.shape) - 1).T)]
        for lo, hi, grid in self.finer:
            near = np.flatnonzero(np.all((points + reach >= lo) & (points - reach <= hi), axis=1))
            if len(near):
                low[near] = np.minimum(low[near], grid.lowest_near(points[near], reach, axis))
        return low

    def extremes(self) -> tuple[float, float]:
        """The smallest and largest node size of this grid and its finer ones."""
        low, high = float(self.values.min()), float(self.values.max())
        for _, _, grid in self.finer:
            low = min(low, grid.extremes()[0])
        return low, high


def _graded_grid(
    placed_patterns, lo, hi, cell: float, gradation: float, global_size: float, budget: float, depth: int = 0
):
    """(GradedGrid over the box ``lo``..``hi`` with cells ``cell`` wide and finer grids of ``budget`` nodes at most,
    G <= raw everywhere so h = G is exactly Lipschitz; (patterns, cells) whether each pattern's mu can be above 0
    somewhere in each cell (its upper bound there), so an evaluation skips it elsewhere).

    Each cell gets a lower bound of the raw size over the whole cell (:func:`_cell_bounds`); each node the
    minimum over its 8 cells; then the nodes are graded exactly in the L1 metric at (g - 1)/sqrt(3).
    Trilinear interpolation of such a grid is Euclidean-Lipschitz with g - 1 and never exceeds the raw size.
    A cell's bound holds over the whole cell, so round a feature far smaller than the cells the size stays at
    the feature's for a cell or two (a hole of radius 0.5 in a 200 x 100 x 10 plate, 0.0625 at its wall on
    0.79 cells: 2.7M of the mesh's 3.0M tets). So cells whose bound is under FINER_BELOW x their width, with
    FINER_MARGIN cells round them, get a finer grid of their own (each group of them one box, cells down to the
    smallest bound in it; at most about FINER_NODES nodes each and FINER_TOTAL in all, the finer grids within
    them included; FINER_DEPTH levels deep, each FINER_STEP x as wide or not at all), and h inside the box is
    the smaller of the two grids'. This grid's nodes in a box take the finer grid's sizes instead of its cells'
    bounds, and those on the box's border a lower bound of the finer grid's sizes round them
    (:meth:`GradedGrid.lowest_near`), so that on the border this grid is the smaller: h is continuous there,
    and Lipschitz with g - 1 across it as on either side. They are then graded with the rest.
    """
    extent = hi - lo
    shape = tuple(int(np.ceil(e / cell)) + 3 for e in extent)
    origin = lo - cell
    cells_shape = tuple(n - 1 for n in shape)
    cell_low, reach = _cell_bounds(placed_patterns, origin, cell, cells_shape, global_size)
    cells = cell_low.reshape(cells_shape)
    boxes = _finer_boxes(cells, cell) if depth < FINER_DEPTH else []
    finer, refined = [], []
    for box in boxes:
        box_lo = origin + cell * np.array([b.start for b in box])
        box_hi = origin + cell * np.array([b.stop for b in box])
        share = min(FINER_NODES, budget / len(boxes))  # half for its own nodes, half for its finer grids
        finer_cell = max(float(cells[box].min()), float(np.cbrt(np.prod(box_hi - box_lo) / (share / 2))))
        if finer_cell > FINER_STEP * cell:  # too few nodes to be worth it (a plate with 60 small holes)
            continue
        grid, _ = _graded_grid(
            placed_patterns, box_lo, box_hi, finer_cell, gradation, global_size, share / 2, depth + 1
        )
        finer.append((box_lo, box_hi, grid))
        refined.append(box)
    boxes = refined
    for box in boxes:
        cells[box] = np.inf  # their nodes take the finer grid's sizes
    padded = np.pad(cells, 1, mode="edge")
    nodes = np.full(shape, np.inf)
    for corner in np.ndindex(2, 2, 2):
        nodes = np.minimum(
            nodes,
            padded[
                corner[0] : corner[0] + shape[0], corner[1] : corner[1] + shape[1], corner[2] : corner[2] + shape[2]
            ],
        )
    for box, (_, _, grid) in zip(boxes, finer):
        at = tuple(slice(b.start, b.stop + 1) for b in box)  # the nodes of the box's cells
        index = np.stack(np.meshgrid(*[np.arange(a.start, a.stop) for a in at], indexing="ij"), -1).reshape(-1, 3)
        positions = np.ascontiguousarray(origin + cell * index)
        inside = grid(positions)
        for axis in range(3):  # the nodes on the box's two faces at right angles to it
            face = np.flatnonzero((index[:, axis] == at[axis].start) | (index[:, axis] == at[axis].stop - 1))
            inside[face] = np.minimum(inside[face], grid.lowest_near(positions[face], cell, axis))
        nodes[at] = np.minimum(nodes[at], inside.reshape(nodes[at].shape))
    rate = (gradation - 1.0) / math.sqrt(3.0)
    for axis in range(3):
        nodes = _grade_along(nodes, axis, rate * cell)
    return GradedGrid(np.ascontiguousarray(nodes), origin, cell, tuple(finer)), reach


def _cell_bounds(placed_patterns, origin, cell: float, cells_shape: tuple, global_size: float):
    """(cells,) a lower bound of the raw size over each cell (interval bounds of every pattern's mu and h over
    the cell, keeping only patterns that can win somewhere in it; a pattern is bounded only on the cells its
    anchor's box grown by its reach holds, elsewhere its mu is 0; the global size where no pattern reaches)
    and (patterns, cells) whether each pattern's mu can be above 0 in each cell."""
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
    return np.where(best_low > 0, cell_low, np.minimum(cell_low, global_size)), reach


def _finer_boxes(cells: np.ndarray, cell: float) -> list[tuple[slice, slice, slice]]:
    """The boxes (index slices of ``cells``) round each group of cells whose bound is under FINER_BELOW x ``cell``,
    FINER_MARGIN cells beyond them (groups whose margins touch are one), within the grid."""
    fine = cells < FINER_BELOW * cell
    if not fine.any():
        return []
    grown = ndimage.binary_dilation(fine, np.ones((3, 3, 3), bool), iterations=FINER_MARGIN)
    labels, _ = ndimage.label(grown)
    return [box for box in ndimage.find_objects(labels) if box is not None]


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
