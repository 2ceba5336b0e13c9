"""Hex-dominant meshes (issue 23): the grid packer, recombination into hexahedra, prisms and pyramids, the
gate's checks and the files, through engine.cli.main on small sizes."""

from __future__ import annotations

import meshio
import numpy as np
import pytest
import yaml

from engine.acceptance import mixed_faces
from engine.cli import main
from engine.mesh import signed_volumes
from engine.recombine import CELL_TYPES, cell_qualities, cell_volumes, recombine

HEX_FLOOR = 0.03  # the L-bracket at size 8 puts 5.3 % of its volume in hexahedra (measured; see bench/hexdom.md)


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
    ],
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
    assert hexdom["hex_volume_share"] > HEX_FLOOR
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
