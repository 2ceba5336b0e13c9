"""engine.sampling.thin: the greedy maximal independent set by seeded random priority, its conflicts found on a
grid."""

import numpy as np
import pytest

from engine import sampling


def greedy_reference(points, radius, priority, fixed):
    """The definition, by brute force: the fixed points, then each point by descending priority unless it is
    closer than the mean of the radii to one already kept."""
    distance = np.linalg.norm(points[:, None] - points[None], axis=2)
    conflict = distance < 0.5 * (radius[:, None] + radius[None])
    kept = fixed.copy()
    for i in np.lexsort((-priority, ~fixed)):
        if not fixed[i]:
            kept[i] = not (conflict[i] & kept).any()
    return kept


@pytest.fixture
def cloud():
    rng = np.random.default_rng(3)
    points = rng.random((700, 3)) * [10.0, 4.0, 1.0]
    radius = 0.2 + 0.25 * points[:, 0] / 10 + 0.3 * (points[:, 1] > 3)  # three radius buckets
    fixed = rng.random(700) < 0.05
    return points, radius, fixed


def test_thin_is_the_greedy_set_by_priority(cloud, monkeypatch):
    points, radius, fixed = cloud
    priority = np.random.default_rng(11).random(len(points))
    expected = greedy_reference(points, radius, priority, fixed)
    assert np.array_equal(sampling.thin(points, radius, np.random.default_rng(11), fixed), expected)
    monkeypatch.setattr(sampling, "MAX_COLUMNS_PER_POINT", 0.01)  # cells far wider than the radii: the same set
    assert np.array_equal(sampling.thin(points, radius, np.random.default_rng(11), fixed), expected)


def test_conflicts_are_every_pair_once_from_its_later_point(cloud):
    points, radius, _ = cloud
    rank = np.random.default_rng(5).permutation(len(points))
    later, earlier = sampling._earlier_conflicts(points, radius, rank)
    distance = np.linalg.norm(points[:, None] - points[None], axis=2)
    i, j = np.nonzero((distance < 0.5 * (radius[:, None] + radius[None])) & (rank[None] < rank[:, None]))
    assert len(later) == len(i) > 100
    assert np.array_equal(np.sort(later.astype(np.int64) * len(points) + earlier), np.sort(i * len(points) + j))


def test_thin_keeps_a_maximal_conflict_free_set_with_the_fixed_points(cloud):
    points, radius, fixed = cloud
    kept = sampling.thin(points, radius, np.random.default_rng(0), fixed)
    distance = np.linalg.norm(points[:, None] - points[None], axis=2)
    conflict = (distance < 0.5 * (radius[:, None] + radius[None])) & ~np.eye(len(points), dtype=bool)
    assert kept[fixed].all()
    both = conflict & kept[:, None] & kept[None]
    assert not (both & ~(fixed[:, None] & fixed[None])).any(), "only fixed points may conflict with each other"
    assert (conflict[~kept] & kept[None]).any(axis=1).all(), "every point left out conflicts with a kept one"
    assert 0 < kept.sum() < len(points)


def test_thin_of_no_point_or_one():
    rng = np.random.default_rng(0)
    assert sampling.thin(np.zeros((0, 3)), np.zeros(0), rng).shape == (0,)
    assert sampling.thin(np.ones((1, 3)), np.ones(1), rng).tolist() == [True]
