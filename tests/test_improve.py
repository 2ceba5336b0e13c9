"""engine/meshing/improve.py: the repairs' round loop (``_in_rounds``, shared by the peels, collapses and swaps) and
the last step for what is left under the target (``mend_below_target``)."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

from engine.mesh import FACES, signed_volumes, single_faces
from engine.meshing.improve import PEEL_ROUNDS, TARGET, _in_rounds, mend_below_target, quality_below, relocate


def test_rounds_stop_at_the_first_that_changes_nothing():
    calls = []

    def step(left, done):
        calls.append(left)
        count = min(left, 2)
        return left - count, done + [count], count

    assert _in_rounds(step, (5, [])) == (0, [2, 2, 1, 0], 5)
    assert calls == [5, 3, 1, 0]


def test_rounds_stop_after_the_last():
    assert _in_rounds(lambda n: (n + 1, 1), (0,)) == (PEEL_ROUNDS, PEEL_ROUNDS)
    assert _in_rounds(lambda n: (n + 1, 3), (0,), rounds=2) == (2, 6)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mend_below_target_flips_open_what_relocation_alone_leaves(seed):
    """The Delaunay tets of a jittered 7 x 7 x 7 lattice in a box (its surface nodes fixed): relocation alone
    leaves a third or more of the tets under the 20 deg target; flips at the target, then relocation, leave at
    most a few, with the box's surface, its nodes and its volume unchanged."""
    rng = np.random.default_rng(seed)
    points = np.stack(np.meshgrid(*[np.arange(7.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    surface = ((points == 0) | (points == 6)).any(axis=1)
    points[~surface] += rng.uniform(-0.35, 0.35, (int((~surface).sum()), 3))
    tets = Delaunay(points).simplices.astype(np.int64)
    volumes = signed_volumes(points, tets)
    tets = tets[np.abs(volumes) > 1e-9]
    tets[signed_volumes(points, tets) < 0] = tets[signed_volumes(points, tets) < 0][:, [0, 2, 1, 3]]
    slide = np.zeros((len(points), 3))
    slide[surface] = np.nan  # fixed
    under = quality_below(points, tets, TARGET).sum()
    relocated, _ = relocate(points, tets, slide, seed)
    after_relocation = quality_below(relocated, tets, TARGET).sum()
    mended, mended_tets, flips, moves = mend_below_target(points, tets, slide, seed)
    assert under > 100 and after_relocation > 0.3 * under
    assert flips > 0 and moves > 0
    assert quality_below(mended, mended_tets, TARGET).sum() <= 2
    assert (signed_volumes(mended, mended_tets) > 0).all()
    assert np.isclose(signed_volumes(mended, mended_tets).sum(), 216.0)
    assert np.array_equal(mended[surface], points[surface])
    assert np.array_equal(_boundary(mended_tets), _boundary(tets))


def _boundary(tets) -> np.ndarray:
    """The faces used by one tet, each as its sorted nodes, in lexicographic order."""
    owner, side = single_faces(tets)
    faces = np.sort(tets[owner[:, None], FACES[side]], axis=1)
    return faces[np.lexsort(faces.T[::-1])]
