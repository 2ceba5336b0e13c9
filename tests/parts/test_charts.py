"""Charts of real parts' smooth surfaces: a patch wrapped round a zero-angle wedge of another (a con-rod's big
end: the arm's side meets the boss through a tangent fillet that ends square on the arm's faces) folds when
flattened, and is cut until no chart's border folds (engine.features.border_folds)."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from engine.features import _chart, border_folds, detect_features
from engine.geometry import load_surface

_spec = importlib.util.spec_from_file_location("make_parts", Path(__file__).with_name("make_parts.py"))
make_parts = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_parts)

BOSS_RADIUS, FILLET_RADIUS, ARM_SIDE = 20.0, 3.0, 8.0  # boss_arm: boss r 20, arm sides y = +-8, fillets r 3
FILLET_AXIS_Y = ARM_SIDE + FILLET_RADIUS  # the fillet at y > 0 is a circle tangent to the boss and the arm side
FILLET_AXIS_X = float(np.sqrt((BOSS_RADIUS + FILLET_RADIUS) ** 2 - FILLET_AXIS_Y**2))


@pytest.fixture(scope="module")
def boss_arm(tmp_path_factory):
    return make_parts.make_parts(tmp_path_factory.mktemp("boss_arm"), ["boss_arm"])["boss_arm"]


def _smooth_surface_through(mesh: trimesh.Trimesh, point) -> np.ndarray:
    """The faces joined to the face nearest ``point`` across edges bent by under 30 degrees."""
    pairs = mesh.face_adjacency[mesh.face_adjacency_angles < np.radians(30)]
    graph = coo_matrix((np.ones(len(pairs)), tuple(pairs.T)), shape=(len(mesh.faces),) * 2)
    labels = connected_components(graph, directed=False)[1]
    seed = int(np.argmin(np.linalg.norm(mesh.triangles_center - point, axis=1)))
    return np.flatnonzero(labels == labels[seed])


@pytest.mark.parametrize("tessellation", ["coarse", "fine"])
def test_the_fold_round_a_tangent_fillets_end_is_found_on_its_two_sides(boss_arm, tessellation):
    mesh = trimesh.load(boss_arm[tessellation], force="mesh")
    surface = _smooth_surface_through(mesh, [0.0, 20.0, 0.0])  # the boss's wall and the fillets tangent to it
    centre = mesh.triangles_center[surface]
    vertices, triangles, uv = _chart(mesh, surface[(centre[:, 0] > 10) & (centre[:, 1] > 0)])  # round one fillet
    first, second = border_folds(vertices, triangles, uv)
    assert len(first) and len(second)
    centres = [vertices[triangles[side]].mean(axis=1) for side in (first, second)]
    on_fillet = [
        np.abs(np.hypot(c[:, 0] - FILLET_AXIS_X, c[:, 1] - FILLET_AXIS_Y) - FILLET_RADIUS) < 0.3 for c in centres
    ]
    on_boss = [np.abs(np.hypot(c[:, 0], c[:, 1]) - BOSS_RADIUS) < 0.3 for c in centres]
    # one side runs along the fillet's end edge, the other along the boss's edge beside it, at one end (z)
    assert {on_fillet[0].mean() > 0.5, on_fillet[1].mean() > 0.5} == {True, False}
    assert on_boss[0].mean() > 0.5 or on_boss[1].mean() > 0.5
    assert np.ptp(np.sign(np.concatenate(centres)[:, 2])) == 0


@pytest.mark.parametrize("tessellation", ["coarse", "fine"])
def test_no_patch_of_the_part_folds_when_flattened(boss_arm, tessellation):
    geometry = load_surface(boss_arm[tessellation])
    features = detect_features(geometry)
    charted = [p for p in features.patches if not p.planar and p.cylinder is None]
    for patch in charted:
        chart = _chart(geometry.mesh, patch.faces)
        assert chart is not None and len(border_folds(*chart)[0]) == 0, patch.id
    assert len(features.patches) < 30  # cut at the folds, not into facets


POCKET_FILLET = 1.5


def _both_tessellations(out, name: str, build, diagonal: float):
    """({tessellation: path of NAME-TESSELLATION.stl}, what ``build`` returned): the OpenCASCADE model ``build()``
    makes, exported at both of the corpus's tessellations (sagitta relative to ``diagonal``)."""
    import gmsh

    gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    paths, value = {}, None
    try:
        for tessellation, (angle, linear) in make_parts.TESSELLATIONS.items():
            gmsh.clear()
            value = build()
            gmsh.model.occ.synchronize()
            paths[tessellation] = out / f"{name}-{tessellation}.stl"
            make_parts._export(paths[tessellation], angle, linear * diagonal)
            make_parts._clean(paths[tessellation])
    finally:
        gmsh.finalize()
    return paths, value


@pytest.fixture(scope="module")
def pocket_with_floor_fillets(tmp_path_factory):
    """A block with a pocket whose floor edges are filleted and whose vertical corners are sharp (a con-rod's
    shank pocket): at each corner two fillets meet in a mitre, sharp at the walls, smooth at the floor. Its
    STL at both tessellations and the fillets' CAD area."""
    import gmsh

    occ = gmsh.model.occ

    def build():
        tool = occ.addBox(10, 8, 6, 40, 14, 10)
        occ.synchronize()
        floor = [c for _, c in gmsh.model.getBoundary([(3, tool)], oriented=False, combined=False)]
        floor = [c for _, c in gmsh.model.getBoundary([(2, f) for f in floor], oriented=False, combined=False)]
        edges = sorted({c for c in floor if make_parts._at_z(6)(occ.getBoundingBox(1, c))})
        block = make_parts._cut(occ.addBox(0, 0, 0, 60, 30, 12), make_parts._fillet(tool, edges, POCKET_FILLET))
        occ.synchronize()
        faces = gmsh.model.getBoundary([(3, block)], oriented=False)
        return sum(occ.getMass(2, t) for _, t in faces if gmsh.model.getType(2, t) == "Cylinder")

    return _both_tessellations(tmp_path_factory.mktemp("pocket"), "pocket", build, float(np.linalg.norm([60, 30, 12])))


@pytest.mark.parametrize("tessellation", ["coarse", "fine"])
def test_fillets_meeting_in_a_mitre_are_four_cylinder_patches(pocket_with_floor_fillets, tessellation):
    """The mitres' sharp parts are continued across the smooth ring to the floor, so that each floor fillet is
    a patch on one cylinder of its radius (without the continuation the ring was cut along its length into
    pieces of two fillets each, on no cylinder: a con-rod's STL lost 4 of its 8 fillets)."""
    paths, area = pocket_with_floor_fillets
    geometry = load_surface(paths[tessellation])
    features = detect_features(geometry)
    fillets = [p for p in features.patches if p.cylinder is not None and abs(p.cylinder.radius - POCKET_FILLET) < 0.05]
    assert len(fillets) == 4
    assert all(p.cylinder.concave for p in fillets)
    assert sum(p.area for p in fillets) == pytest.approx(area, rel=0.02)


DRILL_RADIUS, DRILL_DEPTH = 2.5, 15.0


@pytest.fixture(scope="module")
def drilled_blind_hole(tmp_path_factory):
    """A block with a blind drilled hole ending in a 118-degree drill point; its STL as OpenCASCADE
    tessellates it (fine) and as an analysis surface mesh of Gmsh's (curvature-sized, as another mesher
    exports it), whose small triangles round the tip make the cone's map shrink there."""
    import gmsh

    occ = gmsh.model.occ
    out = tmp_path_factory.mktemp("drill")
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    diagonal = float(np.linalg.norm([40, 40, 30]))
    tip = DRILL_RADIUS / np.tan(np.radians(59))
    paths = {}
    try:
        for tessellation in ("occ", "gmsh"):
            gmsh.clear()
            bore = occ.addCylinder(20, 20, 30 - DRILL_DEPTH, 0, 0, DRILL_DEPTH + 1, DRILL_RADIUS)
            point = occ.addCone(20, 20, 30 - DRILL_DEPTH, 0, 0, -tip, DRILL_RADIUS, 0)
            make_parts._cut(occ.addBox(0, 0, 0, 40, 40, 30), make_parts._fuse(bore, point))
            occ.synchronize()
            path = out / f"drill-{tessellation}.stl"
            if tessellation == "occ":
                angle, linear = make_parts.TESSELLATIONS["fine"]
                make_parts._export(path, angle, linear * diagonal)
            else:
                gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 24)
                gmsh.option.setNumber("Mesh.MeshSizeMax", diagonal / 40)
                gmsh.option.setNumber("Mesh.MeshSizeMin", diagonal / 1000)
                gmsh.model.mesh.generate(2)
                gmsh.option.setNumber("Mesh.Binary", 1)
                gmsh.write(str(path))
            make_parts._clean(path)
            paths[tessellation] = path
    finally:
        gmsh.finalize()
    return paths


@pytest.mark.parametrize("tessellation", ["occ", "gmsh"])
def test_a_drill_point_is_one_chart_and_its_rim_one_circle(drilled_blind_hole, tessellation):
    """A cone's conformal map shrinks towards its tip (2.1 times over a drill point's facets), so the whole
    point was refused as a chart and halved, its rim circle cut in two: the bore's bottom edge was then no
    closed curve (no 'junction'). Its tip's 1 % of area aside, it stretches 1.5 times: one chart. Gmsh's
    surface mesh of it fails so; OpenCASCADE's tessellation, a fan of long facets, never did."""
    geometry = load_surface(drilled_blind_hole[tessellation])
    features = detect_features(geometry)
    centres = geometry.mesh.triangles_center
    below = (centres[:, 2] < 30 - DRILL_DEPTH - 1e-6) & (centres[:, 2] > 30 - DRILL_DEPTH - DRILL_RADIUS)
    point = np.flatnonzero(below & (np.hypot(*(centres[:, :2] - 20).T) < DRILL_RADIUS))
    area = np.bincount(features.face_patch[point], weights=geometry.mesh.area_faces[point])
    assert area.max() > 0.99 * area.sum()  # the tip's few facets, creased all round, aside
    rims = [
        c
        for c in features.curves
        if np.allclose(c.points[:, 2], 30 - DRILL_DEPTH, atol=1e-6)
        and np.allclose(np.hypot(*(c.points[:, :2] - 20).T), DRILL_RADIUS, atol=1e-3)
    ]
    assert len(rims) == 1 and rims[0].closed


@pytest.fixture(scope="module")
def tangent_cylinder_parts(tmp_path_factory):
    names = ["filleted_hole_floor", "fillet_block", "torus_ring", "flange"]
    return make_parts.make_parts(tmp_path_factory.mktemp("tangent"), names)


def _cylinders(path):
    features = detect_features(load_surface(path))
    return features, [p for p in features.patches if p.cylinder is not None]


@pytest.mark.parametrize("tessellation", ["coarse", "fine"])
def test_a_hole_wall_running_into_a_rim_fillet_is_a_cylinder_patch(tangent_cylinder_parts, tessellation):
    """filleted_hole_floor: two through holes (r 7, z 0..18) whose rims meet the pocket floor (z 18) through
    tangent fillets (r 3, z 15..18). Each wall is a patch on its own full-turn concave cylinder (a 'hole'),
    all of the wall and nothing of the fillet; before, wall and fillet were one smooth surface cut into
    three charts, none of them a cylinder."""
    features, cylinders = _cylinders(tangent_cylinder_parts["filleted_hole_floor"][tessellation])
    walls = [p for p in cylinders if p.cylinder.full_turn and p.cylinder.concave]
    assert len(walls) == 2
    for patch in walls:
        assert patch.cylinder.radius == pytest.approx(7.0, rel=1e-3)
        assert abs(patch.cylinder.axis[2]) == pytest.approx(1.0, abs=1e-6)
        assert patch.area == pytest.approx(2 * np.pi * 7.0 * 15.0, rel=1e-2)  # the wall, z 0..15
        assert patch.vertices[:, 2].max() == pytest.approx(15.0, abs=1e-6)
    assert sorted(round(float(p.cylinder.point[0])) for p in walls) == [35, 65]


@pytest.mark.parametrize("tessellation", ["coarse", "fine"])
def test_rounds_between_faces_and_a_torus_alone(tangent_cylinder_parts, tessellation):
    """fillet_block: a block with every edge rounded (r 5) and a bore (r 8). Each of the twelve straight
    rounds, tangent to both faces and to the corner blends, is a patch on a quarter cylinder of radius 5;
    the corner blends (spheres) and a torus ring carry no cylinder."""
    features, cylinders = _cylinders(tangent_cylinder_parts["fillet_block"][tessellation])
    rounds = [p for p in cylinders if not p.cylinder.concave]
    assert len(rounds) == 12
    for patch in rounds:
        assert patch.cylinder.radius == pytest.approx(5.0, rel=1e-3)
        assert patch.cylinder.sweep == pytest.approx(90.0, abs=3.0)
    bore = [p for p in cylinders if p.cylinder.concave]
    assert len(bore) == 1 and bore[0].cylinder.radius == pytest.approx(8.0, rel=1e-3)
    assert _cylinders(tangent_cylinder_parts["torus_ring"][tessellation])[1] == []


@pytest.mark.parametrize("tessellation", ["coarse", "fine"])
def test_blends_round_an_axis_are_tori_and_a_concave_one_is_a_fillet(tangent_cylinder_parts, tessellation):
    """The flange's hub (r 30) meets its disc through a fillet r 4: a concave torus (circle 34, tube 4), a
    'fillet' of radius 4 as a CAD torus face is; filleted_hole_floor's hole rims are rounds (r 3 round holes
    of r 7): convex tori of circle 10, no kind."""
    features, _ = _cylinders(tangent_cylinder_parts["flange"][tessellation])
    (fillet,) = [p for p in features.patches if p.torus is not None]
    assert fillet.torus.concave and fillet.kinds == ["fillet"] and fillet.circle.radius == pytest.approx(4.0)
    assert (fillet.torus.major, fillet.torus.minor) == pytest.approx((34.0, 4.0), rel=1e-6)
    features, _ = _cylinders(tangent_cylinder_parts["filleted_hole_floor"][tessellation])
    rims = [p for p in features.patches if p.torus is not None]
    assert len(rims) == 2 and all(not p.torus.concave and not p.kinds for p in rims)
    assert [p.torus.major for p in rims] + [p.torus.minor for p in rims] == pytest.approx([10, 10, 3, 3], rel=1e-6)


@pytest.fixture(scope="module")
def elbow(tmp_path_factory):
    """A quarter of a bent tube (circle 40, outside tube 10, bore 6) at both tessellations."""
    import gmsh

    occ = gmsh.model.occ

    def build():
        make_parts._cut(occ.addTorus(0, 0, 0, 40, 10, angle=np.pi / 2), occ.addTorus(0, 0, 0, 40, 6, angle=np.pi / 2))

    return _both_tessellations(tmp_path_factory.mktemp("elbow"), "elbow", build, 80.0)[0]


@pytest.mark.parametrize("tessellation", ["coarse", "fine"])
def test_a_bent_bore_cut_into_charts_is_a_hole(elbow, tessellation):
    """The bore's wall turns all the way round its tube; the charts it is cut into turn less than half way
    each. The kind goes by the turn of all the patches on the one torus, as for a CAD torus face: 'hole', not
    'fillet' (each chart alone was a 'fillet'); the outside, convex, has no kind."""
    features, _ = _cylinders(elbow[tessellation])
    bore = [p for p in features.patches if p.torus is not None and p.torus.concave]
    outside = [p for p in features.patches if p.torus is not None and not p.torus.concave]
    assert len(bore) >= 2 and all(p.kinds == ["hole"] and p.torus.minor == pytest.approx(6.0) for p in bore)
    assert outside and all(not p.kinds and p.torus.minor == pytest.approx(10.0) for p in outside)


def test_a_flat_face_of_float32_slivers_is_a_plane(tmp_path):
    """A bracket's gusset (a wedge fused onto a filleted angle) has a flat side faceted by OpenCASCADE into
    long slivers, whose normals, from float32 vertices, stray by 4e-4 rad: the side was no plane (normals
    within 1e-9 required) but a concave 'cylinder' of radius 7.6e5 turning 0.003 deg, so a 'fillet'."""
    import gmsh

    occ = gmsh.model.occ

    def build():
        body = make_parts._fuse(occ.addBox(0, 0, 0, 80, 50, 8), occ.addBox(0, 0, 8, 8, 50, 50))
        occ.synchronize()
        inner = make_parts._curves(lambda b: np.allclose(b[[0, 3, 2, 5]], 8.0))
        body = make_parts._fuse(make_parts._fillet(body, inner, 4), occ.addWedge(8, 21, 8, 40, 8, 40))
        make_parts._cut(body, occ.addCylinder(55, 25, -1, 0, 0, 10, 6), occ.addCylinder(-1, 25, 35, 10, 0, 0, 5))

    paths, _ = _both_tessellations(tmp_path, "bracket", build, 110.7)
    geometry = load_surface(paths["fine"])
    features = detect_features(geometry)
    for patch in features.patches:
        if patch.cylinder is not None:
            assert patch.cylinder.radius < geometry.scale, patch.id
            continue
        flat = np.abs((patch.vertices - patch.centroid) @ patch.normal).max() <= 1e-7 * geometry.scale
        assert patch.planar == flat, patch.id
