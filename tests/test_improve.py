"""The repairs' round loop (engine/meshing/improve.py ``_in_rounds``), shared by the peels, collapses and swaps; the
last relocation pass's check that slid surface nodes keep the boundary on the surface (delaunay.py)."""

import numpy as np

from engine.meshing.improve import PEEL_ROUNDS, _in_rounds


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


def test_a_slid_surface_node_that_would_cut_a_chord_into_the_surface_goes_back():
    """The last relocation pass slides curved-patch nodes over the surface; a move whose boundary triangles
    then stray farther from the surface than before and than SURFACE_TOLERANCE x h is undone (delaunay.py
    ``_chords_kept``). Found on an outside test's motor shaft: a node slid 0.12 along a r 1 shoulder fillet
    left a 0.7 chord 0.055 inside it at h 0.35 (Hausdorff 0.16 h; 0.09 h and 16.6 deg instead of 13.0 after)."""
    from engine.meshing.delaunay import _chords_kept

    def on_cylinder(angle, z):  # points on the cylinder of radius 1 about the z axis
        return np.column_stack([np.cos(angle), np.sin(angle), z])

    def surface(x):  # distances to that cylinder, and its outward normals
        r = np.linalg.norm(x[:, :2], axis=1)
        return np.abs(r - 1.0), np.column_stack([x[:, :2] / r[:, None], np.zeros(len(x))])

    before = on_cylinder(np.array([0.0, 0.3, 0.15]), np.array([0.0, 0.0, 0.3]))
    boundary = np.array([[0, 1, 2]])
    tolerance = np.full(3, 0.05 * 0.35)
    far = before.copy()
    far[1] = on_cylinder(np.array([0.9]), np.array([0.0]))[0]  # a 0.9 chord: 0.1 inside the surface
    np.testing.assert_allclose(_chords_kept(far.copy(), before, boundary, np.array([1]), surface, tolerance), before)
    near = before.copy()
    near[1] = on_cylinder(np.array([0.33]), np.array([0.02]))[0]  # a small slide: the chord stays close
    np.testing.assert_allclose(_chords_kept(near.copy(), before, boundary, np.array([1]), surface, tolerance), near)
