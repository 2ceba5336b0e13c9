"""Charts of real parts' smooth surfaces: a patch wrapped round a zero-angle wedge of another (a con-rod's big
end: the arm's side meets the boss through a tangent fillet that ends square on the arm's faces) folds when
flattened, and is cut until no chart's border folds (engine.features.border_folds)."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from engine.features import _chart, border_folds, detect_features
from engine.geometry import load_surface

_spec = importlib.util.spec_from_file_location("make_parts", Path(__file__).with_name("make_parts.py"))
make_parts = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_parts)

BOSS_RADIUS, FILLET_RADIUS, ARM_SIDE = 20.0, 3.0, 8.0  # boss_arm: boss r 20, arm sides y = +-8, fillets r 3
FILLET_AXIS_Y = ARM_SIDE + FILLET_RADIUS  # the fillet at y > 0 is a circle tangent to the boss and the arm side
FILLET_AXIS_X = float(np.sqrt((BOSS_RADIUS + FILLET_RADIUS) ** 2 - FILLET_AXIS_Y**2))


@pytest.fixture(scope="module")
def boss_arm(tmp_path_factory):
    return make_parts.make_parts(tmp_path_factory.mktemp("boss_arm"), ["boss_arm"])["boss_arm"]


def _smooth_surface_through(mesh: trimesh.Trimesh, point) -> np.ndarray:
    """The faces joined to the face nearest ``point`` across edges bent by under 30 degrees."""
    pairs = mesh.face_adjacency[mesh.face_adjacency_angles < np.radians(30)]
    graph = coo_matrix((np.ones(len(pairs)), tuple(pairs.T)), shape=(len(mesh.faces),) * 2)
    labels = connected_components(graph, directed=False)[1]
    seed = int(np.argmin(np.linalg.norm(mesh.triangles_center - point, axis=1)))
    return np.flatnonzero(labels == labels[seed])


@pytest.mark.parametrize("tessellation", ["coarse", "fine"])
def test_the_fold_round_a_tangent_fillets_end_is_found_on_its_two_sides(boss_arm, tessellation):
    mesh = trimesh.load(boss_arm[tessellation], force="mesh")
    surface = _smooth_surface_through(mesh, [0.0, 20.0, 0.0])  # the boss's wall and the fillets tangent to it
    centre = mesh.triangles_center[surface]
    vertices, triangles, uv = _chart(mesh, surface[(centre[:, 0] > 10) & (centre[:, 1] > 0)])  # round one fillet
    first, second = border_folds(vertices, triangles, uv)
    assert len(first) and len(second)
    centres = [vertices[triangles[side]].mean(axis=1) for side in (first, second)]
    on_fillet = [
        np.abs(np.hypot(c[:, 0] - FILLET_AXIS_X, c[:, 1] - FILLET_AXIS_Y) - FILLET_RADIUS) < 0.3 for c in centres
    ]
    on_boss = [np.abs(np.hypot(c[:, 0], c[:, 1]) - BOSS_RADIUS) < 0.3 for c in centres]
    # one side runs along the fillet's end edge, the other along the boss's edge beside it, at one end (z)
    assert {on_fillet[0].mean() > 0.5, on_fillet[1].mean() > 0.5} == {True, False}
    assert on_boss[0].mean() > 0.5 or on_boss[1].mean() > 0.5
    assert np.ptp(np.sign(np.concatenate(centres)[:, 2])) == 0


@pytest.mark.parametrize("tessellation", ["coarse", "fine"])
def test_no_patch_of_the_part_folds_when_flattened(boss_arm, tessellation):
    geometry = load_surface(boss_arm[tessellation])
    features = detect_features(geometry)
    charted = [p for p in features.patches if not p.planar and p.cylinder is None]
    for patch in charted:
        chart = _chart(geometry.mesh, patch.faces)
        assert chart is not None and len(border_folds(*chart)[0]) == 0, patch.id
    assert len(features.patches) < 30  # cut at the folds, not into facets
