import math

import numpy as np
import pytest
from conftest import gmsh_model

from engine.features import detect_features
from engine.job import job_from_dict
from engine.pipeline import prepare, run


def test_plate_has_the_corners_edges_and_faces_of_a_box(built):
    _, features = built("plate")
    assert (len(features.corners), len(features.curves), len(features.patches)) == (8, 12, 6)
    assert {"top", "bottom", "x-min", "x-max", "y-min", "y-max"} <= set(features.names)
    lengths = sorted(round(c.length, 6) for c in features.curves)
    assert lengths == [20.0] * 4 + [200.0] * 8


def test_ids_are_stable(built):
    shape, features = built("plate_cylinder_junction")
    again = detect_features(shape.geometry, 30.0)
    assert [c.id for c in again.curves] == [c.id for c in features.curves]
    assert all(np.array_equal(a.points, b.points) for a, b in zip(again.curves, features.curves))
    assert [p.id for p in again.patches] == [p.id for p in features.patches]


def test_circular_curves_carry_centre_axis_and_radius(built):
    _, features = built("cylinder", radius=25, height=100)
    assert len(features.curves) == 2 and len(features.corners) == 0
    for curve in features.curves:
        assert curve.closed and curve.circle is not None
        assert curve.circle.radius == pytest.approx(25, rel=1e-6)
        assert np.allclose(np.abs(curve.circle.axis), [0, 0, 1])
    z = sorted(c.circle.centre[2] for c in features.curves)
    assert z == pytest.approx([0, 100])


@pytest.mark.parametrize(
    "kind,name,radius",
    [("cylinder", "top-edge", 25), ("plate_with_hole", "hole", 10), ("plate_cylinder_junction", "junction", 25)],
)
def test_faceting_chordal_error_is_at_most_a_thousandth_of_the_radius(kind, name, radius, built):
    _, features = built(kind)
    curve = next(c for c in features.named(name) if hasattr(c, "closed"))
    line = curve.polyline
    mid = 0.5 * (line[1:] + line[:-1])
    gap = radius - np.linalg.norm((mid - curve.circle.centre)[:, :2], axis=1)
    assert gap.max() <= 1e-3 * radius * (1 + 1e-9)


def test_arc_length_parametrisation(built):
    _, features = built("cylinder", radius=10, height=5)
    curve = features.curves[0]
    s = np.linspace(0, curve.length, 50, endpoint=False)
    points = curve.point_at(s)
    assert np.allclose(np.linalg.norm(points[:, :2] - curve.circle.centre[:2], axis=1), 10, rtol=2e-3)
    assert np.allclose(curve.point_at(curve.length), curve.point_at(0.0))


def test_junction_is_a_concave_circle_and_plate_edge_is_the_near_side(built):
    _, features = built("plate_cylinder_junction", offset=60)
    (junction,) = features.named("junction")
    assert junction.convex is False and junction.circle.radius == pytest.approx(25, rel=1e-6)
    assert junction.circle.centre == pytest.approx([60, 0, 20], abs=1e-6)
    (edge,) = features.named("plate-edge")
    assert edge.normal == pytest.approx([1, 0, 0]) and edge.centroid[0] == pytest.approx(100)
    _, mirrored = built("plate_cylinder_junction", offset=-60)
    (edge,) = mirrored.named("plate-edge")
    assert edge.normal == pytest.approx([-1, 0, 0])


def test_fillet_is_its_own_patch_with_its_area(built):
    _, features = built("l_bracket", fillet_radius=8, width=40)
    (fillet,) = features.named("fillet")
    assert fillet.area == pytest.approx(np.pi / 2 * 8 * 40, rel=2e-3)
    assert not fillet.planar


@pytest.mark.parametrize("crack", ["straight", "semi-elliptical"])
def test_crack_front_lies_inside_the_plate(crack, built):
    shape, features = built("cracked_plate", crack=crack)
    (front,) = features.named("crack-front")
    assert not front.on_surface
    inner = front.points[1:-1]
    assert shape.geometry.contains(inner).all()
    ends = front.points[[0, -1]]
    assert np.allclose(shape.geometry.signed_distance(ends), 0, atol=1e-9)


def test_a_hole_whose_facets_cross_the_cylinder_lines_is_a_hole(tmp_path):
    """Gmsh's surface mesher (and most CAD exports) lays triangles across a cylinder's lines, which tilts their
    normals off the plane across the axis (third singular value 1.3e-2 to 4.7e-2 of the first on an outside
    test's parts): the hole was no cylinder, so no hole at all, and `recipe: static-stress` placed nothing on it."""
    import gmsh
    import trimesh

    from engine.geometry import load_surface

    path = tmp_path / "plate.stl"
    options = {"Mesh.MeshSizeFromCurvature": 24, "Mesh.MeshSizeMax": 5.0, "Mesh.Algorithm": 6}
    with gmsh_model("test-tilted-hole", options) as occ:
        occ.cut([(3, occ.addBox(0, 0, 0, 60, 40, 20))], [(3, occ.addCylinder(30, 20, -1, 0, 0, 22, 8))])
        occ.synchronize()
        gmsh.model.mesh.generate(2)
        gmsh.write(str(path))
    mesh = trimesh.load(path, force="mesh")
    wall = np.abs(np.hypot(mesh.triangles_center[:, 0] - 30, mesh.triangles_center[:, 1] - 20) - 8) < 0.5
    singular = np.linalg.svd(mesh.face_normals[wall], compute_uv=False)
    assert singular[2] > 1e-3 * singular[0], "the facets tilt their normals (else this tests nothing new)"
    features = detect_features(load_surface(path))
    holes = [p for p in features.patches if p.cylinder is not None and p.cylinder.concave and p.cylinder.full_turn]
    assert len(holes) == 1
    assert holes[0].cylinder.radius == pytest.approx(8, rel=1e-3)
    assert abs(holes[0].cylinder.axis @ [0, 0, 1]) == pytest.approx(1, abs=1e-6)


def test_a_plane_written_to_a_few_nanometres_is_a_plane():
    """A CAD tessellation's plane faces lie on their plane only to the coordinates' precision (1e-9 to 1e-8 of
    the model size): at 1e-9 an outside test's bracket's sides were cylinders of radius 1.8e8, so concave, so
    'fillet'. Every face of a subdivided box with its vertices moved 5e-9 x the model size off is planar."""
    import trimesh

    from engine.geometry import validate_surface

    box = trimesh.creation.box([40.0, 30.0, 20.0]).subdivide().subdivide()
    size = float(np.linalg.norm(box.extents))
    noise = np.random.default_rng(0).uniform(-5e-9, 5e-9, box.vertices.shape) * size
    features = detect_features(validate_surface(box.vertices + noise, box.faces, "<noisy box>"))
    assert len(features.patches) == 6
    assert all(p.planar and p.cylinder is None for p in features.patches)


def test_a_seven_sided_hole_is_a_full_turn(tmp_path):
    """A hole of 7 facets (an OpenSCAD export's coarse circle), one patch at feature angle 55: its facet centres
    are 51 deg apart round the axis but its vertices close the gaps, so it is a hole, not a fillet (an outside
    test's coupling and belt clamp)."""
    import trimesh

    from engine.describe import solid_features

    block = trimesh.creation.box([20.0, 20.0, 10.0])
    bore = trimesh.creation.cylinder(radius=2.0, height=12.0, sections=7)
    block.difference(bore, engine="manifold").export(str(tmp_path / "block.stl"))
    _, _, features = solid_features(tmp_path / "block.stl", 55.0)
    (hole,) = [p for p in features.patches if p.cylinder is not None]
    assert hole.cylinder.concave and hole.cylinder.full_turn and hole.kinds == ["hole"]


def test_a_ten_sided_hole_is_a_hole_made_of_ten_planar_patches_and_a_hex_socket_is_not(tmp_path):
    """At the default feature angle a 10-sided hole's facets (36 deg apart) are ten planar patches: they close a
    full turn round one axis with every vertex on one circle, so each takes the ring's cylinder and is a hole of
    radius 2 (an outside test's OpenSCAD endstop: its four bolt holes were not found, and the static-stress
    recipe placed no hole pattern). A 6-sided socket is a polygon of its own."""
    import trimesh

    from engine.describe import solid_features

    block = trimesh.creation.box([20.0, 20.0, 10.0])
    bore = trimesh.creation.cylinder(radius=2.0, height=12.0, sections=10)
    bore.apply_translation([-5.0, 0.0, 0.0])
    socket = trimesh.creation.cylinder(radius=2.0, height=12.0, sections=6)
    socket.apply_translation([5.0, 0.0, 0.0])
    block.difference(bore, engine="manifold").difference(socket, engine="manifold").export(str(tmp_path / "b.stl"))
    _, _, features = solid_features(tmp_path / "b.stl")
    holes = [p for p in features.patches if "hole" in p.kinds]
    assert len(holes) == 10 and all(p.planar for p in holes)
    assert [p.cylinder.radius for p in holes] == pytest.approx([2.0] * 10)
    assert all(p.centroid[0] < 0 for p in holes), "the hexagon's six faces are no hole"


def test_a_cut_leaves_no_island_of_a_face_or_two_apart():
    """A minimum cut's side with a stray face (the spring of an outside test: one facet between two cuts that ran
    along the same edge once unzigzagged, and 100 curve edges missing from its surface triangulation) gives it to
    the side round it; a side's largest component stays however small."""
    from engine.features import _without_islands

    chain = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [5, 6], [6, 7]])
    side = np.array([True, True, True, False, True, False, False, False])
    assert _without_islands(side, chain).tolist() == [True, True, True, False, False, False, False, False]
    alone = np.array([True, False, False, False, False, False, False, False])
    assert _without_islands(alone, chain).tolist() == alone.tolist()


def _keyed_slotted_bracket(occ):
    """An L bracket (base 80 x 50 x 10, wall 10 thick and 20 high) whose inner corner is a fillet of radius 3,
    with a slot 8 wide (two half-cylinder ends of radius 4) and a bore of radius 6 with a keyway 3 x 2 in the
    base."""
    base = occ.fuse([(3, occ.addBox(0, 0, 0, 80, 50, 10))], [(3, occ.addBox(0, 40, 10, 80, 10, 20))])[0][0][1]
    occ.synchronize()
    corner = [
        c for _, c in occ.getEntities(1) if np.allclose(occ.getBoundingBox(1, c), [0, 40, 10, 80, 40, 10], atol=1e-6)
    ]
    base = occ.fillet([base], corner, [3.0])[0][1]
    slot = occ.fuse(
        [(3, occ.addBox(15, 16, -1, 20, 8, 12))],
        [(3, occ.addCylinder(15, 20, -1, 0, 0, 12, 4)), (3, occ.addCylinder(35, 20, -1, 0, 0, 12, 4))],
    )[0]
    keyed = occ.fuse([(3, occ.addCylinder(60, 20, -1, 0, 0, 12, 6))], [(3, occ.addBox(60, 18.5, -1, 8, 3, 12))])[0]
    occ.cut([(3, base)], slot + keyed)


@pytest.mark.parametrize("source", ["step", "stl"])
def test_a_keyed_bore_and_a_slot_end_are_holes_and_a_fillet_is_not(source, tmp_path):
    """A concave cylinder round half a turn or more is a hole's wall (a keyed bore's 330 degrees, a slot end's
    180), one round less a fillet (180 less the angle its faces meet at): an outside test's gear bore with a
    keyway and a sheet bracket's slot ends were 'fillet', so `recipe: static-stress` refined neither."""
    import gmsh

    from engine.describe import solid_features

    path = tmp_path / f"bracket.{source}"
    options = {"Mesh.MeshSizeFromCurvature": 24, "Mesh.MeshSizeMax": 4.0}
    with gmsh_model("test-keyed-slotted", options) as occ:
        _keyed_slotted_bracket(occ)
        occ.synchronize()
        if source == "stl":
            gmsh.model.mesh.generate(2)
        gmsh.write(str(path))
    _, _, features = solid_features(path)
    kinds = sorted((kind, round(p.cylinder.radius, 2)) for p in features.patches if p.cylinder for kind in p.kinds)
    assert kinds == [("fillet", 3.0), ("hole", 4.0), ("hole", 4.0), ("hole", 6.0)]
    (bore,) = [p for p in features.patches if p.cylinder and p.cylinder.radius > 5]
    assert 300 < bore.cylinder.sweep < 345


def test_a_bent_pipe_s_bore_is_a_hole_and_its_outside_no_fillet(tmp_path):
    """A concave torus turning all the way round its tube is a bent bore, a 'hole' of the tube's radius; a
    fillet's torus turns a quarter (an outside test's pipe elbow bore was a 'fillet')."""

    import gmsh

    from engine.describe import solid_features

    path = tmp_path / "bend.step"
    with gmsh_model("test-bent-pipe") as occ:
        outer = occ.addTorus(0, 0, 0, 30, 8, angle=math.pi / 2)
        occ.cut([(3, outer)], [(3, occ.addTorus(0, 0, 0, 30, 5))])
        occ.synchronize()
        gmsh.write(str(path))
    _, _, features = solid_features(path)
    tori = {(*p.names, *p.kinds, round(p.circle.radius, 6)) for p in features.patches if p.circle is not None}
    assert tori == {("face-1", 8.0), ("face-4", "hole", 5.0)}  # each torus is cut into charts: every piece alike


def test_a_keyed_bore_is_unrolled_open_and_a_hole_wall_round(tmp_path):
    """The cylinder chart is periodic only where a triangle crosses the seam put in the patch's widest empty
    sector: a keyed bore (330 degrees, its keyway's gap under the 30 of full_turn) unrolls open, a hole wall
    round."""
    import gmsh
    import trimesh

    from engine.describe import solid_features
    from engine.meshing.surface import PatchChart

    path = tmp_path / "bracket.stl"
    with gmsh_model("test-keyed-chart", {"Mesh.MeshSizeFromCurvature": 24, "Mesh.MeshSizeMax": 4.0}) as occ:
        _keyed_slotted_bracket(occ)
        occ.synchronize()
        gmsh.model.mesh.generate(2)
        gmsh.write(str(path))
    _, geometry, features = solid_features(path)
    (bore,) = [p for p in features.patches if p.cylinder and p.cylinder.radius > 5]
    assert bore.cylinder.full_turn and PatchChart(bore, geometry).turn is None
    block = trimesh.creation.box([20.0, 20.0, 10.0])
    block.difference(trimesh.creation.cylinder(radius=4.0, height=12.0, sections=64), engine="manifold").export(
        tmp_path / "block.stl"
    )
    _, geometry, features = solid_features(tmp_path / "block.stl")
    (wall,) = [p for p in features.patches if p.cylinder is not None]
    assert PatchChart(wall, geometry).turn == pytest.approx(2 * np.pi * 4.0, rel=1e-3)


def test_a_smooth_cut_s_chords_across_a_curved_face_are_put_on_it():
    """A cut unzigzagged across a coarse fillet's facets runs on chords through the solid (a cast housing's
    4 mm base fillet: 0.29 mm inside, and the mesh 0.28 h off the input): points of the surface go between
    the ends of every chord that strays from it by more than CHORD_ON_SURFACE x the length of the chord it came
    from (the first one's here)."""
    import trimesh

    from engine.features import CHORD_ON_SURFACE, _chords_on_surface
    from engine.geometry import validate_surface

    bar = trimesh.creation.cylinder(radius=4.0, height=10.0, sections=8)
    geometry = validate_surface(bar.vertices, bar.faces, "bar.stl")
    ends = np.array([[4.0, 0.0, -5.0], [0.0, 4.0, 5.0], [-4.0, 0.0, 5.0]])  # through the bar, then on its end
    off = geometry.closest_point(0.5 * (ends[1:] + ends[:-1]))[1]
    assert off[0] > 0.5 and off[1] < 1e-9

    points = _chords_on_surface(ends, False, geometry)
    middles = 0.5 * (points[1:] + points[:-1])
    assert len(points) > 3 and np.array_equal(points[-2:], ends[-2:]) and np.array_equal(points[0], ends[0])
    assert (geometry.closest_point(points)[1] < 1e-9).all()
    assert (geometry.closest_point(middles[:-1])[1] <= CHORD_ON_SURFACE * np.linalg.norm(ends[1] - ends[0])).all()
    square = np.array([[5.0, 5.0, 5.0], [5.0, -5.0, 5.0], [-5.0, -5.0, 5.0]])  # on the flat end: kept as it is
    assert np.array_equal(_chords_on_surface(square * [0.5, 0.5, 1.0], False, geometry), square * [0.5, 0.5, 1.0])


def test_a_surface_that_cannot_be_cut_into_charts_is_refused_in_one_line_naming_the_file(monkeypatch):
    """The refusal after MAX_SPLITS halvings names the input (the halving's seeds once shadowed the name, and the
    refusal became an internal error)."""
    import trimesh

    from engine import features
    from engine.errors import GeometryError
    from engine.geometry import validate_surface

    ring = trimesh.creation.torus(major_radius=10.0, minor_radius=3.0)
    geometry = validate_surface(ring.vertices, ring.faces, "ring.stl")
    monkeypatch.setattr(features, "MAX_SPLITS", 1)
    with pytest.raises(GeometryError, match=r"^ring\.stl: a smooth surface around .* cannot be cut into pieces"):
        detect_features(geometry, tori=False)


def test_a_long_list_of_feature_names_is_cut_to_the_first_or_the_closest(built):
    """A STEP gear's 1,157 face-N and edge-N names made its geometry log line 20 kB long."""
    from dataclasses import replace

    _, features = built("plate", length=10.0, width=10.0, thickness=2.0)
    named = replace(
        features,
        corners=[replace(c, names=[f"corner-{k + 1}"]) for k, c in enumerate(features.corners)],
        curves=[replace(c, names=[f"edge-{k + 1}"]) for k, c in enumerate(features.curves)],
        patches=[replace(p, names=[f"face-{k + 1}"]) for k, p in enumerate(features.patches)],
    )
    assert len(named.names) == 26
    first = [f"corner-{k}" for k in range(1, 9)] + [f"edge-{k}" for k in range(1, 5)]
    assert named.names_listed() == f"{', '.join(first)} and 14 more (fuzzymesh features lists them)"
    assert named.names_listed("edge-11").startswith("edge-11, edge-1")
    assert replace(named, curves=[], corners=[]).names_listed() == "face-1, face-2, face-3, face-4, face-5, face-6"


@pytest.mark.parametrize("suffix", [".stl", ".step"])
def test_a_centre_hole_s_cone_tip_is_a_corner_of_its_cut_and_a_node_of_the_mesh(tmp_path, suffix):
    """A bar r 10 with a 60 deg centre hole (cone r 2.3, 4 deep): its cone, a closed smooth patch, is cut in two
    down to the tip and up again; the zigzag's removal took that V's tip for a tooth, round after round (the cut
    stopped 0.8 mm short), and the mesh cut the tip off: exit 4, 2.9 h off the input, on every input of an
    outside test's shaft. The tip is now a corner (its angle defect, 181 deg, is over the feature angle)."""
    import gmsh

    from engine.describe import solid_features

    path = tmp_path / f"bar{suffix}"
    with gmsh_model("test-centre-hole") as occ:
        bar = occ.addCylinder(0, 0, 0, 0, 0, 40, 10)
        occ.cut([(3, bar)], [(3, occ.addCone(0, 0, 40.01, 0, 0, -4, 2.3, 0))])
        occ.synchronize()
        if suffix == ".stl":
            gmsh.option.setNumber("Mesh.StlLinearDeflectionRelative", 0)
            gmsh.option.setNumber("Mesh.StlLinearDeflection", 0.08)
            gmsh.option.setNumber("Mesh.StlAngularDeflection", math.radians(15))
        gmsh.write(str(path))
    _, geometry, features = solid_features(path)
    tip = np.array([0.0, 0.0, 40.01 - 4.0])
    assert min(np.linalg.norm(c.point - tip) for c in features.corners) < 1e-6
    result = run(job_from_dict({"geometry": {"file": str(path)}}), write=False)
    assert np.linalg.norm(result.mesh.points - tip, axis=1).min() < 1e-6
    assert result.boundary["hausdorff_input_to_mesh"]["max_over_h"] < 0.25


def test_a_sliver_facet_strip_of_a_bore_is_no_plane_of_its_own(tmp_path):
    """An outside test's clevis: OpenCASCADE's fine tessellation of its r 8 bore (broken into by a lube hole and
    the fork's slot) is fans of facets 34 mm long and 0.02-0.35 high. Two coplanar ones were wider than 3x the
    slivers they bend into (by 0.1 deg) and so 'planes' of their own: two patches 0.06 mm wide, curves that close,
    narrow-face at 0.0625 and 468k tets at 3.6 deg (the coarse STL: 125k, 13.3 deg). A coplanar region no wider
    than NARROW_REGION x the model size is a strip of the surface it bends into."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location("make_parts", Path(__file__).parent / "parts" / "make_parts.py")
    make_parts = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make_parts)
    path = tmp_path / "clevis-fine.stl"
    with gmsh_model("test-clevis") as occ:
        shank = occ.addCylinder(0, 0, -40, 0, 0, 40.5, 15)
        fork = make_parts._fuse(occ.addBox(-15, -15, 0, 30, 30, 30), occ.addCylinder(0, -15, 30, 0, 30, 0, 15))
        clevis = make_parts._cut(
            make_parts._fuse(shank, fork),
            occ.addBox(-16, -7, 15, 32, 14, 40),
            occ.addCylinder(0, -16, 30, 0, 32, 0, 5),
            make_parts._hole(0, 0, -41, 34, 8),
            occ.addCylinder(-16, 0, -20, 32, 0, 0, 1.5),
        )
        occ.synchronize()
        angle, linear = make_parts.TESSELLATIONS["fine"]
        lo, hi = np.reshape(occ.getBoundingBox(3, clevis), (2, 3))
        make_parts._export(path, angle, linear * float(np.linalg.norm(hi - lo)))
    make_parts._clean(path)
    _, _, _, sizing = prepare(job_from_dict({"geometry": {"file": str(path)}}))
    assert not any(p.pattern == "narrow-face" for p in sizing.placed)
