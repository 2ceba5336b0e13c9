"""A bore's wall with a cross bore through it: the periodic chart's seam must not cut the cross bore's loop
where the triangulation cannot keep both sides (engine.meshing.surface._triangulate_chart tries other seams).
At sizes 2.66 and 3 the first seam ran through it and the part was refused ('a patch triangulation region
lies on both sides of its boundary'), at its default size 2.19 not."""

import importlib.util
from pathlib import Path

import pytest

from engine.job import job_from_dict
from engine.pipeline import run

_spec = importlib.util.spec_from_file_location("make_parts", Path(__file__).with_name("make_parts.py"))
make_parts = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_parts)


@pytest.fixture(scope="module")
def block(tmp_path_factory):
    return make_parts.make_parts(tmp_path_factory.mktemp("cross_bored"), ["cross_bored_block"])["cross_bored_block"]


@pytest.mark.parametrize("tessellation,size", [("coarse", 2.66), ("fine", 3.0)])
def test_a_cross_bored_block_meshes_whatever_the_seam(block, tessellation, size, tmp_path):
    job = job_from_dict(
        {"geometry": {"file": str(block[tessellation])}, "size": size, "output": {"directory": str(tmp_path)}}
    )
    result = run(job, write=False)  # the acceptance gate runs inside: a refused mesh raises
    assert result.quality["min_dihedral"]["min"] >= 10.0
    assert result.boundary["two_manifold"] and result.boundary["boundary_edges"] == 0
