"""FE-ready files: physical groups in .msh (read by Gmsh itself), node sets and element-face surfaces in
Abaqus .inp, quadratic tetrahedra above the scaled-Jacobian floor and boundary nodes on the surface."""

from __future__ import annotations

import functools

import gmsh
import meshio
import numpy as np
import pytest
import yaml
from conftest import gmsh_model
from test_meshers import meshed, packed

from engine.cli import main
from engine.exact import CylinderSurface, curve_surfaces, exact_surfaces
from engine.fe import TET10_EDGES, curve_edges, feature_groups, quadratic, row_index, tet_boundary
from engine.io import ABAQUS_FACE
from engine.levels import NODE_LEVELS
from engine.quadratic import QUADRATIC_FLOOR, _gradients, scaled_jacobian
from engine.shapes import CHORDAL_ERROR


@functools.lru_cache(maxsize=None)
def written(tmp_root, order):
    folder = tmp_root / f"order{order}"
    folder.mkdir()
    job = folder / "job.yaml"
    job.write_text(
        yaml.safe_dump(
            {
                "geometry": {"shape": "plate_cylinder_junction"},
                "size": 12.0,
                "output": {"formats": ["vtu", "msh", "inp", "bdf", "med"], "order": order},
            }
        )
    )
    assert main(["mesh", str(job), "--quiet"]) == 0
    return folder / "out"


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return tmp_path_factory.mktemp("fe")


def test_msh_opens_in_gmsh_with_the_features_as_physical_groups(root):
    out = written(root, 1)
    with gmsh_model("test-fe-output-msh"):
        gmsh.merge(str(out / "mesh.msh"))
        groups = {gmsh.model.getPhysicalName(dim, tag): (dim, tag) for dim, tag in gmsh.model.getPhysicalGroups()}
        assert {"solid", "junction", "cylinder", "top", "bottom", "plate-edge"} <= set(groups)
        assert groups["solid"][0] == 3 and groups["junction"][0] == 1 and groups["cylinder"][0] == 2
        _, nodes = gmsh.model.mesh.getNodesForPhysicalGroup(*groups["junction"])[:2]
        assert len(nodes) > 10
    vtu = meshio.read(out / "mesh.vtu")
    msh = meshio.read(out / "mesh.msh")
    assert len(msh.cells_dict["tetra"]) == len(vtu.cells_dict["tetra"])


def test_abaqus_surfaces_are_the_patches_faces(root):
    out = written(root, 1)
    inp = meshio.read(out / "mesh.inp")
    tets = inp.cells_dict["tetra"]
    assert {"top", "cylinder", "plate_edge", "junction"} <= set(inp.point_sets)
    text = (out / "mesh.inp").read_text()
    assert "*SURFACE, TYPE=ELEMENT, NAME=cylinder" in text
    # the element faces named by the cylinder surface are exactly the cylinder's boundary triangles
    faces = {"S1": [0, 1, 2], "S2": [0, 3, 1], "S3": [1, 3, 2], "S4": [2, 3, 0]}
    named = set()
    for face in faces:
        key = f"_cylinder_{face}"
        if key in inp.cell_sets:
            elements = np.concatenate([np.asarray(x, dtype=int) for x in inp.cell_sets[key]])
            named |= {tuple(sorted(row)) for row in tets[elements][:, faces[face]].tolist()}
    cylinder_nodes = set(inp.point_sets["cylinder"].tolist())
    assert named and all(set(f) <= cylinder_nodes for f in named)
    vtu = meshio.read(out / "mesh.vtu")
    assert np.allclose(vtu.points, inp.points)
    assert set(ABAQUS_FACE.values()) == set(faces)


def test_quadratic_tets_are_above_the_floor_and_curved_on_the_boundary():
    geometry, features, _, _ = packed("junction-edge")
    mesh = meshed("junction-edge")
    points, tets10, triangles6 = quadratic(mesh, geometry, features)
    assert tets10.shape == (len(mesh.tets), 10) and triangles6.shape == (len(mesh.boundary), 6)
    assert scaled_jacobian(points, tets10).min() >= QUADRATIC_FLOOR
    # boundary mid-edge nodes on the exact plane or cylinder of their patch, not on its facets
    surfaces = exact_surfaces(geometry, features)
    assert all(s is not None for s in surfaces), "the junction's patches are planes and a cylinder"
    patch = tet_boundary(mesh)[2]
    off = np.concatenate(
        [
            np.linalg.norm(surfaces[p].project(points[m]) - points[m], axis=1)
            for p in np.unique(patch)
            for m in [np.unique(triangles6[patch == p, 3:])]
        ]
    )
    assert np.mean(off < 1e-9 * geometry.scale) > 0.99, "boundary mid-edge nodes on the exact surfaces"
    _, distance, _ = geometry.closest_point(points[np.unique(triangles6[:, 3:])])
    radius = max(s.radius for s in surfaces if isinstance(s, CylinderSurface))
    assert distance.max() < 1.01 * CHORDAL_ERROR * radius, "within the faceting's sagitta of the input"
    # mid-edge nodes of the junction lie on the exact circle: on the cylinder and on the plate's top plane
    junction = features.curves.index(features.named("junction")[0])
    (group,) = [g for g in feature_groups(mesh, features) if g.name == "junction"]
    edges = np.sort(group.cells, axis=1)
    tet_edges = np.sort(tets10[:, [[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]]].reshape(-1, 2), axis=1)
    lookup = {tuple(e): m for e, m in zip(tet_edges.tolist(), tets10[:, 4:].reshape(-1).tolist())}
    on = points[[lookup[tuple(e)] for e in edges.tolist()]]
    circle = curve_surfaces(geometry, features, surfaces)[junction]
    assert len(circle) == 2
    off = np.max([np.linalg.norm(s.project(on) - on, axis=1) for s in circle], axis=0)
    assert np.mean(off < 1e-9 * geometry.scale) > 0.9, "mid-edge nodes of the junction on the circle"
    assert (mesh.node_level[np.unique(edges)] <= NODE_LEVELS.index("curve")).all()


def test_quadratic_files_read_back(root):
    out = written(root, 2)
    for name in ("mesh.vtu", "mesh.msh", "mesh.inp", "mesh.bdf", "mesh.med"):
        data = meshio.read(out / name)
        tets10 = data.cells_dict["tetra10"]
        assert scaled_jacobian(data.points, tets10).min() >= QUADRATIC_FLOOR, name
    assert "triangle6" in meshio.read(out / "mesh.msh").cells_dict


def test_nastran_and_med_hold_the_same_mesh(root):
    out = written(root, 1)
    vtu = meshio.read(out / "mesh.vtu")
    for name in ("mesh.bdf", "mesh.med"):
        other = meshio.read(out / name)
        assert np.allclose(other.points, vtu.points, rtol=0, atol=1e-7 * np.abs(vtu.points).max())
        assert np.array_equal(other.cells_dict["tetra"], vtu.cells_dict["tetra"]), name
    med = meshio.read(out / "mesh.med")
    assert np.allclose(med.cell_data["h_target"][0], vtu.cell_data["h_target"][0]), "the audit travels in MED"


@pytest.mark.parametrize("order", [1, 2])
def test_med_face_groups_are_the_msh_surface_groups(root, order):
    """Every surface group of the .msh (patches, named surfaces) is a MED family group of the same triangles
    (triangle6 with the same mid-edge nodes at order 2), and the tets keep their families and fields."""
    out = written(root, order)
    msh, med = meshio.read(out / "mesh.msh"), meshio.read(out / "mesh.med")
    kind = "triangle6" if order == 2 else "triangle"
    faces = med.cells_dict[kind]
    family = med.cell_data_dict["cell_tags"][kind]
    in_group = {}
    for number, names in med.cell_tags.items():
        for name in names:
            in_group.setdefault(name, set()).add(number)
    physical = msh.cell_data_dict["gmsh:physical"][kind]
    surfaces = {name: tag for name, (tag, dim) in msh.field_data.items() if dim == 2}
    assert {"cylinder", "top", "bottom"} <= set(surfaces)
    for name, tag in surfaces.items():
        expected = {tuple(row) for row in msh.cells_dict[kind][physical == tag].tolist()}
        got = {tuple(row) for row in faces[np.isin(family, list(in_group[name]))].tolist()}
        assert got == expected, name
    tet = "tetra10" if order == 2 else "tetra"
    assert {"solid"} <= set(in_group) and (med.cell_data_dict["cell_tags"][tet] < 0).all()
    assert len(med.cell_data_dict["h_target"][tet]) == len(med.cells_dict[tet])


def test_mid_edge_nodes_on_flat_faces_stay_at_the_midpoint():
    """A corner counts as on a curve only where it ends that curve: an edge from a box corner to a node of
    another box edge is a diagonal of a flat face, and its mid-node stays at the edge's midpoint; only
    chords of a feature curve (here the hole's rims) bend on a flat face."""
    from engine.job import job_from_dict
    from engine.pipeline import run

    job = job_from_dict(
        {
            "geometry": {"shape": "plate_with_hole"},
            "size": 16.79,
            "place": [
                {"pattern": "uniform-domain"},
                {"pattern": "hole", "every": "hole", "parameters": {"near": 0.375, "far": 3.0}},
            ],
        }
    )
    result = run(job, write=False)
    mesh, features = result.mesh, result.features
    chords, curve = curve_edges(mesh, features)
    corner = mesh.node_level[chords] == NODE_LEVELS.index("corner")
    ends = np.array([[features.curves[c].points[0], features.curves[c].points[-1]] for c in curve])
    gap = np.linalg.norm(mesh.points[chords][:, :, None] - ends[:, None], axis=3).min(axis=2)
    assert corner.any() and (gap[corner] < 1e-9 * result.geometry.scale).all(), "corners end their curve"
    points, _, triangles6 = quadratic(mesh, result.geometry, features)
    planar = np.array([p.planar for p in features.patches])[mesh.boundary_patch]
    edges = triangles6[planar][:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)
    middle = triangles6[planar][:, 3:].ravel()
    not_chord = row_index(np.sort(chords, axis=1), np.sort(edges, axis=1)) < 0
    offset = np.linalg.norm(points[middle] - points[edges].mean(axis=1), axis=1)
    assert offset[~not_chord].max() > 0.01, "the rims' chords bend onto the circles"
    assert offset[not_chord].max() < 1e-9 * result.geometry.scale


def test_limit_curving_keeps_each_element_above_the_floor_curving_as_far_as_it_can():
    """A mid-edge node pulled far across its element ends straight (no fraction of the pull is above the floor);
    a small pull is kept whole; a medium one is cut back by bisection to just above the floor."""
    from engine.fe import BISECTION_STEPS, limit_curving

    corners = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    straight = np.vstack([corners, corners[TET10_EDGES].mean(axis=1)])
    tets10 = np.arange(10)[None]
    far, near, medium = straight.copy(), straight.copy(), straight.copy()
    far[4] += [0.0, 0.0, 2.0 ** (BISECTION_STEPS + 3)]  # edge 0-1's mid-node far above the opposite corner
    near[4] += [0.0, -0.05, 0.0]
    medium[4] += [0.0, 0.3, 0.0]  # towards corner 2: scaled Jacobian 1 - 4 x 0.3
    assert scaled_jacobian(near, tets10)[0] >= QUADRATIC_FLOOR > scaled_jacobian(medium, tets10)[0]
    assert np.array_equal(limit_curving(straight, far, tets10), straight)
    assert np.array_equal(limit_curving(straight, near, tets10), near)
    limited = limit_curving(straight, medium, tets10)
    fraction = (limited[4] - straight[4])[1] / 0.3
    assert np.array_equal(limited[[0, 1, 2, 3, 5, 6, 7, 8, 9]], straight[[0, 1, 2, 3, 5, 6, 7, 8, 9]])
    assert 0 < fraction < 1 and QUADRATIC_FLOOR <= scaled_jacobian(limited, tets10)[0] < QUADRATIC_FLOOR + 0.01


def test_scaled_jacobian_bounds_det_j_from_below():
    """1 on a straight element; at most min det J / det J straight over a fine sampling, and equal to it where
    the minimum is at a corner; negative where an interior point folds."""
    corners = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    straight = np.vstack([corners, corners[TET10_EDGES].mean(axis=1)])
    tets10 = np.arange(10)[None]
    assert np.isclose(scaled_jacobian(straight, tets10)[0], 1.0)
    grid = np.linspace(0, 1, 13)
    r, s, t = (a.ravel() for a in np.meshgrid(grid, grid, grid, indexing="ij"))
    inside = r + s + t <= 1 + 1e-12
    gradients = np.array([_gradients(*p) for p in zip(r[inside], s[inside], t[inside])])  # (p, 10, 3)
    rng = np.random.default_rng(0)
    tight = 0
    for _ in range(50):
        points = straight.copy()
        points[4:] += rng.normal(0, 0.1, (6, 3))
        sampled = np.linalg.det(np.einsum("ai,paj->pij", points, gradients)).min()
        bound = scaled_jacobian(points, tets10)[0]
        assert bound <= sampled + 1e-12
        tight += np.isclose(bound, sampled)
    assert tight > 10, "the bound is the corner value where the minimum is at a corner"
    folded = straight.copy()
    folded[4] += [0.2, 0.6, 0.6]  # edge 0-1's mid-node beyond the opposite face
    assert scaled_jacobian(folded, tets10)[0] < 0


def test_closed_curves_parametrise_across_their_seam():
    """Issue 15's quarter-point element: a chord touching a closed curve's seam vertex got the curve's whole
    length as its arc parameter. Points at and just before the seam are at 0 and just under the length."""
    from engine.features import Curve

    angles = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    points = np.column_stack([10 * np.cos(angles), 10 * np.sin(angles), 0 * angles])
    circle = Curve(id="c", points=points, closed=True, vertices=None)
    seam, before, after = circle.points[0], circle.point_at(circle.length - 0.1), circle.point_at(0.1)
    s = circle.parameter(np.vstack([seam, before, after]))
    assert (
        s[0] == pytest.approx(0.0, abs=1e-9)
        and s[1] == pytest.approx(circle.length - 0.1)
        and s[2] == pytest.approx(0.1)
    )


def test_hole_rim_mid_nodes_sit_in_the_middle_of_their_arcs():
    """Every 10-node chord of the plate's hole rims, the ones across the seam included, has its mid-node at
    the middle of its arc (a quarter-point node ruins the stress at the rim)."""
    from engine.job import job_from_dict
    from engine.pipeline import run

    result = run(
        job_from_dict(
            {"geometry": {"shape": "plate_with_hole"}, "size": 12.0, "output": {"order": 2}},
            base_dir=".",
            source="<test>",
        ),
        write=False,
    )
    mesh, features = result.mesh, result.features
    points, tets10, triangles6 = quadratic(mesh, result.geometry, features)
    chords, curve = curve_edges(mesh, features, triangles6[:, :3])
    tet_edges = np.sort(tets10[:, TET10_EDGES].reshape(-1, 2), axis=1)
    middle = dict(zip(map(tuple, tet_edges.tolist()), tets10[:, 4:].reshape(-1).tolist()))
    checked = 0
    for c in np.unique(curve):
        rim = features.curves[c]
        if not rim.closed:
            continue
        ends = chords[curve == c]
        s = rim.parameter(points[ends.ravel()]).reshape(-1, 2)
        m = rim.parameter(points[[middle[tuple(sorted(e))] for e in ends.tolist()]])
        span = np.mod(s[:, 1] - s[:, 0], rim.length)
        span = np.where(span > rim.length / 2, span - rim.length, span)  # signed, the short way round
        offset = np.mod(m - s[:, 0] + rim.length / 2, rim.length) - rim.length / 2
        assert np.allclose(offset / span, 0.5, atol=0.05), rim.id
        checked += len(ends)
    assert checked > 20
