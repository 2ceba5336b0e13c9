"""Hex-dominant meshes (issue 23): the grid packer, recombination into hexahedra, prisms and pyramids, the
gate's checks and the files, through engine.cli.main on small sizes."""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest
import yaml

from engine.acceptance import mixed_faces
from engine.cli import main
from engine.mesh import signed_volumes
from engine.meshing.hexcore import KUHN_FACES, KUHN_TETS
from engine.recombine import CELL_TYPES, HEX_FACES, cell_qualities, cell_volumes, recombine

# the share of the volume in hexahedra, measured (bench/hexdom.md): L-bracket size 8 87.7 %, junction-edge
# size 12 81.5 %
HEX_FLOOR = {"l_bracket": 0.86, "plate_cylinder_junction": 0.81}


EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
JUNCTION_EDGE = yaml.safe_load((EXAMPLES / "junction-edge.yaml").read_text())["place"]


def _job(tmp_path, geometry, **extra):
    job = {
        "geometry": geometry,
        "output": {"directory": "out", "formats": ["vtu", "msh", "inp"], "elements": "hex-dominant"},
        **extra,
    }
    path = tmp_path / "job.yaml"
    path.write_text(yaml.safe_dump(job))
    return path


def test_grid_cubes_recombine_into_hexahedra():
    grid = np.stack(np.meshgrid(*[np.arange(5.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    from scipy.spatial import Delaunay

    tets = Delaunay(grid, qhull_options="Qbb Qc Qz Q12").simplices
    flip = signed_volumes(grid, tets) < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    tets = tets[np.abs(signed_volumes(grid, tets)) > 1e-12]  # Qhull's flat tets of co-spherical eights
    mixed = recombine(grid, tets)
    assert [len(c) for c in mixed.cells] == [64, 0, 0, 0]
    assert np.allclose(cell_qualities(mixed.points, mixed.cells[0], 0), 1.0)
    assert cell_volumes(mixed.points, mixed.cells[0], 0).sum() == pytest.approx(64.0, rel=1e-12)


@pytest.mark.parametrize(
    "geometry, extra",
    [
        ({"shape": "l_bracket"}, {"size": 8}),
        (
            {"shape": "plate_cylinder_junction", "parameters": {"offset": 60}},
            {"size": 12, "knowledge": [str(EXAMPLES / "knowledge" / "paper-sizing.yaml")], "place": JUNCTION_EDGE},
        ),
    ],
    ids=["l_bracket", "junction_edge"],
)
def test_hex_dominant_through_the_cli(tmp_path, geometry, extra):
    path = _job(tmp_path, geometry, **extra)
    assert main(["mesh", str(path)]) == 0
    vtu = meshio.read(tmp_path / "out" / "mesh.vtu")
    types = {block.type for block in vtu.cells}
    assert types <= set(CELL_TYPES) and "hexahedron" in types and "pyramid" in types
    points = vtu.points
    cells = [np.zeros((0, n), np.int64) for n in (8, 6, 5, 4)]
    for block in vtu.cells:
        cells[CELL_TYPES.index(block.type)] = block.data
    for kind, c in enumerate(cells):
        assert (cell_qualities(points, c, kind) > 0).all()  # every corner Jacobian positive
    for kind in range(3):
        assert (cell_qualities(points, cells[kind], kind) >= 0.2).all()

    class Mixed:
        pass

    mixed = Mixed()
    mixed.cells = cells
    faces, _ = mixed_faces(mixed)
    _, inverse, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    assert counts.max() <= 2  # conforming: every face in one or two cells
    single = faces[counts[inverse.ravel()] == 1]
    quad = single[:, 3] >= 0
    boundary = np.vstack([single[~quad, :3], single[quad][:, [0, 1, 2]], single[quad][:, [0, 2, 3]]])
    edges, edge_counts = np.unique(
        np.sort(boundary[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0, return_counts=True
    )
    assert (edge_counts == 2).all()  # closed
    volumes = [cell_volumes(points, c, k) for k, c in enumerate(cells)]
    total = sum(v.sum() for v in volumes)
    import json

    report = json.loads((tmp_path / "out" / "mesh.report.json").read_text())
    hexdom = report["quality"]["hex_dominant"]
    assert total == pytest.approx(report["volume"]["mesh"], rel=1e-9)
    assert hexdom["hex_volume_share"] == pytest.approx(volumes[0].sum() / total, rel=1e-9)
    assert hexdom["hex_volume_share"] > HEX_FLOOR[geometry["shape"]]
    assert report["mesher"]["hex_core"]["boxes"] > 0  # the hex-core mesher kept the lattice's boxes
    if geometry["shape"] == "plate_cylinder_junction":  # hexahedra from the lattice to the cylinder's wall
        assert report["mesher"]["hex_core"]["wall_boxes"] > 0
    msh = meshio.read(tmp_path / "out" / "mesh.msh")
    assert {"hexahedron", "pyramid", "tetra", "quad", "triangle"} <= {b.type for b in msh.cells}
    inp = (tmp_path / "out" / "mesh.inp").read_text()
    assert "TYPE=C3D8" in inp and "TYPE=C3D5" in inp and "TYPE=C3D4" in inp and "*SURFACE" in inp


def test_hex_dominant_refuses_other_formats(tmp_path):
    path = tmp_path / "job.yaml"
    path.write_text(
        yaml.safe_dump({"geometry": {"shape": "l_bracket"}, "output": {"formats": ["bdf"], "elements": "hex-dominant"}})
    )
    assert main(["mesh", str(path)]) != 0


def test_kuhn_split_matches_the_face_diagonals():
    """The six Kuhn tets fill the box, and split each of its faces along the diagonal from the face's low
    corner, the same on both sides of a face shared by two boxes."""
    corners = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    volumes = signed_volumes(corners, KUHN_TETS)
    assert np.allclose(np.abs(volumes), 1 / 6)
    assert sorted(map(sorted, KUHN_FACES.tolist())) == sorted(map(sorted, HEX_FACES.tolist()))
    faces = np.sort(KUHN_TETS[:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]].reshape(-1, 3), axis=1)
    keys, counts = np.unique(faces, axis=0, return_counts=True)
    outer = {tuple(k) for k in keys[counts == 1].tolist()}
    split = {tuple(sorted(f[[0, 1, 2]])) for f in KUHN_FACES} | {tuple(sorted(f[[0, 2, 3]])) for f in KUHN_FACES}
    assert outer == split
    for face in KUHN_FACES:  # the diagonal 0-2 joins the face's lowest corner to its highest
        p = corners[face]
        assert p[0].sum() == p.sum(axis=1).min() and p[2].sum() == p.sum(axis=1).max()


def test_hex_core_without_a_lattice_is_the_delaunay_mesher():
    from engine.job import job_from_dict
    from engine.meshing import get_mesher
    from engine.packing import get_packer
    from engine.pipeline import prepare

    job = job_from_dict({"geometry": {"shape": "l_bracket"}, "size": 16})
    _, geometry, features, sizing = prepare(job)
    packing = get_packer("lattice")(geometry, features, sizing, seed=0)
    mesh = get_mesher("hex-core")(packing, geometry, features, seed=0)
    assert mesh.stats["hex_core"] == {"boxes": 0, "fallback": "the packing has no grid lattice"}
    assert (mesh.volumes() > 0).all()


def test_a_plate_is_all_hexahedra(tmp_path):
    """The plate's faces lie on the lattice's cell boundaries (the grid packer's plane warp): every box reaches
    the surface, no pyramid or tet is left, and the files hold hexahedra only."""
    path = _job(tmp_path, {"shape": "plate"}, size=10)
    assert main(["mesh", str(path)]) == 0
    vtu = meshio.read(tmp_path / "out" / "mesh.vtu")
    assert [block.type for block in vtu.cells] == ["hexahedron"]
    assert (cell_qualities(vtu.points, vtu.cells[0].data, 0) > 0.99).all()
    assert cell_volumes(vtu.points, vtu.cells[0].data, 0).sum() == pytest.approx(200 * 200 * 20, rel=1e-9)
    inp = (tmp_path / "out" / "mesh.inp").read_text()
    assert "TYPE=C3D8" in inp and "TYPE=C3D4" not in inp
