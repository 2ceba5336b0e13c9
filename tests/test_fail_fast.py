"""Refusals that depend only on the geometry and the rules come before packing, within seconds (issue 14)."""

from __future__ import annotations

import math
import time

import gmsh
import pytest
import trimesh
import yaml
from conftest import gmsh_model

from engine.curvature import curvature
from engine.errors import LimitError
from engine.features import classify
from engine.job import load_job
from engine.knowledge import load_knowledge
from engine.pipeline import build_geometry, job_placements, run
from engine.sizing import bind
from engine.thickness import local_size

HOLES = 18


@pytest.fixture(scope="module")
def holed_block(tmp_path_factory):
    """A block 200 x 120 x 20 with 18 through holes of radius 3.5, tessellated by OpenCASCADE as a CAD
    system exports STL (5 deg angular, 0.05 mm linear deflection: long thin facets on the hole walls)."""
    path = tmp_path_factory.mktemp("holed") / "block.stl"
    options = {
        "Mesh.Binary": 1,
        "Mesh.StlOneSolidPerSurface": 0,
        "Mesh.StlLinearDeflectionRelative": 0,
        "Mesh.StlLinearDeflection": 0.05,
        "Mesh.StlAngularDeflection": math.radians(5.0),
    }
    with gmsh_model("test-fail-fast-holed-block", options) as occ:
        block = occ.addBox(0, 0, 0, 200, 120, 20)
        holes = [(3, occ.addCylinder(20 + 32 * (i % 6), 25 + 35 * (i // 6), -1, 0, 0, 22, 3.5)) for i in range(HOLES)]
        occ.cut([(3, block)], holes)
        occ.synchronize()
        gmsh.write(str(path))
    surface = trimesh.load(path, force="mesh")
    trimesh.repair.fix_normals(surface)  # Gmsh writes a reversed face's triangles as they are
    surface.export(path)
    return path


def _job(folder, recipe="static-stress"):
    job = folder / "job.yaml"
    job.write_text(
        yaml.safe_dump({"geometry": {"file": "block.stl"}, "recipe": recipe, "output": {"directory": "out"}})
    )
    return load_job(job)


def test_holes_bind_in_well_under_a_second(holed_block):
    job = _job(holed_block.parent)
    kb = load_knowledge(job.knowledge)
    geometry, features = build_geometry(job)
    features = classify(features, kb.feature_kinds)
    local_size(geometry), curvature(geometry, features)  # the always-placed rules' surface
    start = time.perf_counter()  # measures, once per solid (0.5 s)
    placed = bind(kb, job_placements(job, kb), features, geometry, geometry.scale / 40)
    seconds = time.perf_counter() - start
    assert sum(p.pattern == "hole" for p in placed) == HOLES
    assert seconds < 0.5, f"binding {HOLES} holes took {seconds:.2f} s"


def test_too_many_elements_is_refused_before_packing_within_seconds(holed_block):
    # the default size asks for about 2.7M tetrahedra (hole walls at r/8): refused on the estimate alone
    folder = holed_block.parent
    job = _job(folder)
    start = time.perf_counter()
    with pytest.raises(LimitError, match=r"tetrahedra \(limit 1e\+06\)"):
        run(job, max_elements=1e6)
    seconds = time.perf_counter() - start
    assert seconds < 10.0, f"the refusal took {seconds:.1f} s"
    assert sorted(p.name for p in folder.rglob("*")) == ["block.stl", "job.yaml"], "nothing is written"
