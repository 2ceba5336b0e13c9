"""The real-parts acceptance (issue 14): every corpus part meshes at its default size and with the
static-stress recipe, from both of its tessellations, into a valid mesh that follows its surface.

Checked on the pipeline's own result (no files): every tet of positive volume, a closed two-manifold
boundary, min dihedral >= 10 deg, volume within 0.5 % of the STL's, and the two-sided Hausdorff
distance between the mesh boundary and the input surface within 0.1 h (h the target size there).
The heavy ones run in bench/parts.py.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import igl
import numpy as np
import pytest
import yaml

from engine.job import load_job
from engine.pipeline import run
from engine.quality import tet_quality

_spec = importlib.util.spec_from_file_location("make_parts", Path(__file__).with_name("make_parts.py"))
make_parts = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_parts)

PARTS = sorted(make_parts.PARTS)
# every part at its default size from both tessellations, and with the static-stress recipe from the
# coarse one; the runs of over ~500k tets are benchmarks (bench/parts.py runs every case), not tests
CASES = [(part, tessellation, None) for part in PARTS for tessellation in ("coarse", "fine")] + [
    (part, "coarse", "static-stress") for part in PARTS
]
# and the fillet recipe where two smoothed cuts 0.017 mm apart bound a sliver of fillet (refused before)
CASES += [("drafted_housing", "coarse", "fatigue-fillet")]
HEAVY = {
    ("thin_tube", "coarse", None): "2 elements through its 0.6 mm wall: about 2M tets",
    ("thin_tube", "fine", None): "2 elements through its 0.6 mm wall: about 2M tets",
    ("thin_tube", "coarse", "static-stress"): "2 elements through its 0.6 mm wall: about 2M tets",
    ("hole_pattern_block", "coarse", "static-stress"): "18 holes at radius / 8: about 3.7M tets",
    ("drilled_block", "coarse", "static-stress"): "the hole pattern on its bores: about 1.3M tets",
    ("flange", "coarse", "static-stress"): "the hole pattern on its bolt circle: about 0.5M tets",
}
SAMPLES = 20_000  # points on each surface for the Hausdorff distances
MIN_DIHEDRAL = 10.0
VOLUME = 0.005
HAUSDORFF = 0.1  # x h


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("parts")
    return folder, make_parts.make_parts(folder)


def _cases():
    for case in CASES:
        if case in HEAVY:
            continue
        part, tessellation, recipe = case
        yield pytest.param(*case, id=f"{part}-{tessellation}-{recipe or 'default'}")


def _surface_samples(vertices, triangles, count, rng):
    area = 0.5 * np.linalg.norm(
        np.cross(
            vertices[triangles[:, 1]] - vertices[triangles[:, 0]], vertices[triangles[:, 2]] - vertices[triangles[:, 0]]
        ),
        axis=1,
    )
    pick = rng.choice(len(triangles), size=count, p=area / area.sum())
    weights = rng.dirichlet([1.0, 1.0, 1.0], size=count)
    return np.einsum("ij,ijk->ik", weights, vertices[triangles[pick]])


def _distance(points, vertices, triangles):
    squared, _, _ = igl.point_mesh_squared_distance(
        np.ascontiguousarray(points), np.ascontiguousarray(vertices), np.ascontiguousarray(triangles, dtype=np.int64)
    )
    return np.sqrt(squared)


@pytest.mark.parametrize("part, tessellation, recipe", list(_cases()))
def test_part_meshes_valid_and_close_to_its_surface(corpus, part, tessellation, recipe):
    folder, paths = corpus
    job = {"geometry": {"file": str(paths[part][tessellation])}, "output": {"formats": ["vtu"]}}
    if recipe:
        job["recipe"] = recipe
    (folder / f"{part}-{tessellation}-{recipe}.yaml").write_text(yaml.safe_dump(job))
    result = run(load_job(folder / f"{part}-{tessellation}-{recipe}.yaml"), write=False)
    mesh, geometry = result.mesh, result.geometry

    quality = tet_quality(mesh.points, mesh.tets)
    assert (quality.volume > 0).all(), "every tet of positive volume"
    assert result.boundary["two_manifold"] and result.boundary["boundary_edges"] == 0, "closed two-manifold boundary"
    assert quality.min_dihedral.min() >= MIN_DIHEDRAL, f"min dihedral {quality.min_dihedral.min():.2f} deg"
    assert abs(mesh.volume / geometry.volume - 1) <= VOLUME, (
        f"volume {100 * (mesh.volume / geometry.volume - 1):+.3f} %"
    )

    rng = np.random.default_rng(0)
    on_mesh = _surface_samples(mesh.points, mesh.boundary, SAMPLES, rng)
    on_input = _surface_samples(geometry.vertices, geometry.faces, SAMPLES, rng)
    mesh_to_input = _distance(on_mesh, geometry.vertices, geometry.faces) / result.sizing(on_mesh)
    input_to_mesh = _distance(on_input, mesh.points, mesh.boundary) / result.sizing(on_input)
    assert mesh_to_input.max() <= HAUSDORFF, f"mesh -> input {mesh_to_input.max():.3f} h"
    assert input_to_mesh.max() <= HAUSDORFF, f"input -> mesh {input_to_mesh.max():.3f} h"


@pytest.mark.parametrize("size", [1 / 55, 1 / 60])
def test_an_fe_tools_stl_is_followed_across_its_folds_without_flat_caps(tmp_path, size):
    """The hex nut as an FE tool writes it (Gmsh's own 2-D mesh, its size a 55th and a 60th of the diagonal): its
    chamfers' triangles fold by ~20-40 deg within one smooth patch, and the fold probes put nodes on the folds.
    Each takes the place of the nearest packing node within 0.5 h of it: kept beside it, the 60th's came out at
    13.0 deg (a flat cap of four surface nodes, two of them 0.4 h apart across a fold) and the 55th's 0.11-0.16 h
    from the input; now 19.2 deg and 0.06 h."""
    path = make_parts.gmsh_meshed(tmp_path, "hex_nut", size=size)
    (tmp_path / "job.yaml").write_text(yaml.safe_dump({"geometry": {"file": str(path)}}))
    result = run(load_job(tmp_path / "job.yaml"), write=False)
    mesh, geometry = result.mesh, result.geometry
    quality = tet_quality(mesh.points, mesh.tets)
    assert (quality.volume > 0).all()
    assert quality.min_dihedral.min() >= 17.0, f"min dihedral {quality.min_dihedral.min():.2f} deg"
    on_mesh = _surface_samples(mesh.points, mesh.boundary, SAMPLES, np.random.default_rng(0))
    mesh_to_input = _distance(on_mesh, geometry.vertices, geometry.faces) / result.sizing(on_mesh)
    assert mesh_to_input.max() <= HAUSDORFF, f"mesh -> input {mesh_to_input.max():.3f} h"
