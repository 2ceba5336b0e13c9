"""Feature kinds that test a curve's dihedral angle (``dihedral_above`` / ``dihedral_below``) and convexity,
whatever the job's ``geometry.feature_angle`` (issue 16, item 6). The broken files are in
tests/broken/features/dihedral-*.yaml."""

from __future__ import annotations

import json

import numpy as np
import pytest

from engine.cli import main
from engine.features import classify, detect_features
from engine.geometry import validate_surface
from engine.knowledge import KnowledgeBase

KINDS = """\
kind: features
doc: curve kinds by dihedral angle
kinds:
  steep-edge:
    of: curve
    when: {dihedral_above: 100}
    doc: faces meeting at more than 100 degrees between their normals
  middle-edge:
    of: curve
    when: {dihedral_above: 100, dihedral_below: 130}
    doc: between 100 and 130 degrees
  right-edge:
    of: curve
    when: {dihedral_above: 80, dihedral_below: 100, convex: true}
    doc: a convex right-angled edge
  smooth-border:
    of: curve
    when: {dihedral_below: 10}
    doc: where two face groups meet smoothly (a tangent fillet)
  concave-edge:
    of: curve
    when: {dihedral_above: 60, convex: false}
    doc: a concave edge steeper than 60 degrees
"""


def _kinds(tmp_path):
    path = tmp_path / "kinds.yaml"
    path.write_text(KINDS)
    return KnowledgeBase().with_file(path).feature_kinds


def _prism():
    """A prism on the right triangle with angles 90, 60 and 30 degrees: its long edges have dihedral angles
    (between the face normals) of 90, 120 and 150 degrees, its end edges 90."""
    a, b, h = 10.0, 10.0 * np.tan(np.radians(60)), 10.0
    section = np.array([[0, 0], [a, 0], [0, b]])
    vertices = np.vstack([np.column_stack([section, np.zeros(3)]), np.column_stack([section, np.full(3, h)])])
    faces = [[0, 2, 1], [3, 4, 5], [0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [2, 0, 3], [2, 3, 5]]
    return validate_surface(vertices, faces, "prism")


def _long_edge(curve, x, y):
    return np.allclose(curve.points[:, :2], [x, y])


@pytest.mark.parametrize("feature_angle", [30.0, 60.0])
def test_dihedral_tests_pick_curves_by_angle_whatever_the_feature_angle(tmp_path, feature_angle):
    features = classify(detect_features(_prism(), feature_angle), _kinds(tmp_path))
    right = next(c for c in features.curves if _long_edge(c, 0, 0))
    middle = next(c for c in features.curves if _long_edge(c, 10, 0))
    steep = next(c for c in features.curves if _long_edge(c, 0, 10 * np.tan(np.radians(60))))
    assert (right.dihedral, middle.dihedral, steep.dihedral) == pytest.approx((90, 120, 150))
    assert [c.id for c in features.curves if "steep-edge" in c.kinds] == sorted([middle.id, steep.id])
    assert [c.id for c in features.curves if "middle-edge" in c.kinds] == [middle.id]
    assert len(features.curves) == 9
    assert {c.id for c in features.curves if "right-edge" in c.kinds} == {
        c.id for c in features.curves if c not in (middle, steep)
    }  # the 6 end edges and the right one
    assert not any("smooth-border" in c.kinds or "concave-edge" in c.kinds for c in features.curves)


def test_dihedral_tests_tell_a_fillets_smooth_borders_from_the_sharp_edges(tmp_path, fresh_features):
    features = classify(fresh_features("l_bracket"), _kinds(tmp_path))
    borders = [c for c in features.curves if "smooth-border" in c.kinds]
    assert len(borders) == 2 and all(not c.sharp for c in borders)
    assert all("right-edge" in c.kinds for c in features.curves if c.sharp and c.convex)


def test_a_given_curve_has_no_dihedral_and_passes_no_angle_test(tmp_path, fresh_features):
    features = classify(fresh_features("cracked_plate"), _kinds(tmp_path))
    (front,) = features.named("crack-front")
    assert front.dihedral is None and front.kinds == []


def test_features_json_gives_each_curves_dihedral_and_convexity(tmp_path, capsys):
    job = tmp_path / "job.yaml"
    job.write_text("geometry: {shape: plate_cylinder_junction}\n")
    (tmp_path / "kinds.yaml").write_text(KINDS)
    assert main(["features", str(job), "--json", "--knowledge", str(tmp_path / "kinds.yaml")]) == 0
    curves = json.loads(capsys.readouterr().out)["curves"]
    (junction,) = [c for c in curves if "junction" in c["names"]]
    assert junction["dihedral"] == pytest.approx(90) and junction["convex"] is False
    assert "concave-edge" in junction["kinds"] and "right-edge" not in junction["kinds"]
