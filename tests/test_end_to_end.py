"""The whole chain through the CLI: files that meshio reads back, valid tetrahedra, the solid's volume."""

import os
import subprocess
import sys

import meshio
import numpy as np
import pytest
import yaml

from engine.cli import main
from engine.shapes import SHAPES


def signed_volumes(points, tets):
    p = points[tets]
    return np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) / 6.0


def check_mesh_file(path, solid_volume, tolerance=0.01):
    mesh = meshio.read(path)
    tets = mesh.cells_dict["tetra"]
    volumes = signed_volumes(mesh.points, tets)
    assert len(tets) > 100
    assert (volumes > 0).all()
    assert volumes.sum() == pytest.approx(solid_volume, rel=tolerance)
    assert np.isin(np.arange(len(mesh.points)), tets).all(), "every node belongs to a tetrahedron"
    return mesh


def write_job(tmp_path, data):
    path = tmp_path / "job.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


SIZES = {
    "cylinder": 5.0,
    "plate": 20.0,
    "plate_with_hole": 6.0,
    "plate_cylinder_junction": 12.0,
    "l_bracket": 6.0,
    "cracked_plate": 12.0,
    "hollow_sphere_octant": 10.0,
}


@pytest.mark.parametrize("kind", sorted(SHAPES))
def test_every_shape_meshes_from_a_job_file(tmp_path, kind, built):
    job = write_job(tmp_path, {"geometry": {"shape": kind}, "size": SIZES[kind], "output": {"directory": "result"}})
    assert main(["mesh", str(job), "--quiet"]) == 0
    shape, _ = built(kind)
    for name in ("mesh.vtu", "mesh.msh"):
        check_mesh_file(tmp_path / "result" / name, shape.geometry.volume)


def test_stl_file_meshes(tmp_path, built):
    shape, _ = built("l_bracket")
    shape.geometry.mesh.export(tmp_path / "bracket.stl")
    job = write_job(tmp_path, {"geometry": {"file": "bracket.stl"}, "size": 6.0, "output": {"formats": ["vtu"]}})
    assert main(["mesh", str(job), "--quiet"]) == 0
    check_mesh_file(tmp_path / "out" / "mesh.vtu", shape.geometry.volume)
    assert not (tmp_path / "out" / "mesh.msh").exists()


def test_default_example_as_in_the_readme(tmp_path, built):
    """`fuzzymesh mesh` with no job: the junction near the plate edge, written to ./out."""
    result = subprocess.run(
        [sys.executable, "-m", "engine.cli", "mesh"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": os.getcwd()},
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    shape, _ = built("plate_cylinder_junction")
    for name in ("mesh.vtu", "mesh.msh"):
        mesh = check_mesh_file(tmp_path / "out" / name, shape.geometry.volume)
    assert set(mesh.point_data) >= {"node_level", "node_entity"}
    assert "tetrahedra" in result.stderr and "packing" in result.stderr


def test_same_seed_same_mesh_other_seed_other_mesh(tmp_path):
    def run(seed, folder):
        job = write_job(
            tmp_path,
            {
                "geometry": {"shape": "l_bracket"},
                "size": 8.0,
                "seed": seed,
                "output": {"directory": folder, "formats": ["vtu"]},
            },
        )
        assert main(["mesh", str(job), "--quiet"]) == 0
        return meshio.read(tmp_path / folder / "mesh.vtu")

    a, b, c = run(7, "a"), run(7, "b"), run(8, "c")
    assert np.array_equal(a.points, b.points)
    assert np.array_equal(a.cells_dict["tetra"], b.cells_dict["tetra"])
    assert len(a.points) != len(c.points) or not np.array_equal(a.points, c.points)


def test_command_line_overrides(tmp_path):
    # a thick plate: the thin-wall rule (2 elements through the thickness) caps neither size
    job = write_job(tmp_path, {"geometry": {"shape": "plate", "parameters": {"thickness": 100}}, "size": 40.0})
    assert main(["mesh", str(job), "--size", "25", "--out", str(tmp_path / "other"), "--quiet"]) == 0
    coarse = meshio.read(tmp_path / "other" / "mesh.vtu")
    assert main(["mesh", str(job), "--quiet"]) == 0
    coarser = meshio.read(tmp_path / "out" / "mesh.vtu")
    assert len(coarse.points) > len(coarser.points)


def test_unwritable_output_is_one_line_and_leaves_nothing(tmp_path, capsys):
    (tmp_path / "blocker").write_text("a file where the output folder should be")
    job = write_job(tmp_path, {"geometry": {"shape": "plate"}, "size": 40.0, "output": {"directory": "blocker"}})
    assert main(["mesh", str(job), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fuzzymesh: error:") and "blocker" in err[0]
