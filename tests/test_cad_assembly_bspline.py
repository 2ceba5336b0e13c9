"""An assembly whose shared faces are B-spline halves of one cylinder (issue 17, the outside test's
``as1_nut_rod_bracket`` from Gmsh's tutorial assembly as1): a rod through a thin nut, pressed against a plate
the rod also passes through. Every face is a B-spline (``occ.convertToNURBS``) and each cylinder two halves.

The nut's hole (1 long, radius 5) is one patch of the two halves it is written as; its facets fit no cylinder
(their normals lean off the axis: the circle at the plate side is cut by the plate's hole into quarters, the
other into halves), and it was cut into three charts, each keyed by the same CAD faces: the rod took the
nut's triangles of one chart for all three ("the interface [2, 7] lost its prescribed triangles", exit 4).
The nut's face against the plate lies inside the plate's coplanar face: the nut's corners there are points of
a curve of the plate, not corners of it ("an interface node ... is on no curve or corner of the next body").
Built plate first, the plate meshes the nut's face first: its rim, one closed curve of four CAD edges, is four
curves of the nut, and each rim node must go onto the side it lies on, with a node on each of the nut's corners.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import gmsh
import meshio
import numpy as np
import pymeshlab
import pytest
from conftest import gmsh_model

from engine.cad import load_cad
from engine.cli import main
from engine.geometry import validate_surface
from engine.meshing.improve import min_dihedrals

occ = gmsh.model.occ
FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


def _rod(x0: float, length: float, start: float = 0.0) -> int:
    """A rod of radius 5 along x from ``x0``, its wall two half-cylinder faces (split at ``start``)."""
    arcs = [occ.addCircle(x0, 0, 0, 5, angle1=a, angle2=a + math.pi, zAxis=[1, 0, 0]) for a in (start, start + math.pi)]
    disc = occ.addPlaneSurface([occ.addCurveLoop(arcs)])
    return [t for d, t in occ.extrude([(2, disc)], length, 0, 0) if d == 3][0]


def _plate() -> list:
    """A 10 thick plate against the nut, its hole's halves split at right angles to the rod's."""
    return occ.cut([(3, occ.addBox(1, -15, -15, 10, 30, 30))], [(3, _rod(0, 12, math.pi / 2))])[0]


@pytest.fixture(scope="module", params=["rod first", "plate first"])
def nut_rod_plate(tmp_path_factory, request):
    """(STEP path, CAD volumes of its solids in file order): the rod, nut and plate, or the plate, rod and nut
    (the bodies mesh in file order: the plate then meshes the nut's face first, its rim one closed curve of
    four CAD edges, four curves of the nut with the nut's corners on it)."""
    path = tmp_path_factory.mktemp("cad-assembly-bspline") / "nut_rod_plate.step"
    with gmsh_model("test-cad-assembly-bspline"):
        plate_first = request.param == "plate first"
        plate = _plate() if plate_first else None
        rod = _rod(-20, 60)
        nut = occ.cut([(3, occ.addBox(0, -10, -10, 1, 20, 20))], [(3, _rod(-1, 3))])[0]
        if plate_first:
            occ.fragment(plate, [(3, rod)] + nut)
        else:
            occ.fragment([(3, rod)], nut + _plate())
        occ.synchronize()
        occ.convertToNURBS(occ.getEntities(3))
        occ.synchronize()
        assert {gmsh.model.getType(2, face) for _, face in occ.getEntities(2)} == {"BSpline surface"}
        volumes = [occ.getMass(3, tag) for _, tag in occ.getEntities(3)]
        gmsh.write(str(path))
    return path, volumes


def test_a_cylinder_of_bspline_halves_is_one_patch_in_each_body(nut_rod_plate):
    """Each body's patches are distinct sets of CAD faces; the nut's hole, two B-spline halves, is one full-turn
    cylinder of radius 5 in the nut and in the rod."""
    _, features = load_cad(nut_rod_plate[0])
    assembly = features.assembly
    assert len(assembly.bodies) == 3
    for (_, body), keys in zip(assembly.bodies, assembly.patch_faces):
        assert len(set(keys)) == len(keys)
    hole = [
        body.patches[p]
        for (_, body), keys in zip(assembly.bodies, assembly.patch_faces)
        for p, key in enumerate(keys)
        if len(key) == 2 and frozenset(key) <= assembly.shared_faces and body.patches[p].area < 40
    ]
    assert len(hole) == 2  # the nut's side and the rod's
    for patch in hole:
        assert patch.cylinder is not None and patch.cylinder.full_turn
        assert patch.cylinder.radius == pytest.approx(5, rel=1e-6)
        assert patch.area == pytest.approx(2 * math.pi * 5, rel=0.01)


def test_an_assembly_with_bspline_interface_halves_meshes_conformingly(nut_rod_plate, tmp_path):
    """The three bodies mesh (exit 0): each a physical group of its CAD volume (within the gate's 2 %), every
    interface triangle a face of a tet of both bodies it joins, no dihedral angle below 10 degrees."""
    path, volumes = nut_rod_plate
    job = tmp_path / "job.yaml"
    job.write_text(f"geometry: {{file: {path}}}\noutput: {{directory: {tmp_path / 'out'}, formats: [msh]}}\n")
    assert main(["mesh", str(job), "--quiet"]) == 0
    mesh = meshio.read(tmp_path / "out" / "mesh.msh")
    names = {int(tag): name for name, (tag, _) in mesh.field_data.items()}
    groups = {}
    for block, tags in zip(mesh.cells, mesh.cell_data["gmsh:physical"]):
        for tag in np.unique(tags):
            groups[names[int(tag)]] = block.data[tags == tag]
    assert len(np.unique(mesh.points, axis=0)) == len(mesh.points)
    assert min_dihedrals(mesh.points, groups["solid"]).min() >= 10
    bodies = [groups[f"solid-{k}"] for k in (1, 2, 3)]
    for tets, volume in zip(bodies, volumes):
        x = mesh.points[tets]
        v = np.einsum("ij,ij->i", x[:, 1] - x[:, 0], np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0])).sum() / 6
        assert v == pytest.approx(volume, rel=0.02)  # the gate's tolerance: chords of r 5 at the default size
    interfaces = [name for name in groups if name.startswith("interface-")]
    assert len(interfaces) == 3
    for name in interfaces:
        a, b = (int(k) - 1 for k in name.removeprefix("interface-solid-").split("-solid-"))
        triangles = np.sort(groups[name], axis=1)
        assert len(triangles) > 20
        for tets in (bodies[a], bodies[b]):
            faces = {tuple(f) for f in np.sort(tets[:, FACES].reshape(-1, 3), axis=1).tolist()}
            assert all(tuple(t) in faces for t in triangles.tolist())


def _loaded(path) -> list:
    """What load_cad makes of ``path``: the union's vertex and triangle counts and its volume, and each body's."""
    geometry, features = load_cad(path)
    return [
        [len(g.mesh.vertices), len(g.mesh.faces), round(g.volume, 6)]
        for g in [geometry, *(body for body, _ in features.assembly.bodies)]
    ]


def test_the_assembly_loads_alike_after_other_meshes_in_one_process(nut_rod_plate):
    """Issue 17: in a process that had meshed other models first, the file's OpenCASCADE tessellation was refused
    ("the surface intersects itself (2 faces cross other faces)"), the faces were meshed by Gmsh instead and the
    assembly ended in "the interface [2, 7] lost its prescribed triangles"; in a fresh process it meshed. Each mesh
    calls pymeshlab's topological measures once (engine.quality.boundary_report); after a few (four here),
    pymeshlab's self-intersection test tests each pair of faces both ways round for the rest of the process, and
    one way round it takes two coplanar triangles of the rod's end, 1 mm apart, for crossing."""
    fresh = subprocess.run(
        [
            sys.executable,
            "-c",
            f"import json, sys; sys.path.insert(0, {str(__file__.rsplit('/', 1)[0])!r}); "
            f"from test_cad_assembly_bspline import _loaded; print(json.dumps(_loaded({str(nut_rod_plate[0])!r})))",
        ],
        capture_output=True,
        text=True,
    )
    assert fresh.returncode == 0, fresh.stderr[-2000:]
    box = pymeshlab.MeshSet()
    box.add_mesh(pymeshlab.Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]]), FACES))
    for _ in range(4):  # what four meshes of the process leave behind
        box.get_topological_measures()
    assert _loaded(nut_rod_plate[0]) == json.loads(fresh.stdout.splitlines()[-1])


def test_a_bodys_surface_is_valid_whatever_the_order_of_its_faces(nut_rod_plate, caplog):
    """pymeshlab took two coplanar triangles of the rod's end, 1 mm apart, for crossing when it tested the later
    one first: the rod's surface, faces reversed, "intersects itself (2 faces cross other faces)"."""
    _, features = load_cad(nut_rod_plate[0])
    assert "meshed by Gmsh instead" not in caplog.text  # OpenCASCADE's tessellation, with the rod's end
    for body, _ in features.assembly.bodies:
        faces = np.asarray(body.mesh.faces)
        for order in (faces, faces[::-1]):
            assert validate_surface(np.asarray(body.mesh.vertices), order, "body").volume == pytest.approx(body.volume)
