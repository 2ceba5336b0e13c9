"""The sizing field: patterns placed on features, composed by membership dominance.

Every placed pattern k gives a membership mu_k(x) and a size h_k(x) from the
distance of x to its anchor (per zone: a spacing law h(d) and a trapezoid
mu(d); a pattern's value at x is its zone with the highest mu). At every point
the placed pattern with the highest mu wins (ties: the smaller h) and sets the
raw size: the paper's rule "a node of pattern A is kept where mu_A >= mu_B".
The gradation limit then caps growth: h(y) <= h(x) + (g - 1) |x - y|, via a
background grid graded exactly in the L1 metric at rate (g - 1)/sqrt(3) (so
its trilinear interpolant is Euclidean-Lipschitz with rate g - 1) and
h = min(raw, graded grid). Every evaluation can return its audit arrays.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import trimesh
from scipy import ndimage

from .._numba import numba
from ..anchors import DomainDistance, SampledDistance, curve_distance, patch_distance
from ..curvature import curvature
from ..errors import KnowledgeError, LimitError
from ..fuzzy import Term
from ..knowledge import LOCAL_SCALES, KnowledgeBase, Placement, Zone, check_placement, expression_value, zone_values
from ..regions import RegionDistance
from ..thickness import local_size

log = logging.getLogger(__name__)

GRID_NODES = 400_000  # background grid for the gradation
SAMPLES_PER_NEAR = 3  # anchor samples per finest size of the pattern
TETS_PER_NODE = 5.5  # tetrahedra per node of a well-spaced Delaunay mesh
NODES_PER_H3 = 1.43  # nodes per h^3 of volume of a mesh whose mean edge is h (fitted, see estimate_counts)
NODES_PER_H2 = 0.32  # extra nodes per h^2 of surface (fitted, see estimate_counts)
NODES_PER_H = 1.15  # nodes per h along a feature curve: 1 / the bubble diameter (0.87 h), see estimate_counts
GRADED_THRESHOLD = 0.01  # an element counts as graded when the gradation limit lowered its h by more than this share


@dataclass
class BoundZone:
    """A zone with its numbers evaluated for one placement."""

    zone: Zone
    near: float
    far: float
    over: float
    exponent: float
    trapezoid: tuple | None
    height: float
    role: str | None  # ligament role, or None for the anchor distance
    gap: float = 0.0

    @property
    def reach(self) -> float:
        """Distance beyond which the membership is zero."""
        return math.inf if self.trapezoid is None else self.trapezoid[3]

    def size(self, d: np.ndarray) -> np.ndarray:
        if self.zone.law == "constant":
            return np.full(len(d), self.near)
        t = np.clip(d / self.over, 0.0, 1.0)
        if self.zone.law == "linear":
            return self.near + (self.far - self.near) * t
        if self.zone.law == "geometric":
            return self.near * (self.far / self.near) ** t
        return self.near + (self.far - self.near) * t**self.exponent

    def membership(self, d: np.ndarray) -> np.ndarray:
        if self.trapezoid is None:
            return np.full(len(d), self.height)
        mu = np.zeros(len(d))
        finite = np.isfinite(d)
        mu[finite] = self.height * Term("zone", self.trapezoid).membership(d[finite])
        return mu


@dataclass
class PlacedPattern:
    """One pattern bound to one anchor, with evaluated parameters."""

    id: str
    pattern: str
    placement: Placement
    feature: str | None
    length: float | None  # L
    parameters: dict
    zones: list[BoundZone]
    distance: object
    roles: dict = field(default_factory=dict)  # role -> distance to the role feature(s)
    ties: bool = False  # dominance 'tie': where it reaches, its mu is the highest of the other patterns

    @property
    def reach(self) -> float:
        """Anchor distance beyond which every zone's membership is zero (a ligament is >= d_anchor - gap)."""
        return max((z.reach + z.gap for z in self.zones), default=0.0)

    def evaluate(self, points: np.ndarray):
        """(mu, h, zone index) at ``points``; mu = 0, h = inf and zone = -1 where no zone reaches."""
        n = len(points)
        best_mu, best_h, best_zone = np.zeros(n), np.full(n, np.inf), np.full(n, -1)
        d_anchor = self.distance(points, self.reach)
        for k, zone in enumerate(self.zones):
            # only points the zone can reach; the ligament d_anchor + d_role - gap is >= d_anchor - gap
            idx = np.flatnonzero(d_anchor < zone.reach + zone.gap) if np.isfinite(zone.reach) else np.arange(n)
            d = d_anchor[idx]
            if zone.role is not None:  # >= 0 exactly; clamp the sampling error of the gap
                d = np.maximum(d + self.roles[zone.role](points[idx], zone.reach + zone.gap) - zone.gap, 0.0)
            mu = zone.membership(d)
            h = np.where(mu > 0, zone.size(d), np.inf)
            better = (mu > best_mu[idx]) | ((mu == best_mu[idx]) & (h < best_h[idx]) & (mu > 0))
            won = idx[better]
            best_mu[won], best_h[won], best_zone[won] = mu[better], h[better], k
        return best_mu, best_h, best_zone

    def bounds(self, centres: np.ndarray, radius: float):
        """Lower and upper bound of mu, and lower bound of h, over balls of ``radius`` around ``centres``.

        Distances are 1-Lipschitz (ligament distances 2-Lipschitz), trapezoids
        take their extremes at interval ends or on their plateau, and the size
        laws are monotone in the distance.
        """
        n = len(centres)
        mu_low, mu_high, h_low = np.zeros(n), np.zeros(n), np.full(n, np.inf)
        d_anchor = self.distance(centres, self.reach + 2 * radius)
        for zone in self.zones:
            if zone.role is None:
                d, spread = d_anchor, radius
            else:
                d = np.maximum(
                    d_anchor + self.roles[zone.role](centres, zone.reach + zone.gap + 2 * radius) - zone.gap, 0.0
                )
                spread = 2 * radius
            lo, hi = np.maximum(d - spread, 0.0), d + spread
            ends_lo, ends_hi = _membership_at(zone, lo), _membership_at(zone, hi)
            low = np.minimum(ends_lo, ends_hi)
            high = np.maximum(ends_lo, ends_hi)
            if zone.trapezoid is None:
                plateau = np.ones(n, bool)
            else:
                plateau = (lo <= zone.trapezoid[2]) & (hi >= zone.trapezoid[1])
            high = np.where(plateau, zone.height, high)
            reached = high > 0
            size_low = np.full(n, np.inf)
            finite = reached & np.isfinite(lo)
            size_low[finite] = np.minimum(
                zone.size(np.minimum(lo[finite], 1e300)), zone.size(np.minimum(hi[finite], 1e300))
            )
            size_low[reached & ~np.isfinite(lo)] = min(zone.near, zone.far)
            mu_low = np.maximum(mu_low, low)
            mu_high = np.maximum(mu_high, high)
            h_low = np.minimum(h_low, size_low)
        if self.ties:  # its mu follows the others': it can win wherever it reaches, and outranks none
            mu_low, mu_high = np.zeros(n), np.where(mu_high > 0, 1.0, 0.0)
        return mu_low, mu_high, h_low

    def legend(self) -> dict:
        return {
            "id": self.id,
            "pattern": self.pattern,
            "placement": self.placement.source,
            "origin": self.placement.origin,
            "feature": self.feature,
            "L": self.length,
            "parameters": self.parameters,
            "zones": [{"id": z.zone.id, "source": z.zone.source} for z in self.zones],
        }


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


class SizingField:
    """h(x) from placed patterns by membership dominance, with the gradation limit and bounds."""

    def __init__(
        self,
        placed: list[PlacedPattern],
        geometry,
        gradation: float,
        global_size: float,
        min_size: float | None = None,
        max_size: float | None = None,
        features=None,
    ):
        if not placed:
            raise KnowledgeError("no pattern is placed", fix="place the base pattern 'uniform-domain'")
        self.placed = placed
        self.geometry, self.features = geometry, features
        self.global_size = global_size
        self.gradation = gradation
        self.min_size, self.max_size = min_size, max_size
        self._build_grid(geometry)

    # -- raw composition
    def _raw(self, points: np.ndarray):
        """Raw size, winner, runner-up, winner's zone, and (n, patterns) memberships and sizes."""
        n, count = len(points), len(self.placed)
        mu, size, zone = np.empty((count, n)), np.empty((count, n)), np.empty((count, n), dtype=np.int64)
        for k, placed in enumerate(self.placed):
            mu[k], size[k], zone[k] = placed.evaluate(points)
        _tie(mu, np.array([placed.ties for placed in self.placed]))
        winner, runner_up = _dominance(mu, size)
        rows = np.arange(n)
        safe = np.maximum(winner, 0)
        raw = np.where(winner >= 0, size[safe, rows], self.global_size)
        return raw, winner, runner_up, zone[safe, rows], mu.T, size.T

    # -- gradation grid
    def _build_grid(self, geometry) -> None:
        """Graded background grid G with G <= raw everywhere, so h = G is exactly Lipschitz.

        Each cell gets a lower bound of the raw size over the whole cell (interval
        bounds of every pattern's mu and h over the cell, keeping only patterns
        that can win somewhere in it; a pattern is bounded only on the cells
        its anchor's box grown by its reach holds, elsewhere its mu is 0); each
        node the minimum over its 8 cells;
        then the nodes are graded exactly in the L1 metric at (g - 1)/sqrt(3).
        Trilinear interpolation of such a grid is Euclidean-Lipschitz with g - 1
        and never exceeds the raw size.
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
        for placed in self.placed:
            index = _cells_near(placed.distance, placed.reach + 2 * half_diagonal, origin, cell, cells_shape)
            centres = origin + cell * (np.column_stack(np.unravel_index(index, cells_shape)) + 0.5)
            bounded.append((index, *placed.bounds(centres, half_diagonal)))
        best_low = np.zeros(math.prod(cells_shape))
        for index, m_lo, _, _ in bounded:
            best_low[index] = np.maximum(best_low[index], m_lo)
        cell_low = np.full(len(best_low), np.inf)
        for index, _, m_hi, h_lo in bounded:
            can_win = (m_hi > 0) & (m_hi >= best_low[index])
            cell_low[index[can_win]] = np.minimum(cell_low[index[can_win]], h_lo[can_win])
        cell_low = np.where(best_low > 0, cell_low, np.minimum(cell_low, self.global_size))
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
        rate = (self.gradation - 1.0) / math.sqrt(3.0)
        grid = nodes
        for axis in range(3):
            grid = _grade_along(grid, axis, rate * cell)
        self.grid, self.origin, self.cell, self.shape = grid, origin, cell, shape
        self.h_min, self.h_max = float(grid.min()), float(grid.max())
        if self.min_size is not None:
            self.h_min = max(self.h_min, self.min_size)
        if self.max_size is not None:
            self.h_max = min(self.h_max, self.max_size)

    def _graded(self, points: np.ndarray) -> np.ndarray:
        """Trilinear interpolation of the graded grid."""
        coordinates = ((points - self.origin) / self.cell).T
        return ndimage.map_coordinates(self.grid, coordinates, order=1, mode="nearest")

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
    def expected_counts(self) -> tuple[float, float]:
        """(nodes, tetrahedra) a packing of this field should have (:func:`estimate_counts`), computed once."""
        return estimate_counts(self.geometry, self, self.features)


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


def _membership_at(zone: BoundZone, d: np.ndarray) -> np.ndarray:
    """The zone's membership at distances d (0 for infinite d)."""
    return zone.membership(np.where(np.isfinite(d), d, np.inf))


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


# ------------------------------------------------------------------------------- binding


def bind(kb: KnowledgeBase, placements: list[Placement], features, geometry, global_size: float) -> list[PlacedPattern]:
    """Place each placement's pattern on its anchors; evaluate its parameters."""
    placed = []
    for placement in placements:
        pattern = check_placement(kb, placement)
        if pattern.anchor == "curvature":
            placement = _within_volume_budget(pattern, placement, features, geometry, global_size)
        anchors = _anchors(pattern, placement, features, geometry)
        local = pattern.anchor in LOCAL_SCALES
        if not anchors and not local:
            log.info(
                "note: %s places '%s' on %s, but the solid has none; not placed (%s)",
                placement.origin,
                pattern.name,
                placement.every or placement.at,
                placement.source,
            )
        for feature, make_distance in anchors:
            one = _bind_one(
                pattern,
                placement,
                feature,
                make_distance,
                features,
                geometry,
                global_size,
                multiple=len(anchors) > 1 or local,
            )
            if one.zones or not local:  # a class of walls (gaps) whose zones are all off sizes nothing
                placed.append(one)
    return placed


def _within_volume_budget(pattern, placement, features, geometry, global_size):
    """The curvature placement with 'per_circle' raised until the chords' predicted volume change is within
    its 'volume_change' share of the solid's volume (0: as placed); see patterns/curvature.yaml."""
    params = {name: p.default for name, p in pattern.parameters.items()} | placement.parameters
    budget = float(params.get("volume_change", 0.0))
    if budget <= 0:
        return placement
    per_circle, before, after = curvature(geometry, features.feature_angle).per_circle_for_volume(
        float(geometry.mesh.volume),
        budget,
        float(params["per_circle"]),
        float(params["finest"]) * global_size,
        global_size,
    )
    if per_circle <= float(params["per_circle"]):
        return placement
    log.info(
        "%s: %g elements per circle would change the volume by %+.2f %% (straight chords on curved faces); "
        "%g keeps it to %+.2f %% (volume_change %g %%)",
        placement.id,
        params["per_circle"],
        100 * before,
        per_circle,
        100 * after,
        100 * budget,
    )
    return replace(placement, parameters={**placement.parameters, "per_circle": per_circle})


def _anchors(pattern, placement, features, geometry):
    """[(feature or None, spacing -> distance object)] for the placement."""
    if pattern.anchor == "domain":
        return [(None, lambda spacing: DomainDistance())]
    if pattern.anchor == "region":
        region = RegionDistance(placement.region, placement.source)
        return [(None, lambda spacing: region)]
    if pattern.anchor in LOCAL_SCALES:
        parts = (
            curvature(geometry, features.feature_angle).parts()
            if pattern.anchor == "curvature"
            else local_size(geometry).parts(pattern.anchor)
        )
        return [(part, part.distance) for part in parts]
    if pattern.anchor == "point":
        if placement.point is not None:
            point = np.asarray(placement.point, dtype=float)
            return [(None, lambda spacing: SampledDistance(point))]
        corners = [c for c in features.corners if placement.at in c.names]
        if not corners:
            raise _no_feature(placement, features)
        return [(c, lambda spacing, c=c: SampledDistance(c.point)) for c in corners]
    group = features.curves if pattern.anchor == "curve" else features.patches
    if placement.at is not None:
        chosen = [f for f in group if placement.at in f.names]
        if not chosen:
            raise _no_feature(placement, features)
    else:
        chosen = [f for f in group if placement.every in f.kinds]
    if pattern.anchor == "curve":
        return [(f, lambda spacing, f=f: curve_distance(f, spacing)) for f in chosen]
    return [(f, lambda spacing, f=f: patch_distance(geometry, f, spacing)) for f in chosen]


def _union(distances: list):
    """One distance object for several features of the same kind."""
    if len(distances) == 1:
        return distances[0]
    first = distances[0]
    offsets = np.cumsum([0] + [len(d.vertices) for d in distances[:-1]])
    return type(first)(
        np.concatenate([d.vertices for d in distances]),
        np.concatenate([d.simplices + o for d, o in zip(distances, offsets)]),
        first.spacing,
    )


def _no_feature(placement, features):
    names = ", ".join(features.names) or "none"
    return KnowledgeError(
        f"no feature named '{placement.at}' of the kind the pattern needs",
        where=placement.source,
        fix=f"named features of this solid: {names}",
    )


def _length(pattern, placement, feature, features):
    if placement.scale is not None:
        return float(placement.scale)
    if pattern.scale == "none":
        return None
    if pattern.scale in LOCAL_SCALES.values():
        return feature.length
    if pattern.scale in ("radius", "fillet_radius") and feature is not None:
        circle = getattr(feature, "circle", None)
        cylinder = getattr(feature, "cylinder", None)
        if circle is not None:
            return float(circle.radius)
        if cylinder is not None:
            return float(cylinder.radius)
    if pattern.scale in features.lengths:
        return float(features.lengths[pattern.scale])
    raise KnowledgeError(
        f"pattern '{pattern.name}' needs the length '{pattern.scale}' (L) of "
        f"{feature.id if feature is not None else 'its anchor'}, which is not known",
        where=placement.source,
        fix="give 'scale: LENGTH' in the placement",
    )


def _bind_one(pattern, placement, feature, make_distance, features, geometry, global_size, multiple):
    L = _length(pattern, placement, feature, features)
    params = {name: p.default for name, p in pattern.parameters.items()}
    params.update(placement.parameters)
    env = {**params, "H": global_size}
    if L is not None:
        env["L"] = L
    where = placement.source
    on = f" on {feature.id}" if feature is not None and getattr(feature, "id", None) else ""
    # the finest size the zones ask for sets the anchor sampling
    nears = [expression_value(pattern, zone, zone.near, "'near'", env, placement, on) for zone in pattern.zones]
    spacing = min([near for near in nears if near > 0], default=global_size) / SAMPLES_PER_NEAR
    distance = make_distance(spacing)
    roles = {}
    for role, (default, _) in pattern.roles.items():
        name = placement.roles.get(role, default)
        targets = [f for f in features.patches if name in f.names] or [f for f in features.curves if name in f.names]
        if targets:
            roles[role] = _union(
                [
                    patch_distance(geometry, f, spacing) if hasattr(f, "faces") else curve_distance(f, spacing)
                    for f in targets
                ]
            )
            anchor_samples = getattr(distance, "samples", None)
            env[f"gap_{role}"] = roles[role].gap_to(distance) if anchor_samples is not None else 0.0
        else:
            env[f"gap_{role}"] = math.inf
            log.info(
                "note: %s: role '%s' of pattern '%s' names '%s', which this solid does not have; "
                "the zones that use it are off",
                where,
                role,
                pattern.name,
                name,
            )
    zones = []
    for zone in pattern.zones:
        role = zone.distance.split(":", 1)[1] if zone.distance.startswith("ligament:") else None
        if role is not None and role not in roles:
            continue
        numbers = zone_values(pattern, zone, env, placement, on)
        if numbers is not None:
            gap = env.get(f"gap_{role}", 0.0) if role else 0.0
            zones.append(BoundZone(zone, **numbers, role=role, gap=gap))
    suffix = f"@{feature.id}" if feature is not None and (multiple or placement.every) else ""
    return PlacedPattern(
        placement.id + suffix,
        pattern.name,
        placement,
        getattr(feature, "id", None),
        L,
        params,
        zones,
        distance,
        roles,
        ties=pattern.dominance == "tie",
    )


# ------------------------------------------------------------------------- count estimate


def estimate_counts(geometry, sizing, features=None, samples: int = 1 << 16, seed: int = 0) -> tuple[float, float]:
    """Expected (nodes, tetrahedra) of a mesh of the sizing field: h is the mean edge length (docs/rules.md
    section 4), which the bubble packer meets with bubbles of diameter 0.87 h (its ``diameter`` setting).

    nodes = NODES_PER_H3 * integral of h^-3 over the volume + NODES_PER_H2 * integral
    of h^-2 over the surface + NODES_PER_H * integral of h^-1 along the feature curves + corners.
    The volume integral samples one random point in each cell of a grid of about
    ``samples`` cells over the bounding box (stratified, seeded: far less variance than
    as many independent points); the surface integral ``samples // 4`` area-weighted points.
    The constants were fitted to the bubble packings of the built-in shapes (bench/size_calibration.py's cases)
    (cylinder, plate, plate_with_hole, junction, l_bracket, hollow sphere octant, each at two sizes; 880
    to 17,400 nodes): packings hold 0.945 to 1.038 of the estimate. Bubbles of diameter d = 0.87 h
    pack the volume at about 0.94 / d^3 = 1.43 / h^3, the surface layer adds 0.32 / h^2, a curve
    1 / d = 1.15 / h. TETS_PER_NODE is the large meshes' ratio (5.5 at 1M tetrahedra; 3.7 to 5.3 on
    the small meshes above, where more nodes lie on the surface): an upper bound for the guard.
    """
    rng = np.random.default_rng(seed)
    points = stratified_points(*geometry.bounds, samples, rng)
    inside = geometry.contains(points)
    volume_density = float(np.mean(sizing(points[inside]) ** -3.0)) if inside.any() else sizing.h_min**-3.0
    on_surface, _ = trimesh.sample.sample_surface(geometry.mesh, samples // 4, seed=seed)
    nodes = NODES_PER_H3 * geometry.volume * volume_density + NODES_PER_H2 * geometry.area * float(
        np.mean(sizing(on_surface) ** -2.0)
    )
    if features is not None:
        for curve in features.curves:
            if curve.on_surface:
                s = np.linspace(0.0, curve.length, 200)
                nodes += NODES_PER_H * curve.length * float(np.mean(1.0 / sizing(curve.point_at(s))))
        nodes += len(features.corners)
    return nodes, nodes * TETS_PER_NODE


def stratified_points(lo: np.ndarray, hi: np.ndarray, count: int, rng) -> np.ndarray:
    """One uniform random point in each cell of a grid of about ``count`` near-cubic cells over [lo, hi]."""
    extent = np.maximum(hi - lo, 1e-300)
    cell = float(np.cbrt(np.prod(extent) / count))
    shape = np.maximum(1, np.round(extent / cell)).astype(int)
    index = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), -1).reshape(-1, 3)
    return lo + (index + rng.random(index.shape)) * (extent / shape)


def check_element_limit(sizing, max_elements: float) -> float:
    """Refuse (one line) when the sizes would need more than ``max_elements`` tetrahedra."""
    _, tets = sizing.expected_counts
    if not math.isfinite(tets) or tets > max_elements:
        raise LimitError(
            f"the sizes would need about {tets:.3g} tetrahedra (limit {max_elements:.3g}); "
            f"the smallest size is {sizing.h_min:.4g}",
            fix="use larger sizes, or raise the limit with --max-elements",
        )
    return tets
