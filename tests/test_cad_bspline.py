"""CAD faces that are not analytic (issue 17 item 3): exporters write many cylinders, tori and cones as B-spline
faces (or surfaces of revolution, extrusion, offset), whose Gmsh type names no shape. engine/cad.py fits
OpenCASCADE's own points on such a face (no faceting error) to a plane, sphere, cylinder, cone or torus; a
face that fits one gets the kinds and radius of that analytic face.

Parts: STEP files written here by Gmsh's OpenCASCADE with every face converted to a B-spline
(``occ.convertToNURBS``: exact, rational), and a hole lofted through two interpolated circles (a
non-rational B-spline, a few micrometres off its cylinder). Checked: each face's type is a B-spline, the holes,
fillets (a cylinder and a torus) and countersink with the radii of the same part's analytic faces, a hole of
two B-spline halves one hole, the ``fuzzymesh features`` listing, and a part meshed end to end onto its CAD
faces. Also a tee's fillet along a curve that is not a circle (a rolling ball's blend: a fillet of its
radius), and a freeform cap whose tessellation OpenCASCADE folds: it is made again at another angle.
"""

from __future__ import annotations

import importlib.util
import logging
import math
import re
from pathlib import Path

import gmsh
import numpy as np
import pytest
from conftest import gmsh_model

from engine.cad import CadEntity
from engine.cli import main
from engine.describe import solid_features
from engine.exact import Cone, CylinderSurface, Plane, Torus, fit_analytic
from engine.fe import side_cells, tet_boundary
from engine.job import job_from_dict
from engine.pipeline import run

_spec = importlib.util.spec_from_file_location("make_parts", Path(__file__).parent / "parts" / "make_parts.py")
make_parts = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_parts)
occ = gmsh.model.occ


def boss_plate():
    """An 80 x 80 x 10 plate with a boss of radius 12 joined by a concave fillet of radius 3 (a torus), a
    through bore of radius 5, and a hole of radius 4 countersunk by a 45-degree cone."""
    plate = make_parts._fuse(occ.addBox(-40, -40, 0, 80, 80, 10), occ.addCylinder(0, 0, 5, 0, 0, 25, 12))
    occ.synchronize()
    root = make_parts._curves(lambda b: abs(b[2] - 10) < 1e-6 and abs(b[5] - 10) < 1e-6 and b[3] - b[0] < 30)
    plate = make_parts._fillet(plate, root, 3)
    return make_parts._cut(
        plate,
        occ.addCylinder(0, 0, -1, 0, 0, 40, 5),
        occ.addCylinder(25, 25, -1, 0, 0, 12, 4),
        occ.addCone(25, 25, 7, 0, 0, 3.01, 4, 7.01),
    )


def split_hole():
    """A 60 x 40 x 10 plate with a hole of radius 6 whose wall is two half-cylinder faces."""
    halves = [occ.addCylinder(30, 20, -1, 0, 0, 12, 6, angle=math.pi) for _ in range(2)]
    occ.rotate([(3, halves[1])], 30, 20, 0, 0, 0, 1, math.pi)
    return make_parts._cut(occ.addBox(0, 0, 0, 60, 40, 10), *halves)


def spline_hole():
    """A 60 x 40 x 10 plate with a hole of radius 6 lofted through two closed splines, each interpolating 24
    points of the circle: a non-rational B-spline face a few micrometres off the cylinder."""
    wires = []
    for z in (-1, 11):
        points = [occ.addPoint(30 + 6 * math.cos(a), 20 + 6 * math.sin(a), z) for a in np.linspace(0, 2 * np.pi, 25)]
        wires.append(occ.addWire([occ.addSpline(points[:-1] + points[:1])]))
    tool = occ.addThruSections(wires, makeSolid=True, makeRuled=False)
    return make_parts._one(occ.cut([(3, occ.addBox(0, 0, 0, 60, 40, 10))], tool)[0])


def freeform_cap():
    """An 80 x 60 block under a twisted, bulging B-spline top (the block extruded from it and cut by a box),
    its vertical edges rounded with radius 3: the rounds are B-spline faces, and OpenCASCADE's tessellation
    folds the corner where one meets the top."""
    n = 5
    points = [
        occ.addPoint(
            80 * i / (n - 1),
            60 * j / (n - 1),
            30
            + 6 * math.sin(math.pi * i / (n - 1)) * math.sin(math.pi * j / (n - 1))
            + 4 * i / (n - 1)
            - 1.8 * j / (n - 1),
        )
        for j in range(n)
        for i in range(n)
    ]
    top = occ.addBSplineSurface(points, n)
    extruded = [t for d, t in occ.extrude([(2, top)], 0, 0, -40) if d == 3][0]
    block = make_parts._one(occ.intersect([(3, extruded)], [(3, occ.addBox(0, 0, 0, 80, 60, 60))])[0])
    occ.synchronize()
    return make_parts._fillet(block, make_parts._curves(lambda b: b[3] - b[0] < 1e-6 and b[4] - b[1] < 1e-6), 3)


def tee():
    """A solid tee: a bar of radius 25 along x, a branch of radius 20 along z, joined by a fillet of radius 6
    along their intersection curve (not a circle: a rolling ball's blend, two B-spline faces)."""
    tee = make_parts._fuse(occ.addCylinder(-80, 0, 0, 160, 0, 0, 25), occ.addCylinder(0, 0, 0, 0, 0, 80, 20))
    occ.synchronize()
    return make_parts._fillet(tee, make_parts._curves(lambda b: b[2] > 5 and b[5] < 26 and 39 < b[3] - b[0] < 41), 6)


PARTS = {"bracket": make_parts.bracket, "boss_plate": boss_plate, "split_hole": split_hole}


@pytest.fixture(scope="module")
def step_files(tmp_path_factory):
    """{part: (STEP path, CAD volume)}: each part with its faces converted to B-splines (``{part}``) and as
    built (``{part}-analytic``), and the spline hole as built."""
    folder = tmp_path_factory.mktemp("cad-bspline")
    out = {}
    for name, build in [*PARTS.items(), ("spline_hole", spline_hole), ("freeform_cap", freeform_cap), ("tee", tee)]:
        with gmsh_model(f"test-cad-bspline-{name}"):
            tag = build()
            occ.synchronize()
            volume = occ.getMass(3, tag)
            if name in PARTS:
                gmsh.write(str(folder / f"{name}-analytic.step"))
                out[f"{name}-analytic"] = (folder / f"{name}-analytic.step", volume)
                occ.convertToNURBS([(3, tag)])
                occ.synchronize()
            assert {gmsh.model.getType(2, face) for _, face in occ.getEntities(2)} >= {"BSpline surface"}
            gmsh.write(str(folder / f"{name}.step"))
            out[name] = (folder / f"{name}.step", volume)
    return out


def _kinds(features) -> dict:
    """{kind: sorted radii (a cylinder's or a torus's tube, to 1e-9; None for a cone)} of the patches."""
    out = {}
    for p in features.patches:
        radius = p.cylinder.radius if p.cylinder else p.circle.radius if p.circle else None
        for kind in p.kinds:
            out.setdefault(kind, []).append(None if radius is None else round(radius, 9))
    return {k: sorted(v, key=lambda r: r or 0) for k, v in out.items()}


@pytest.mark.parametrize("part", ["bracket", "boss_plate"])
def test_bspline_faces_get_the_kinds_and_radii_of_their_analytic_faces(step_files, part):
    _, _, analytic = solid_features(step_files[f"{part}-analytic"][0])
    _, geometry, features = solid_features(step_files[part][0])
    fitted = {"bracket": {"Plane", "Cylinder"}, "boss_plate": {"Plane", "Cylinder", "Torus", "Cone"}}[part]
    assert {p.surface for p in features.patches} == {f"BSpline surface on {shape}" for shape in fitted}
    kinds = _kinds(features)
    assert kinds == _kinds(analytic)
    expected = {
        "bracket": {"fillet": [8.0], "hole": [4.0] * 4},
        "boss_plate": {"fillet": [3.0], "hole": [4.0, 5.0], "countersink": [None]},
    }[part]
    assert kinds == expected
    # exact (rational) B-splines: their analytic surfaces are the exact surfaces, as an analytic face's are
    shapes = {type(s) for s in features.exact[0]}
    assert shapes == ({Plane, CylinderSurface} if part == "bracket" else {Plane, CylinderSurface, Torus, Cone})
    assert geometry.volume == pytest.approx(step_files[part][1], rel=2e-3)


def test_a_hole_of_two_bspline_halves_is_one_hole(step_files):
    _, _, features = solid_features(step_files["split_hole"][0])
    (hole,) = [p for p in features.patches if p.cylinder is not None]
    assert len(hole.names) == 2 and hole.kinds == ["hole"]
    assert hole.cylinder.radius == pytest.approx(6.0, rel=1e-9)


def test_a_hole_lofted_through_splines_is_a_hole_on_its_cad_face(step_files):
    """Off its cylinder by more than an STL's vertices would be (EXACT_TOLERANCE): a hole of the fitted radius,
    whose mesh nodes go onto the CAD face itself."""
    _, _, features = solid_features(step_files["spline_hole"][0])
    ((k, hole),) = [(k, p) for k, p in enumerate(features.patches) if p.surface == "BSpline surface on Cylinder"]
    assert hole.kinds == ["hole"] and hole.cylinder.radius == pytest.approx(6.0, rel=1e-4)
    assert isinstance(features.exact[0][k], CadEntity)


def test_a_rolling_ball_blend_is_a_fillet_of_its_radius(step_files):
    """The tee's fillet fits no analytic surface; its smaller principal radius stays within 0.6 % of 6 over
    both faces (OpenCASCADE's approximation of the rolling ball): two fillet patches of radius 6."""
    _, _, features = solid_features(step_files["tee"][0])
    blends = [p for p in features.patches if p.surface == "BSpline surface"]
    assert len(blends) == 2 and all(p.kinds == ["fillet"] for p in blends)
    assert [p.circle.radius for p in blends] == pytest.approx([6, 6], rel=2e-3)
    assert not [p for p in features.patches if p.kinds and p.surface != "BSpline surface"]  # convex bars


def test_fit_analytic_tells_the_shapes_apart():
    """Points and unit normals of a plane, cylinder, cone and torus (its tube radius among those given) are
    fitted to their own shape; a saddle, none of them, to none."""
    u, v = np.random.default_rng(1).uniform(0, 1, (2, 200))
    ring = np.column_stack([np.cos(3 * u), np.sin(3 * u), np.zeros_like(u)])  # 172 degrees round the z axis
    z = np.array([0, 0, 1.0])

    flat = fit_analytic(np.column_stack([u, v, np.zeros_like(u)]), np.tile(z, (200, 1)), 1e-6)
    assert isinstance(flat, Plane)

    cylinder = fit_analytic(5 * ring + np.outer(10 * v, z), ring, 1e-6)
    assert isinstance(cylinder, CylinderSurface) and cylinder.radius == pytest.approx(5)
    band = 5 * ring + np.outer(0.4 * v, z)  # a bolt's washer face: within 0.004 of a sphere as well
    assert isinstance(fit_analytic(band, ring, 0.005), CylinderSurface)

    angle = math.radians(30)
    points = (5 + 10 * v)[:, None] * (math.sin(angle) * ring + math.cos(angle) * z)
    cone = fit_analytic(points, Cone(np.zeros(3), z, angle).normals(points), 1e-6)
    assert isinstance(cone, Cone) and cone.angle == pytest.approx(angle) and cone.apex == pytest.approx(0, abs=1e-9)

    tube = np.cos(2 * v)[:, None] * ring + np.sin(2 * v)[:, None] * z
    points = np.array([1.0, 2, 3]) + 20 * ring + 3 * tube
    torus = fit_analytic(points, tube, 1e-6, tube_radii=[1 / 0.05, 3.0])
    assert isinstance(torus, Torus) and (torus.major, torus.minor) == pytest.approx((20, 3))
    assert fit_analytic(points, tube, 1e-6) is None  # no tube radius given: no torus

    saddle = np.column_stack([u, v, u**2 - v**2])
    normals = np.column_stack([-2 * u, 2 * v, np.ones_like(u)])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    assert fit_analytic(saddle, normals, 1e-4, tube_radii=[0.5, 2.0]) is None


def test_features_lists_the_bspline_holes_and_fillets(step_files, capsys):
    path = step_files["boss_plate"][0]
    assert main(["features", str(path)]) == 0
    rows = [re.split(r"\s{2,}", line.strip()) for line in capsys.readouterr().out.splitlines()[2:]]
    listed = sorted((cells[2], cells[3].split(", r ")[-1]) for cells in rows if cells[0].startswith("patch-"))
    assert [(kind, radius) for kind, radius in listed if kind != "-"] == [
        ("countersink", "BSpline surface on Cone A 146.5"),
        ("fillet", "3"),
        ("hole", "4"),
        ("hole", "5"),
    ]


def test_a_bspline_part_meshes_onto_its_cad_faces(step_files, tmp_path):
    """The B-spline boss plate at size 8 (2 at least): the gate passes, the boundary nodes lie on the CAD faces
    within 0.01 h, the volume is the CAD's within 0.5 %, and the fillet, hole and countersink are found."""
    path, cad_volume = step_files["boss_plate"]
    job = job_from_dict(
        {
            "geometry": {"file": str(path)},
            "size": 8,
            "min_size": 2,
            "output": {"directory": str(tmp_path / "out"), "formats": ["vtu"]},
        }
    )
    result = run(job)
    mesh, features, h = result.mesh, result.features, result.sizing.global_size
    owner, side, patch = tet_boundary(mesh)
    triangles = side_cells(mesh.tets, owner, side)
    worst = 0.0
    for p in np.unique(patch):
        nodes = np.unique(triangles[patch == p])
        moved = features.exact[0][p].project(mesh.points[nodes])
        worst = max(worst, float(np.linalg.norm(moved - mesh.points[nodes], axis=1).max()))
    assert worst < 0.01 * h
    assert abs(mesh.volume / cad_volume - 1) < 5e-3
    assert result.quality["min_dihedral"]["min"] > 10
    assert {kind for p in features.patches for kind in p.kinds} >= {"hole", "fillet", "countersink"}


def test_a_folded_tessellation_is_made_again(step_files, tmp_path, caplog):
    """OpenCASCADE folds the freeform cap's round under its top at 10 degrees per facet (edges inside one face
    turning by up to 79 degrees: four slivers of patches, tets of 1.1 degrees there at this size, the mesh
    rejected); at 15 degrees it does not: each face is one patch, the rounds are cylinders of radius 3 (convex:
    no kind), and the part meshes."""
    caplog.set_level(logging.INFO, logger="engine.cad")
    path, cad_volume = step_files["freeform_cap"]
    _, _, features = solid_features(path)
    assert "edges inside CAD faces turn by more than 30 degrees" in caplog.text and "tessellating again" in caplog.text
    assert "meshed by Gmsh" not in caplog.text
    names = [p.names[0] for p in features.patches]
    assert len(names) == len(set(names)) == 10
    rounds = [p for p in features.patches if p.surface == "BSpline surface on Cylinder" and p.cylinder is not None]
    assert [p.cylinder.radius for p in rounds] == pytest.approx([3] * 4, rel=1e-4)
    assert not any(p.kinds for p in rounds)
    job = job_from_dict(
        {
            "geometry": {"file": str(path)},
            "size": 8,
            "min_size": 2,
            "output": {"directory": str(tmp_path), "formats": ["vtu"]},
        }
    )
    result = run(job)
    assert abs(result.mesh.volume / cad_volume - 1) < 5e-3
    assert result.quality["min_dihedral"]["min"] > 10


def test_closest_points_on_bspline_faces_and_edges_are_gmsh_s_at_a_fraction_of_its_time(step_files):
    """engine.cad.Parametrized (a grid of parameters, then Gauss-Newton on Gmsh's getValue / getDerivative)
    finds points on every B-spline face and edge of the tee as close to points near them as Gmsh's
    getClosestPoint does (4 ms a point on an outside test's swept spring face: minutes for its 80k nodes)."""
    from engine.cad import CadModel

    path = step_files["tee"][0]
    model = CadModel(str(path), "test-closest-points")
    rng = np.random.default_rng(0)
    with model.current() as gm:
        lo, hi = np.reshape(gm.getBoundingBox(-1, -1), (2, 3))
        size = float(np.linalg.norm(hi - lo))
        checked = 0
        for dim in (1, 2):
            for _, tag in gm.getEntities(dim):
                if gm.getType(dim, tag) not in ("BSpline surface", "BSpline"):
                    continue
                low, high = (np.asarray(b, float) for b in gm.getParametrizationBounds(dim, tag))
                on = np.reshape(gm.getValue(dim, tag, rng.uniform(low, high, (40, dim)).ravel()), (-1, 3))
                near = on + 0.005 * size * rng.normal(size=on.shape)
                theirs = np.reshape(gm.getClosestPoint(dim, tag, near.ravel())[0], (-1, 3))
                ours = model.closest(dim, (tag,), near)
                gap = np.linalg.norm(ours - near, axis=1) - np.linalg.norm(theirs - near, axis=1)
                assert gap.max() <= 1e-9 * size, (dim, tag, gap.max())
                checked += 1
    assert checked >= 3


def test_the_tessellation_s_chord_is_how_far_its_facets_stray_from_the_cad_faces(step_files, monkeypatch):
    """geometry.chord, which the gate's Hausdorff check allows a CAD mesh for the tessellation it is measured
    against, is at least what the tessellation is asked for, and what it measures (with no such floor) is at
    least the distance of the longest facets' centroids from the CAD faces by Gmsh's own projection."""
    from engine import cad

    path = step_files["tee"][0]
    _, geometry, features = solid_features(path)
    corners = geometry.mesh.triangles
    longest = np.argsort(-np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1))[:100]
    centres = geometry.mesh.triangles_center[longest]
    with cad.CadModel(str(path), "test-chord").current() as gm:
        distance = np.min(
            [
                np.linalg.norm(np.reshape(gm.getClosestPoint(2, tag, centres.ravel())[0], (-1, 3)) - centres, axis=1)
                for _, tag in gm.getEntities(2)
            ],
            axis=0,
        )
    assert geometry.chord >= cad.DEFLECTION * geometry.scale
    monkeypatch.setattr(cad, "DEFLECTION", 0.0)
    measured, _ = cad._chord(geometry, features)
    assert 0 < float(distance.max()) * (1 - 1e-6) <= measured <= geometry.chord
