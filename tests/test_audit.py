"""The audit: every element's size traced to the pattern, zone, placement and rule behind it."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import meshio
import numpy as np
import pytest

from engine.cli import main


@pytest.fixture(scope="module")
def junction(junction_run):
    out, result = junction_run
    return out.parent, result


def test_recomputed_sizing_reproduces_the_audit_of_1000_random_elements(junction):
    folder, result = junction
    vtu = meshio.read(folder / "out" / "mesh.vtu")
    cells = {name: values[0] for name, values in vtu.cell_data.items()}
    tets = vtu.cells_dict["tetra"]
    pick = np.random.default_rng(0).choice(len(tets), size=1000, replace=False)
    evaluation = result.sizing.evaluate(vtu.points[tets[pick]].mean(axis=1))
    assert np.allclose(cells["h_target"][pick], evaluation.h, rtol=1e-9)
    assert np.array_equal(cells["winner"][pick], evaluation.winner)
    assert np.allclose(cells["winner_mu"][pick], evaluation.mu[np.arange(1000), evaluation.winner])
    assert np.array_equal(cells["graded"][pick].astype(bool), evaluation.graded)
    assert len(np.unique(cells["winner"])) >= 2, "the junction pattern and the base both size elements"


def existing_location(source: str) -> bool:
    match = re.fullmatch(r"(.+):(\d+):(\d+)", source)
    if not match:
        return False
    path, line = Path(match.group(1)), int(match.group(2))
    return path.is_file() and line <= len(path.read_text().splitlines())


def test_every_id_in_the_mesh_is_in_the_legend_with_an_existing_file_line(junction):
    folder, _ = junction
    vtu = meshio.read(folder / "out" / "mesh.vtu")
    legend = json.loads((folder / "out" / "mesh.audit.json").read_text())
    cells, nodes = {k: v[0] for k, v in vtu.cell_data.items()}, vtu.point_data
    tables = {"winner": "patterns", "runner_up": "patterns", "zone": "zones", "placement": "placements"}
    for field, table in tables.items():
        for index in np.unique(cells[field]):
            if index >= 0:
                entry = legend[table][index]
                assert entry["index"] == index
                source = entry.get("source") or legend["placements"][entry["placement_index"]]["source"]
                assert existing_location(source), (field, entry)
    for index in np.unique(nodes["insert_rule"]):
        if index >= 0:
            assert existing_location(legend["rules"][index]["source"])
    assert (nodes["inserted_at"] >= 0).any(), "some nodes were inserted by the population rules"
    levels = np.unique(nodes["node_level"])
    assert set(levels) <= set(range(len(legend["levels"])))
    for level, table in enumerate(("corners", "curves", "patches")):
        entities = np.unique(nodes["node_entity"][nodes["node_level"] == level])
        assert entities.max(initial=-1) < len(legend[table])


def test_explain_an_element_and_a_point_from_the_saved_files(junction, capsys):
    folder, result = junction
    out = folder / "out"
    vtu = meshio.read(out / "mesh.vtu")
    cells = {k: v[0] for k, v in vtu.cell_data.items()}
    element = int(np.flatnonzero(cells["graded"] == 1)[0])
    assert main(["explain", str(out), "--element", str(element)]) == 0
    text = capsys.readouterr().out
    winner = result.sizing.placed[cells["winner"][element]]
    assert f"element {element}" in text and winner.id in text and winner.placement.source in text
    assert "lowered the size" in text
    junction_point = result.features.named("junction")[0].points[0] + [0.5, 0.0, -0.5]
    assert main(["explain", str(out / "mesh.vtu"), "--at", *map(str, junction_point)]) == 0
    text = capsys.readouterr().out
    assert "lies in element" in text and "plate-edge-junction" in text
    assert main(["explain", str(out), "--element", "-1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fuzzymesh: error: ")


def test_a_placed_pattern_that_wins_no_element_is_a_warning_in_the_log_and_the_report(tmp_path, caplog):
    import logging

    import yaml

    from engine.job import load_job
    from engine.pipeline import run

    job = tmp_path / "job.yaml"
    job.write_text(
        yaml.safe_dump(
            {
                "geometry": {"shape": "cylinder"},
                "size": 12.0,
                "output": {"formats": ["vtu"]},
                "place": [
                    {"pattern": "uniform-domain", "id": "coarse", "parameters": {"size": 1.2}},  # ties, larger h
                    {"pattern": "uniform-domain", "id": "base"},
                    {
                        "pattern": "uniform-region",
                        "id": "far-away",
                        "parameters": {"size": 3},
                        "region": {"box": {"min": [500, 500, 500], "max": [510, 510, 510]}},
                    },
                ],
            }
        )
    )
    with caplog.at_level(logging.WARNING):
        result = run(load_job(job))
    won = np.bincount(result.audit.cells["winner"] + 1, minlength=len(result.sizing.placed) + 1)[1:]
    idle = {p.id for p, n in zip(result.sizing.placed, won) if n == 0 and p.placement.origin == "job"}
    assert idle == {"coarse", "far-away"}
    logged = [
        m for m in (r.getMessage() for r in caplog.records if r.levelno == logging.WARNING) if "wins no element" in m
    ]
    report = json.loads((tmp_path / "out" / "mesh.report.json").read_text())
    # the job's own placements only: the sizing defaults' (thin-wall, curvature, ...) are placed on every feature
    assert report["warnings"] == logged == result.warnings and len(logged) == len(idle)
    assert all("placed by job" in warning for warning in logged)
    coarse = next(w for w in logged if "'coarse'" in w)
    far = next(w for w in logged if "'far-away'" in w)
    assert f"{job}:" in coarse and "membership is > 0 at" in coarse and "higher" in coarse
    assert "membership is 0 at every element" in far
    page = (tmp_path / "out" / "mesh.report.html").read_text()
    assert all(html.escape(warning) in page for warning in logged), "each warning is a row of the HTML report"
    assert "mesh → input max" in page, "the report gives both Hausdorff directions"
