"""The narrow-face rule (patterns/narrow-face.yaml, engine/facewidth.py): a face narrower than the elements
around it is measured between the curves that bound it and gets elements at most 'stretch' x its width; curves
that meet (a cusp) are not measured against each other.

Found by an outside test: a gear's 0.25 mm tooth chamfers at H 1.7 were crossed by flat tetrahedra (0.4 deg,
exit 4 on 5 jobs) that no rule saw (thin-wall and narrow-gap measure the solid, not a face).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import gmsh_model

from engine.facewidth import facet_widths
from engine.job import job_from_dict
from engine.pipeline import prepare, run

CHAMFER = 0.3  # legs of the disk's chamfer: a face 0.42 wide
SIZE = 2.0


@pytest.fixture(scope="module")
def disk(tmp_path_factory):
    """A STEP disk r 12, 6 thick, its top edge chamfered 0.3 mm."""
    import gmsh

    path = tmp_path_factory.mktemp("narrow-face") / "disk.step"
    with gmsh_model("test-narrow-face-disk") as occ:
        cylinder = occ.addCylinder(0, 0, 0, 0, 0, 6, 12)
        occ.synchronize()
        top = [tag for _, tag in occ.getEntitiesInBoundingBox(-13, -13, 5.9, 13, 13, 6.1, 1)]
        faces = [gmsh.model.getAdjacencies(1, edge)[0][0] for edge in top]
        occ.chamfer([cylinder], top, faces, [CHAMFER])
        occ.synchronize()
        gmsh.write(str(path))
    return path


@pytest.fixture(scope="module")
def round_into_wall(tmp_path_factory):
    """A STEP block with a channel whose floor edge is rounded r 2, the round dying into the channel walls: each
    wall face has two cusps (its edge and the round's arc leave one corner together)."""
    import gmsh

    path = tmp_path_factory.mktemp("narrow-face") / "round.step"
    with gmsh_model("test-narrow-face-round") as occ:
        block = occ.cut([(3, occ.addBox(0, 0, 0, 60, 40, 20))], [(3, occ.addBox(15, -1, 14, 30, 42, 7))])[0]
        occ.synchronize()
        edges = [
            tag
            for _, tag in occ.getEntitiesInBoundingBox(14, -0.1, 13.9, 46, 0.1, 14.1, 1)
            if abs(occ.getBoundingBox(1, tag)[3] - occ.getBoundingBox(1, tag)[0] - 30) < 1e-6
        ]
        occ.fillet([block[0][1]], edges, [2.0])
        occ.synchronize()
        gmsh.write(str(path))
    return path


@pytest.fixture(scope="module")
def tangent_strips(tmp_path_factory):
    """A STEP block 80 x 30 x 10 whose side y = 0 turns by 0.5 and then 1.5 deg through two faces 0.2 mm wide
    side by side, in one plane (an exporter's strips, as between a 48-tooth gear's flanks and roots), its edge at
    (80, 30) rounded r 0.3 (a face as narrow that turns 90 deg)."""
    import gmsh

    path = tmp_path_factory.mktemp("narrow-face") / "strips.step"
    with gmsh_model("test-narrow-face-strips") as occ:
        rise = 0.2 * math.tan(math.radians(0.5))
        ends = [(0, 0), (39.6, 0), (39.8, rise), (40, 2 * rise), (80, 2 * rise + 40 * math.tan(math.radians(2)))]
        points = [occ.addPoint(x, y, 0) for x, y in ends + [(80, 30), (0, 30)]]
        lines = [occ.addLine(a, b) for a, b in zip(points, points[1:] + points[:1])]
        block = occ.extrude([(2, occ.addPlaneSurface([occ.addCurveLoop(lines)]))], 0, 0, 10)
        occ.synchronize()
        edge = [tag for _, tag in occ.getEntitiesInBoundingBox(79.9, 29.9, -1, 80.1, 30.1, 11, 1)]
        occ.fillet([tag for dim, tag in block if dim == 3], edge, [0.3])
        occ.synchronize()
        gmsh.write(str(path))
    return path


def test_narrow_faces_meeting_a_neighbour_smoothly_are_part_of_its_patch(tangent_strips):
    """Each strip was a patch of its own (then the two one patch: each other's smoothest neighbour), its edges
    curves 0.2 apart, and narrow-face sized for it (on the gear: 733,740 tets against 26,663 from its STL); each
    now joins the wide face beside it; the round, as narrow, stays a patch of its own."""
    _, geometry, features, sizing = prepare(job_from_dict({"geometry": {"file": str(tangent_strips)}}))
    centres = geometry.mesh.triangles_center
    area = geometry.mesh.area_faces
    assert len(features.patches) == 8  # of 10 CAD faces
    for lo, hi in ((39.6, 39.8), (39.8, 40.0)):
        (patch,) = np.unique(features.face_patch[(centres[:, 0] > lo) & (centres[:, 0] < hi) & (centres[:, 1] < 0.01)])
        assert len(features.patches[patch].names) == 2 and area[features.face_patch == patch].sum() > 300
    (round_,) = [p for p in features.patches if p.cylinder is not None and p.cylinder.radius == pytest.approx(0.3)]
    assert len(round_.names) == 1
    assert not any(p.pattern == "narrow-face" and p.length < 0.5 for p in sizing.placed)


def test_the_chamfer_is_a_narrow_face_and_nothing_else_is(disk):
    _, geometry, features, _ = prepare(job_from_dict({"geometry": {"file": str(disk)}, "size": SIZE}))
    width = facet_widths(geometry, features, SIZE)
    centres = geometry.mesh.triangles_center
    on_chamfer = (centres[:, 2] > 6 - CHAMFER - 1e-6) & (np.hypot(centres[:, 0], centres[:, 1]) > 12 - CHAMFER - 1e-6)
    assert on_chamfer.any()
    assert np.isfinite(width[on_chamfer]).mean() > 0.9
    measured = width[on_chamfer & np.isfinite(width)]
    assert measured.min() == pytest.approx(CHAMFER * math.sqrt(2), rel=0.05)
    assert not np.isfinite(width[~on_chamfer]).any()


def test_curves_that_meet_at_a_cusp_are_not_measured_against_each_other(round_into_wall):
    _, geometry, features, _ = prepare(job_from_dict({"geometry": {"file": str(round_into_wall)}, "size": 4.0}))
    width = facet_widths(geometry, features, 4.0)
    assert not (width < 0.9 * 2.0).any()  # a cusp's two curves would measure down to 0 near it


def test_the_chamfered_disk_meshes_with_good_elements_at_little_cost(disk):
    """At H 2 the 0.42 mm chamfer was crossed by flat elements (12 deg); now 19.9 deg with 2.7x the elements of
    H alone (at 1 x the width instead of 2: 10x)."""
    result = run(job_from_dict({"geometry": {"file": str(disk)}, "size": SIZE}), write=False)
    assert result.quality["min_dihedral"]["min"] >= 17.0
    winners = {result.sizing.placed[k].pattern for k in np.unique(result.audit.cells["winner"])}
    assert "narrow-face" in winners
    off = [{"pattern": "uniform-domain"}, {"pattern": "narrow-face", "parameters": {"stretch": 1e6}}]
    alone = run(job_from_dict({"geometry": {"file": str(disk)}, "size": SIZE, "place": off}), write=False)
    assert not any(p.pattern == "narrow-face" for p in alone.sizing.placed)
    assert len(result.mesh.tets) < 4 * len(alone.mesh.tets)
