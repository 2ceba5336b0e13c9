"""Bad inputs reach the user as one clear line, exit code 2, and no output files.

Every test runs ``fuzzymesh mesh JOB.yaml`` (in-process through
``engine.cli.main``; two tests use a real subprocess) on a job file written
into ``tmp_path`` whose ``output.directory`` points into ``tmp_path``. For a
bad input the contract is:

* stderr holds exactly one line starting with ``fuzzymesh: error:`` (progress
  lines of the pipeline such as ``geometry: ...`` may precede it, nothing else);
* that line names the file (``file:line:col`` for job-file errors), says what is
  wrong and what to do;
* the exit code is 2, there is no traceback, and no mesh file is written.

The surface files are made here with numpy/trimesh or written by hand.
"""

from __future__ import annotations

import contextlib
import logging
import re
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from engine.cli import main

ERROR_PREFIX = "fuzzymesh: error:"
# lines the pipeline logs at INFO level while it works; anything else on stderr is suspect
PROGRESS_LINE = re.compile(
    r"^(geometry|sizing|packing|meshing|exact surfaces|quality|boundary|size conformity|audit|acceptance|output|done)"
    r"( \([\w-]+\)| (curve|patch|volume))?: "
)
MESH_SUFFIXES = {".vtu", ".msh"}
SMALL = 2.5  # element size for the cube of side 10 in the cases that must mesh


# --------------------------------------------------------------------------- helpers


@pytest.fixture(autouse=True)
def _in_tmp_path(monkeypatch, tmp_path):
    """Run in tmp_path, so that anything written relative to the working folder is seen too."""
    monkeypatch.chdir(tmp_path)


@contextlib.contextmanager
def _like_a_terminal():
    """Make logging and Python warnings reach the captured stderr as they would in a real run.

    pytest keeps its own handlers on the root logger (so ``main``'s
    ``logging.basicConfig`` would be a no-op) and records warnings itself.
    Within this context the root logger has no handlers, so ``main`` installs
    its stderr handler; it is removed again afterwards. Warnings are recorded
    under Python's default filters and printed to stderr the way the
    interpreter would print them.
    """
    root = logging.getLogger()
    saved_handlers, saved_level = root.handlers[:], root.level
    root.handlers = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.resetwarnings()
            warnings.simplefilter("default")
            for category in (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning):
                warnings.filterwarnings("ignore", category=category)
            yield
        for w in caught:
            sys.stderr.write(warnings.formatwarning(w.message, w.category, w.filename, w.lineno, w.line))
    finally:
        for handler in root.handlers:
            handler.close()
        root.handlers = saved_handlers
        root.setLevel(saved_level)


def cube(side: float = 10.0, offset=(0.0, 0.0, 0.0)):
    """Vertices and outward-oriented faces of an axis-aligned cube with its min corner at ``offset``."""
    box = trimesh.creation.box(extents=(side, side, side))
    vertices = np.asarray(box.vertices, dtype=float) + side / 2 + np.asarray(offset, dtype=float)
    faces = np.asarray(box.faces, dtype=np.int64)
    return vertices, faces


def two_cubes(offset):
    v1, f1 = cube()
    v2, f2 = cube(offset=offset)
    return np.vstack([v1, v2]), np.vstack([f1, f2 + len(v1)])


def _num(x) -> str:
    return repr(float(x))  # 'nan', 'inf' stay readable by the parsers


def write_obj(path: Path, vertices, faces) -> Path:
    lines = [f"v {_num(x)} {_num(y)} {_num(z)}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_ascii_stl(path: Path, vertices, faces) -> Path:
    out = ["solid broken"]
    for tri in faces:
        out += ["  facet normal 0 0 0", "    outer loop"]
        out += [f"      vertex {_num(x)} {_num(y)} {_num(z)}" for x, y, z in np.asarray(vertices)[tri]]
        out += ["    endloop", "  endfacet"]
    out.append("endsolid broken")
    path.write_text("\n".join(out) + "\n")
    return path


def write_off(path: Path, vertices, faces) -> Path:
    lines = ["OFF", f"{len(vertices)} {len(faces)} 0"]
    lines += [f"{_num(x)} {_num(y)} {_num(z)}" for x, y, z in vertices]
    lines += [f"3 {a} {b} {c}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def write_with_trimesh(path: Path, vertices, faces) -> Path:
    """Binary STL / PLY through trimesh, keeping the faces exactly as given."""
    trimesh.Trimesh(vertices, faces, process=False).export(str(path))
    return path


def write_job(tmp_path: Path, text: str, name: str = "job.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text).lstrip("\n"))
    return path


def surface_job(tmp_path: Path, surface: str) -> Path:
    """A job meshing ``surface`` (relative to the job file) into tmp_path/out."""
    return write_job(
        tmp_path,
        f"""
        geometry:
          file: {surface}
        size: {SMALL}
        output:
          directory: out
        """,
    )


def mesh_files(tmp_path: Path) -> list[Path]:
    """Mesh outputs (and leftover temporary files of the atomic writer) anywhere under tmp_path."""
    return [
        p for p in tmp_path.rglob("*") if p.is_file() and (p.suffix in MESH_SUFFIXES or p.name.startswith(".mesh."))
    ]


def run_cli(capture, *argv) -> tuple[int, str, str]:
    """``fuzzymesh mesh ARGV...`` in-process; ``capture`` is pytest's capsys or capfd."""
    with _like_a_terminal():
        code = main(["mesh", *map(str, argv)])
    captured = capture.readouterr()
    return code, captured.out, captured.err


def error_line(err: str) -> str:
    """The single error line of ``err``; fails if stderr holds anything else but progress lines."""
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    others = [line for line in lines if not PROGRESS_LINE.match(line)]
    assert len(others) == 1, f"expected exactly one non-progress line on stderr, got:\n{err}"
    line = others[0]
    assert line.startswith(ERROR_PREFIX), f"not an error line: {line!r}"
    assert lines[-1] == line, f"the error must be the last line:\n{err}"
    assert len(line) < 600, f"error line is unreasonably long ({len(line)} chars): {line!r}"
    return line


def assert_refused(capsys, tmp_path: Path, job: Path, *fragments: str, where: str | None = None) -> str:
    """Run the job; check exit 2, one located error line containing ``fragments``, no output files."""
    code, out, err = run_cli(capsys, job)
    line = error_line(err)
    assert code == 2, f"exit code {code}, stderr: {err}"
    assert "Traceback" not in out
    if where is not None:
        assert f"{ERROR_PREFIX} {where}: " in line, f"expected location {where!r} in: {line!r}"
    for fragment in fragments:
        assert fragment.lower() in line.lower(), f"{fragment!r} missing from: {line!r}"
    message = line[len(ERROR_PREFIX) :]
    assert "; " in message, f"the error says nothing about what to do: {line!r}"
    assert not mesh_files(tmp_path), f"output files left behind: {mesh_files(tmp_path)}"
    return line


def notes(err: str) -> list[str]:
    """The lines of a successful run's stderr that are not progress lines (i.e. the warnings)."""
    return [line for line in err.splitlines() if line.strip() and not PROGRESS_LINE.match(line)]


def assert_meshed(capsys, tmp_path: Path, job: Path) -> str:
    code, out, err = run_cli(capsys, job)
    assert code == 0, f"exit code {code}, stderr: {err}"
    assert "Traceback" not in err and ERROR_PREFIX not in err, err
    written = sorted(p.name for p in mesh_files(tmp_path))
    assert written == ["mesh.msh", "mesh.vtu"], written
    assert all((tmp_path / "out" / name).stat().st_size > 0 for name in written)
    return err


# --------------------------------------------------------------------------- geometry files


def test_missing_surface_file(capsys, tmp_path):
    job = surface_job(tmp_path, "nowhere.stl")
    assert_refused(capsys, tmp_path, job, "file not found", "check the path", where=str(tmp_path / "nowhere.stl"))


def test_empty_surface_file(capsys, tmp_path):
    (tmp_path / "empty.stl").write_bytes(b"")
    job = surface_job(tmp_path, "empty.stl")
    assert_refused(capsys, tmp_path, job, "empty", where=str(tmp_path / "empty.stl"))


def test_unknown_surface_extension(capsys, tmp_path):
    write_obj(tmp_path / "cube.xyz", *cube())
    job = surface_job(tmp_path, "cube.xyz")
    line = assert_refused(capsys, tmp_path, job, "unknown surface format", "'.xyz'", where=str(tmp_path / "cube.xyz"))
    for fmt in (".stl", ".obj", ".ply", ".off"):
        assert fmt in line


RANDOM_BYTES = np.random.default_rng(1).integers(0, 256, 1000, dtype=np.uint8).tobytes()


@pytest.mark.parametrize(
    "name, content",
    [
        pytest.param("garbage.stl", b"this is not an STL file at all\njust some words\n", id="stl-text"),
        pytest.param("garbage.stl", RANDOM_BYTES, id="stl-random-bytes"),
        pytest.param(
            "garbage.stl",
            b"solid x\n  facet normal 0 0 0\n    outer loop\n      vertex 1 2\n",
            id="stl-truncated-ascii",
        ),
        pytest.param("garbage.stl", b"\0" * 80 + (5).to_bytes(4, "little"), id="stl-binary-header-only"),
        pytest.param("garbage.obj", bytes(range(256)) * 4, id="obj-binary"),
        pytest.param("garbage.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", id="obj-index-out-of-range"),
        pytest.param("garbage.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", id="obj-no-faces"),
        pytest.param(
            "garbage.ply",
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n",
            id="ply-truncated",
        ),
        pytest.param("garbage.off", b"OFF\n3 1 0\n0 0 0\n1 0\n", id="off-truncated"),
        pytest.param("garbage.glb", b"glTF\x02\x00\x00\x00garbage", id="glb-garbage"),
    ],
)
def test_garbage_surface_file(capsys, tmp_path, name, content):
    (tmp_path / name).write_bytes(content)
    job = surface_job(tmp_path, name)
    assert_refused(capsys, tmp_path, job, where=str(tmp_path / name))


@pytest.mark.parametrize("name", ["garbage.stl", "garbage.obj"])
def test_garbage_surface_file_message_is_about_the_file(capsys, tmp_path, name):
    (tmp_path / name).write_bytes(RANDOM_BYTES)
    line = assert_refused(capsys, tmp_path, surface_job(tmp_path, name), where=str(tmp_path / name))
    assert "No module named" not in line and "ModuleNotFoundError" not in line, line


def test_not_watertight(capsys, tmp_path):
    vertices, faces = cube()
    normals = trimesh.Trimesh(vertices, faces, process=False).face_normals
    keep = ~np.isclose(normals[:, 2], 1.0)  # drop the two triangles of the top side
    assert keep.sum() == 10
    write_ascii_stl(tmp_path / "open.stl", vertices, faces[keep])
    job = surface_job(tmp_path, "open.stl")
    assert_refused(capsys, tmp_path, job, "not closed", "watertight", "4 edges", where=str(tmp_path / "open.stl"))


def test_not_manifold(capsys, tmp_path):
    # two closed cubes sharing one edge: that edge joins four faces
    write_obj(tmp_path / "edge.obj", *two_cubes(offset=(10.0, 10.0, 0.0)))
    job = surface_job(tmp_path, "edge.obj")
    assert_refused(capsys, tmp_path, job, "not manifold", "more than two faces", where=str(tmp_path / "edge.obj"))


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
@pytest.mark.parametrize("writer, suffix", [(write_obj, ".obj"), (write_ascii_stl, ".stl")])
def test_non_finite_coordinates(capsys, tmp_path, value, writer, suffix):
    vertices, faces = cube()
    vertices[3, 1] = float(value)
    path = writer(tmp_path / f"bad{suffix}", vertices, faces)
    assert value in path.read_text()
    job = surface_job(tmp_path, path.name)
    assert_refused(capsys, tmp_path, job, "NaN or infinite", where=str(path))


def _doubled_sheet(tmp_path):
    vertices = np.array([[0.0, 0, 0], [10, 0, 0], [0, 10, 0]])
    faces = np.array([[0, 1, 2], [0, 2, 1]])  # the same triangle twice, opposite winding: closed, volume 0
    write_obj(tmp_path / "sheet.obj", vertices, faces)
    return surface_job(tmp_path, "sheet.obj")


def test_zero_volume_doubled_sheet_is_refused(capsys, tmp_path):
    job = _doubled_sheet(tmp_path)
    code, _, err = run_cli(capsys, job)
    assert code == 2 and "Traceback" not in err
    errors = [line for line in err.splitlines() if line.startswith(ERROR_PREFIX)]
    assert len(errors) == 1 and f"{tmp_path / 'sheet.obj'}: the surface encloses no volume" in errors[0]
    assert not mesh_files(tmp_path)


def test_zero_volume_doubled_sheet_one_line(capsys, tmp_path):
    assert_refused(capsys, tmp_path, _doubled_sheet(tmp_path), "no volume", where=str(tmp_path / "sheet.obj"))


def test_zero_volume_flat_tetrahedron(capsys, tmp_path):
    # a closed tetrahedron whose apex lies in the base plane (by 1e-9: the triangles keep a non-zero area)
    vertices = np.array([[0.0, 0, 0], [10, 0, 0], [0, 10, 0], [3, 3, 1e-9]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]])
    write_off(tmp_path / "flat.off", vertices, faces)
    job = surface_job(tmp_path, "flat.off")
    assert_refused(capsys, tmp_path, job, "no volume", where=str(tmp_path / "flat.off"))


def test_overlapping_cubes_are_refused_naming_the_bodies(capsys, tmp_path):
    write_with_trimesh(tmp_path / "overlap.stl", *two_cubes(offset=(5.0, 5.0, 5.0)))
    job = surface_job(tmp_path, "overlap.stl")
    assert_refused(
        capsys,
        tmp_path,
        job,
        "holds 2 bodies",
        "bodies 1 and 2 touch or overlap",
        "unite",
        where=str(tmp_path / "overlap.stl"),
    )


def test_two_disjoint_cubes_refused(capsys, tmp_path):
    write_obj(tmp_path / "two.obj", *two_cubes(offset=(20.0, 0.0, 0.0)))
    job = surface_job(tmp_path, "two.obj")
    assert_refused(
        capsys, tmp_path, job, "2 disconnected solids", "allow_multiple_solids: true", where=str(tmp_path / "two.obj")
    )


def test_two_disjoint_cubes_allowed(capsys, tmp_path):
    write_obj(tmp_path / "two.obj", *two_cubes(offset=(20.0, 0.0, 0.0)))
    job = surface_job(tmp_path, "two.obj")
    job.write_text(job.read_text().replace("  file: two.obj\n", "  file: two.obj\n  allow_multiple_solids: true\n"))
    assert "allow_multiple_solids: true" in job.read_text()
    assert_meshed(capsys, tmp_path, job)
    import meshio

    mesh = meshio.read(tmp_path / "out" / "mesh.vtu")
    tets = mesh.cells_dict["tetra"]
    # both cubes are meshed: nodes on each side of the gap, total volume of two cubes
    assert (mesh.points[:, 0] < 10 + 1e-9).any() and (mesh.points[:, 0] > 20 - 1e-9).any()
    p = mesh.points[tets]
    volume = np.abs(np.einsum("ij,ij->i", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]))).sum() / 6
    assert volume == pytest.approx(2000.0, rel=1e-3)


def test_inside_out_cube_is_turned(capsys, tmp_path):
    vertices, faces = cube()
    write_off(tmp_path / "inverted.off", vertices, faces[:, ::-1])
    job = surface_job(tmp_path, "inverted.off")
    err = assert_meshed(capsys, tmp_path, job)
    (warning,) = notes(err)
    assert warning.startswith(f"warning: {tmp_path / 'inverted.off'}: ") and "turned 1 inside-out shell" in warning


def test_inconsistent_winding_is_fixed(capsys, tmp_path):
    vertices, faces = cube()
    faces = faces.copy()
    faces[[1, 4, 9]] = faces[[1, 4, 9]][:, ::-1]  # flip three of the twelve triangles
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert not mesh.is_winding_consistent
    write_with_trimesh(tmp_path / "mixed.ply", vertices, faces)
    job = surface_job(tmp_path, "mixed.ply")
    err = assert_meshed(capsys, tmp_path, job)
    (warning,) = notes(err)
    assert warning.startswith(f"warning: {tmp_path / 'mixed.ply'}: ")
    assert "fixed inconsistent face orientation" in warning


# --------------------------------------------------------------------------- job files


def test_missing_job_file(capsys, tmp_path):
    assert_refused(capsys, tmp_path, tmp_path / "nojob.yaml", "file not found", where=str(tmp_path / "nojob.yaml"))


@pytest.mark.parametrize(
    "text, location, fragment",
    [
        pytest.param("geometry:\n\tshape: cylinder\n", "2:1", "'\\t'", id="tab"),
        pytest.param("geometry:\n  shape: cylinder\nsize: [1, 2\n", "4:1", "expected ','", id="unclosed-bracket"),
        pytest.param("geometry: shape: cylinder\n", "1:16", "mapping values are not allowed", id="nested-colon"),
    ],
)
def test_broken_yaml_syntax(capsys, tmp_path, text, location, fragment):
    job = tmp_path / "job.yaml"
    job.write_text(text)
    assert_refused(capsys, tmp_path, job, "invalid YAML", fragment, "fix the YAML syntax", where=f"{job}:{location}")


def test_libyaml_reads_what_the_pure_python_parser_reads():
    """Every shipped YAML file (knowledge, patterns, examples) parses to the same values, key order and source
    marks (line, column of every mapping and key) with libyaml's parser as with PyYAML's pure-Python one, which
    parse_yaml falls back to for its error messages (the broken-YAML tests above go through it)."""
    import yaml

    from engine.yamlfile import FAST_LOADER, _loader_for

    if FAST_LOADER is None:
        pytest.skip("PyYAML without libyaml")

    def same(a, b, path):
        assert type(a) is type(b) and (a == b or a != a), path  # NaN equals NaN here
        if isinstance(a, dict):
            assert list(a) == list(b) and (a.line, a.col, a.key_marks) == (b.line, b.col, b.key_marks), path
            for key in a:
                same(a[key], b[key], f"{path}/{key}")
        elif isinstance(a, list):
            for i, (x, y) in enumerate(zip(a, b)):
                same(x, y, f"{path}[{i}]")

    root = Path(__file__).resolve().parents[1]
    files = [f for folder in ("knowledge", "patterns", "examples") for f in sorted((root / folder).rglob("*.yaml"))]
    assert len(files) > 20
    for path in files:
        text = path.read_text()
        same(
            yaml.load(text, Loader=_loader_for(str(path))),
            yaml.load(text, Loader=_loader_for(str(path), base=FAST_LOADER)),
            path.name,
        )  # noqa: S506


def test_job_file_not_utf8(capsys, tmp_path):
    job = tmp_path / "job.yaml"
    job.write_bytes(b"geometry:\n  shape: cyl\xe9nder\n")
    assert_refused(capsys, tmp_path, job, "cannot read", "UTF-8", where=str(job))


@pytest.mark.parametrize("text", ["", "\n\n", "# only a comment\n"], ids=["zero-bytes", "blank", "comment"])
def test_empty_job_file(capsys, tmp_path, text):
    job = tmp_path / "job.yaml"
    job.write_text(text)
    assert_refused(capsys, tmp_path, job, "empty", where=f"{job}:1:1")


@pytest.mark.parametrize(
    "text",
    [
        pytest.param("- geometry:\n    shape: cylinder\n", id="list"),
        pytest.param("just a sentence\n", id="string"),
        pytest.param("42\n", id="number"),
    ],
)
def test_top_level_not_a_mapping(capsys, tmp_path, text):
    job = tmp_path / "job.yaml"
    job.write_text(text)
    assert_refused(capsys, tmp_path, job, "must be a YAML mapping", where=str(job))


def test_unknown_top_level_key(capsys, tmp_path):
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: cylinder
        size: 10
        sizes: 2.5
        output:
          directory: out
        """,
    )
    line = assert_refused(
        capsys, tmp_path, job, "unknown key 'sizes' at the top level", "allowed keys:", where=f"{job}:4:1"
    )
    for key in ("geometry", "size", "packer", "mesher", "seed", "output"):
        assert re.search(rf"\b{key}\b", line.split("allowed keys:")[1]), key


def test_unknown_key_in_geometry(capsys, tmp_path):
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: cylinder
          colour: red
        output:
          directory: out
        """,
    )
    line = assert_refused(
        capsys, tmp_path, job, "unknown key 'colour' in 'geometry'", "allowed keys:", where=f"{job}:3:3"
    )
    assert "shape" in line and "file" in line and "allow_multiple_solids" in line


def test_unknown_shape_parameter(capsys, tmp_path):
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: cylinder
          parameters:
            radius: 5
            diameter: 10
        output:
          directory: out
        """,
    )
    line = assert_refused(
        capsys, tmp_path, job, "unknown key 'diameter'", "cylinder", "allowed keys:", where=f"{job}:5:5"
    )
    assert "radius" in line.split("allowed keys:")[1] and "height" in line.split("allowed keys:")[1]


@pytest.mark.parametrize(
    "value, fragment",
    [
        pytest.param('"big"', "must be number, got string 'big'", id="string"),
        pytest.param("[1, 2]", "must be number, got a list", id="list"),
        pytest.param("true", "must be number, got boolean", id="bool"),
        pytest.param("0", "must be a finite number > 0, got 0", id="zero"),
        pytest.param("-1", "must be a finite number > 0, got -1", id="negative"),
        pytest.param(".nan", "must be a finite number > 0, got nan", id="nan"),
        pytest.param(".inf", "must be a finite number > 0, got inf", id="inf"),
    ],
)
def test_bad_size(capsys, tmp_path, value, fragment):
    job = write_job(
        tmp_path,
        f"""
        geometry:
          shape: cylinder
        size: {value}
        output:
          directory: out
        """,
    )
    assert_refused(capsys, tmp_path, job, "'size'", fragment, where=f"{job}:3:1")


@pytest.mark.parametrize(
    "value, fragment",
    [
        pytest.param("1.5", "'seed' must be integer, got number 1.5", id="float"),
        pytest.param("abc", "'seed' must be integer, got string 'abc'", id="string"),
    ],
)
def test_bad_seed(capsys, tmp_path, value, fragment):
    job = write_job(
        tmp_path,
        f"""
        geometry:
          shape: cylinder
        size: 10
        seed: {value}
        output:
          directory: out
        """,
    )
    assert_refused(capsys, tmp_path, job, fragment, where=f"{job}:4:1")


def test_negative_seed(capsys, tmp_path):
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: cylinder
        size: 20
        seed: -1
        output:
          directory: out
        """,
    )
    assert_refused(capsys, tmp_path, job, "'seed'", where=f"{job}:4:1")


def test_size_in_exponent_notation_is_a_number(capsys, tmp_path):
    write_obj(tmp_path / "cube.obj", *cube())
    job = write_job(
        tmp_path,
        """
        geometry:
          file: cube.obj
        size: 2.5e0
        output:
          directory: out
        """,
    )
    assert_meshed(capsys, tmp_path, job)


def test_unknown_shape(capsys, tmp_path):
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: donut
        output:
          directory: out
        """,
    )
    line = assert_refused(
        capsys, tmp_path, job, "'geometry.shape' is 'donut', which is not known", "choose one of:", where=f"{job}:2:3"
    )
    for shape in ("cylinder", "plate", "plate_with_hole", "plate_cylinder_junction", "l_bracket", "cracked_plate"):
        assert shape in line


def test_unknown_packer(capsys, tmp_path):
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: cylinder
        packer: bubbles-of-doom
        output:
          directory: out
        """,
    )
    assert_refused(
        capsys,
        tmp_path,
        job,
        "'packer' is 'bubbles-of-doom', which is not known",
        "choose one of:",
        "lattice",
        where=f"{job}:3:1",
    )


def test_unknown_mesher(capsys, tmp_path):
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: cylinder
        mesher: advancing-front-9000
        output:
          directory: out
        """,
    )
    assert_refused(capsys, tmp_path, job, "'mesher' is 'advancing-front-9000'", "delaunay", where=f"{job}:3:1")


def test_geometry_with_shape_and_file(capsys, tmp_path):
    write_obj(tmp_path / "cube.obj", *cube())
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: cylinder
          file: cube.obj
        output:
          directory: out
        """,
    )
    assert_refused(capsys, tmp_path, job, "exactly one of 'shape' or 'file'", where=f"{job}:2:3")


@pytest.mark.parametrize(
    "geometry, location",
    [
        pytest.param("geometry:\n  allow_multiple_solids: true\n", "2:3", id="other-key-only"),
        pytest.param("geometry: {}\n", "1:11", id="empty-mapping"),
    ],
)
def test_geometry_with_neither_shape_nor_file(capsys, tmp_path, geometry, location):
    job = tmp_path / "job.yaml"
    job.write_text(geometry + "output:\n  directory: out\n")
    assert_refused(capsys, tmp_path, job, "exactly one of 'shape' or 'file'", where=f"{job}:{location}")


@pytest.mark.parametrize(
    "text",
    [
        pytest.param("output:\n  directory: out\n", id="no-geometry-key"),
        pytest.param("geometry:\noutput:\n  directory: out\n", id="geometry-null"),
    ],
)
def test_geometry_missing(capsys, tmp_path, text):
    job = tmp_path / "job.yaml"
    job.write_text(text)
    assert_refused(capsys, tmp_path, job, "missing key 'geometry'", "add 'geometry:'", where=f"{job}:1:1")


@pytest.mark.parametrize(
    "formats, fragment",
    [
        pytest.param("[vtu, stl]", "unknown or no formats ['stl']", id="unknown"),
        pytest.param("[]", "unknown or no formats", id="empty"),
        pytest.param("vtu", "'output.formats' must be list", id="not-a-list"),
    ],
)
def test_bad_output_formats(capsys, tmp_path, formats, fragment):
    job = write_job(
        tmp_path,
        f"""
        geometry:
          shape: cylinder
        size: 10
        output:
          directory: out
          formats: {formats}
        """,
    )
    line = assert_refused(capsys, tmp_path, job, fragment, where=f"{job}:6:3")
    if "unknown" in fragment:
        assert "allowed: vtu, msh" in line


def test_output_directory_is_a_file(capsys, tmp_path):
    write_obj(tmp_path / "cube.obj", *cube())
    job = write_job(
        tmp_path,
        """
        geometry:
          file: cube.obj
        size: 2.5
        output:
          directory: cube.obj
        """,
    )
    assert_refused(capsys, tmp_path, job, "is an existing file", "name a folder", where=f"{job}:5:3")


def test_output_target_is_a_directory(capsys, tmp_path):
    write_obj(tmp_path / "cube.obj", *cube())
    (tmp_path / "out" / "mesh.msh").mkdir(parents=True)
    job = surface_job(tmp_path, "cube.obj")
    assert_refused(capsys, tmp_path, job, "mesh.msh")


def test_empty_output_name(capsys, tmp_path):
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: cylinder
        size: 20
        output:
          directory: out
          name: ''
        """,
    )
    assert_refused(capsys, tmp_path, job, "'output.name'", where=f"{job}:6:3")


def test_parameters_with_file(capsys, tmp_path):
    write_obj(tmp_path / "cube.obj", *cube())
    job = write_job(
        tmp_path,
        """
        geometry:
          file: cube.obj
          parameters:
            radius: 5
        size: 2.5
        output:
          directory: out
        """,
    )
    assert_refused(
        capsys, tmp_path, job, "'parameters' is for built-in shapes only", "use 'shape:'", where=f"{job}:3:3"
    )


INCONSISTENT_SHAPES = {
    # shape: (parameters, what the message says, the parameter it advises to change)
    "plate_with_hole": ("{width: 40, hole_radius: 30}", "the hole does not fit inside the plate", "hole_radius"),
    "plate_cylinder_junction": ("{offset: 500}", "the cylinder does not stand inside the plate", "offset"),
    "l_bracket": ("{fillet_radius: 100}", "the bracket profile is inconsistent", "fillet_radius"),
    "cracked_plate": ("{crack: straight, crack_length: 500}", "the crack is longer than the plate", "crack_length"),
}


def _inconsistent_shape_job(tmp_path, shape):
    parameters = INCONSISTENT_SHAPES[shape][0]
    return write_job(
        tmp_path,
        f"""
        geometry:
          shape: {shape}
          parameters: {parameters}
        size: 10
        output:
          directory: out
        """,
    )


@pytest.mark.parametrize("shape", INCONSISTENT_SHAPES)
def test_inconsistent_shape_parameters(capsys, tmp_path, shape):
    _, what, parameter = INCONSISTENT_SHAPES[shape]
    job = _inconsistent_shape_job(tmp_path, shape)
    code, _, err = run_cli(capsys, job)
    line = error_line(err)
    assert code == 2
    assert what in line and parameter in line.split(";", 1)[1], line
    assert not mesh_files(tmp_path)


@pytest.mark.parametrize("shape", INCONSISTENT_SHAPES)
def test_inconsistent_shape_parameters_names_the_job_file(capsys, tmp_path, shape):
    job = _inconsistent_shape_job(tmp_path, shape)
    line = error_line(run_cli(capsys, job)[2])
    assert f"{ERROR_PREFIX} {job}:3:3: " in line, line


@pytest.mark.parametrize(
    "shape, parameter, value",
    [
        ("plate_with_hole", "hole_x", ".nan"),
        ("plate_with_hole", "hole_y", ".inf"),
        ("plate_cylinder_junction", "offset", ".nan"),
    ],
)
def test_non_finite_shape_position(capsys, tmp_path, shape, parameter, value):
    job = write_job(
        tmp_path,
        f"""
        geometry:
          shape: {shape}
          parameters:
            {parameter}: {value}
        size: 10
        output:
          directory: out
        """,
    )
    assert_refused(capsys, tmp_path, job, f"'geometry.parameters ({shape}).{parameter}'", "finite", where=f"{job}:4:5")


def _junction_too_fine(tmp_path):
    return write_job(
        tmp_path,
        """
        geometry:
          shape: plate_cylinder_junction
        size: 0.001
        output:
          directory: out
        """,
    )


def test_impossible_size_hits_element_limit(capsys, tmp_path):
    job = _junction_too_fine(tmp_path)
    code, _, err = run_cli(capsys, job)
    line = error_line(err)
    assert code == 2
    assert "tetrahedra (limit " in line and "--max-elements" in line and "larger size" in line
    assert not mesh_files(tmp_path)


def test_the_default_limit_is_what_the_machine_s_memory_holds(capsys, tmp_path, monkeypatch):
    """With no --max-elements the guard refuses more than 2e7 tetrahedra, or a run expected to need more memory at
    its peak than the machine has available now: an outside test's heat sink (1e7 tets at its default size) ran
    70 s and died of a MemoryError (exit 3), or was killed by the kernel with no message at all; a relief groove's
    job expected at 14 GB ran 11 minutes where another user held half of a 23 GB machine."""
    from engine.sizing import counts

    available, total = counts.available_memory()  # this machine's, read from /proc/meminfo
    assert 0 < available <= total < float("inf")
    monkeypatch.setattr(counts, "available_memory", lambda: (2.0**29, 2.0**34))  # the junction at size 2: ~1 GiB
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: plate_cylinder_junction
        size: 2
        output:
          directory: out
        """,
    )
    code, _, err = run_cli(capsys, job)
    line = error_line(err)
    assert code == 2 and "GiB of memory at the run's peak: this machine has 0.5 GiB available now (of 16.0" in line
    assert "--max-elements" in line
    assert not mesh_files(tmp_path)
    tets = 1e6
    small = counts.ExpectedCounts(nodes=tets / 5.5, boundary_nodes=0.1 * tets / 5.5, tets=tets, patterns=2)
    assert 0.3e9 < small.peak_bytes() < small.peak_bytes(order=2) < 2e9
    finned = small._replace(boundary_nodes=0.7 * tets / 5.5)
    assert finned.peak_bytes() > small.peak_bytes(), "a boundary node costs more than an interior one"


def test_running_out_of_memory_is_one_line(capsys, tmp_path, monkeypatch):
    import engine.pipeline

    def starved(*args, **kwargs):
        raise MemoryError("Unable to allocate 3.99 GiB for an array with shape (178732484, 3)")

    monkeypatch.setattr(engine.pipeline, "run", starved)
    job = write_job(tmp_path, "geometry:\n  shape: plate\noutput:\n  directory: out\n")
    code, _, err = run_cli(capsys, job)
    line = error_line(err)
    assert code == 2 and "out of memory" in line and "3.99 GiB" in line and "--max-elements" in line


def test_max_elements_option_is_honoured(capsys, tmp_path):
    # the junction at size 8 needs far more than 10 tetrahedra: the limit given on the command line applies
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: plate_cylinder_junction
        size: 8
        output:
          directory: out
        """,
    )
    code, _, err = run_cli(capsys, job, "--max-elements", "10")
    line = error_line(err)
    assert code == 2 and "(limit 10)" in line
    assert not mesh_files(tmp_path)


def test_a_refused_count_names_the_pattern_that_needs_the_elements(capsys, tmp_path):
    """A 2 mm plate meshed at size 20: the sizing defaults' thin-wall rule (2 elements through) sets the size where
    nearly all the elements are, so a larger size would not help: the line names the rule and how to replace it
    (an outside test's heat sink: 57 % of its 1e7 tets under 0.8 mm fins)."""
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: plate
          parameters: {length: 200, width: 200, thickness: 2}
        size: 20
        output:
          directory: out
        """,
    )
    code, _, err = run_cli(capsys, job, "--max-elements", "1e5")
    line = error_line(err)
    assert code == 2 and "(limit 1e+05)" in line
    assert "of them lie where 'thin-wall" in line and "(pattern 'thin-wall', placed by sizing defaults)" in line
    assert "place 'thin-wall' in the job with coarser parameters (it then replaces the sizing defaults')" in line
    assert not mesh_files(tmp_path)


def test_a_refused_count_names_the_pattern_whose_size_the_gradation_spreads(capsys, tmp_path):
    """A block with a 0.1 mm slit: the slit's narrow-gap size (0.05) grows by the gradation through most of the
    block, where the base pattern wins with a far larger size; the line names the slit's pattern, not 'base'
    (an outside test's adapter with four 0.1 mm slits)."""
    block = trimesh.creation.box([20.0, 20.0, 10.0])
    slit = trimesh.creation.box([0.1, 30.0, 8.0])
    slit.apply_translation([0.0, 0.0, 2.0])
    block.difference(slit, engine="manifold").export(str(tmp_path / "slit.stl"))
    job = write_job(tmp_path, "geometry: {file: slit.stl}\noutput: {directory: out}\n")
    code, _, err = run_cli(capsys, job, "--max-elements", "1e4")
    line = error_line(err)
    assert code == 2 and "of them lie where the size grows (by the gradation, 1.3) from the 0.05 that" in line, line
    assert "'narrow-gap@gap-" in line and "place 'narrow-gap' in the job with coarser parameters" in line
    assert not mesh_files(tmp_path)


def test_impossible_size_names_the_job_file(capsys, tmp_path):
    job = _junction_too_fine(tmp_path)
    line = error_line(run_cli(capsys, job)[2])
    assert str(job) in line, line


def test_duplicate_key(capsys, tmp_path):
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: cylinder
        size: 10
        size: 5
        output:
          directory: out
        """,
    )
    assert_refused(capsys, tmp_path, job, "duplicate key 'size'", "once", where=f"{job}:4:1")


def test_duplicate_nested_key(capsys, tmp_path):
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: cylinder
          parameters:
            radius: 5
            radius: 6
        output:
          directory: out
        """,
    )
    assert_refused(capsys, tmp_path, job, "duplicate key 'radius'", where=f"{job}:5:5")


def test_yaml_is_loaded_safely(capfd, tmp_path):
    marker = tmp_path / "hacked"
    job = write_job(
        tmp_path,
        f"""
        geometry:
          shape: !!python/object/apply:os.system ["echo hacked; touch {marker}"]
        output:
          directory: out
        """,
    )
    code, out, err = run_cli(capfd, job)  # file-descriptor level: would see the shell's echo
    line = error_line(err)
    assert code == 2
    assert not marker.exists()
    assert "hacked" not in out
    assert f"{job}:2:10: " in line and "python/object/apply:os.system" in line
    assert not mesh_files(tmp_path)


def test_bad_command_line_size(capsys, tmp_path):
    job = write_job(
        tmp_path,
        """
        geometry:
          shape: cylinder
        output:
          directory: out
        """,
    )
    try:
        code = main(["mesh", str(job), "--size", "-1"])
    except SystemExit as exit_:
        code = exit_.code
    line = error_line(capsys.readouterr().err)
    assert code == 2 and "--size" in line


# --------------------------------------------------------------------------- end to end


def _cli_command() -> list[str]:
    script = Path(sys.executable).parent / "fuzzymesh"
    return [str(script)] if script.exists() else [sys.executable, "-m", "engine.cli"]


@pytest.mark.parametrize("case", ["overlapping", "broken-yaml"])
def test_subprocess_one_line_no_traceback(tmp_path, case):
    if case == "overlapping":
        write_with_trimesh(tmp_path / "overlap.stl", *two_cubes(offset=(5.0, 5.0, 5.0)))
        job = surface_job(tmp_path, "overlap.stl")
        command, expected = _cli_command(), "touch or overlap"
    else:
        job = tmp_path / "job.yaml"
        job.write_text("geometry:\n  shape: [cylinder\n")
        command, expected = [sys.executable, "-m", "engine.cli"], "invalid YAML"
    proc = subprocess.run([*command, "mesh", str(job)], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert proc.stdout == ""
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"{ERROR_PREFIX} {job if case == 'broken-yaml' else tmp_path / 'overlap.stl'}")
    assert expected in lines[0]
    assert not mesh_files(tmp_path)
