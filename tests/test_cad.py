"""CAD input (issue 17): STEP files written by Gmsh's OpenCASCADE here, read back through engine/cad.py.

Parts: a box with two holes, the corpus's filleted bracket and lofted handle (tests/parts/make_parts.py), the
plate-cylinder junction, a hole whose wall is two faces, two boxes apart, and two assemblies of touching solids
(two boxes sharing a face, a cylinder standing on a plate). Checked: each
CAD face a patch named face-N with its type, holes and fillets with the CAD's radii, the junction's concave
circle, exact surfaces (mesh nodes and 10-node mid-nodes on the CAD faces), the volume against the CAD's, the
pipeline's gate and files, the assemblies through the CLI (each body and the interface a group of the .msh
and .inp, the body volumes, the interface conforming at order 1 and 2, the gate's body volume and interface
checks), and the STEP part against its STL export.
"""

from __future__ import annotations

import importlib.util
import math
import shutil
from pathlib import Path

import gmsh
import meshio
import numpy as np
import pytest
from conftest import gmsh_model

from engine.acceptance import interface_sides
from engine.cad import load_cad
from engine.cli import main
from engine.describe import solid_features
from engine.errors import GeometryError
from engine.fe import TET10_EDGES, quadratic, row_index, side_cells, tet_boundary
from engine.job import job_from_dict
from engine.mesh import FACES, signed_volumes
from engine.meshing.improve import min_dihedrals
from engine.pipeline import run

_spec = importlib.util.spec_from_file_location("make_parts", Path(__file__).parent / "parts" / "make_parts.py")
make_parts = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_parts)
occ = gmsh.model.occ


def box_with_holes():
    """A 100 x 60 x 20 box with through holes of radius 6 and 4."""
    return make_parts._cut(
        occ.addBox(0, 0, 0, 100, 60, 20),
        occ.addCylinder(30, 30, -1, 0, 0, 22, 6),
        occ.addCylinder(70, 30, -1, 0, 0, 22, 4),
    )


def junction():
    """The plate-cylinder junction: a 200 x 200 x 20 plate, a cylinder of radius 25 standing on it 60 off centre."""
    return make_parts._fuse(occ.addBox(-100, -100, 0, 200, 200, 20), occ.addCylinder(60, 0, 10, 0, 0, 110, 25))


def two_boxes():
    """Two boxes sharing the face x = 40 (an assembly of two solids)."""
    occ.addBox(0, 0, 0, 40, 30, 20)
    occ.addBox(40, 0, 0, 30, 30, 20)


def cylinder_on_plate():
    """A cylinder of radius 10 standing on a 60 x 60 x 8 plate (an assembly of two solids touching on a disc)."""
    occ.addBox(-30, -30, 0, 60, 60, 8)
    occ.addCylinder(5, 0, 8, 0, 0, 20, 10)


def pin_in_plate():
    """A pin of radius 3 filling a through hole of a 60 x 40 x 10 plate, flush with both faces: its whole
    curved face is the interface, the union a box with no curved face."""
    make_parts._cut(occ.addBox(0, 0, 0, 60, 40, 10), occ.addCylinder(30, 20, 0, 0, 0, 10, 3))
    occ.addCylinder(30, 20, 0, 0, 0, 10, 3)


def split_hole():
    """A 60 x 40 x 10 plate with a hole of radius 6 whose wall is two half-cylinder faces (as exporters split
    periodic faces)."""
    halves = [occ.addCylinder(30, 20, -1, 0, 0, 12, 6, angle=math.pi) for _ in range(2)]
    occ.rotate([(3, halves[1])], 30, 20, 0, 0, 0, 1, math.pi)
    return make_parts._cut(occ.addBox(0, 0, 0, 60, 40, 10), *halves)


def faces_only():
    """The faces of a 10 x 20 x 30 box with a hole of radius 3, without the solid."""
    make_parts._cut(occ.addBox(0, 0, 0, 10, 20, 30), occ.addCylinder(5, 5, -1, 0, 0, 32, 3))
    occ.remove(occ.getEntities(3))


def sliver_step():
    """Two 10 mm boxes side by side, the second 1e-6 taller: their top faces meet through a face 1e-6 wide
    (as exporters leave between two faces that should have been one)."""
    occ.fuse([(3, occ.addBox(0, 0, 0, 10, 10, 10))], [(3, occ.addBox(10, 0, 0, 10, 10, 10 + 1e-6))])


def apart():
    """Two boxes 10 apart, one with a hole."""
    occ.addBox(0, 0, 0, 40, 30, 20)
    make_parts._cut(occ.addBox(50, 0, 0, 30, 30, 20), occ.addCylinder(65, 15, -1, 0, 0, 22, 5))


PARTS = {
    "box_with_holes": box_with_holes,
    "bracket": make_parts.bracket,
    "junction": junction,
    "two_boxes": two_boxes,
    "cylinder_on_plate": cylinder_on_plate,
    "pin_in_plate": pin_in_plate,
    "apart": apart,
    "sliver_step": sliver_step,
    "split_hole": split_hole,
    "faces_only": faces_only,
    "lofted_handle": make_parts.lofted_handle,
}


@pytest.fixture(scope="module")
def step_files(tmp_path_factory):
    """{part: (STEP path, CAD volume)}, written by Gmsh's OpenCASCADE."""
    folder = tmp_path_factory.mktemp("cad")
    out = {}
    for name, build in PARTS.items():
        with gmsh_model(f"test-cad-{name}"):
            build()
            occ.synchronize()
            path = folder / f"{name}.step"
            gmsh.write(str(path))  # OpenCASCADE's STEP writer prints its statistics
            out[name] = (path, sum(occ.getMass(3, tag) for _, tag in occ.getEntities(3)) or None)
            if name == "box_with_holes":
                for suffix in ("brep", "igs"):
                    gmsh.write(str(path.with_suffix(f".{suffix}")))
                    out[f"{name}.{suffix}"] = (path.with_suffix(f".{suffix}"), out[name][1])
    return out


def test_faces_are_named_patches_with_kinds_from_their_types(step_files):
    _, geometry, features = solid_features(step_files["box_with_holes"][0])
    assert sorted(p.surface for p in features.patches) == ["Cylinder"] * 2 + ["Plane"] * 6
    assert all(len(p.names) == 1 and p.names[0].startswith("face-") for p in features.patches)
    holes = sorted(p.cylinder.radius for p in features.patches if "hole" in p.kinds)
    assert holes == [4.0, 6.0]  # the CAD's radii, not a fit
    assert all(c.names and c.names[0].startswith("edge-") for c in features.curves)
    assert geometry.volume == pytest.approx(step_files["box_with_holes"][1], rel=2e-3)

    _, _, bracket = solid_features(step_files["bracket"][0])
    fillets = [p for p in bracket.patches if "fillet" in p.kinds]
    assert [p.cylinder.radius for p in fillets] == [8.0]
    assert sorted(p.cylinder.radius for p in bracket.patches if "hole" in p.kinds) == [4.0] * 4


def test_a_hole_split_into_two_faces_is_one_hole(step_files):
    _, _, features = solid_features(step_files["split_hole"][0])
    (hole,) = [p for p in features.patches if p.surface == "Cylinder"]
    assert len(hole.names) == 2 and hole.kinds == ["hole"] and hole.cylinder.radius == 6.0


def test_junction_is_a_concave_circle(step_files):
    _, _, features = solid_features(step_files["junction"][0])
    junctions = [c for c in features.curves if "junction" in c.kinds]
    assert len(junctions) == 1 and junctions[0].circle.radius == pytest.approx(25, rel=1e-6)


def _job(path: Path, tmp_path: Path, order: int = 1, **keys):
    return job_from_dict(
        {
            "geometry": {"file": str(path)},
            "output": {"directory": str(tmp_path / "out"), "formats": ["vtu", "msh", "inp"], "order": order},
            **keys,
        }
    )


def _off_surface(points: np.ndarray, triangles: np.ndarray, patch: np.ndarray, surfaces: list) -> float:
    """Largest distance of the nodes of ``triangles`` from the exact surface of their triangle's patch."""
    worst = 0.0
    for p in np.unique(patch):
        nodes = np.unique(triangles[patch == p])
        worst = max(worst, float(np.linalg.norm(surfaces[p].project(points[nodes]) - points[nodes], axis=1).max()))
    return worst


def test_step_part_meshes_onto_the_cad(step_files, tmp_path):
    """Default size: the gate passes and files are written; boundary nodes and 10-node mid-nodes lie on the
    CAD faces within 0.01 h; the linear mesh's volume is within 0.5 % of the CAD's (chords of the holes), the
    10-node mesh's within 0.1 % (the sides curved onto the faces)."""
    path, cad_volume = step_files["bracket"]
    result = run(_job(path, tmp_path, order=2, recipe="static-stress"))
    assert {f.suffix for f in result.files} >= {".vtu", ".msh", ".inp"}
    mesh, features, h = result.mesh, result.features, result.sizing.global_size
    surfaces = features.exact[0]
    owner, side, patch = tet_boundary(mesh)
    assert _off_surface(mesh.points, side_cells(mesh.tets, owner, side), patch, surfaces) < 0.01 * h
    points, _, triangles6 = quadratic(mesh, result.geometry, features)
    assert _off_surface(points, triangles6[:, 3:], patch, surfaces) < 0.01 * h
    assert abs(mesh.volume / cad_volume - 1) < 5e-3
    assert result.geometry.exact_volume == pytest.approx(cad_volume, rel=1e-6)
    assert result.quality["quadratic"]["volume"] == pytest.approx(cad_volume, rel=1e-3)
    assert result.quality["min_dihedral"]["min"] > 10


def test_solids_apart_are_bodies_touching_ones_an_assembly(step_files):
    _, geometry, features = solid_features(step_files["apart"][0])
    assert geometry.bodies == 2 and features.assembly is None
    assert geometry.volume == pytest.approx(step_files["apart"][1], rel=2e-3)
    assert [p.cylinder.radius for p in features.patches if "hole" in p.kinds] == [5.0]
    with pytest.raises(GeometryError, match="holds 2 solids.*allow_multiple_solids"):
        load_cad(step_files["apart"][0])
    geometry, features = load_cad(step_files["two_boxes"][0])  # touching: an assembly, no key needed
    assert geometry.bodies == 2 and features.assembly.names == ["solid-1", "solid-2"]
    assert features.assembly.volumes == pytest.approx([40 * 30 * 20, 30 * 30 * 20])
    with pytest.raises(
        GeometryError, match="2 of the file's 2 solids touch .*share 1 faces.*does not mesh an assembly"
    ):
        load_cad(step_files["two_boxes"][0], assembly=False)


def _cli_job(tmp_path: Path, path: Path, order: int = 1, knowledge: str | None = None, **keys) -> Path:
    """A job file in tmp_path meshing ``path`` into tmp_path / out (vtu, msh, inp), with a knowledge folder
    holding ``knowledge`` as sizing.yaml, if given."""
    import yaml

    data = {"geometry": {"file": str(path)}, **keys}
    data["output"] = {"directory": "out", "formats": ["vtu", "msh", "inp", "med"], "order": order}
    if knowledge is not None:
        (tmp_path / "kb").mkdir()
        (tmp_path / "kb" / "sizing.yaml").write_text(knowledge)
        data["knowledge"] = ["kb"]
    job = tmp_path / "job.yaml"
    job.write_text(yaml.safe_dump(data))
    return job


def _groups(mesh) -> dict:
    """{name: cells} of a .msh read by meshio, from its physical tags."""
    names = {int(tag): name for name, (tag, _) in mesh.field_data.items()}
    out = {}
    for block, tags in zip(mesh.cells, mesh.cell_data["gmsh:physical"]):
        for tag in np.unique(tags):
            out[names[int(tag)]] = block.data[tags == tag]
    return out


@pytest.mark.parametrize(
    "part, size, order, volumes",
    [
        ("two_boxes", 3.0, 2, [40 * 30 * 20, 30 * 30 * 20]),
        ("cylinder_on_plate", 1.7, 1, [60 * 60 * 8, math.pi * 100 * 20]),
    ],
)
def test_an_assembly_meshes_through_the_cli(step_files, tmp_path, part, size, order, volumes):
    """Touching solids of a STEP file, no job key: OpenCASCADE's fragment, each solid meshed with the union's
    sizing, the shared face triangulated once. The .msh holds each body as a group whose volume is its CAD
    solid's, the interface as a group of triangles (triangle6 at order 2) that are faces of tets of both bodies
    (mid-edge nodes included), no duplicate nodes; the .inp each body's element set and the interface surface; the
    .med the interface as a face group;
    the VTU the body field; the report is written."""
    job = _cli_job(tmp_path, step_files[part][0], order, size=size)
    assert main(["mesh", str(job), "--quiet"]) == 0
    out = tmp_path / "out"
    assert (out / "mesh.report.html").is_file() and (out / "mesh.audit.json").is_file()
    mesh = meshio.read(out / "mesh.msh")
    groups = _groups(mesh)
    assert len(np.unique(mesh.points, axis=0)) == len(mesh.points)  # the interface's nodes merged
    solid, bodies = groups["solid"], [groups["solid-1"], groups["solid-2"]]
    assert solid.shape[1] == (10 if order == 2 else 4)
    assert min_dihedrals(mesh.points, solid[:, :4]).min() >= 10
    for tets, expected in zip(bodies, volumes):
        assert signed_volumes(mesh.points, tets[:, :4]).sum() == pytest.approx(expected, rel=5e-3)
    body = meshio.read(out / "mesh.vtu").cell_data["body"][0]
    assert np.bincount(body).tolist() == [0, len(bodies[0]), len(bodies[1])]
    assert len(bodies[0]) + len(bodies[1]) == len(solid)
    interface = groups["interface-solid-1-solid-2"]
    assert interface.shape == (len(interface), 6 if order == 2 else 3) and len(interface) > 50
    for tets in bodies:  # each interface triangle is a face of a tet of each body, its mid-edge nodes those tets'
        faces = np.sort(tets[:, FACES].reshape(-1, 3), axis=1)
        assert (row_index(faces, np.sort(interface[:, :3], axis=1)) >= 0).all()
        if order == 2:
            edges = np.sort(tets[:, TET10_EDGES].reshape(-1, 2), axis=1)
            ends = np.stack([interface[:, :3], np.roll(interface[:, :3], -1, axis=1)], axis=2).reshape(-1, 2)
            rows = row_index(edges, np.sort(ends, axis=1))
            assert (rows >= 0).all()
            assert np.array_equal(tets[:, 4:].reshape(-1)[rows], interface[:, 3:].ravel())
    inp = meshio.read(out / "mesh.inp")
    assert [len(inp.cell_sets[name][0]) for name in ("solid_1", "solid_2")] == [len(t) for t in bodies]
    assert "*SURFACE, TYPE=ELEMENT, NAME=interface_solid_1_solid_2" in (out / "mesh.inp").read_text()
    med = meshio.read(out / "mesh.med")
    kind = "triangle6" if order == 2 else "triangle"
    named = [f for f, names in med.cell_tags.items() if "interface-solid-1-solid-2" in names]
    in_med = med.cells_dict[kind][np.isin(med.cell_data_dict["cell_tags"][kind], named)]
    assert {tuple(row) for row in in_med.tolist()} == {tuple(row) for row in interface.tolist()}


def test_a_curved_interface_gets_the_curvature_rule(step_files, tmp_path):
    """The curvature rule measures every body's faces, the interfaces too: a pin filling a plate's hole (the
    union a box: no curved face) was meshed at H, 10 elements round it, its volume -5 % and the mesh refused.
    Now 24 per circle (about -1.1 %, the chords); the union's volume budget sees the pin's and the hole's
    chords cancel and raises nothing."""
    path, _ = step_files["pin_in_plate"]
    job = _cli_job(tmp_path, path)
    assert main(["mesh", str(job), "--quiet"]) == 0
    mesh = meshio.read(tmp_path / "out" / "mesh.msh")
    pin = _groups(mesh)["solid-2"]
    volume = signed_volumes(mesh.points, pin[:, :4]).sum()
    assert volume == pytest.approx(math.pi * 9 * 10, rel=0.015)
    assert volume < math.pi * 9 * 10  # the chords, not another body's tets
    assert min_dihedrals(mesh.points, _groups(mesh)["solid"][:, :4]).min() >= 10


def test_an_assembly_body_off_its_cad_volume_is_rejected(step_files, tmp_path, capsys):
    """The gate's body volume: the union within 0.3 % of the CAD's, the cylinder's chords at size 2 without the
    curvature pattern not; one line, exit 4, no files."""
    knowledge = "kind: sizing\nbase_pattern: uniform-domain\nacceptance:\n  volume: 0.003\n"
    job = _cli_job(tmp_path, step_files["cylinder_on_plate"][0], knowledge=knowledge, size=2.0)
    assert main(["mesh", str(job), "--quiet"]) == 4
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line.startswith("fuzzymesh: error: mesh rejected (body volume): the body 'solid-2' has -")
    assert not (tmp_path / "out").exists()


def test_the_gate_counts_the_tets_on_each_interface_triangle():
    """Two tets sharing a face: of different bodies, of one body, and apart (the interface's nodes not merged)."""
    tets = np.array([[0, 1, 2, 3], [0, 2, 1, 4]])
    count, different = interface_sides(tets, np.array([0, 1]), np.array([[0, 1, 2]]))
    assert count.tolist() == [2] and different.tolist() == [True]
    assert interface_sides(tets, np.array([1, 1]), np.array([[2, 1, 0]]))[1].tolist() == [False]
    apart = np.array([[0, 1, 2, 3], [5, 7, 6, 4]])
    assert interface_sides(apart, np.array([0, 1]), np.array([[0, 1, 2]]))[0].tolist() == [1]


def test_long_coplanar_slivers_are_opencascade_s_tessellation(step_files, caplog):
    """The lofted handle's elliptic end cap, BRepMesh's long slivers across a plane: pymeshlab took 12 of them for
    crossing each other (CGAL's exact test: none cross) and the faces were meshed by Gmsh instead. Its chords
    (sagitta up to 1e-3 of the model's size) hold 0.30 % less than the CAD's volume (Gmsh's finer mesh: 0.16 %)."""
    _, geometry, features = solid_features(step_files["lofted_handle"][0])
    assert "meshed by Gmsh instead" not in caplog.text
    assert geometry.volume == pytest.approx(step_files["lofted_handle"][1], rel=4e-3)
    assert {p.surface for p in features.patches} == {"BSpline surface", "Plane", "Cylinder"}


def test_a_face_opencascade_tessellates_badly_is_meshed_by_gmsh(step_files, caplog, monkeypatch):
    """Where BRepMesh's tessellation is no valid solid at either turn, Gmsh's 2-D mesher meshes the faces."""
    import engine.cad

    def folded(vertices, triangles, face_tag, angle, source):
        raise GeometryError("a fold (made up)", where=source)

    monkeypatch.setattr(engine.cad, "_refuse_folds", folded)
    _, geometry, features = solid_features(step_files["lofted_handle"][0])
    assert "meshed by Gmsh instead" in caplog.text
    assert geometry.volume == pytest.approx(step_files["lofted_handle"][1], rel=2e-3)
    assert {p.surface for p in features.patches} == {"BSpline surface", "Plane", "Cylinder"}


def test_step_lengths_are_read_in_millimetres(step_files, tmp_path):
    """The box with holes declared in metres instead of millimetres: the job's unit is the millimetre."""
    text = step_files["box_with_holes"][0].read_text()
    assert "SI_UNIT(.MILLI.,.METRE.)" in text
    metres = tmp_path / "box_in_metres.stp"
    metres.write_text(text.replace("SI_UNIT(.MILLI.,.METRE.)", "SI_UNIT($,.METRE.)"))
    _, geometry, features = solid_features(metres)
    assert geometry.bounds[1] == pytest.approx([100e3, 60e3, 20e3])
    assert sorted(p.cylinder.radius for p in features.patches if "hole" in p.kinds) == pytest.approx([4e3, 6e3])


def test_a_file_written_again_at_its_path_is_read_again(step_files, tmp_path):
    """The Gmsh model of a file was kept under its path alone: a file written again at the same path in one
    process (a batch worker, a test's fixture) loaded as the earlier file's model, its faces, tags and volume."""
    path = tmp_path / "part.step"
    shutil.copy(step_files["box_with_holes"][0], path)
    assert load_cad(path)[0].volume == pytest.approx(step_files["box_with_holes"][1], rel=2e-3)
    shutil.copy(step_files["bracket"][0], path)
    assert load_cad(path)[0].volume == pytest.approx(step_files["bracket"][1], rel=2e-3)


def test_a_file_of_faces_is_healed_into_a_solid(step_files):
    _, geometry, features = solid_features(step_files["faces_only"][0])
    assert geometry.volume == pytest.approx(10 * 20 * 30 - math.pi * 3**2 * 30, rel=2e-3)
    assert [p.cylinder.radius for p in features.patches if "hole" in p.kinds] == [3.0]


def test_brep_and_iges(step_files, caplog):
    """BREP as STEP; IGES (faces only, sewn into the solid; its cylinders are surfaces of revolution, no hole is
    recognised). The IGES's tessellation is OpenCASCADE's: pymeshlab took 11 slivers of its planes for crossing
    (CGAL's exact test: none cross) and Gmsh meshed the faces instead."""
    _, geometry, features = solid_features(step_files["box_with_holes.brep"][0])
    assert sorted(p.cylinder.radius for p in features.patches if "hole" in p.kinds) == [4.0, 6.0]
    _, geometry, features = solid_features(step_files["box_with_holes.igs"][0])
    assert geometry.volume == pytest.approx(step_files["box_with_holes"][1], rel=2e-3)
    assert "meshed by Gmsh instead" not in caplog.text


def test_bodies_named_alike_get_numbers_in_file_order():
    """An assembly's STEP file names every instance of a part alike (Gmsh's as1-tu-203: eight 'nut', five
    'bolt'); each body's group and interface names must be its own."""
    from engine.cad import _numbered

    assert _numbered(["nut", "rod", "nut", "plate", "nut"]) == ["nut-1", "rod", "nut-2", "plate", "nut-3"]
    assert _numbered(["solid-1", "solid-2"]) == ["solid-1", "solid-2"]


def test_the_gate_does_not_charge_a_cad_mesh_with_the_tessellation_s_chords(step_files):
    """A CAD part's input surface is OpenCASCADE's tessellation, up to its sagitta (DEFLECTION x the model size)
    off the CAD faces, where the mesh's nodes are: an outside test's collar (a 0.08 mm sliver wall made h 0.07
    there) was refused for a node on the CAD cylinder 0.03 from a facet (0.42 h). A fine cylinder (the mesh on
    the CAD) against a coarse one (the tessellation, 16 sides): far over h, unless the sagitta is allowed for."""
    import trimesh

    from engine.cad import DEFLECTION
    from engine.quality import surface_distances

    geometry, _ = load_cad(step_files["box_with_holes"][0])
    assert geometry.chord == pytest.approx(DEFLECTION * np.linalg.norm(np.ptp(geometry.bounds, axis=0)))
    tessellation = trimesh.creation.cylinder(radius=20.0, height=10.0, sections=16)
    mesh = trimesh.creation.cylinder(radius=20.0, height=10.0, sections=720)
    sagitta = 20.0 * (1 - np.cos(np.pi / 16))
    tiny = lambda x: np.full(len(x), 0.05)  # noqa: E731  elements far smaller than the facets
    plain = surface_distances(mesh.vertices, mesh.faces, tessellation, tiny, 5000)
    assert plain["mesh_to_input"]["max"] == pytest.approx(sagitta, rel=0.01)
    assert plain["mesh_to_input"]["max_over_h"] > 7
    allowed = surface_distances(mesh.vertices, mesh.faces, tessellation, tiny, 5000, chord=sagitta)
    assert allowed["mesh_to_input"]["max_over_h"] < 0.01 and allowed["input_to_mesh"]["max_over_h"] < 0.01


def test_a_face_a_micrometre_wide_is_healed_away(step_files, tmp_path):
    """The model is healed of a face narrower than SLIVER x its size: its two edges, 1e-6 apart, made 1,231 tets
    under 5 deg (the gate refused the mesh); an outside test's bracket had two such faces."""
    path, volume = step_files["sliver_step"]
    _, geometry, features = solid_features(path)
    assert len(features.patches) == 7 and geometry.exact_volume == pytest.approx(volume, rel=1e-6)
    result = run(_job(path, tmp_path, size=2.0))
    assert result.quality["min_dihedral"]["min"] > 15


def test_a_cad_volume_its_tessellation_disagrees_with_is_not_reported_as_exact(step_files, caplog, monkeypatch):
    """OpenCASCADE's volume of a solid is the exact one only where its tessellation agrees, within what its
    chords leave out: a lofted blade's was 1.5 % low (every tessellation and mesh agreed to 0.03 %), and the
    report gave the meshes +1.5 % of 'the exact solid'. Here its volume is made 1 % high: not reported, and
    warned of; the true one is kept."""
    import gmsh

    path, volume = step_files["box_with_holes"]
    _, geometry, _ = solid_features(path)
    assert geometry.exact_volume == pytest.approx(volume, rel=1e-9)
    assert abs(geometry.volume / volume - 1) > 1e-5, "the holes' chords leave some out (else this tests little)"
    mass = gmsh.model.occ.getMass
    monkeypatch.setattr(gmsh.model.occ, "getMass", lambda dim, tag: mass(dim, tag) * (1.01 if dim == 3 else 1))
    _, geometry, _ = solid_features(path)
    assert geometry.exact_volume is None
    assert "not reported as the exact volume" in caplog.text


def test_a_piece_of_a_freeform_face_is_no_cylinder_however_its_facets_fit_one(tmp_path):
    """A CAD face's kinds come from the face: a chart piece of a B-spline face that fits no cylinder as a whole
    keeps no cylinder its few facets fit (a lofted blade's scraps of 0.01 mm2 were 'fillet's of radius 1.7 to
    3.5), while the whole face keeps its facets' cylinder."""
    import trimesh

    from engine.cad import Surface, _face_kinds

    block = trimesh.creation.box([20.0, 20.0, 10.0]).difference(
        trimesh.creation.cylinder(radius=4.0, height=12.0, sections=64), engine="manifold"
    )
    block.export(tmp_path / "block.stl")
    _, geometry, features = solid_features(tmp_path / "block.stl")
    (wall,) = [p for p in features.patches if p.cylinder is not None]
    freeform = Surface("BSpline surface", np.zeros(0), None)
    piece = _face_kinds(wall, freeform, geometry, np.arange(len(geometry.mesh.faces)))
    whole = _face_kinds(wall, freeform, geometry, wall.faces)
    assert piece.cylinder is None and whole.cylinder is wall.cylinder
