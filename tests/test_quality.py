"""Tetrahedron quality metrics on tetrahedra whose values are known."""

import itertools
import math
import time
from types import SimpleNamespace

import numpy as np
import pytest

from engine.quality import boundary_report, tet_quality, triangle_quality

REGULAR = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)


def test_regular_tetrahedron_scores_one_everywhere():
    q = tet_quality(REGULAR, np.array([[0, 2, 1, 3]]))
    assert q.volume[0] == pytest.approx(8 / 3)
    assert q.radius_ratio[0] == pytest.approx(1.0)
    assert q.mean_ratio[0] == pytest.approx(1.0)
    assert q.aspect_ratio[0] == pytest.approx(1.0)
    dihedral = math.degrees(math.acos(1 / 3))
    assert q.min_dihedral[0] == pytest.approx(dihedral) and q.max_dihedral[0] == pytest.approx(dihedral)


def test_right_corner_tetrahedron():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    q = tet_quality(points, np.array([[0, 1, 2, 3]]))
    assert q.volume[0] == pytest.approx(1 / 6)
    assert q.min_dihedral[0] == pytest.approx(54.7356, abs=1e-3)  # at the slanted face's edges
    assert q.max_dihedral[0] == pytest.approx(90.0)
    inradius = 1 / (3 + math.sqrt(3))
    circumradius = math.sqrt(3) / 2
    assert q.radius_ratio[0] == pytest.approx(3 * inradius / circumradius)


def test_sliver_and_orientation():
    sliver = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1e-3]], dtype=float)
    q = tet_quality(sliver, np.array([[0, 1, 2, 3], [1, 0, 2, 3]]))
    assert q.volume[0] == -q.volume[1]
    assert (q.radius_ratio < 0.01).all() and (q.min_dihedral < 1).all() and (q.max_dihedral > 179).all()
    summary = tet_quality(sliver, np.array([[0, 1, 2, 3]])).summary()
    assert summary["below"]["min_dihedral_5"] == 1 and summary["below"]["radius_ratio_0.1"] == 1


def test_signed_volumes_are_the_triple_product_over_six():
    """engine.mesh.signed_volumes (a numba kernel) against numpy's (b - a) . ((c - a) x (d - a)) / 6 on random tets
    (to rounding: the kernel sums the terms in the order einsum does here, but einsum's order is its own), and
    the sign."""
    from engine.mesh import signed_volumes

    rng = np.random.default_rng(5)
    points = rng.normal(size=(300, 3))
    tets = rng.integers(0, len(points), size=(5000, 4))
    p = points[tets]
    expected = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6.0
    np.testing.assert_allclose(signed_volumes(points, tets), expected, rtol=0, atol=1e-14)
    assert signed_volumes(REGULAR, np.array([[0, 2, 1, 3], [2, 0, 1, 3]])) == pytest.approx([8 / 3, -8 / 3])


def test_distinct_pairs_are_numpys_unique_rows():
    """engine.mesh.distinct_pairs (one int64 key per pair) against np.unique(axis=0), rows and counts."""
    from engine.mesh import distinct_pairs

    pairs = np.random.default_rng(2).integers(0, 40, size=(3000, 2))
    rows, counts = np.unique(pairs, axis=0, return_counts=True)
    distinct, seen = distinct_pairs(pairs, counts=True)
    assert np.array_equal(distinct, rows) and np.array_equal(seen, counts)
    assert np.array_equal(distinct_pairs(pairs), rows)


def test_scale_and_rotation_invariance():
    rng = np.random.default_rng(0)
    points = rng.normal(size=(4, 3))
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    a = tet_quality(points, np.array([[0, 1, 2, 3]]))
    b = tet_quality(7.5 * points @ rotation.T + 3.0, np.array([[0, 1, 2, 3]]))
    for name in ("radius_ratio", "mean_ratio", "min_dihedral", "max_dihedral", "aspect_ratio"):
        assert getattr(a, name)[0] == pytest.approx(getattr(b, name)[0], rel=1e-9)


def test_million_tetrahedra_speed_figure():
    """Not a timed test: prints the time for 1M tetrahedra (target <= 1 s on the reference machine)."""
    rng = np.random.default_rng(1)
    points = rng.random((200_000, 3))
    tets = rng.integers(0, len(points), size=(1_000_000, 4))
    start = time.perf_counter()
    q = tet_quality(points, tets)
    print(f"quality of 1,000,000 tetrahedra: {time.perf_counter() - start:.2f} s")
    assert np.isfinite(q.min_dihedral).all()


def test_a_tet_with_a_repeated_node_is_flat():
    """Its volume is rounding only: radius ratio 0 whatever the rounding, not the ratio of two rounding errors."""
    points = np.random.default_rng(1).random((3, 3))
    rows = np.array([r for r in itertools.product(range(3), repeat=4) if len(set(r)) == 3])
    q = tet_quality(points, rows)
    assert (q.volume != 0).any()  # the rounding this is about
    assert (q.radius_ratio == 0).all() and (q.mean_ratio < 1e-9).all() and (q.aspect_ratio > 1e9).all()


def test_the_optimiser_aims_at_what_the_report_measures():
    """One kernel (engine/tetmetrics.py): the optimiser's min dihedral and q = min(radius ratio, min dihedral /
    70.53 deg) are the report's, bit for bit; -1 for the optimiser where the tet is not positive."""
    from engine.meshing.improve import REGULAR_DIHEDRAL, min_dihedrals, quality_below

    rng = np.random.default_rng(2)
    points = rng.random((300, 3))
    tets = rng.integers(0, len(points), size=(20_000, 4))
    tets = tets[np.array([len(set(r)) == 4 for r in tets.tolist()])]
    q = tet_quality(points, tets)
    positive = q.volume > 0
    assert 0.4 < positive.mean() < 0.6
    optimiser = min_dihedrals(points, tets)
    assert np.array_equal(optimiser[positive], q.min_dihedral[positive]) and (optimiser[~positive] == -1).all()
    aim = np.where(positive, np.minimum(q.radius_ratio, q.min_dihedral / REGULAR_DIHEDRAL), -1.0)
    for threshold in (0.05, 10 / REGULAR_DIHEDRAL, 0.2, 20 / REGULAR_DIHEDRAL, 0.5):
        assert np.array_equal(quality_below(points, tets, threshold), aim < threshold)


def test_triangle_quality_is_twice_inradius_over_circumradius():
    points = np.array([[0, 0, 0], [1, 0, 0], [0.5, math.sqrt(3) / 2, 0], [0, 1, 0], [2, 0, 0]], dtype=float)
    q = triangle_quality(points, np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4]]))
    # right isosceles: r = (2 - sqrt 2) / 2, R = sqrt 2 / 2; three collinear points: 0
    assert q == pytest.approx([1.0, 2 * (2 - math.sqrt(2)) / math.sqrt(2), 0.0])


def test_boundary_report_topology_of_two_tets_touching_at_a_node():
    """A closed boundary whose two shells share one node is not two-manifold there, though every edge is in
    exactly two faces; one shell is."""
    import trimesh

    from engine.mesh import TetMesh

    points = np.vstack([REGULAR, 2 * REGULAR[0] - REGULAR[1:]])  # the second tet: the first reflected through node 0
    tets = np.array([[0, 2, 1, 3], [0, 4, 5, 6]])
    tets[1] = tets[1] if tet_quality(points, tets[1:]).volume[0] > 0 else tets[1, [0, 2, 1, 3]]
    level = np.zeros(len(points), np.int8)
    for shells, manifold in ((tets, False), (tets[:1], True)):
        mesh = TetMesh(points=points, tets=shells, node_level=level, node_entity=np.full(len(points), -1))
        geometry = SimpleNamespace(mesh=trimesh.Trimesh(points, mesh.boundary_faces()), chord=0.0)
        report = boundary_report(mesh, geometry, lambda x: np.ones(len(x)), samples=200)
        assert report["two_manifold"] is manifold
        assert report["boundary_edges"] == 0 and report["holes"] == 0
        assert report["components"] == len(shells)
        assert report["volume"] == pytest.approx(len(shells) * 8 / 3)
        assert report["hausdorff_mesh_to_input"]["max"] == pytest.approx(0.0, abs=1e-9)
