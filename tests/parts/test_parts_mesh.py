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
