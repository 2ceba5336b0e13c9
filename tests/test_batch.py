"""Batch meshing on dask.distributed (engine/batch.py, docs/batch.md): study files, a LocalCluster of 2 worker
processes on a 6-variant junction family (one variant refused), the table, the page, resuming, Ctrl-C."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import meshio
import pyarrow.parquet as pq
import pytest

from engine.batch import batch, load_study
from engine.cli import main
from engine.errors import JobError

ROOT = Path(__file__).resolve().parents[1]
PAPER_SIZING = ROOT / "examples" / "knowledge" / "paper-sizing.yaml"
STUDY = """job: base.yaml
cross:
  radius: {from: 15, to: 25, step: 5}
  offset: [60, 75]          # offset 75 + radius 25 puts the cylinder on the plate edge: refused
output: {directory: out}
"""


def write_study(folder: Path, study: str = STUDY) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "base.yaml").write_text(
        f"geometry: {{shape: plate_cylinder_junction}}\nsize: 25\n"
        f"knowledge: [{PAPER_SIZING}]\noutput: {{formats: [vtu]}}\n"
    )
    (folder / "study.yaml").write_text(study)
    return folder / "study.yaml"


def test_a_grid_crosses_ranges_and_lists_and_zips_keys_together(tmp_path):
    study = load_study(write_study(tmp_path))
    assert [v.name for v in study.variants] == [f"radius-{r}_offset-{o}" for r in (15, 20, 25) for o in (60, 75)]
    assert study.variants[1].job["geometry"]["parameters"] == {"radius": 15, "offset": 75}
    assert {Path(v.directory).parent for v in study.variants} == {(tmp_path / "out" / "variants").resolve()}
    zipped = load_study(
        write_study(
            tmp_path,
            "job: base.yaml\nzip: {seed: [0, 1], output.order: [1, 2]}\ncross: {size: {from: 20, to: 30, count: 3}}\n",
        )
    )
    assert [(v.job["size"], v.job["seed"], v.job["output"]["order"]) for v in zipped.variants] == [
        (s, seed, seed + 1) for s in (20.0, 25.0, 30.0) for seed in (0, 1)
    ]
    assert len({v.digest for v in zipped.variants}) == 6, "every variant is a different job"


@pytest.mark.parametrize(
    "study, message, line",
    [
        ("job: base.yaml\ncross: {radius: [10, 20]}\nzip: {seed: [0, 1], size: [5]}\n", "different lengths", 3),
        ("job: base.yaml\ncross:\n  radiu: [10, 20]\n", "neither a job key nor a parameter", 3),
        ("job: base.yaml\ncross:\n  radius: [10, -1]\n", "'radius' must be", 3),
        ("job: base.yaml\ncross:\n  size: {from: 10, to: 20}\n", "exactly one of 'step' or 'count'", 3),
        ("job: base.yaml\ncross:\n  output.directory: [a, b]\n", "the study sets output.directory", 3),
        ("job: base.yaml\nfiles: parts/*.stl\n", "names no geometry file", 2),
        ("job: base.yaml\ncross: {seed: [1, 1]}\n", "more than once", 1),
        ("job: base.yaml\ngrid: {seed: [1]}\n", "unknown key 'grid'", 2),
    ],
)
def test_a_bad_study_is_refused_with_one_located_line(tmp_path, study, message, line):
    path = write_study(tmp_path, study)
    with pytest.raises(JobError) as error:
        load_study(path)
    assert message in str(error.value) and f"{path}:{line}:" in str(error.value)
    assert "\n" not in str(error.value)


def test_a_folder_of_parts_is_one_variant_per_file_and_the_hash_follows_the_file(tmp_path):
    parts = tmp_path / "parts"
    parts.mkdir()
    for name in ("a.stl", "b.stl"):
        (parts / name).write_bytes((ROOT / "examples" / "bearing-block.stl").read_bytes())
    (parts / "notes.txt").write_text("not a part")
    study = load_study(write_study(tmp_path, "job: base.yaml\nfiles: parts\n"))
    assert [v.name for v in study.variants] == ["a.stl", "b.stl"]
    assert "shape" not in study.variants[0].job["geometry"] and study.variants[0].parameters["file"].endswith("a.stl")
    before = study.variants[0].digest
    (parts / "a.stl").write_bytes((parts / "a.stl").read_bytes() + b"\n")
    assert load_study(tmp_path / "study.yaml").variants[0].digest != before


@pytest.fixture(scope="module")
def meshed(tmp_path_factory):
    """The 6-variant junction family on a LocalCluster of 2 worker processes."""
    path = write_study(tmp_path_factory.mktemp("study"))
    start = time.perf_counter()
    rows, files = batch(path, workers=2)
    return path, rows, files, time.perf_counter() - start


def test_the_study_meshes_every_variant_and_refuses_one_without_stopping_the_others(meshed):
    path, rows, files, seconds = meshed
    assert [r["status"] for r in rows] == ["ok"] * 5 + ["refused"]
    assert "does not stand inside the plate" in rows[-1]["message"] and "[radius-25_offset-75]" in rows[-1]["message"]
    assert len({r["worker"] for r in rows[:5]}) == 2, "both worker processes meshed"
    for row in rows[:5]:
        vtu = meshio.read(Path(row["directory"]) / "mesh.vtu")
        assert row["tetrahedra"] == len(vtu.cells_dict["tetra"]) > 0 and row["nodes"] == len(vtu.points)
        assert row["min_dihedral"] >= 5 and 0 < row["conformity_within"] <= 1
        assert row["time_packing"] > 0 and row["time_total"] >= sum(
            v for k, v in row.items() if k.startswith("time_") and k != "time_total"
        )
        assert 50 < row["peak_memory_mb"] < 4000
    assert len({r["tetrahedra"] for r in rows[:5]}) > 1, "the radius changes the mesh"
    assert not list(path.parent.rglob(".*")), "no temporary files left"
    print(f"6 variants on 2 workers in {seconds:.1f} s")


def test_the_table_and_the_page(meshed):
    path, rows, files, _ = meshed
    assert [p.name for p in files] == ["study.csv", "study.parquet", "study.html"]
    with open(files[0], newline="") as handle:
        table = list(csv.DictReader(handle))
    assert [r["variant"] for r in table] == [r["variant"] for r in rows]
    assert [r["radius"] for r in table] == ["15", "15", "20", "20", "25", "25"]
    assert table[0]["tetrahedra"] == str(rows[0]["tetrahedra"]) and table[-1]["tetrahedra"] == ""
    parquet = pq.read_table(files[1]).to_pylist()
    assert [r["status"] for r in parquet] == [r["status"] for r in rows]
    assert parquet[2]["min_dihedral"] == pytest.approx(rows[2]["min_dihedral"])
    page = files[2].read_text()
    assert page.count("data:image/png;base64,") == 2, "one figure per varied parameter"
    assert "5 ok, 1 refused, 0 rejected, 0 failed" in page


def test_a_second_run_meshes_only_what_is_missing(meshed):
    path, rows, _, _ = meshed
    (Path(rows[2]["directory"]) / "mesh.vtu").unlink()
    again, _ = batch(path, workers=2)
    assert [r.get("cached") for r in again] == [True, True, False, True, True, None]
    assert [r["status"] for r in again] == [r["status"] for r in rows]
    assert again[2]["tetrahedra"] == rows[2]["tetrahedra"], "same job, same seed: the same mesh"
    assert (Path(rows[2]["directory"]) / "mesh.vtu").is_file()


def test_the_command_line_refuses_a_bad_study_with_one_line(tmp_path, capsys):
    assert main(["batch", str(write_study(tmp_path, "job: base.yaml\n"))]) == 2
    assert "the study varies nothing" in capsys.readouterr().err


def test_ctrl_c_stops_the_study_and_leaves_no_partial_files(tmp_path):
    path = write_study(tmp_path, STUDY.replace("[60, 75]", "[60, 70, 75]"))
    env = {k: v for k, v in os.environ.items() if k != "DASK_SCHEDULER_ADDRESS"}
    run = subprocess.Popen(
        [sys.executable, "-m", "engine.cli", "batch", str(path), "--workers", "2", "-q"],
        env=env,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    deadline = time.time() + 60
    while not list(tmp_path.glob("out/variants/*/variant.json")) and time.time() < deadline:
        time.sleep(0.2)
    os.killpg(run.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole process group
    assert run.wait(timeout=60) == 130, run.stderr.read()
    assert not list(tmp_path.rglob(".*")), "no temporary files left"
    assert not (tmp_path / "out" / "study.csv").exists()
    done = [p.parent for p in tmp_path.glob("out/variants/*/variant.json")]
    assert 0 < len(done) < 9
