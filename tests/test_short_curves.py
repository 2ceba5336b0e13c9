"""Curves far shorter than the element size are no mesh edges: their end corners share one node.

A CAD model's sliver edges (0.004 mm where a gear tooth's flank, tip land and 0.25 mm chamfer meet, at h 0.4)
made mesh edges h / 100 long and every tetrahedron on them flat: an outside test's gear was refused on all five
of its jobs (0.32-0.42 deg). Here a box's corner is cut off by a triangle 0.028 mm across (h 0.43): before,
flat tetrahedra and exit 4 (2.2 deg with a 0.057 mm triangle); now its three corners are one node and the
mesh is as good as the box's.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from conftest import gmsh_model

from engine.features import detect_features
from engine.geometry import load_surface
from engine.job import load_job
from engine.packing import CORNER
from engine.packing.start import SHORT_CURVE, short_curve_groups
from engine.pipeline import prepare, run

CUT = 0.02  # how far the cut reaches along each edge from the corner, mm (the triangle's sides: CUT sqrt 2)


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    """A job meshing a 10 mm box whose corner (10, 10, 10) is cut off by the plane x + y + z = 30 - CUT (STL)."""
    import gmsh

    folder = tmp_path_factory.mktemp("short-curves")
    with gmsh_model("test-short-curves", {"Mesh.MeshSizeMax": 2.0}) as occ:
        box = occ.addBox(0, 0, 0, 10, 10, 10)
        cutter = occ.addBox(-30, -30, 0, 60, 60, 30)  # the half-space z > 0, turned to face (1, 1, 1)
        occ.rotate([(3, cutter)], 0, 0, 0, -1, 1, 0, math.acos(1 / math.sqrt(3)))
        shift = (30 - CUT) / 3
        occ.translate([(3, cutter)], shift, shift, shift)
        occ.cut([(3, box)], [(3, cutter)])
        occ.synchronize()
        gmsh.model.mesh.generate(2)
        gmsh.write(str(folder / "box.stl"))
    path = folder / "job.yaml"
    path.write_text(yaml.safe_dump({"geometry": {"file": str(folder / "box.stl")}, "output": {"formats": ["vtu"]}}))
    return load_job(path)


def test_the_cut_corner_is_there(job):
    """The STL has the three short curves, each far below SHORT_CURVE x h (else this tests nothing)."""
    features = detect_features(load_surface(job.geometry_file))
    short = [c for c in features.curves if c.length < 0.1]
    assert len(short) == 3
    assert max(c.length for c in short) == pytest.approx(CUT * math.sqrt(2), rel=0.05)
    assert len(features.corners) == 10


def test_the_short_curves_corners_share_one_node(job):
    _, geometry, features, sizing = prepare(job)
    assert CUT * math.sqrt(2) < SHORT_CURVE * sizing.h_min
    first = short_curve_groups(features, sizing)
    assert len(np.unique(first)) == len(features.corners) - 2  # the triangle's three corners: one node
    result = run(job, write=False)
    corners = result.mesh.node_level == CORNER
    assert corners.sum() == len(features.corners) - 2


def test_the_box_meshes_as_well_as_without_the_cut(job):
    result = run(job, write=False)
    assert result.quality["min_dihedral"]["min"] >= 15.0
    assert result.boundary["hausdorff_mesh_to_input"]["max_over_h"] <= 0.1
    assert result.boundary["hausdorff_input_to_mesh"]["max_over_h"] <= 0.1
    assert abs(result.mesh.volume / result.geometry.volume - 1) < 1e-4
