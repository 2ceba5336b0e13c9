"""Binding: each placement's pattern put on its anchors (features by name or kind, a point, a region, the
domain, the classes of thin walls, narrow gaps and curvature), L taken and the parameters evaluated, giving
the placed patterns (:class:`PlacedPattern`: mu and h of one pattern at any point) the sizing field composes."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..anchors import DomainDistance, SampledDistance, curve_distance, patch_distance
from ..curvature import curvature
from ..errors import KnowledgeError
from ..facewidth import narrow_faces
from ..fuzzy import Term
from ..knowledge import LOCAL_SCALES, KnowledgeBase, Placement, Zone, check_placement, expression_value, zone_values
from ..regions import RegionDistance
from ..thickness import local_size

log = logging.getLogger(__name__)

SAMPLES_PER_NEAR = 3  # anchor samples per finest size of the pattern


@dataclass(frozen=True, kw_only=True)
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


@dataclass(frozen=True, kw_only=True)
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


def _membership_at(zone: BoundZone, d: np.ndarray) -> np.ndarray:
    """The zone's membership at distances d (0 for infinite d)."""
    return zone.membership(np.where(np.isfinite(d), d, np.inf))


def bind(kb: KnowledgeBase, placements: list[Placement], features, geometry, global_size: float) -> list[PlacedPattern]:
    """Place each placement's pattern on its anchors; evaluate its parameters."""
    placed = []
    for placement in placements:
        pattern = check_placement(kb, placement)
        raised = _volume_budget(pattern, placement, features, geometry, global_size)
        anchors = _anchors(pattern, placement, features, geometry, global_size)
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
                _raised(placement, raised.get(getattr(feature, "id", None))),
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


def _volume_budget(pattern, placement, features, geometry, global_size) -> dict:
    """{curvature class id: per_circle} for a curvature placement whose chords would change the volume by
    more than its 'volume_change' (0: off); {} otherwise. See patterns/curvature.yaml."""
    if pattern.anchor != "curvature":
        return {}
    params = {name: p.default for name, p in pattern.parameters.items()} | placement.parameters
    budget = float(params.get("volume_change", 0.0))
    if budget <= 0:
        return {}
    raised, before, after = curvature(geometry, features).raised_per_circle(
        float(geometry.mesh.volume),
        budget,
        float(params["per_circle"]),
        float(params["finest"]) * global_size,
        global_size,
    )
    if raised:
        log.info(
            "%s: at %g elements per circle the chords of the curved faces it sizes would change the volume by "
            "%+.2f %%; "
            "raised on %d of its radius classes (%s) to keep it to %+.2f %% (volume_change %g %%)",
            placement.id,
            params["per_circle"],
            100 * before,
            len(raised),
            ", ".join(f"{part} {n:g}" for part, n in raised.items()),
            100 * after,
            100 * budget,
        )
    return raised


def _raised(placement, per_circle: float | None):
    """The placement with 'per_circle' replaced, or as it is (None)."""
    if per_circle is None:
        return placement
    return replace(placement, parameters={**placement.parameters, "per_circle": per_circle})


def _anchors(pattern, placement, features, geometry, global_size):
    """[(feature or None, spacing -> distance object)] for the placement (H = ``global_size``)."""
    if pattern.anchor == "domain":
        return [(None, lambda spacing: DomainDistance())]
    if pattern.anchor == "region":
        region = RegionDistance(placement.region, placement.source)
        return [(None, lambda spacing: region)]
    if pattern.anchor in LOCAL_SCALES:
        if pattern.anchor == "curvature":
            parts = curvature(geometry, features).parts()
        elif pattern.anchor == "narrow-face":
            parts = narrow_faces(geometry, features, global_size)
        else:
            parts = local_size(geometry).parts(pattern.anchor)
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
    return KnowledgeError(
        f"no feature named '{placement.at}' of the kind the pattern needs",
        where=placement.source,
        fix=f"named features of this solid: {features.names_listed(placement.at)}",
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
            zones.append(BoundZone(zone=zone, **numbers, role=role, gap=gap))
    suffix = f"@{feature.id}" if feature is not None and (multiple or placement.every) else ""
    return PlacedPattern(
        id=placement.id + suffix,
        pattern=pattern.name,
        placement=placement,
        feature=getattr(feature, "id", None),
        length=L,
        parameters=params,
        zones=zones,
        distance=distance,
        roles=roles,
        ties=pattern.dominance == "tie",
    )
