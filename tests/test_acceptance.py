"""The acceptance gate (engine/acceptance.py, issue 16): no broken mesh leaves with exit 0, whichever packer or
mesher made it; a rejected mesh writes no files, prints one line naming the check, the place and the fix, and
exits with code 4; --keep-invalid writes it as <name>.invalid.*; the tolerances come from the knowledge base."""

from __future__ import annotations

import dataclasses
import textwrap
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import gmsh_model

from engine.acceptance import Tolerances, boundary_topology, cusps, forced_flat_clause, next_to_cusps
from engine.cli import main
from engine.errors import MeshRejected
from engine.job import load_job
from engine.knowledge import load_knowledge
from engine.packing import VOLUME, get_packer, register_packer
from engine.pipeline import run

SMALL = {"geometry": {"shape": "cylinder", "parameters": {"radius": 5, "height": 12}}, "size": 2.5}
BRACKET = {"geometry": {"shape": "l_bracket"}, "size": 12.0}


def _job(tmp_path, body: dict, knowledge: str | None = None, **extra):
    """A job file in tmp_path (with a knowledge folder holding ``knowledge`` as sizing.yaml, if given)."""
    import yaml

    data = {**body, **extra, "output": {"directory": "out", "formats": ["vtu", "msh"]}}
    if knowledge is not None:
        (tmp_path / "kb").mkdir()
        (tmp_path / "kb" / "sizing.yaml").write_text(textwrap.dedent(knowledge))
        data["knowledge"] = ["kb"]
    path = tmp_path / "job.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _refused(capsys, argv, check: str) -> str:
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 4, err
    line = err.splitlines()[-1]
    assert line.startswith(f"fuzzymesh: error: mesh rejected ({check}):"), line
    assert "--keep-invalid" in line and "Traceback" not in err
    return line


def test_a_good_mesh_passes_and_both_hausdorff_directions_are_reported(tmp_path):
    result = run(load_job(_job(tmp_path, SMALL)), write=False)
    for direction in ("hausdorff_input_to_mesh", "hausdorff_mesh_to_input"):
        far = result.boundary[direction]
        assert 0 < far["max"] <= far["max_over_h"] * result.sizing.h_max * 1.01
        assert far["max_over_h"] <= Tolerances.hausdorff
        assert far["at_distance"] <= far["max"] and len(far["at"]) == 3
    assert "acceptance" in result.timings


def test_boundary_topology_finds_open_and_misoriented_edges():
    tet = np.array([[0, 1, 2, 3]])
    assert boundary_topology(tet)["open_edges"] == 0 and boundary_topology(tet)["misoriented"] == 0
    # two tets sharing only the edge 0-1: that edge is in four boundary faces
    bowtie = np.array([[0, 1, 2, 3], [0, 1, 4, 5]])
    assert boundary_topology(bowtie)["open_edges"] == 1
    # a tet and its mirror image glued on face 1-2-3, the mirror inverted: their outer faces disagree
    flipped = np.array([[0, 1, 2, 3], [4, 1, 2, 3]])
    assert boundary_topology(flipped)["misoriented"] > 0
    # two tets sharing only node 0: every edge is in two faces, but the faces round node 0 are two fans
    pinch = np.array([[0, 1, 2, 3], [0, 4, 5, 6]])
    topology = boundary_topology(pinch)
    assert topology["open_edges"] == topology["misoriented"] == 0
    assert topology["pinched"] == 1 and topology["bad_node"] == 0
    assert boundary_topology(tet)["pinched"] == 0 and boundary_topology(flipped)["pinched"] == 0


def test_a_non_manifold_mesh_is_refused_with_no_files_and_kept_on_request(capsys, tmp_path):
    # qhull connects the bracket's nodes into their convex hull and drops tets by centroid: its boundary is
    # neither the bracket's surface nor (in general) two-manifold
    job = _job(tmp_path, BRACKET, mesher="qhull")
    code = main(["mesh", str(job)])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 4 and err.startswith("fuzzymesh: error: mesh rejected ("), err
    assert " near patch-" in err and "(centroid " in err and "--keep-invalid" in err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
    assert main(["mesh", str(job), "--keep-invalid"]) == 4
    kept = {p.name for p in (tmp_path / "out").iterdir()}
    assert {"mesh.invalid.msh", "mesh.invalid.vtu"} <= kept
    assert all(".invalid." in name for name in kept)


def test_a_plug_in_packer_is_gated_like_the_built_in_ones(tmp_path):
    """A third-party packer that labels every node a volume node leaves the surface unconstrained."""
    bubble = get_packer("bubble")

    @register_packer("test-all-volume")
    def all_volume(geometry, features, sizing, *, seed, knowledge=None):
        packing = bubble(geometry, features, sizing, seed=seed, knowledge=knowledge)
        keep = np.arange(len(packing)) % 3 != 0
        return dataclasses.replace(
            packing,
            points=packing.points[keep],
            level=np.full(keep.sum(), VOLUME, np.int8),
            entity=np.full(keep.sum(), -1),
            radius=packing.radius[keep],
            ids=None,
        )

    job = dataclasses.replace(load_job(_job(tmp_path, BRACKET)), packer="test-all-volume")
    with pytest.raises(MeshRejected):
        run(job)
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


RELAXED = {"min_dihedral": 0.0, "volume": 0.5, "hausdorff": 50.0}


@pytest.mark.parametrize(
    "setting, check",
    [
        ({"min_dihedral": 45.0}, "minimum dihedral angle"),
        ({"volume": 1e-7}, "volume"),
        ({"hausdorff": 1e-4}, "Hausdorff distance"),
    ],
)
def test_the_tolerances_are_knowledge(capsys, tmp_path, setting, check):
    """The job's own sizing defaults replace the shipped ones (no curvature pattern here): relaxed
    everywhere but in the one tolerance under test."""
    tolerances = "".join(f"\n          {key}: {value}" for key, value in {**RELAXED, **setting}.items())
    knowledge = f"""\
        kind: sizing
        base_pattern: uniform-domain
        acceptance:{tolerances}
        """
    job = _job(tmp_path, SMALL, knowledge)
    assert load_knowledge([tmp_path / "kb"]).sizing["acceptance"] == Tolerances(**{**RELAXED, **setting})
    line = _refused(capsys, ["mesh", str(job)], check)
    assert " at (" in line and "acceptance." in line
    assert not (tmp_path / "out").exists()


def test_a_tolerance_of_the_wrong_type_is_one_line(capsys, tmp_path):
    job = _job(
        tmp_path,
        SMALL,
        """\
        kind: sizing
        acceptance:
          min_dihedral: sharp
        """,
    )
    assert main(["mesh", str(job)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "sizing.yaml:3:" in err and "min_dihedral" in err


def test_an_output_folder_that_is_a_file_is_refused_before_any_work(capsys, tmp_path):
    job = _job(tmp_path, SMALL)
    (tmp_path / "out").write_text("not a folder")
    assert main(["mesh", str(job)]) == 2
    err = capsys.readouterr().err
    assert "is an existing file" in err and "job.yaml:" in err
    assert "packing" not in err and "geometry:" not in err


def test_the_exit_codes_are_documented():
    from pathlib import Path

    readme = (Path(__file__).parents[1] / "README.md").read_text()
    assert "exit code 4" in readme and "--keep-invalid" in readme


def test_a_10_node_element_below_the_floor_is_refused(tmp_path):
    """Order 2: the curving stops at the floor (acceptance.quadratic_jacobian), and the gate checks it."""
    from engine.acceptance import check_mesh
    from engine.quality import tet_quality

    job = dataclasses.replace(load_job(_job(tmp_path, SMALL)), output_order=2)
    result = run(job, write=False)
    elements = tet_quality(result.mesh.points, result.mesh.tets)
    tolerances = load_knowledge().sizing["acceptance"]
    check_mesh(
        result.mesh,
        result.geometry,
        result.features,
        elements,
        result.boundary,
        tolerances,
        np.full(len(result.mesh.tets), tolerances.quadratic_jacobian),
    )
    jacobians = np.ones(len(result.mesh.tets))
    jacobians[7] = 0.5 * tolerances.quadratic_jacobian
    with pytest.raises(MeshRejected, match="10-node element validity"):
        check_mesh(result.mesh, result.geometry, result.features, elements, result.boundary, tolerances, jacobians)


def test_population_rules_that_delete_every_bubble_give_no_mesh(capsys, tmp_path):
    """The issue's expert case: a job's own population rules (overrides: true) with the delete threshold at 0.
    The packer then leaves too few nodes for a mesh of the solid: one line, exit 4, no files (it was an
    internal error, exit 3, and with milder thresholds a broken mesh with exit 0)."""
    from pathlib import Path

    shipped = (Path(__file__).parents[1] / "knowledge" / "population.yaml").read_text()
    assert shipped.count("action: {output: q, threshold: 0.45,") == 1 and shipped.count("id: population\n") == 1
    rules = shipped.replace("action: {output: q, threshold: 0.45,", "action: {output: q, threshold: 0.0,")
    (tmp_path / "rules").mkdir()
    overriding = rules.replace("id: population\n", "id: population\noverrides: true\n")
    (tmp_path / "rules" / "population.yaml").write_text(overriding)
    job = _job(tmp_path, {"geometry": {"shape": "plate_cylinder_junction"}, "size": 10.0}, knowledge=None)
    job.write_text(job.read_text() + "knowledge: [rules]\n")
    code = main(["mesh", str(job)])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert code == 4 and err.startswith("fuzzymesh: error: mesh rejected ("), err
    assert "(meshing)" not in err or "population rules" in err, "a meshing failure names the rules to check"
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_a_rejection_next_to_a_cusp_names_it():
    """Two curves leaving a corner 2.9 deg apart are a cusp: a tet that spans the face between them near the
    corner is said to be next to it; one as close to the corner but off the face, one farther along than ten of
    its edges, or one at a 90 deg corner is not."""
    from engine.features import Curve

    def curve(name, end):
        return Curve(id=name, points=np.array([[0.0, 0.0, 0.0], end]), closed=False, vertices=None)

    features = SimpleNamespace(
        corners=[SimpleNamespace(point=np.zeros(3))],
        curves=[curve("wall-edge", [10.0, 0.0, 0.0]), curve("round-edge", [10.0, 0.5, 0.0])],
    )
    tet = np.array([[1.0, 0.0, 0.0], [1.5, 0.1, 0.0], [1.2, 0.0, 0.4], [1.3, 0.3, 0.2]])
    clause = forced_flat_clause(tet, None, features, cusps(features))
    assert "wall-edge and round-edge leave the corner at (0, 0, 0) 2.9 deg apart" in clause

    def near(corners):
        return next_to_cusps(corners[None], features, cusps(features))[0] >= 0

    assert near(tet)
    assert near(tet + [3.0, 0.0, 0.0]), "3 along, the face (0.2 wide) is still narrower"
    assert not near(tet + [0.0, -1.0, 0.0]), "off the face, as near the corner"
    assert not near(0.1 * tet + [9.0, 0.0, 0.0]), "farther along than ten of its edges"
    features.curves[1] = curve("round-edge", [0.0, 10.0, 0.0])
    assert not near(tet)


def test_a_tet_across_a_face_narrower_than_a_quarter_of_it_is_next_to_a_narrow_face(tmp_path):
    """A block with a recess 0.002 deep in its bottom (an outside test's endstop: 3 um, 56 tets under 5 deg):
    the recess's rim is a face 0.002 wide. A tet of edge 0.05 across it is next to that narrow face, and the
    clause names the face and its width; one of edge 0.004 (the face is wider than a quarter of it), or one far
    from the rim, is not."""
    import trimesh

    from engine.acceptance import next_to_narrow_faces
    from engine.describe import solid_features

    block = trimesh.creation.box([4.0, 4.0, 2.0])
    recess = trimesh.creation.box([1.5, 0.5, 0.002])
    recess.apply_translation([0.0, 0.0, -0.999])
    block.difference(recess, engine="manifold").export(str(tmp_path / "recess.stl"))
    _, geometry, features = solid_features(tmp_path / "recess.stl")
    unit = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) - 0.25
    rim = np.array([0.75, 0.0, -0.999])
    tets = np.stack([rim + 0.05 * unit, rim + 0.004 * unit, [0.0, 1.5, 0.0] + 0.05 * unit])
    facet, width = next_to_narrow_faces(tets, geometry, features)
    assert facet[0] >= 0 and width[0] == pytest.approx(0.002, rel=0.5) and (facet[1:] == -1).all()
    clause = forced_flat_clause(tets[0], geometry, features, cusps(features))
    assert f"next to {features.patches[features.face_patch[facet[0]]].id} (centroid" in clause
    assert "wide there: narrower than the elements" in clause


def _hex_head(path):
    """A bolt head: a hexagon 10 across flats on a washer face of radius 5, which touches each flat at its
    middle (six cusps, as on a real M6 bolt: an outside test's STEP bolt had 12 tets under 5 deg there)."""
    import gmsh

    with gmsh_model("test-hex-head") as occ:
        washer = occ.addCylinder(0, 0, 0, 0, 0, 0.4, 5)
        corners = [
            occ.addPoint(10 / np.sqrt(3) * np.cos(a), 10 / np.sqrt(3) * np.sin(a), 0.4)
            for a in np.arange(6) * np.pi / 3
        ]
        lines = [occ.addLine(corners[k], corners[(k + 1) % 6]) for k in range(6)]
        hexagon = occ.addPlaneSurface([occ.addCurveLoop(lines)])
        prism = occ.extrude([(2, hexagon)], 0, 0, 3.6)
        occ.fuse([(3, washer)], [d for d in prism if d[0] == 3])
        occ.synchronize()
        gmsh.write(str(path))


def test_flat_tets_next_to_a_cusp_are_kept_with_a_warning_others_refused(tmp_path):
    """min_dihedral applies everywhere but next to a cusp, where acceptance.cusp_min_dihedral does: the tets
    flattened there are reported, not refused; one as flat elsewhere, or flatter than the cusp floor, is."""
    from engine.acceptance import check_mesh, cusps, next_to_cusps
    from engine.job import job_from_dict
    from engine.quality import tet_quality

    _hex_head(tmp_path / "head.step")
    result = run(job_from_dict({"geometry": {"file": str(tmp_path / "head.step")}, "size": 0.6}), write=False)
    mesh, tolerances = result.mesh, load_knowledge().sizing["acceptance"]
    near = next_to_cusps(mesh.points[mesh.tets], result.features, cusps(result.features)) >= 0
    centre = np.linalg.norm(mesh.points[mesh.tets].mean(axis=1)[:, :2], axis=1) < 1.0
    assert near.any() and not near[centre].any()
    elements = tet_quality(mesh.points, mesh.tets)

    def gate(flat, angle):
        quality = dataclasses.replace(elements, min_dihedral=np.where(flat, angle, elements.min_dihedral))
        return check_mesh(mesh, result.geometry, result.features, quality, result.boundary, tolerances)

    kept = gate(near, 3.0)
    assert len(kept) == 1 and "next to a cusp" in kept[0] and "all next to cusps" in kept[0]
    with pytest.raises(
        MeshRejected, match=r"1 tetrahedra have .* \(and \d+ more next to cusps or narrow faces, down to 3 deg"
    ):
        gate(near | (centre & (np.cumsum(centre) == 1)), 3.0)
    with pytest.raises(MeshRejected, match="cusp_min_dihedral"):
        gate(near, 0.5 * tolerances.cusp_min_dihedral)
