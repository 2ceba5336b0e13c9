"""Packers and meshers: the contract every registered packer and mesher keeps (plug-ins included), and the
default mesher's acceptance on the issue's solids (closed conforming boundary, volume, Hausdorff distance,
element quality)."""

from __future__ import annotations

import functools

import igl
import numpy as np
import pytest

from engine.job import job_from_dict
from engine.knowledge import load_knowledge
from engine.levels import NODE_LEVELS
from engine.mesh import TetMesh
from engine.meshing import get_mesher, mesher_names
from engine.meshing.qhull import boundary_defects
from engine.packing import CORNER, CURVE, EVENT, LEVELS, PATCH, VOLUME, get_packer, packer_names
from engine.pipeline import prepare
from engine.quality import surface_deviation, tet_quality

CASES = {  # the solids: junction at the centre and near the edge, each at a default and a fine size
    "cylinder": {"geometry": {"shape": "cylinder"}},
    "plate_with_hole": {"geometry": {"shape": "plate_with_hole"}, "recipe": "static-stress"},
    "l_bracket": {"geometry": {"shape": "l_bracket"}, "recipe": "fatigue-fillet"},
    "junction-centre": {
        "geometry": {"shape": "plate_cylinder_junction", "parameters": {"offset": 0}},
        "recipe": "junction-edge",
    },
    "junction-edge": {"geometry": {"shape": "plate_cylinder_junction"}, "recipe": "junction-edge"},
}
FINE = 0.75  # the fine size, x the default global size


@functools.lru_cache(maxsize=None)
def packed(case: str, fine: bool = False):
    spec = dict(CASES[case])
    kb, geometry, features, sizing = prepare(job_from_dict(spec))
    if fine:
        kb, geometry, features, sizing = prepare(job_from_dict({**spec, "size": FINE * geometry.scale / 40.0}))
    packing = get_packer("bubble")(geometry, features, sizing, seed=0, knowledge=kb)
    return geometry, features, sizing, packing


@functools.lru_cache(maxsize=None)
def meshed(case: str, fine: bool = False, mesher: str = "delaunay"):
    geometry, features, sizing, packing = packed(case, fine)
    return get_mesher(mesher)(packing, geometry, features, seed=0)


def edge_use(triangles):
    """How many times each directed edge is used."""
    directed = np.stack([triangles, np.roll(triangles, -1, axis=1)], axis=2).reshape(-1, 2)
    keys, counts = np.unique(directed, axis=0, return_counts=True)
    return {tuple(k): c for k, c in zip(keys.tolist(), counts)}


def check_packer_contract(packer: str, case: str = "l_bracket") -> None:
    """What the meshers rely on (engine/plugins.py, Packer): every corner a node at its corner, curve nodes on
    their curve, patch nodes on their patch, volume nodes inside, radius h / 2, the same nodes for the seed."""
    geometry, features, sizing, _ = packed(case)
    kb = load_knowledge()
    packing = get_packer(packer)(geometry, features, sizing, seed=0, knowledge=kb)
    n = len(packing)
    assert packing.points.shape == (n, 3) and np.isfinite(packing.points).all() and n > 100
    assert packing.level.shape == packing.entity.shape == packing.radius.shape == (n,)
    assert set(np.unique(packing.level)) <= set(range(len(LEVELS)))
    corners = np.flatnonzero(packing.level == CORNER)
    assert sorted(packing.entity[corners]) == list(range(len(features.corners))), "every corner is a node"
    assert np.allclose(packing.points[corners], [features.corners[i].point for i in packing.entity[corners]])
    tolerance = 1e-9 * geometry.scale
    for level, entities in ((CURVE, features.curves), (PATCH, features.patches)):
        on = packing.level == level
        assert set(np.unique(packing.entity[on])) <= set(range(len(entities)))
        for k in np.unique(packing.entity[on]):
            points = packing.points[on & (packing.entity == k)]
            if level == CURVE:
                assert (
                    np.linalg.norm(entities[k].point_at(entities[k].parameter(points)) - points, axis=1).max()
                    < tolerance
                ), f"nodes on curve {k}"
            else:
                faces = geometry.mesh.faces[entities[k].faces].astype(np.int64)
                squared, _, _ = igl.point_mesh_squared_distance(points, np.asarray(geometry.mesh.vertices), faces)
                assert np.sqrt(squared).max() < tolerance, f"nodes on patch {k}"
    volume = packing.level == VOLUME
    assert (packing.entity[volume] == -1).all() and geometry.contains(packing.points[volume]).all()
    assert np.allclose(packing.radius, sizing(packing.points) / 2, rtol=1e-6)
    assert packing.ids is None or len(np.unique(packing.ids)) == n
    assert packing.events.dtype == EVENT
    again = get_packer(packer)(geometry, features, sizing, seed=0, knowledge=kb)
    assert np.array_equal(again.points, packing.points) and np.array_equal(again.level, packing.level), "deterministic"


@pytest.mark.parametrize("packer", packer_names())
def test_packer_contract(packer):
    check_packer_contract(packer)


@pytest.mark.parametrize("mesher", mesher_names())
def test_mesher_contract(mesher):
    geometry, features, _, packing = packed("l_bracket")
    mesh = meshed("l_bracket", False, mesher)
    n = len(mesh.points)
    assert mesh.tets.dtype == np.int64 and mesh.tets.shape[1] == 4 and len(mesh.tets) > 1000
    assert (mesh.volumes() > 0).all(), "positively oriented tetrahedra"
    assert np.array_equal(np.unique(mesh.tets), np.arange(n)), "every node is used"
    assert mesh.node_level.shape == mesh.node_entity.shape == (n,)
    assert mesh.node_level.min() >= 0 and mesh.node_level.max() < len(NODE_LEVELS)
    corners = mesh.node_level == NODE_LEVELS.index("corner")
    assert np.allclose(mesh.points[corners], [features.corners[i].point for i in mesh.node_entity[corners]])
    curve_nodes = np.flatnonzero(mesh.node_level == NODE_LEVELS.index("curve"))
    for index in np.unique(mesh.node_entity[curve_nodes]):
        on = mesh.points[curve_nodes[mesh.node_entity[curve_nodes] == index]]
        curve = features.curves[index]
        if curve.sharp:
            closest = curve.point_at(curve.parameter(on))
            assert np.linalg.norm(closest - on, axis=1).max() < 1e-9 * geometry.scale, "curve nodes on their curve"
        else:  # a smooth cut is no feature: its nodes may slide on the surface
            assert np.abs(geometry.signed_distance(on)).max() < 1e-9 * geometry.scale, "cut nodes on the surface"
    assert "seconds" in mesh.stats
    again = get_mesher(mesher)(packing, geometry, features, seed=0)
    assert np.array_equal(again.tets, mesh.tets) and np.array_equal(again.points, mesh.points), "deterministic"
    assert mesh.volume == pytest.approx(geometry.volume, rel=0.02)


@pytest.mark.parametrize("fine", [False, True], ids=["default", "fine"])
@pytest.mark.parametrize("case", list(CASES))
def test_default_mesher_acceptance(case, fine):
    geometry, features, sizing, packing = packed(case, fine)
    mesh = meshed(case, fine)
    assert (mesh.volumes() > 0).all()
    # the boundary is closed, 2-manifold, outward, and it is exactly the tets' free faces
    use = edge_use(mesh.boundary)
    assert all(c == 1 for c in use.values()) and all((b, a) in use for a, b in use)
    free = mesh.boundary_faces()
    assert np.array_equal(np.unique(np.sort(free, axis=1), axis=0), np.unique(np.sort(mesh.boundary, axis=1), axis=0))
    assert len(mesh.boundary_patch) == len(mesh.boundary)
    assert set(np.unique(mesh.boundary_patch)) == set(range(len(features.patches)))
    # on the input surface, close to it, and of the solid's volume
    deviation = surface_deviation(mesh, geometry, sizing)
    assert deviation["nodes_off_surface"] < 1e-9 * geometry.scale
    assert deviation["input_to_mesh_over_h"] <= 0.1
    assert mesh.volume == pytest.approx(geometry.volume, rel=0.005)
    # element quality
    quality = tet_quality(mesh.points, mesh.tets)
    assert quality.min_dihedral.min() >= 10.0
    assert quality.radius_ratio.min() >= 0.15


def test_feature_curves_are_mesh_edges():
    geometry, features, _, _ = packed("junction-edge")
    mesh = meshed("junction-edge")
    edges = {
        tuple(sorted(e))
        for e in np.concatenate([mesh.tets[:, [i, j]] for i in range(4) for j in range(i + 1, 4)]).tolist()
    }
    curve_nodes = np.flatnonzero(mesh.node_level == NODE_LEVELS.index("curve"))
    junction = features.curves.index(features.named("junction")[0])
    on_junction = curve_nodes[mesh.node_entity[curve_nodes] == junction]
    assert len(on_junction) > 20
    # consecutive nodes around the junction circle are joined by mesh edges
    centre = features.curves[junction].circle.centre
    angle = np.arctan2(*(mesh.points[on_junction] - centre)[:, [1, 0]].T)
    ring = on_junction[np.argsort(angle)]
    assert all(tuple(sorted(pair)) in edges for pair in zip(ring, np.roll(ring, -1)))


def test_qhull_mesher_reports_its_boundary_defects():
    """The paper's method keeps slivers; the comparison is honest only if they show."""
    mesh = meshed("l_bracket", False, "qhull")
    quality = tet_quality(mesh.points, mesh.tets)
    assert quality.min_dihedral.min() < 10.0
    assert len(mesh.boundary) == 0, "no conforming boundary is claimed"
    assert mesh.stats["boundary_faces"] == len(mesh.boundary_faces())
    assert mesh.stats == {**mesh.stats, **boundary_defects(mesh)}


def test_boundary_defects_counts_a_hole_through_the_volume():
    """A conforming mesh has no defect; removing a tet of volume nodes opens four faces through the volume."""
    mesh = meshed("l_bracket")
    assert boundary_defects(mesh)["boundary_faces_through_volume"] == 0
    assert boundary_defects(mesh)["non_manifold_boundary_edges"] == 0
    inner = np.flatnonzero((mesh.node_level[mesh.tets] == NODE_LEVELS.index("volume")).all(axis=1))[0]
    holed = TetMesh(
        points=mesh.points,
        tets=np.delete(mesh.tets, inner, axis=0),
        node_level=mesh.node_level,
        node_entity=mesh.node_entity,
    )
    defects = boundary_defects(holed)
    assert defects["boundary_faces"] == len(mesh.boundary_faces()) + 4
    assert defects["boundary_faces_through_volume"] == 4


def mesh_file(tmp_path, mesh, size):
    """Mesh a trimesh surface through the CLI; (exit code, stderr, vtu or None)."""
    import subprocess
    import sys

    import meshio
    import yaml

    mesh.export(tmp_path / "solid.stl")
    (tmp_path / "job.yaml").write_text(
        yaml.safe_dump({"geometry": {"file": "solid.stl"}, "size": size, "output": {"formats": ["vtu"]}})
    )
    run = subprocess.run(
        [sys.executable, "-m", "engine.cli", "mesh", "job.yaml", "--quiet"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    out = tmp_path / "out" / "mesh.vtu"
    return run.returncode, run.stderr, meshio.read(out) if out.exists() else None


def test_a_sphere_is_cut_into_two_patches_and_meshed(tmp_path):
    import trimesh

    surface = trimesh.creation.icosphere(4, radius=10.0)
    code, err, mesh = mesh_file(tmp_path, surface, 1.5)
    assert code == 0, err
    tets = mesh.cells_dict["tetra"]
    p = mesh.points[tets]
    volumes = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6
    assert (volumes > 0).all()
    assert volumes.sum() == pytest.approx(surface.volume, rel=0.015)
    radius = np.linalg.norm(mesh.points[mesh.point_data["node_level"] < 3], axis=1)
    assert radius.min() > 9.9, "surface nodes stay on the sphere"


def test_a_smooth_torus_is_cut_into_charts_and_meshed(tmp_path):
    """A closed smooth surface of genus one (no border, no plane, no cylinder) is cut into charts by smooth
    cuts; the mesh is valid, its surface nodes on the torus and its volume that of the faceted input."""
    import trimesh

    surface = trimesh.creation.torus(20.0, 6.0, major_sections=64, minor_sections=24)
    code, err, mesh = mesh_file(tmp_path, surface, 2.0)
    assert code == 0, err
    p = mesh.points[mesh.cells_dict["tetra"]]
    volumes = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6
    assert (volumes > 0).all()
    assert volumes.sum() == pytest.approx(surface.volume, rel=0.01)

    def off_torus(points):
        return np.abs(np.hypot(np.hypot(points[:, 0], points[:, 1]) - 20.0, points[:, 2]) - 6.0)

    faceting = off_torus(np.vstack([surface.sample(20_000, seed=0), surface.triangles_center])).max()
    assert off_torus(mesh.points[mesh.point_data["node_level"] < 3]).max() <= faceting * 1.05, (
        "surface nodes on the input surface"
    )
    assert tet_quality(mesh.points, mesh.cells_dict["tetra"]).min_dihedral.min() >= 10.0


def test_an_acute_wedge_meshes_with_a_closed_boundary(tmp_path):
    import trimesh

    angle = np.radians(20)
    base = np.array([[0, 0, 0], [60, 0, 0], [60 * np.cos(angle), 60 * np.sin(angle), 0]])
    vertices = np.vstack([base, base + [0, 0, 15]])
    faces = [[0, 2, 1], [3, 4, 5], [0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [2, 0, 3], [2, 3, 5]]
    surface = trimesh.Trimesh(vertices, faces)
    code, err, mesh = mesh_file(tmp_path, surface, 3.0)
    assert code == 0, err
    tets = mesh.cells_dict["tetra"]
    p = mesh.points[tets]
    volumes = np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6
    assert (volumes > 0).all() and volumes.sum() == pytest.approx(surface.volume, rel=1e-6)


def test_pymeshlab_agrees_the_boundary_is_closed_and_close_to_the_input():
    """The boundary report's topology (pymeshlab) and its two-sided distances (libigl, over h) against
    pymeshlab's own Hausdorff sampling, an independent implementation."""
    import pymeshlab

    from engine.quality import boundary_report

    geometry, features, sizing, _ = packed("l_bracket")
    mesh = meshed("l_bracket")
    report = boundary_report(mesh, geometry, sizing)
    assert report["two_manifold"] and report["boundary_edges"] == 0 and report["components"] == 1
    assert report["volume"] == pytest.approx(geometry.volume, rel=0.005)
    assert report["area"] == pytest.approx(report["input_area"], rel=0.005)
    faces = mesh.boundary_faces()
    used, local = np.unique(faces, return_inverse=True)
    meshes = pymeshlab.MeshSet()
    meshes.add_mesh(pymeshlab.Mesh(mesh.points[used], local.reshape(-1, 3)))
    meshes.add_mesh(pymeshlab.Mesh(np.asarray(geometry.mesh.vertices), np.asarray(geometry.mesh.faces)))
    for direction, (sampled, target) in (("hausdorff_mesh_to_input", (0, 1)), ("hausdorff_input_to_mesh", (1, 0))):
        theirs = meshes.get_hausdorff_distance(
            sampledmesh=sampled, targetmesh=target, samplevert=True, sampleface=True, samplenum=200_000
        )["max"]
        assert report[direction]["max"] == pytest.approx(theirs, rel=0.2, abs=1e-3 * geometry.scale), direction
        assert report[direction]["max_over_h"] >= report[direction]["max"] / sizing.h_max
    assert report["triangle_quality"]["min"] > 0.2


def test_a_flat_tet_between_two_boundary_faces_is_peeled():
    """A sliver lying on a pyramid (its lower faces shared, its upper two on the boundary) goes; the
    boundary becomes its lower faces, outward, and still equals the free faces of the tets."""
    from engine.mesh import TetMesh
    from engine.meshing.improve import FLOOR, peel_boundary_slivers
    from engine.meshing.tetra import orient

    points = np.array([[0, 0, 0], [1, 0, 0.05], [1, 1, 0], [0, 1, 0.05], [0.5, 0.5, -1.0]])
    tets, _ = orient(points, np.array([[0, 1, 2, 3], [0, 1, 2, 4], [0, 2, 3, 4]]))
    boundary = TetMesh(
        points=points, tets=tets, node_level=np.zeros(5, np.int8), node_entity=np.zeros(5, np.int64)
    ).boundary_faces()
    patch = np.zeros(len(boundary), np.int64)
    tets, boundary, patch, removed = peel_boundary_slivers(points, tets, boundary, patch, FLOOR)
    assert removed == 1 and len(tets) == 2 and len(boundary) == len(patch) == 6

    def rotated(faces):  # each face from its smallest node: same set = same faces, same orientation
        return {tuple(np.roll(f, -int(np.argmin(f)))) for f in np.asarray(faces).tolist()}

    assert rotated(boundary) == rotated(
        TetMesh(
            points=points, tets=tets, node_level=np.zeros(5, np.int8), node_entity=np.zeros(5, np.int64)
        ).boundary_faces()
    )
    assert {tuple(sorted(f)) for f in boundary.tolist()} >= {(0, 1, 2), (0, 2, 3)}


def test_a_flat_tet_inside_is_unfolded_not_dropped():
    """Two pyramids on one square (four coplanar, cospherical nodes: a thin plate's edges packed alike on top
    and bottom) split it by different diagonals, with a zero-volume tet between them, as HXT returned once on
    a plate with a hole (the IN/OUT pass dropped it: 4 boundary edges of one face, the mesh refused). It is
    inside; unfolded, the four tets fill the bipyramid, every one positive, its eight faces the boundary."""
    from engine.mesh import TetMesh, signed_volumes
    from engine.meshing.tetra import inside_by_boundary, orient, unfold_flat

    a, b, c, d, p, q = range(6)
    points = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0], [1, 0.5, 1], [0.8, 0.4, -1.2]], float)
    tets, _ = orient(points, np.array([[p, a, b, c], [p, a, c, d], [q, a, b, d], [q, b, c, d], [a, b, c, d]]))
    pyramid = [[p, a, b], [p, b, c], [p, c, d], [p, d, a], [q, b, a], [q, c, b], [q, d, c], [q, a, d]]
    outward = [np.cross(*(points[f[1:]] - points[f[0]])) @ (points[f].mean(0) - points.mean(0)) > 0 for f in pyramid]
    boundary = np.array([f if out else f[::-1] for f, out in zip(pyramid, outward)])
    inside = inside_by_boundary(points, tets, boundary)
    assert inside.all()  # the flat tet too: it has a neighbour across every face and no boundary face
    unfolded = unfold_flat(points, tets[inside])
    assert len(unfolded) == 4 and (signed_volumes(points, unfolded) > 1e-3).all()
    assert signed_volumes(points, unfolded).sum() == pytest.approx(2 * 2.2 / 3)
    mesh = TetMesh(points=points, tets=unfolded, node_level=np.zeros(6, np.int8), node_entity=np.zeros(6, np.int64))
    assert {tuple(sorted(f)) for f in mesh.boundary_faces().tolist()} == {tuple(sorted(f)) for f in pyramid}


def test_a_flat_tet_between_no_pyramids_is_swapped_out_not_dropped():
    """The square's upper side is split by a-c into triangles of two tets of different apexes (no pyramid to
    re-split: a rectangle rim to edge through a 10 mm ligament at h 11, seeds 0 and 1, refused with 4 boundary
    edges), the lower side by b-d: unfold_flat keeps the flat tet, the mesher's swaps remove it (edge a-c's
    ring retriangulated): every tet positive, the volume and the outer faces as before."""
    from engine.mesh import TetMesh, signed_volumes
    from engine.meshing.delaunay import FLAT_QUALITY
    from engine.meshing.improve import swap_bad_faces
    from engine.meshing.tetra import orient, unfold_flat

    a, b, c, d, p1, p2, q = range(7)
    points = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0], [1.4, 0.2, 1], [0.6, 0.8, 1], [1, 0.5, -1]], float)
    # the flat tet in the order its neighbours agree with (positive with the ridge a-c lifted, b-d lowered)
    rows = [[p1, a, b, c], [p2, a, c, d], [p1, p2, a, c], [q, a, b, d], [q, b, c, d], [b, a, c, d]]
    tets, volumes = orient(points, np.array(rows))
    outer = {
        tuple(sorted(f))
        for f in TetMesh(points=points, tets=tets, node_level=np.zeros(7, np.int8), node_entity=np.zeros(7, np.int64))
        .boundary_faces()
        .tolist()
    }
    kept = unfold_flat(points, tets)
    assert len(kept) == 6  # not dropped: that left a hole
    swapped, flips = swap_bad_faces(points, kept, FLAT_QUALITY)
    assert flips >= 1 and (signed_volumes(points, swapped) > 1e-3).all()
    assert signed_volumes(points, swapped).sum() == pytest.approx(volumes.sum())
    mesh = TetMesh(points=points, tets=swapped, node_level=np.zeros(7, np.int8), node_entity=np.zeros(7, np.int64))
    assert {tuple(sorted(f)) for f in mesh.boundary_faces().tolist()} == outer


def test_two_curves_between_the_same_corners_a_hair_apart_are_one_chain():
    """A patch collapsed between two curves 0.017 mm apart (a drafted housing's sliver of fillet) left the surface
    open along one of them at h 0.8; the later curve now takes the earlier one's nodes, reversed to its own
    direction, so the patches outside meet on one chain. Curves 0.3 mm apart (wider than 0.1 h) keep their own."""
    from types import SimpleNamespace

    from engine.features import Curve
    from engine.meshing.surface import _coincident

    line = np.array([[0.0, 0.0, 0.0], [0.7, 0.0, 0.0], [1.4, 0.0, 0.0]])
    bent = line + [[0, 0, 0], [0, 0.017, 0], [0, 0, 0]]
    wide = line + [[0, 0, 0], [0, 0.3, 0], [0, 0, 0]]
    packing = SimpleNamespace(radius=np.full(6, 0.4))  # h 0.8
    for second, merged in ((bent, True), (wide, False)):
        curves = [
            Curve(id=f"curve-{k}", points=p, closed=False, vertices=None) for k, p in enumerate((line, second[::-1]))
        ]
        features = SimpleNamespace(curves=curves)
        chains = _coincident(packing, features, {0: np.array([0, 2, 1]), 1: np.array([1, 3, 0])})
        assert chains[0].tolist() == [0, 2, 1]
        assert chains[1].tolist() == ([1, 2, 0] if merged else [1, 3, 0])


def test_a_flat_cap_gets_a_node_beneath_it():
    """A flat tet under a roof of two boundary faces (16 deg, a fold on a convex patch: no swap of its ring
    helps) becomes, with the ring around its inner edge, the star of one new node beneath: every tet
    positive, same volume, same boundary faces, min dihedral 39 deg."""
    from engine.mesh import TetMesh, signed_volumes
    from engine.meshing.improve import TARGET, fill_flat_caps, min_dihedrals
    from engine.meshing.tetra import orient

    points = np.array([[-1, 0, 0], [1, 0, 0], [0, -0.6, 0.15], [0, 0.6, 0.15], [0, -0.6, -0.9], [0, 0.6, -0.9]])
    tets, _ = orient(points, np.array([[0, 1, 2, 3], [0, 1, 3, 5], [0, 1, 5, 4], [0, 1, 4, 2]]))

    def free(p, t):
        mesh = TetMesh(points=p, tets=t, node_level=np.zeros(len(p), np.int8), node_entity=np.zeros(len(p), np.int64))
        return {tuple(np.roll(f, -int(np.argmin(f)))) for f in mesh.boundary_faces().tolist()}

    boundary = np.array(sorted(free(points, tets)))
    assert min_dihedrals(points, tets).min() < 17
    filled, capped, added = fill_flat_caps(points, tets, boundary, TARGET)
    assert added == 1 and len(filled) == 7 and len(capped) == 8
    assert np.allclose(filled[:6], points) and filled[6, 2] < 0  # the new node is last, beneath the roof
    assert (signed_volumes(filled, capped) > 0).all()
    assert signed_volumes(filled, capped).sum() == pytest.approx(signed_volumes(points, tets).sum())
    assert free(filled, capped) == free(points, tets)
    assert min_dihedrals(filled, capped).min() > 35


def test_an_inner_edge_of_needles_is_swapped_away():
    """Three needles around an inner edge (radius ratio 0.08, under the floor) become the two tets of the
    triangle around it: same volume, same free faces."""
    from engine.mesh import TetMesh, signed_volumes
    from engine.meshing.improve import FLOOR, min_dihedrals, swap_bad_faces
    from engine.meshing.tetra import orient

    angles = np.radians([90, 210, 330])
    points = np.vstack([np.column_stack([np.cos(angles), np.sin(angles), np.zeros(3)]), [[0, 0, 3], [0, 0, -3]]])
    tets, _ = orient(points, np.array([[3, 4, 0, 1], [3, 4, 1, 2], [3, 4, 2, 0]]))
    swapped, flips = swap_bad_faces(points, tets, FLOOR)
    assert flips == 1 and len(swapped) == 2 and min_dihedrals(points, swapped).min() > 60
    assert signed_volumes(points, swapped).sum() == pytest.approx(signed_volumes(points, tets).sum())

    def free(t):
        return {
            tuple(sorted(f))
            for f in TetMesh(points=points, tets=t, node_level=np.zeros(5, np.int8), node_entity=np.zeros(5, np.int64))
            .boundary_faces()
            .tolist()
        }

    assert free(swapped) == free(tets)


def test_a_crowded_surface_node_is_collapsed_along_a_boundary_edge():
    """A surface node 0.03 from a corner (its three tets flat) merges into the corner along their shared
    boundary edge: one tet is left, its boundary the tet's four faces, outward."""
    from engine.mesh import TetMesh
    from engine.meshing.improve import FLOOR, collapse_bad_nodes
    from engine.meshing.tetra import orient

    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.02, 0.02, 0.0]])
    tets, _ = orient(points, np.array([[4, 1, 2, 3], [4, 2, 0, 3], [4, 0, 1, 3]]))
    boundary = TetMesh(
        points=points, tets=tets, node_level=np.zeros(5, np.int8), node_entity=np.zeros(5, np.int64)
    ).boundary_faces()
    patch = np.zeros(len(boundary), np.int64)
    collapsible = np.array([False, False, False, False, True])
    tets, boundary, patch, collapsed = collapse_bad_nodes(points, tets, boundary, patch, FLOOR, collapsible)
    assert collapsed == 1 and len(tets) == 1 and len(boundary) == len(patch) == 4
    assert {tuple(np.roll(f, -int(np.argmin(f)))) for f in boundary.tolist()} == {
        tuple(np.roll(f, -int(np.argmin(f))))
        for f in TetMesh(points=points, tets=tets, node_level=np.zeros(5, np.int8), node_entity=np.zeros(5, np.int64))
        .boundary_faces()
        .tolist()
    }


def test_a_surface_node_no_triangle_uses_is_left_out(monkeypatch):
    """A surface node that no boundary triangle uses (a patch node its patch's triangulation left out) lies on the
    surface, here on a boundary triangle's centroid: it stays out of the constrained Delaunay (a node on a
    constrained triangle made Gmsh fail to recover it, on a filleted flange of 680k nodes) and is counted."""
    from dataclasses import replace

    import engine.meshing.delaunay as delaunay
    from engine.packing import Packing

    real = delaunay.triangulate_boundary
    centre = []

    def with_a_stray_node(packing, geometry, features):
        surface = real(packing, geometry, features)
        centre.append(surface.nodes.points[surface.triangles[0]].mean(axis=0))
        stray = Packing(
            points=centre[0][None],
            level=np.array([PATCH], np.int8),
            entity=surface.patch[:1],
            radius=surface.nodes.radius[surface.triangles[0, :1]],
            ids=np.array([-1]),
        )
        return replace(surface, nodes=Packing.concatenate([surface.nodes, stray], surface.nodes.stats))

    geometry, features, _, packing = packed("l_bracket")
    before = meshed("l_bracket").stats["unused_surface_nodes_dropped"]
    monkeypatch.setattr(delaunay, "triangulate_boundary", with_a_stray_node)
    mesh = get_mesher("delaunay")(packing, geometry, features, seed=0)
    assert mesh.stats["unused_surface_nodes_dropped"] == before + 1
    assert (tet_quality(mesh.points, mesh.tets).volume > 0).all()
    assert np.linalg.norm(mesh.points - centre[0], axis=1).min() > 1e-9


def test_chain_edges_a_triangulation_keeps_missing_are_refused_with_their_place(monkeypatch):
    """A patch triangulation that misses a chain edge round after round (here forced) ends in one message that
    names where: the point around the missed edges and their curves with centroids."""
    import engine.meshing.surface as surface

    real = surface._triangulate_patch

    def missing_one(chart, points, radius, constraints, droppable, constrained=False):
        tri, crowded, lost, new_points, new_radius = real(chart, points, radius, constraints, droppable, constrained)
        return tri, crowded, constraints[:1], new_points, new_radius

    geometry, features, _, packing = packed("l_bracket")
    monkeypatch.setattr(surface, "_triangulate_patch", missing_one)
    with pytest.raises(RuntimeError) as error:
        surface.triangulate_boundary(packing, geometry, features)
    message = str(error.value)
    assert "feature-curve edges still missing from the surface triangulation, around (" in message
    assert "(centroid " in message and "curve-" in message


def test_a_chart_without_triangles_has_no_stray_points():
    """A patch whose nodes make no triangle in its chart (three in a row, on a cast housing's corner) has no
    input point to add: libigl's distance query on no triangles read past its arrays and crashed the process."""
    from types import SimpleNamespace

    from engine.meshing.surface import _stray_points

    chart = SimpleNamespace(
        probe_uv=np.array([[0.5, 0.1], [1.5, -0.1]]), probe_xyz=np.zeros((2, 3)), flat_tolerance=1e-3
    )
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    none = np.zeros((0, 3), np.int64)
    point, badness, h = _stray_points(chart, uv, none, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    assert point.shape == (0, 2) and len(badness) == len(h) == 0


def test_a_patch_node_slid_off_its_patch_or_to_poorer_tets_is_put_back(built):
    """Relocation weighs a sliding node's tets off the surface: put back onto it, a gear flank's node had slid
    1.1 h past the flank's foot onto the root (7.6 deg), another to 0.07 h from the foot's curve (5.3 deg)."""
    from engine.meshing.delaunay import _on_own_patches

    shape, features = built("plate", length=10.0, width=10.0, thickness=10.0)
    (top,) = [k for k, p in enumerate(features.patches) if "top" in p.names]
    points = np.array([[-5, -5, 10], [5, -5, 10], [5, 5, 10], [-5, 5, 10], [3, 3, 10], [0, 0, 2]], float)
    level = np.array([CORNER] * 4 + [PATCH, VOLUME], np.int8)
    entity = np.array([0, 1, 2, 3, top, -1])
    star = np.array([[1, 0, 4, 5], [2, 1, 4, 5], [3, 2, 4, 5], [0, 3, 4, 5]])  # 14.5 deg at (3, 3)
    none = np.zeros((0, 4), np.int64)
    cases = (
        ([0.5, 0.5, 10], star, True),  # 45.6 deg
        ([4.99, 0, 10], star, False),  # 0.1 deg, against the border
        ([5, 0, 8], none, False),  # on the side face (its tets aside)
    )
    for after, tets, kept in cases:
        slid = points.copy()
        slid[4] = after
        landed = features.face_patch[shape.geometry.closest_point(slid[[4]])[2]]
        no_faces, h = np.zeros((0, 3), np.int64), np.full(len(points), 1.0)
        out = _on_own_patches(slid, points, np.array([4]), landed, level, entity, tets, no_faces, shape.geometry, h)
        assert np.array_equal(out[4], after if kept else points[4])


def test_a_patch_node_slid_so_that_its_triangle_strays_off_the_surface_is_put_back(built):
    """Beside a centre hole's cone tip two slid nodes left a boundary triangle spanning the tip 0.28 h off the
    surface (the mesh refused). On a cylinder r 25: a triangle's third node slid from 0 to 40 deg round the axis
    leaves its centroid 1.40 off the surface (0.06 before): over 0.06 h (h 10), so it goes back; the same slide
    with h 100 (0.06 h = 6) stays."""
    from engine.meshing.delaunay import _on_own_patches

    shape, features = built("cylinder", radius=25.0, height=100.0)
    (side,) = [k for k, p in enumerate(features.patches) if "side" in p.names]

    def at(degrees, z):
        return [25 * np.cos(np.radians(degrees)), 25 * np.sin(np.radians(degrees)), z]

    points = np.array([at(-5, 50), at(5, 50), at(0, 55)])
    level = np.full(3, PATCH, np.int8)
    entity = np.full(3, side)
    slid = points.copy()
    slid[2] = at(40, 55)
    landed = np.array([side])
    faces = np.array([[0, 1, 2]])
    for h, kept in ((10.0, False), (100.0, True)):
        out = _on_own_patches(
            slid.copy(),
            points,
            np.array([2]),
            landed,
            level,
            entity,
            np.zeros((0, 4), np.int64),
            faces,
            shape.geometry,
            np.full(3, h),
        )
        assert np.array_equal(out[2], slid[2] if kept else points[2])
