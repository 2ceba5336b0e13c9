"""The bubble packer: regular spacing, bubbles on their entities, counts, fuzzy population control."""

import igl
import numpy as np
import pytest
from scipy.spatial import cKDTree

from engine.job import job_from_dict
from engine.knowledge import load_knowledge
from engine.packing import CURVE, PATCH, VOLUME, get_packer
from engine.pipeline import prepare

KB = load_knowledge()
_CACHE = {}


def prepared(job: dict):
    """(geometry, features, sizing) of a job dict, cached (the name 'setup' would be pytest's module setup)."""
    key = repr(job)
    if key not in _CACHE:
        _CACHE[key] = tuple(prepare(job_from_dict(job)))[1:]
    return _CACHE[key]


def pack(job, packer="bubble", **options):
    geometry, features, sizing = prepared(job)
    return get_packer(packer)(geometry, features, sizing, seed=0, knowledge=KB, **options)


DIAMETER = KB.packer_settings["population"]["diameter"]  # bubble diameter / h


def spacing_share(packing, sizing, diameter=1.0):
    """Share of nodes whose nearest neighbour is within [0.85, 1.15] of the stable distance of bubbles of
    diameter ``diameter`` x h (the bubble packer's setting; the lattice packer spaces by h)."""
    h = diameter * sizing(packing.points)
    distance, index = cKDTree(packing.points).query(packing.points, k=2)
    ratio = distance[:, 1] / (0.5 * (h + h[index[:, 1]]))
    return float(np.mean((ratio >= 0.85) & (ratio <= 1.15)))


CUBE = {"geometry": {"shape": "plate", "parameters": {"length": 60, "width": 60, "thickness": 60}}, "size": 5.0}
CYLINDER = {"geometry": {"shape": "cylinder"}, "size": 6.0}
JUNCTION = {"geometry": {"shape": "plate_cylinder_junction"}, "size": 12.0, "recipe": "junction-edge"}


@pytest.mark.parametrize("job", [CUBE, CYLINDER], ids=["cube", "cylinder"])
def test_bubbles_settle_at_the_stable_distance(job):
    _, _, sizing = prepared(job)
    bubble = pack(job)
    lattice = pack(job, "lattice")
    share, baseline = spacing_share(bubble, sizing, DIAMETER), spacing_share(lattice, sizing)
    initial = bubble.stats["initial_nearest_over_r0"]["within_0.85_1.15"]
    print(
        f"nearest neighbour within [0.85, 1.15] r0: bubble {share:.3f}, lattice {baseline:.3f}, "
        f"bubble's initial placement {initial:.3f}"
    )
    assert share == pytest.approx(bubble.stats["nearest_over_r0"]["within_0.85_1.15"])
    assert share >= 0.90
    assert share > baseline + 0.2
    assert share > initial + 0.1  # the start is already rows of a lattice on a cylinder's wall and end faces


def test_bubbles_lie_on_their_entities():
    geometry, features, _ = prepared(JUNCTION)
    packing = pack(JUNCTION)
    tolerance = 1e-9 * geometry.scale
    for k in np.unique(packing.entity[packing.level == CURVE]):
        points = packing.points[(packing.level == CURVE) & (packing.entity == k)]
        line = features.curves[k].polyline
        segments = np.column_stack([np.arange(len(line) - 1), np.arange(1, len(line))]).astype(np.int64)
        squared, _, _ = igl.point_mesh_squared_distance(points, line, segments)
        assert np.sqrt(squared).max() <= tolerance
    mesh = geometry.mesh
    for k in np.unique(packing.entity[packing.level == PATCH]):
        points = packing.points[(packing.level == PATCH) & (packing.entity == k)]
        faces = mesh.faces[features.patches[k].faces].astype(np.int64)
        squared, _, _ = igl.point_mesh_squared_distance(points, np.asarray(mesh.vertices), faces)
        assert np.sqrt(squared).max() <= tolerance
    assert geometry.contains(packing.points[packing.level == VOLUME]).all()


def test_count_matches_the_sizing_field_estimate_on_the_junction():
    packing = pack(JUNCTION)
    ratio = len(packing) / packing.stats["expected_nodes"]
    print(f"junction-edge: {len(packing)} bubbles, estimate {packing.stats['expected_nodes']:.0f}, ratio {ratio:.3f}")
    assert 0.9 <= ratio <= 1.1


@pytest.mark.parametrize("density,action,rule_base", [(2.0, "delete", "delete"), (0.5, "insert", "insert")])
def test_population_control_restores_the_count(density, action, rule_base):
    normal = len(pack(CUBE))
    packing = pack(CUBE, initial_density=density)
    start = sum(packing.stats["initial"].values())
    print(f"start {start}, end {len(packing)}, normal {normal}")
    assert abs(start - normal) > 0.3 * normal, "the start is far from the target"
    assert abs(len(packing) - normal) <= 0.1 * normal
    acted = packing.events[packing.events.action == action]
    assert len(acted) >= 0.2 * abs(start - normal)
    rule_ids = {f"population.{rule_base}/{r.id}" for r in KB.rulebases[f"population.{rule_base}"].rules}
    assert set(acted.rule) <= rule_ids
    assert ((acted.firing > 0) & (acted.firing <= 1)).all()
    assert packing.stats["deleted" if action == "delete" else "inserted"] == len(acted)
    ids = set(packing.ids.tolist())
    if action == "insert":
        survivors = set(acted.bubble.tolist()) & ids
        assert len(survivors) >= 0.7 * len(acted), "inserted bubbles stay, under their own ids"
    else:
        assert not (set(acted.bubble.tolist()) & ids), "deleted bubbles are gone"


def test_same_seed_same_packing():
    a, b = pack(CYLINDER), pack(CYLINDER)
    assert np.array_equal(a.points, b.points) and np.array_equal(a.level, b.level)


def _wedge_prism(folder, degrees: float):
    """An STL prism 6 thick on a triangle whose corner at the origin is ``degrees`` (sides 40 and 36 long): the
    two edges leaving that corner on each face leave it together."""
    import trimesh

    angle = np.radians(degrees)
    outline = np.array([(0.0, 0.0), (40.0, 0.0), (36 * np.cos(angle), 36 * np.sin(angle))])
    vertices = np.vstack([np.column_stack([outline, np.zeros(3)]), np.column_stack([outline, np.full(3, 6.0)])])
    faces = [[0, 2, 1], [3, 4, 5], [0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [2, 0, 3], [2, 3, 5]]
    path = folder / f"wedge-{degrees:g}.stl"
    trimesh.Trimesh(vertices, faces).export(path)
    return path


def _apex_pair(path):
    """(features, [(curve, end)] x 2) of the top face's two edges at the prism's corner over the origin."""
    from engine.packing.bubble import _leaving_together

    _, features, _ = prepared({"geometry": {"file": str(path)}})
    curve, end, other, other_end, together = _leaving_together(features)
    at_apex = [
        k
        for k in np.flatnonzero(together)
        if np.allclose(features.curves[curve[k]].points[0 if end[k] == 0 else -1], (0, 0, 6), atol=1e-6)
    ]
    assert len(at_apex) == 1
    k = at_apex[0]
    return features, [(curve[k], end[k]), (other[k], other_end[k])]


def _along(features, c, e, distance):
    """Points at these distances from curve c's end e."""
    feature = features.curves[c]
    return feature.point_at(np.asarray(distance) if e == 0 else feature.length - np.asarray(distance))


def test_curves_leaving_a_corner_together_start_at_one_distance(tmp_path):
    """A concentric shell at an acute corner (bubble._shells_at_acute_corners): the first bubbles of the two
    curves at the mean of their distances from it, the bubbles after them where they were. Found on an outside
    test's bearing cartridge (a counterbore cutting a boss fillet, 10.8 deg corners): first nodes 0.43 and 0.97 h
    from the corner, a 164 deg triangle and a 6.8 deg tetrahedron; with the shells 11.1 deg."""
    from engine.packing.bubble import _shells_at_acute_corners

    features, pair = _apex_pair(_wedge_prism(tmp_path, 10.0))
    points = np.vstack([_along(features, *pair[0], [0.43, 1.4, 2.4]), _along(features, *pair[1], [0.97, 1.9, 2.9])])
    entity = np.repeat([pair[0][0], pair[1][0]], 3)
    moved = _shells_at_acute_corners(points, entity, features)
    for (c, e), rows in zip(pair, (slice(0, 3), slice(3, 6))):
        s = features.curves[c].parameter(moved[rows])
        distance = s if e == 0 else features.curves[c].length - s
        assert distance[0] == pytest.approx(0.70, abs=1e-9)
        np.testing.assert_allclose(moved[rows][1:], points[rows][1:])
    # a first bubble that would pass half the way to its neighbour stays
    crowded = np.vstack([_along(features, *pair[0], [0.2, 0.5, 1.5]), _along(features, *pair[1], [0.97, 1.9, 2.9])])
    np.testing.assert_allclose(_shells_at_acute_corners(crowded, entity, features), crowded)


def test_no_shell_at_a_cusp(tmp_path):
    """Under SHELL_ANGLE the two first bubbles would be one node twice (a wing nut's 1.8 deg cusp: 0.02 mm apart
    at h 0.38, 3.5 deg tets): they stay where the packer put them."""
    from engine.packing.bubble import SHELL_ANGLE, _shells_at_acute_corners

    features, pair = _apex_pair(_wedge_prism(tmp_path, SHELL_ANGLE / 2))
    points = np.vstack([_along(features, *pair[0], [0.43, 1.4, 2.4]), _along(features, *pair[1], [0.97, 1.9, 2.9])])
    entity = np.repeat([pair[0][0], pair[1][0]], 3)
    np.testing.assert_allclose(_shells_at_acute_corners(points, entity, features), points)


def test_a_hole_wall_and_the_plate_round_it_start_on_rings():
    """The start (the lattice packer: no dynamics) puts a hole's wall nodes on rows at right angles to its axis,
    each row's nodes equally spaced round it, the rows of one count shifted half a step from their neighbours,
    and the plate's nodes next to the hole on circles round it: rows of near-equilateral triangles where the
    stress peaks, not a random scatter (the shipped start: as many heights as wall nodes)."""
    job = {
        "geometry": {"shape": "plate_with_hole", "parameters": {"thickness": 20.0, "hole_radius": 12.0}},
        "size": 4.0,
    }
    geometry, features, sizing = prepared(job)
    wall = next(k for k, p in enumerate(features.patches) if p.cylinder is not None)
    cylinder = features.patches[wall].cylinder
    packing = pack(job, "lattice")
    nodes = packing.points[(packing.level == PATCH) & (packing.entity == wall)]
    heights = np.round(nodes[:, 2], 6)
    rows = np.unique(heights)
    assert 3 <= len(rows) <= 6 and len(rows) < len(nodes) / 10
    counts = [np.count_nonzero(heights == z) for z in rows]
    assert max(counts) - min(counts) <= 1, counts
    first = None
    for z in rows:
        angle = np.sort(np.arctan2(nodes[heights == z, 1], nodes[heights == z, 0]))
        gaps = np.diff(np.r_[angle, angle[0] + 2 * np.pi])
        assert gaps.max() / gaps.min() < 1.05  # equal steps round the ring (h is the same all round)
        if first is None:
            first = angle
        elif len(angle) == len(first):  # a neighbouring row's nodes sit halfway between this row's, or on them
            offset = np.abs(np.angle(np.exp(1j * (angle[:, None] - first[None])))).min(axis=1) / gaps.mean()
            assert (offset < 0.05).all() or (np.abs(offset - 0.5) < 0.05).all()
        first = angle
    top = packing.points[(packing.level == PATCH) & (np.abs(packing.points[:, 2] - 20.0) < 1e-9)]
    radius = np.hypot(top[:, 0], top[:, 1])
    near = top[radius < 2 * cylinder.radius]
    circles = np.unique(np.round(np.hypot(near[:, 0], near[:, 1]), 6))
    assert len(near) > 40 and len(circles) <= len(near) / 10  # concentric rings of nodes round the hole
