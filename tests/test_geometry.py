import numpy as np
import pytest
import trimesh

from engine.geometry import load_surface, validate_surface


def test_inside_test_agrees_with_exact_signed_distance(built):
    shape, _ = built("plate_cylinder_junction")
    geometry = shape.geometry
    points = np.random.default_rng(3).uniform(*geometry.bounds, size=(200_000, 3))
    fast = geometry.contains(points)
    exact = geometry.signed_distance(points) > 0
    assert 0.1 < fast.mean() < 0.9
    assert np.array_equal(fast, exact)


def test_inside_test_on_points_hugging_the_surface(built):
    shape, _ = built("cylinder")
    geometry = shape.geometry
    rng = np.random.default_rng(0)
    on_surface, _ = trimesh.sample.sample_surface(geometry.mesh, 20_000, seed=1)
    normals = geometry.mesh.face_normals[geometry.closest_point(on_surface)[2]]
    offset = rng.uniform(1e-6, 1e-3, size=(len(on_surface), 1))
    assert geometry.contains(on_surface - offset * normals).all()
    assert not geometry.contains(on_surface + offset * normals).any()


def test_signed_distance_is_positive_inside_and_exact_for_a_box(built):
    shape, _ = built("plate", length=100, width=60, thickness=10)
    geometry = shape.geometry
    points = np.array([[0, 0, 5], [0, 0, 12], [49, 0, 5], [60, 0, 5]])
    assert np.allclose(geometry.signed_distance(points), [5, -2, 1, -10])


def test_closest_point_lies_on_the_surface(built):
    shape, _ = built("cylinder")
    geometry = shape.geometry
    points = np.random.default_rng(1).uniform(*geometry.bounds, size=(5000, 3))
    closest, distance, face = geometry.closest_point(points)
    assert np.allclose(np.linalg.norm(closest - points, axis=1), distance)
    tri = geometry.mesh.triangles[face]
    normal = geometry.mesh.face_normals[face]
    assert np.abs(np.einsum("ij,ij->i", closest - tri[:, 0], normal)).max() < 1e-9 * geometry.scale


@pytest.mark.parametrize("suffix", [".stl", ".obj", ".ply", ".off", ".glb"])
def test_every_surface_format_loads_as_the_same_solid(tmp_path, suffix, built):
    shape, _ = built("plate_with_hole")
    path = tmp_path / f"part{suffix}"
    shape.geometry.mesh.export(path)
    geometry = load_surface(path)
    assert geometry.volume == pytest.approx(shape.geometry.volume, rel=1e-6)
    assert len(geometry.faces) == len(shape.geometry.faces)


def test_cavity_counts_as_one_solid_and_keeps_inward_orientation():
    outer = trimesh.creation.box((10, 10, 10))
    inner = trimesh.creation.box((4, 4, 4))
    inner.invert()
    both = trimesh.util.concatenate([outer, inner])
    geometry = validate_surface(both.vertices, both.faces, "hollow box")
    assert geometry.volume == pytest.approx(1000 - 64)
    assert not geometry.contains(np.array([[0.0, 0, 0]]))[0]
    assert geometry.contains(np.array([[4.0, 0, 0]]))[0]
    # a cavity given with outward faces is turned inward, and said so
    inner.invert()
    wrong = trimesh.util.concatenate([outer, inner])
    fixed = validate_surface(wrong.vertices, wrong.faces, "hollow box")
    assert fixed.volume == pytest.approx(1000 - 64)
    assert any("inside-out" in note for note in fixed.notes)


def test_a_t_junction_needle_is_swapped_not_removed():
    """A cube whose top triangle is split at the middle of an edge its side triangle does not split, closed by a
    zero-area needle along that edge (as an OpenSCAD export has them): removing the needle would open the
    surface ('edges bound a hole', an outside test's bar clamp); swapping its long edge keeps it closed."""
    box = trimesh.creation.box([2.0, 2.0, 2.0])
    vertices, faces = box.vertices.copy(), box.faces.copy()
    top = int(np.flatnonzero(box.face_normals[:, 2] > 0.5)[0])
    a, b, x = faces[top]
    m = len(vertices)
    vertices = np.vstack([vertices, (vertices[a] + vertices[b]) / 2])
    faces = np.vstack([np.delete(faces, top, axis=0), [[a, m, x], [m, b, x], [a, b, m]]])
    assert not trimesh.Trimesh(vertices, faces[:-1], process=False).is_watertight
    geometry = validate_surface(vertices, faces, "needle.stl")
    assert geometry.mesh.is_watertight and geometry.volume == pytest.approx(8.0)
    assert any("T-junctions" in note for note in geometry.notes)
    assert geometry.mesh.nondegenerate_faces(height=1e-9).all()
