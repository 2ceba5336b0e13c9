"""Boundary groups are the tets' own faces: in .msh (triangle / triangle6 physical groups) and Abaqus .inp
(element-face surfaces) every boundary face is a face of exactly one tetrahedron, outward, with that tet's
mid-nodes, and together they cover the boundary. .vtu and .med hold no faces."""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

import meshio
import numpy as np
import pytest

from engine.atomic import write_all_or_nothing
from engine.fe import SIDE_NODES, TET10_EDGES, tet_boundary
from engine.io import FEModel, mesh_targets
from engine.job import job_from_dict
from engine.knowledge import load_knowledge
from engine.mesh import TetMesh
from engine.meshing import get_mesher
from engine.packing import get_packer
from engine.pipeline import build_geometry, build_sizing, fe_model
from engine.validation import plate_hole

# per side of a tet (face k opposite corner k, outward), its corners and its edges' mid-nodes in VTK order
SIDES = np.array([[1, 2, 3, 5, 9, 8], [0, 3, 2, 7, 9, 6], [0, 1, 3, 4, 8, 7], [0, 2, 1, 6, 5, 4]])
ROTATIONS = np.array([[0, 1, 2, 3, 4, 5], [1, 2, 0, 4, 5, 3], [2, 0, 1, 5, 3, 4]])  # of a triangle6
ABAQUS_SIDE = {"S1": 3, "S2": 2, "S3": 0, "S4": 1}  # Abaqus face label -> side index (opposite corner)
_spec = importlib.util.spec_from_file_location("make_parts", Path(__file__).parent / "parts" / "make_parts.py")
make_parts = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_parts)


def plate(scale: float) -> dict:
    """The validation plate at ``scale`` x its default size, uniform (the hole pattern's study sizing)."""
    return plate_hole.job(scale, graded=False, rules=False)


CASES = {
    "plate-1": plate(1.0),
    "plate-2": plate(2.0),
    "plate-0.7": plate(0.7),
    "l_bracket": {"geometry": {"shape": "l_bracket"}},
    "cone_pin": None,
}


@functools.lru_cache(maxsize=None)
def meshed(case: str, root: Path):
    """(job, mesh, geometry, features) of a case, through the pipeline's stages up to the mesher."""
    spec = CASES[case]
    if spec is None:
        stl = make_parts.make_parts(root / "parts", [case])[case]["coarse"]
        spec = {"geometry": {"file": str(stl)}}
    job = job_from_dict(spec)
    geometry, features = build_geometry(job)
    kb = load_knowledge(job.knowledge)
    sizing = build_sizing(job, geometry, features, kb)
    packing = get_packer(job.packer)(geometry, features, sizing, seed=job.seed, knowledge=kb)
    return job, get_mesher(job.mesher)(packing, geometry, features, seed=job.seed), geometry, features


def boundary_sides(tets: np.ndarray) -> np.ndarray:
    """(t, 3 or 6) the sides of ``tets`` (m, 4 or 10) used by one tet only, outward, with mid-nodes."""
    k = 6 if tets.shape[1] == 10 else 3
    sides = tets[:, SIDES[:, :k]].reshape(-1, k)
    _, inverse, counts = np.unique(np.sort(sides[:, :3], axis=1), axis=0, return_inverse=True, return_counts=True)
    return sides[counts[inverse.ravel()] == 1]


def assert_tet_faces(faces: np.ndarray, tets: np.ndarray, label: str) -> None:
    """Every row of ``faces`` is a boundary side of ``tets`` with the same orientation and mid-nodes, and
    together they cover every boundary side."""
    sides = boundary_sides(tets)
    index = {tuple(sorted(s[:3])): i for i, s in enumerate(sides.tolist())}
    rows = np.array([index.get(tuple(sorted(f[:3])), -1) for f in faces.tolist()])
    assert (rows >= 0).all(), f"{label}: {(rows < 0).sum()} of {len(faces)} faces are no boundary face of a tet"
    k = faces.shape[1]
    same = (faces[:, None, :] == sides[rows][:, ROTATIONS[:, :k]]).all(axis=2).any(axis=1)
    assert same.all(), f"{label}: {(~same).sum()} faces differ from their tet's side in orientation or mid-nodes"
    assert len(set(rows.tolist())) == len(sides), f"{label}: the faces leave part of the boundary out"


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return tmp_path_factory.mktemp("boundary")


def test_side_table_is_the_outward_faces_with_their_edge_mid_nodes():
    assert np.array_equal(SIDE_NODES, SIDES)
    corners = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    for k, side in enumerate(SIDES):
        a, b, c = corners[side[:3]]
        assert np.dot(np.cross(b - a, c - a), a - corners[k]) > 0, "outward: away from the opposite corner"
        for i, middle in enumerate(side[3:]):
            assert set(TET10_EDGES[middle - 4]) == {side[i], side[(i + 1) % 3]}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("order", [1, 2])
def test_every_boundary_face_in_every_format_is_a_face_of_a_tet(root, case, order):
    job, mesh, geometry, features = meshed(case, root)
    job = job_from_dict({**job.raw, "output": {"order": order}})
    folder = root / f"{case}-{order}"
    model = fe_model(job, mesh, geometry, features)
    write_all_or_nothing(mesh_targets(model, folder, "mesh", ["msh", "inp", "vtu", "med"]))
    kind = "tetra10" if order == 2 else "tetra"
    msh = meshio.read(folder / "mesh.msh")
    faces = np.vstack([c.data for c in msh.cells if c.type == ("triangle6" if order == 2 else "triangle")])
    assert_tet_faces(np.unique(faces, axis=0), msh.cells_dict[kind], f"{case} .msh")
    inp = meshio.read(folder / "mesh.inp")
    tets = inp.cells_dict[kind]
    named = [
        (np.concatenate([np.asarray(x, int) for x in cells]), ABAQUS_SIDE[name[-2:]])
        for name, cells in inp.cell_sets.items()
        if name.startswith("_") and name[-2:] in ABAQUS_SIDE
    ]
    sides = np.vstack([tets[elements][:, SIDES[side, :3]] for elements, side in named])
    assert_tet_faces(np.unique(sides, axis=0), tets[:, :4], f"{case} .inp")
    for name in ("mesh.vtu", "mesh.med"):
        assert np.array_equal(meshio.read(folder / name).cells_dict[kind], msh.cells_dict[kind]), name


def test_a_quad_split_along_the_other_diagonal_takes_the_patch_of_the_mesher_triangles():
    """A cube of 6 tets whose mesher boundary splits the top (patch 1) along the other diagonal than its tets:
    the tets' top faces belong to patch 1, the mesher's two top triangles to no group."""
    corners = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=float)
    tets = np.array([[0, 1, 3, 7], [0, 1, 7, 5], [0, 5, 7, 4], [0, 3, 2, 7], [0, 2, 6, 7], [0, 6, 4, 7]])
    assert (TetMesh(points=corners, tets=tets, node_level=None, node_entity=None).volumes() > 0).all()
    faces = TetMesh(points=corners, tets=tets, node_level=None, node_entity=None).boundary_faces()
    top = corners[faces][:, :, 2].min(axis=1) == 1
    declared = np.vstack([faces[~top], [[4, 5, 6], [5, 7, 6]]])  # the top split along 5-6, the tets along 4-7
    patch = np.r_[np.zeros((~top).sum(), int), 1, 1]
    mesh = TetMesh(
        points=corners,
        tets=tets,
        node_level=np.zeros(8, np.int8),
        node_entity=np.zeros(8, np.int64),
        boundary=declared,
        boundary_patch=patch,
    )
    owner, side, found = tet_boundary(mesh)
    on = tets[owner[:, None], SIDES[side, :3]]
    assert np.array_equal(found == 1, corners[on][:, :, 2].min(axis=1) == 1) and (found == 1).sum() == 2
    model = FEModel.build(mesh)
    assert_tet_faces(model.boundary, tets, "linear model")
