"""Several bodies in one surface: each its own group and `body` field; bodies that touch or overlap are
refused with one line naming how many bodies the file holds; a cavity belongs to the body around it."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from conftest import gmsh_model

from engine.errors import GeometryError
from engine.geometry import validate_surface


def boxes(*placed) -> trimesh.Trimesh:
    """Boxes of the given (extents, centre) in one surface, in that order."""
    return trimesh.util.concatenate(
        [
            trimesh.creation.box(extents, trimesh.transformations.translation_matrix(centre))
            for extents, centre in placed
        ]
    )


CUBE = (10, 10, 10)


def test_separate_boxes_are_bodies_in_file_order():
    surface = boxes((CUBE, (0, 30, 0)), (CUBE, (0, 0, 0)), (CUBE, (30, 0, 0)))
    geometry = validate_surface(surface.vertices, surface.faces, "three", allow_multiple_solids=True)
    assert geometry.bodies == 3
    centres = geometry.mesh.triangles_center
    for body, y in enumerate((30, 0, 0)):
        assert np.allclose(centres[geometry.face_body == body, 1].mean(), y)


def test_a_cavity_and_an_island_in_it():
    hollow = boxes((CUBE, (0, 0, 0)), ((6, 6, 6), (0, 0, 0)))
    geometry = validate_surface(hollow.vertices, hollow.faces, "hollow")
    assert geometry.bodies == 1 and geometry.volume == pytest.approx(1000 - 216)
    island = boxes((CUBE, (0, 0, 0)), ((6, 6, 6), (0, 0, 0)), ((2, 2, 2), (0, 0, 0)))
    geometry = validate_surface(island.vertices, island.faces, "island", allow_multiple_solids=True)
    assert geometry.bodies == 2 and np.bincount(geometry.face_body).tolist() == [24, 12]


@pytest.mark.parametrize(
    "second, message",
    [
        ((CUBE, (5, 5, 5)), "the surface holds 2 bodies and bodies 1 and 2 touch or overlap"),  # overlap
        ((CUBE, (10, 10, 10)), "bodies 1 and 2 touch"),  # a shared corner
        ((CUBE, (10, 3, 0)), "bodies 1 and 2 touch"),  # faces in contact
        (((2, 30, 2), (0, 0, 0)), "bodies 1 and 2 touch"),  # bars crossing
        (((4, 4, 4), (3, 0, 0)), "holds 1 body and two shells of body 1"),  # cavity on the wall
    ],
)
def test_touching_or_overlapping_shells_are_refused(second, message):
    first = ((30, 2, 2), (0, 0, 0)) if second[0] == (2, 30, 2) else (CUBE, (0, 0, 0))
    surface = boxes(first, second)
    with pytest.raises(GeometryError, match=message) as error:
        validate_surface(surface.vertices, surface.faces, "two", allow_multiple_solids=True)
    assert "\n" not in str(error.value) and "; " in str(error.value)


def test_one_shell_crossing_itself_is_still_named_so():
    box = trimesh.creation.box(CUBE)
    vertices = box.vertices.copy()
    vertices[np.argmax(vertices.sum(axis=1))] = (0, 0, -8)
    with pytest.raises(GeometryError, match="intersects itself"):
        validate_surface(vertices, box.faces, "dent")


def mesh_job(folder, surface: trimesh.Trimesh, **geometry) -> tuple[int, object]:
    """Write ``surface`` as parts.stl and a job meshing it into folder/out (all formats); run the CLI."""
    import yaml

    from engine.cli import main

    surface.export(folder / "parts.stl")
    job = folder / "job.yaml"
    job.write_text(
        yaml.safe_dump(
            {
                "geometry": {"file": "parts.stl", **geometry},
                "size": 2.5,
                "output": {"formats": ["vtu", "msh", "inp", "med"]},
            }
        )
    )
    return main(["mesh", str(job), "--quiet"]), folder / "out"


def test_two_boxes_mesh_as_two_bodies(tmp_path):
    import gmsh
    import meshio

    code, out = mesh_job(tmp_path, boxes((CUBE, (0, 0, 0)), (CUBE, (20, 0, 0))), allow_multiple_solids=True)
    assert code == 0
    vtu = meshio.read(out / "mesh.vtu")
    tets = vtu.cells_dict["tetra"]
    body = vtu.cell_data["body"][0]
    centroids = vtu.points[tets].mean(axis=1)
    assert set(body.tolist()) == {1, 2} and ((centroids[:, 0] > 10) == (body == 2)).all()
    with gmsh_model("test-bodies-msh"):
        gmsh.merge(str(out / "mesh.msh"))
        groups = {gmsh.model.getPhysicalName(dim, tag): (dim, tag) for dim, tag in gmsh.model.getPhysicalGroups()}
        assert {"solid", "solid-1", "solid-2"} <= set(groups) and groups["solid-2"][0] == 3
        nodes = gmsh.model.mesh.getNodesForPhysicalGroup(*groups["solid-2"])[1].reshape(-1, 3)
        assert (nodes[:, 0] > 14.99).all() and len(nodes) > 8
    inp = meshio.read(out / "mesh.inp")
    for name, number in (("solid_1", 1), ("solid_2", 2)):
        cells = np.concatenate([np.asarray(c, dtype=int) for c in inp.cell_sets[name]])
        assert sorted(cells.tolist()) == np.flatnonzero(body == number).tolist()
    med = meshio.read(out / "mesh.med")
    names = {tag: set(groups) for tag, groups in med.cell_tags.items()}
    families = med.cell_data["cell_tags"][0]
    assert [names[f] for f in families[[0, -1]]] == [{"solid", f"solid-{body[0]}"}, {"solid", f"solid-{body[-1]}"}]


def test_a_box_with_a_cavity_is_one_body(tmp_path):
    import meshio

    code, out = mesh_job(tmp_path, boxes((CUBE, (0, 0, 0)), ((4, 4, 4), (0, 0, 0))))
    assert code == 0
    vtu = meshio.read(out / "mesh.vtu")
    assert set(vtu.cell_data["body"][0].tolist()) == {1}
    assert "solid-1" not in meshio.read(out / "mesh.msh").field_data


def test_overlapping_boxes_exit_2_with_one_line_and_no_files(tmp_path, capsys):
    code, out = mesh_job(
        tmp_path, boxes((CUBE, (0, 0, 0)), (CUBE, (6, 0, 0)), (CUBE, (40, 0, 0))), allow_multiple_solids=True
    )
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    (line,) = err.strip().splitlines()
    assert "the surface holds 3 bodies and bodies 1 and 2 touch or overlap; " in line
