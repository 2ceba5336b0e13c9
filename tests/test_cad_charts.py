"""A CAD face's surface triangulation in its own parameters (issue 17 item 2): engine/facechart.py ``FaceChart``.

Parts written by Gmsh's OpenCASCADE: a pin whose tip is a full cone (radius 10 to 3: periodic, its scale
varying 3.3x), a quarter elbow (a torus piece periodic round its tube), a disc with a root fillet (a torus piece
periodic round its axis), the corpus's block with a B-spline top, a ball on a neck (a sphere with its pole: polar),
a blind hole's drill point (a cone's apex: not charted) and a ring (a whole torus: periodic both ways, halved).
Checked: each charted face is one patch (not cut into charts; the ring two), periodic ones with their turn; the
chart is faithful (lift(uv(x)) = x on the face) and, for the surfaces of revolution, conformal (a short step on
the face is the chart's step times its scale, the same in every direction); the meshes pass the gate with the
charted faces' triangles within 0.08 h of the CAD faces at their centres (the chart's sizes and deviation test
measured on the face, through its scale).
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import gmsh
import numpy as np
import pytest
from conftest import gmsh_model

from engine.describe import solid_features
from engine.job import job_from_dict
from engine.pipeline import run

_spec = importlib.util.spec_from_file_location("make_parts", Path(__file__).parent / "parts" / "make_parts.py")
make_parts = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_parts)
occ = gmsh.model.occ


def cone_tip_pin():
    shank = occ.addCylinder(0, 0, 0, 0, 0, 30, 10)
    tip = occ.addCone(0, 0, 30, 0, 0, 12, 10, 3)
    occ.fuse([(3, shank)], [(3, tip)])


def elbow():
    occ.addTorus(0, 0, 0, 30, 8, angle=math.pi / 2)


def root_fillet_disc():
    disc = occ.addCylinder(0, 0, 0, 0, 0, 8, 40)
    hub = occ.addCylinder(0, 0, 8, 0, 0, 20, 15)
    (body,), _ = occ.fuse([(3, disc)], [(3, hub)])
    occ.synchronize()
    root = [t for _, t in occ.getEntities(1) if abs(occ.getBoundingBox(1, t)[3] - 15) < 1e-6]
    root = [t for t in root if abs(occ.getBoundingBox(1, t)[2] - 8) < 1e-6]
    occ.fillet([body[1]], root, [4])


def ball_on_neck():
    ball = occ.addSphere(0, 0, 40, 12)
    neck = occ.addCylinder(0, 0, 0, 0, 0, 35, 6)
    occ.fuse([(3, ball)], [(3, neck)])


def drill_point():
    block = occ.addBox(-15, -15, 0, 30, 30, 30)
    bore = occ.addCylinder(0, 0, 10, 0, 0, 21, 5)
    tip = occ.addCone(0, 0, 10 - 5 / math.tan(math.radians(59)), 0, 0, 5 / math.tan(math.radians(59)), 0, 5)
    (tool,), _ = occ.fuse([(3, bore)], [(3, tip)])
    occ.cut([(3, block)], [tool])


def ring():
    occ.addTorus(0, 0, 0, 30, 8)


PARTS = {
    f.__name__: f
    for f in (cone_tip_pin, elbow, root_fillet_disc, make_parts.freeform_top, ball_on_neck, drill_point, ring)
}


@pytest.fixture(scope="module")
def step_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cad-charts")
    out = {}
    for name, build in PARTS.items():
        with gmsh_model(f"test-cad-charts-{name}"):
            build()
            occ.synchronize()
            out[name] = folder / f"{name}.step"
            gmsh.write(str(out[name]))
    return out


def _charted(features, surface: str) -> list:
    return [(p, c) for p, c in zip(features.patches, features.charts) if c is not None and p.surface == surface]


@pytest.mark.parametrize(
    "part, surface, periodic",
    [
        ("cone_tip_pin", "Cone", True),
        ("elbow", "Torus", True),
        ("root_fillet_disc", "Torus", True),
        ("freeform_top", "BSpline surface", False),
    ],
)
def test_a_face_is_triangulated_in_its_own_parameters(step_files, part, surface, periodic):
    _, geometry, features = solid_features(step_files[part])
    assert sorted(len(p.names) for p in features.patches) == [1] * len(features.patches)
    assert len({p.names[0] for p in features.patches}) == len(features.patches)  # no face cut into charts
    [(patch, chart)] = _charted(features, surface)
    assert (chart.turn is not None) == periodic
    rng = np.random.default_rng(0)
    with chart.model.current() as gm:
        low, high = (np.asarray(b, float) for b in gm.getParametrizationBounds(2, chart.tag))
        at = low + (0.2 + 0.6 * rng.random((200, 2))) * (high - low)  # inside the face, steps too
        on = np.reshape(gm.getValue(2, chart.tag, at.ravel()), (-1, 3))
    size = geometry.scale
    uv = chart.uv(on)
    assert np.abs(chart.lift(uv) - on).max() < 1e-7 * size
    if periodic:  # a turn further round is the same point
        assert np.abs(chart.lift(uv + [chart.turn, 0.0]) - on).max() < 1e-7 * size
    step = 1e-3 * size * np.column_stack([np.cos(angle := rng.uniform(0, 2 * np.pi, len(uv))), np.sin(angle)])
    stretch = np.linalg.norm(chart.lift(uv + step) - on, axis=1) / (chart.scale(uv) * np.linalg.norm(step, axis=1))
    tolerance = 0.01 if surface != "BSpline surface" else 0.05  # conformal (0.3-0.5 % measured); a near-uniform
    # spline's arc-length chart nearly so (0.9 %)
    assert np.abs(stretch - 1).max() < tolerance


def test_a_dome_is_charted_polar_with_its_pole_one_point(step_files):
    """The ball's sphere reaches its axis at the top: a polar chart (the stereographic map), conformal up to the
    pole, which is the chart's origin; a drill point's cone reaches its axis at an apex, where no conformal chart
    keeps its scale: refused (its facets' chart, which puts a node at the tip)."""
    _, geometry, features = solid_features(step_files["ball_on_neck"])
    [(patch, chart)] = _charted(features, "Sphere")
    assert chart.polar is not None and chart.turn is None
    assert np.linalg.norm(chart.lift(np.zeros((1, 2))) - [0, 0, 52]) < 1e-9 * geometry.scale  # the pole
    rng = np.random.default_rng(1)
    on = 12 * (x := rng.normal(size=(200, 3))) / np.linalg.norm(x, axis=1, keepdims=True) + [0, 0, 40]
    on = on[on[:, 2] > 40]  # the upper half, the pole's side
    uv = chart.uv(on)
    assert np.abs(chart.lift(uv) - on).max() < 1e-7 * geometry.scale
    step = 1e-3 * geometry.scale * np.column_stack([np.cos(a := rng.uniform(0, 2 * np.pi, len(uv))), np.sin(a)])
    stretch = np.linalg.norm(chart.lift(uv + step / chart.scale(uv)[:, None]) - on, axis=1) / np.linalg.norm(
        step, axis=1
    )
    assert np.abs(stretch - 1).max() < 0.01
    _, _, drilled = solid_features(step_files["drill_point"])
    assert [p.surface for p, c in zip(drilled.patches, drilled.charts) if c is not None] == []


def test_a_whole_torus_is_halved_and_each_half_charted_round_its_tube(step_files):
    """The ring's one face is periodic both ways and has no border: it is halved across its first parameter
    (the cut, a curve of no CAD edge), and each half, which goes round the tube only, is charted with the tube's
    turn, its other parameter unwrapped round the half's middle."""
    _, geometry, features = solid_features(step_files["ring"])
    assert [p.names for p in features.patches] == [["face-1"], ["face-1"]]
    assert all(c is not None and c.turn is not None for c in features.charts)
    for patch, chart in zip(features.patches, features.charts):
        on = geometry.vertices[np.unique(geometry.faces[patch.faces])]
        assert np.abs(chart.lift(chart.uv(on)) - on).max() < 1e-3 * geometry.scale  # facets' chords: 2e-4


@pytest.mark.parametrize("part", ["cone_tip_pin", "elbow", "root_fillet_disc", "freeform_top", "ball_on_neck", "ring"])
def test_charted_faces_mesh_onto_the_cad(step_files, tmp_path, part):
    job = job_from_dict(
        {"geometry": {"file": str(step_files[part])}, "output": {"directory": str(tmp_path), "formats": ["vtu"]}}
    )
    result = run(job, write=False)
    mesh, features = result.mesh, result.features
    assert result.quality["min_dihedral"]["min"] > 15
    for p, chart in enumerate(features.charts):
        if chart is None:
            continue
        triangles = mesh.boundary[mesh.boundary_patch == p]
        centres = mesh.points[triangles].mean(axis=1)
        chord = np.linalg.norm(features.exact[0][p].project(centres) - centres, axis=1) / result.sizing(centres)
        assert chord.max() < 0.08  # the chart's deviation test: 0.06 h at a circumcentre (0.012-0.056 measured)
