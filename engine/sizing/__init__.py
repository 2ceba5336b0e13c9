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

Three modules, each name importable from here (``from engine.sizing import X``):

- ``binding``: placements → :class:`PlacedPattern` (``bind``: anchors, L, evaluated parameters and zones);
- ``field``: :class:`SizingField` (a frozen value built complete by ``SizingField.build``: dominance, gradation
  grid, ``evaluate`` with the audit, ``__call__``);
- ``counts``: the element-count estimate (``estimate_counts``) and the guard before packing
  (``check_element_limit``).
"""

from __future__ import annotations

from .binding import SAMPLES_PER_NEAR, BoundZone, PlacedPattern, bind
from .counts import (
    NODES_PER_H,
    NODES_PER_H2,
    NODES_PER_H3,
    TETS_PER_NODE,
    check_element_limit,
    estimate_counts,
    pattern_shares,
    stratified_points,
)
from .field import GRADED_THRESHOLD, GRID_NODES, SizingAudit, SizingField

__all__ = [
    "BoundZone",
    "PlacedPattern",
    "SizingAudit",
    "SizingField",
    "bind",
    "estimate_counts",
    "stratified_points",
    "check_element_limit",
    "pattern_shares",
    "GRID_NODES",
    "SAMPLES_PER_NEAR",
    "TETS_PER_NODE",
    "NODES_PER_H3",
    "NODES_PER_H2",
    "NODES_PER_H",
    "GRADED_THRESHOLD",
]
