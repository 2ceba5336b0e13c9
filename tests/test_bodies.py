"""Several bodies in one surface: each its own group and `body` field; bodies that touch or overlap are
refused with one line naming how many bodies the file holds; a cavity belongs to the body around it."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from engine.errors import GeometryError
from engine.geometry import validate_surface


def boxes(*placed) -> trimesh.Trimesh:
    """Boxes of the given (extents, centre) in one surface, in that order."""
    return trimesh.util.concatenate([trimesh.creation.box(extents, trimesh.transformations.translation_matrix(centre))
                                     for extents, centre in placed])


CUBE = (10, 10, 10)


def test_separate_boxes_are_bodies_in_file_order():
    surface = boxes((CUBE, (0, 30, 0)), (CUBE, (0, 0, 0)), (CUBE, (30, 0, 0)))
    geometry = validate_surface(surface.vertices, surface.faces, "three", allow_multiple_solids=True)
    assert geometry.bodies == 3
    centres = geometry.mesh.triangles_center
    for body, y in enumerate((30, 0, 0)):
        assert np.allclose(centres[geometry.face_body == body, 1].mean(), y)


def test_a_cavity_and_an_island_in_it():
    hollow = boxes((CUBE, (0, 0, 0)), ((6, 6, 6), (0, 0, 0)))
    geometry = validate_surface(hollow.vertices, hollow.faces, "hollow")
    assert geometry.bodies == 1 and geometry.volume == pytest.approx(1000 - 216)
    island = boxes((CUBE, (0, 0, 0)), ((6, 6, 6), (0, 0, 0)), ((2, 2, 2), (0, 0, 0)))
    geometry = validate_surface(island.vertices, island.faces, "island", allow_multiple_solids=True)
    assert geometry.bodies == 2 and np.bincount(geometry.face_body).tolist() == [24, 12]


@pytest.mark.parametrize("second, message", [
    ((CUBE, (5, 5, 5)), "the surface holds 2 bodies and bodies 1 and 2 touch or overlap"),    # overlap
    ((CUBE, (10, 10, 10)), "bodies 1 and 2 touch"),                                              # a shared corner
    ((CUBE, (10, 3, 0)), "bodies 1 and 2 touch"),                                                # faces in contact
    (((2, 30, 2), (0, 0, 0)), "bodies 1 and 2 touch"),                                           # bars crossing
    (((4, 4, 4), (3, 0, 0)), "holds 1 body and two shells of body 1"),                           # cavity on the wall
])
def test_touching_or_overlapping_shells_are_refused(second, message):
    first = ((30, 2, 2), (0, 0, 0)) if second[0] == (2, 30, 2) else (CUBE, (0, 0, 0))
    surface = boxes(first, second)
    with pytest.raises(GeometryError, match=message) as error:
        validate_surface(surface.vertices, surface.faces, "two", allow_multiple_solids=True)
    assert "\n" not in str(error.value) and "; " in str(error.value)


def test_one_shell_crossing_itself_is_still_named_so():
    box = trimesh.creation.box(CUBE)
    vertices = box.vertices.copy()
    vertices[np.argmax(vertices.sum(axis=1))] = (0, 0, -8)
    with pytest.raises(GeometryError, match="intersects itself"):
        validate_surface(vertices, box.faces, "dent")
