"""Thin walls and narrow gaps: the local feature size measured by ray casting, the always-placed thin-wall and
narrow-gap patterns (dominance 'tie': they win only where they ask for smaller elements), and meshes of a
thin-walled tube and of a plate thinner than the global size."""

import json

import manifold3d as m3
import meshio
import numpy as np
import pytest
import trimesh
import yaml

from engine.cli import main
from engine.errors import LimitError
from engine.explain import explain_point
from engine.job import job_from_dict
from engine.knowledge import load_knowledge
from engine.pipeline import job_placements, prepare
from engine.quality import tet_quality
from engine.sizing import check_element_limit
from engine.thickness import measure

KB = load_knowledge()


def solid(manifold) -> trimesh.Trimesh:
    mesh = manifold.to_mesh()
    return trimesh.Trimesh(mesh.vert_properties[:, :3], mesh.tri_verts)


def tube(outer=5.0, wall=0.3, length=58.0, segments=128) -> trimesh.Trimesh:
    inner = m3.Manifold.cylinder(length + 2, outer - wall, outer - wall, segments).translate([0, 0, -1])
    return solid(m3.Manifold.cylinder(length, outer, outer, segments) - inner)


def rib_on_block(rib=2.0) -> trimesh.Trimesh:
    block = m3.Manifold.cube([40, 40, 10])
    return solid(block + m3.Manifold.cube([rib, 30, 15]).translate([20 - rib / 2, 5, 10]))


def pieces_where(local, test):
    """Measures of the pieces whose centroids pass ``test`` (a function of the centroids)."""
    return test(local.triangles.mean(axis=1))


# ------------------------------------------------------------------------------------------ measure


def test_slab_thickness_on_its_faces_and_none_small_at_its_corners():
    slab = solid(m3.Manifold.cube([100, 100, 2]))
    local = measure(slab.vertices, slab.faces)
    flat = pieces_where(local, lambda c: (c[:, 2] < 1e-9) | (c[:, 2] > 2 - 1e-9))
    assert flat.any() and np.allclose(local.thickness[flat], 2.0, rtol=1e-3)
    assert local.thickness.min() > 2.0 * (1 - 1e-3), "the side faces see across the slab, no corner hit"
    assert not np.isfinite(local.gap).any(), "a convex solid has no gap"


def test_cube_corners_give_no_thickness_below_the_side():
    cube = solid(m3.Manifold.cube([10, 10, 10]))
    local = measure(cube.vertices, cube.faces)
    assert np.allclose(local.thickness, 10.0, rtol=1e-3)


def test_tube_wall_within_a_few_percent_and_its_bore_no_narrow_gap():
    t = tube()
    local = measure(t.vertices, t.faces)
    radius = np.hypot(*pieces_where(local, lambda c: c[:, :2]).T)
    wall = radius < 5.0 - 1e-6  # the faceted inner and outer faces (ends: radius up to 5 too, but on z = 0, 58)
    sides = (
        (radius > 4.6)
        & ~np.isclose(local.triangles.mean(axis=1)[:, 2], 0)
        & ~np.isclose(local.triangles.mean(axis=1)[:, 2], 58)
    )
    assert sides.sum() > 200 and wall.any()
    assert np.allclose(local.thickness[sides], 0.3, rtol=0.03)
    bore = local.gap[np.isfinite(local.gap)]
    assert np.allclose(bore, 2 * 4.7, rtol=0.03), "the inner face sees across the bore"
    parts = local.parts("thin-wall")
    assert parts[0].id == "wall-0.297" and parts[0].length == pytest.approx(0.3, rel=0.03)


def test_rib_on_a_block_measures_the_rib_and_the_block():
    rib = rib_on_block(2.0)
    local = measure(rib.vertices, rib.faces)
    c = local.triangles.mean(axis=1)
    rib_sides = (np.isclose(c[:, 0], 19) | np.isclose(c[:, 0], 21)) & (c[:, 2] > 10)
    assert rib_sides.any() and np.allclose(local.thickness[rib_sides], 2.0, rtol=1e-3)
    block_top = np.isclose(c[:, 2], 10)
    assert np.allclose(local.thickness[block_top], 10.0, rtol=1e-3)
    assert local.thickness.min() > 2.0 * (1 - 1e-3)


def test_an_acute_wedge_tip_is_no_wall_and_a_slot_is_a_gap():
    angle = np.radians(20)  # wider than OPPOSITE_WITHIN: the faces at the tip are not the two sides of a wall
    base = np.array([[0, 0, 0], [60, 0, 0], [60 * np.cos(angle), 60 * np.sin(angle), 0]])
    local = measure(
        np.vstack([base, base + [0, 0, 15]]),
        np.array([[0, 2, 1], [3, 4, 5], [0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [2, 0, 3], [2, 3, 5]]),
    )
    assert local.thickness[np.isfinite(local.thickness)].min() == pytest.approx(15.0, rel=1e-3)
    slotted = solid(m3.Manifold.cube([30, 20, 10]) - m3.Manifold.cube([1, 30, 8]).translate([14.5, -5, 3]))
    local = measure(slotted.vertices, slotted.faces)
    c = local.triangles.mean(axis=1)
    slot_faces = (np.isclose(c[:, 0], 14.5) | np.isclose(c[:, 0], 15.5)) & (c[:, 2] > 3)
    assert slot_faces.any() and np.allclose(local.gap[slot_faces], 1.0, rtol=1e-3)
    assert local.parts("narrow-gap")[0].length == pytest.approx(1.0, rel=1e-3)


# ---------------------------------------------------------------------------------------- knowledge


def test_every_job_gets_the_always_placed_patterns_unless_it_places_them_itself():
    plate = {"geometry": {"shape": "plate_with_hole"}}
    assert [p.pattern for p in job_placements(job_from_dict(plate), KB)] == [
        "uniform-domain",
        "thin-wall",
        "narrow-gap",
        "narrow-face",
        "curvature",
    ]
    assert [p.pattern for p in job_placements(job_from_dict({**plate, "recipe": "static-stress"}), KB)] == [
        "uniform-domain",
        "hole",
        "fillet",
        "re-entrant-edge",
        "thin-wall",
        "narrow-gap",
        "narrow-face",
        "curvature",
    ]
    place = [{"pattern": "uniform-domain"}, {"pattern": "thin-wall", "parameters": {"through": 3}}]
    own = job_placements(job_from_dict({**plate, "place": place}), KB)
    assert [(p.pattern, p.parameters) for p in own] == [
        ("uniform-domain", {}),
        ("thin-wall", {"through": 3}),
        ("narrow-gap", {}),
        ("narrow-face", {}),
        ("curvature", {}),
    ]
    assert KB.patterns["thin-wall"].dominance == "tie" and KB.patterns["thin-wall"].scale == "wall_thickness"


def test_thin_wall_sizes_a_thin_plate_and_never_coarsens_a_finer_pattern():
    """A 10 mm plate at H = 20: the thin-wall pattern asks 5 (2 elements through) and wins over the base;
    inside a uniform-region of size 1 (membership 0.9 < 1) it ties and the region's finer size wins. The hole
    (20 wide) is a narrow gap at this H: narrow-gap asks 10 on its wall, and loses to thin-wall's 5; its wall is
    curved: the curvature rule asks 2.6 (24 elements around) within 5.2 of it."""
    job = job_from_dict(
        {
            "geometry": {"shape": "plate_with_hole"},
            "size": 20.0,
            "place": [
                {"pattern": "uniform-domain"},
                {
                    "pattern": "uniform-region",
                    "region": {"sphere": {"centre": [50, 0, 5], "radius": 5}},
                    "parameters": {"size": 1.0},
                },
            ],
        }
    )
    _, geometry, features, sizing = prepare(job)
    names = [p.pattern for p in sizing.placed]
    assert names.count("thin-wall") == 1 and names.count("narrow-gap") == 1
    thin = names.index("thin-wall")
    points = np.random.default_rng(0).uniform(*geometry.bounds, size=(20000, 3))
    points = points[geometry.contains(points)]
    audit = sizing.evaluate(points)
    region = np.linalg.norm(points - [50, 0, 5], axis=1) < 4
    assert np.allclose(audit.raw[region], 1.0) and (audit.winner[region] != thin).all()
    elsewhere = (np.linalg.norm(points - [50, 0, 5], axis=1) > 15) & (np.hypot(points[:, 0], points[:, 1]) > 16)
    assert (audit.winner[elsewhere] == thin).all() and np.allclose(audit.raw[elsewhere], 5.0, rtol=1e-3)
    competing = [k for k, p in enumerate(sizing.placed) if not p.ties]
    mu, sizes = audit.mu[:, competing], audit.sizes[:, competing]
    best = sizes[np.arange(len(points)), np.argmax(mu, axis=1)]  # the winner without the tying patterns
    won = audit.winner == thin
    assert won.any() and (audit.sizes[won, thin] < best[won]).all(), "it wins only where it asks for smaller"


def test_explain_names_the_thin_wall_and_its_tie():
    job = job_from_dict({"geometry": {"shape": "plate", "parameters": {"thickness": 4}}, "size": 10.0})
    text = explain_point(prepare(job).sizing, [0, 0, 2], inside=True)
    assert "thin-wall@wall-3.36: pattern 'thin-wall', mu = 0.2500, h = 2 (dominance tie" in text
    assert "winner: thin-wall@wall-3.36 (highest mu 0.2500 over runner-up base with 0.2500, a tie" in text
    assert "L = 4" in text and "element size h = 2" in text


def test_a_thick_part_gets_no_thin_wall():
    job = job_from_dict({"geometry": {"shape": "plate_cylinder_junction"}, "recipe": "junction-edge"})
    _, geometry, features, sizing = prepare(job, max_elements=float("inf"))
    assert [p.pattern for p in sizing.placed if p.pattern in ("thin-wall", "narrow-gap")] == []


def test_the_element_guard_counts_the_thin_wall_refinement():
    job = job_from_dict({"geometry": {"shape": "plate", "parameters": {"thickness": 1}}, "size": 10.0})
    _, geometry, features, sizing = prepare(job, max_elements=float("inf"))
    assert sizing.h_min == pytest.approx(0.5, rel=1e-3)
    with pytest.raises(LimitError):
        check_element_limit(sizing, 1e5)


# --------------------------------------------------------------------------------------------- meshes


def containing_tet(points, tets, query, candidates=64):
    """Index of a tet containing each query point (among the tets with the nearest centroids), -1 if none."""
    from scipy.spatial import cKDTree

    _, near = cKDTree(points[tets].mean(axis=1)).query(query, k=candidates)
    corners = points[tets[near]]  # (n, k, 4, 3)
    edges = np.stack([corners[..., i, :] - corners[..., 0, :] for i in (1, 2, 3)], axis=-1)
    bary = np.linalg.solve(edges, (query[:, None, :] - corners[..., 0, :])[..., None])[..., 0]
    inside = (bary >= -1e-9).all(axis=-1) & (bary.sum(axis=-1) <= 1 + 1e-9)
    return np.where(inside.any(axis=1), near[np.arange(len(query)), np.argmax(inside, axis=1)], -1)


def mesh(tmp_path, job: dict):
    (tmp_path / "job.yaml").write_text(yaml.safe_dump({**job, "output": {"directory": "out"}}))
    assert main(["mesh", str(tmp_path / "job.yaml"), "--quiet"]) == 0
    out = tmp_path / "out"
    result = meshio.read(out / "mesh.vtu")
    return result, json.loads((out / "mesh.audit.json").read_text())


def test_a_thin_walled_tube_meshes_with_two_elements_through_its_wall(tmp_path):
    """Wall 0.3, H = 1.5 (5 wall thicknesses): the bore stays open (volume within 0.5 %), every radial line
    crosses at least 2 elements of the wall, no sliver, and the thin-wall pattern sizes every element."""
    t = tube(outer=3.0, wall=0.3, length=6.0, segments=96)
    t.export(tmp_path / "tube.stl")
    result, legend = mesh(tmp_path, {"geometry": {"file": "tube.stl"}, "size": 1.5})
    points, tets = result.points, result.cells_dict["tetra"]
    p = points[tets]
    volume = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])).sum() / 6
    assert volume == pytest.approx(t.volume, rel=0.005)
    rng = np.random.default_rng(0)
    angle, z = rng.uniform(0, 2 * np.pi, 2000), rng.uniform(0.3, 5.7, 2000)
    line = np.column_stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)])
    near_inner = containing_tet(points, tets, 2.705 * line + np.outer(z, [0, 0, 1]))
    near_outer = containing_tet(points, tets, 2.995 * line + np.outer(z, [0, 0, 1]))
    assert (near_inner >= 0).all() and (near_outer >= 0).all()
    assert (near_inner != near_outer).all(), "at least 2 elements through the wall on every radial line"
    assert tet_quality(points, tets).min_dihedral.min() >= 10.0
    thin = [q["index"] for q in legend["patterns"] if q["pattern"] == "thin-wall"]
    assert thin and np.isin(result.cell_data["winner"][0], thin).all()


def test_a_plate_thinner_than_the_global_size_meshes_without_slivers(tmp_path):
    """plate_with_hole 400 x 100 x 5 at size 10: before the thin-wall rule, min dihedral 2 deg (85 tets
    under 10 deg); now 2 elements through the plate."""
    result, legend = mesh(
        tmp_path,
        {
            "geometry": {
                "shape": "plate_with_hole",
                "parameters": {"length": 400, "width": 100, "thickness": 5, "hole_radius": 12},
            },
            "size": 10,
        },
    )
    assert tet_quality(result.points, result.cells_dict["tetra"]).min_dihedral.min() >= 10.0
    thin = [q["index"] for q in legend["patterns"] if q["pattern"] == "thin-wall"]
    assert np.isin(result.cell_data["winner"][0], thin).mean() > 0.9


def test_a_thick_block_is_meshed_as_before(tmp_path):
    solid(m3.Manifold.cube([30, 20, 10])).export(tmp_path / "block.stl")
    result, legend = mesh(tmp_path, {"geometry": {"file": "block.stl"}})
    assert [q["pattern"] for q in legend["patterns"]] == ["uniform-domain"]
