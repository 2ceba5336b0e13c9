"""`fuzzymesh features FILE_OR_JOB`: every corner, curve and patch with its kinds, size and place; JSON with
--json; one error line and exit code 2 on a broken file; `describe` names a feature by id and centroid."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
import yaml

from engine.cli import main
from engine.features import describe


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main(["features", *map(str, argv)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def columns(line: str) -> list[str]:
    """The cells of a table row (columns are separated by two spaces or more)."""
    return re.split(r"\s{2,}", line.strip())


@pytest.fixture
def plate_job(tmp_path):
    job = tmp_path / "plate.yaml"
    job.write_text(
        yaml.safe_dump({"geometry": {"shape": "plate_with_hole", "parameters": {"hole_radius": 12, "hole_x": 20}}})
    )
    return job


def test_the_hole_of_a_built_in_plate_is_listed_with_its_radius_and_centroid(capsys, plate_job):
    code, out, _ = run(capsys, plate_job)
    assert code == 0
    lines = out.splitlines()
    assert lines[0].startswith(f"{plate_job}: 8 corners, 14 curves, 7 patches (feature angle 30 deg)")
    header = lines[1].split()
    assert header[:4] == ["id", "names", "kinds", "size"]
    (hole,) = [cells for cells in map(columns, lines[2:]) if cells[2] == "hole"]
    assert hole[0].startswith("patch-") and hole[1:] == [
        "hole",
        "hole",
        "A 753.7, r 12",
        "20, 0, 5",
        "[8, -12, 0] .. [32, 12, 10]",
    ]
    # the columns line up: every row's centroid starts where the header's does
    column = lines[1].index("centroid")
    assert all(line[column - 2 : column] == "  " for line in lines[2:])


def test_json_parses_and_holds_the_same_features(capsys, plate_job):
    code, out, _ = run(capsys, plate_job, "--json", "--feature-angle", "45")
    assert code == 0
    listing = json.loads(out)
    assert listing["feature_angle"] == 45 and listing["bodies"] == 1
    assert [len(listing[k]) for k in ("corners", "curves", "patches")] == [8, 14, 7]
    (hole,) = [p for p in listing["patches"] if "hole" in p["kinds"]]
    assert hole["names"] == ["hole"] and hole["radius"] == pytest.approx(12, rel=1e-6)
    assert hole["centroid"] == pytest.approx([20, 0, 5], abs=1e-6)
    rims = [c for c in listing["curves"] if c["radius"] is not None]
    assert len(rims) == 2 and all(c["closed"] and c["length"] == pytest.approx(2 * np.pi * 12, rel=2e-3) for c in rims)


def test_a_surface_file_lists_its_kinds(capsys):
    from pathlib import Path

    stl = Path(__file__).resolve().parents[1] / "examples" / "bearing-block.stl"
    code, out, _ = run(capsys, stl)
    assert code == 0
    rows = [columns(line) for line in out.splitlines()[2:]]
    holes = [row for row in rows if row[2] == "hole"]
    assert len(holes) == 3 and sorted(row[3].split(", r ")[1] for row in holes) == ["12", "6", "6"]
    assert any(row[2] == "junction, re-entrant-edge" and row[3].endswith("r 22") for row in rows)


def test_a_broken_file_is_one_line_and_exit_2(capsys, tmp_path):
    broken = tmp_path / "part.stl"
    broken.write_text("solid part\n  facet normal 0 0 1\nendsolid\n")
    code, out, err = run(capsys, broken)
    assert code == 2 and out == ""
    (line,) = err.strip().splitlines()
    assert line.startswith(f"fuzzymesh: error: {broken}: ") and "; " in line


def test_describe_gives_id_and_centroid(built):
    _, features = built("plate_with_hole")
    (hole,) = [p for p in features.patches if "hole" in p.names]
    assert describe(hole) == f"{hole.id} (centroid 0, 0, 5)"
    rim = next(c for c in features.curves if "hole" in c.names and np.allclose(c.points[:, 2], 10))
    assert describe(rim) == f"{rim.id} (centroid 0, 0, 10)"
    assert describe(features.corners[0]).startswith(f"{features.corners[0].id} (centroid -100, -50, ")


def test_a_listing_with_smooth_cuts_says_what_they_are(capsys, tmp_path):
    """A ball's surface is cut into charts along smooth curves: the table marks them and a line below says what a
    smooth cut is (an outside tester found '(smooth cut)' unexplained); a plate, with none, has no such line."""
    import trimesh

    trimesh.creation.icosphere(subdivisions=3, radius=5.0).export(str(tmp_path / "ball.stl"))
    code, out, _ = run(capsys, tmp_path / "ball.stl")
    lines = out.splitlines()
    assert code == 0 and any("(smooth cut)" in line for line in lines[2:-1])
    assert lines[-1].startswith("(smooth cut): not an edge of the solid but a cut across a smooth surface")
    plate = tmp_path / "plate.yaml"
    plate.write_text(yaml.safe_dump({"geometry": {"shape": "plate_with_hole"}}))
    code, out, _ = run(capsys, plate)
    assert code == 0 and "(smooth cut)" not in out
