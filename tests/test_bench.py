"""The benchmark harness (bench/run.py) on a tiny case, so it does not rot: it runs every mesher, writes
every figure, Gmsh sees our sizes, and the ratios are the ratios of the figures."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"
sys.path.insert(0, str(BENCH))  # the bench scripts import each other as top-level modules

from harness import FIGURES, MESH_STAGES  # noqa: E402

MESHERS = ("fuzzymesh", "gmsh-delaunay", "gmsh-hxt")


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """bench/run.py on the junction at the plate centre with every size x 8, one run each: 8k-14k
    tets (the curvature and thin-wall rules of knowledge/sizing.yaml floor the sizes whatever the scale)."""
    out = tmp_path_factory.mktemp("bench")
    done = subprocess.run(
        [
            sys.executable,
            str(BENCH / "run.py"),
            "--cases",
            "junction-centre",
            "--scale",
            "8",
            "--repeats",
            "1",
            "--no-warm-up",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return out, json.loads((out / "results.json").read_text())


def test_every_mesher_measured(tiny):
    _, results = tiny
    machine = {"cpu", "cores", "memory_gb", "date", "python", "numpy", "gmsh", "omp_wait_policy"}
    assert machine <= set(results["machine"])
    (row,) = results["rows"]
    assert row["case"] == "junction-centre" and row["scale"] == 8
    assert set(row["meshers"]) == set(MESHERS)
    for name, entry in row["meshers"].items():
        assert "error" not in entry, entry
        assert set(MESH_STAGES[name]) <= set(entry["seconds"])
        assert math.isclose(entry["mesh_seconds"], sum(entry["seconds"][s] for s in MESH_STAGES[name]), rel_tol=1e-9)
        for key in FIGURES:
            assert entry[key] > 0, (name, key)
        assert 500 < entry["tets"] < 20_000 and entry["nodes"] < entry["tets"]  # ours 14k: h is the mean edge
        assert entry["peak_mb"] >= entry["start_mb"] > 10
        assert 0 < entry["min_dihedral"] <= entry["p01_dihedral"] < 70.6
        assert 0 < entry["conformity_within"] <= 1 and entry["inverted"] == 0
        assert abs(entry["volume_error"]) < 0.02  # h ~ 13 chords on the r = 25 cylinder
    fuzzymesh = row["meshers"]["fuzzymesh"]
    assert {"packing", "meshing", "quality", "audit"} <= set(fuzzymesh["seconds"])
    assert fuzzymesh["peak_mb_pipeline"] >= fuzzymesh["peak_mb"]


def test_ratios_are_the_figures_ratios(tiny):
    _, results = tiny
    (row,) = results["rows"]
    ours = row["meshers"]["fuzzymesh"]
    assert set(row["ratios"]) == {"gmsh-delaunay", "gmsh-hxt"}
    for against, ratios in row["ratios"].items():
        theirs = row["meshers"][against]
        for key in FIGURES:
            assert math.isclose(ratios[key], ours[key] / theirs[key], rel_tol=1e-12), (against, key)


def test_gmsh_meshes_our_sizes(tiny):
    """The same grid in the fuzzymesh worker as in the harness, and Gmsh asks for our h(x) along every curve."""
    _, results = tiny
    field = results["rows"][0]["size_field"]
    assert field["same_as_fuzzymesh"] is True
    assert field["gmsh_probe"]["samples"] > 100
    assert field["gmsh_probe"]["max_relative_difference"] < 1e-9


def test_tables_and_plot(tiny):
    out, results = tiny
    text = (out / "results.md").read_text()
    assert results["machine"]["date"] in text
    for name in MESHERS:
        assert f"| junction-centre | x8 | {name} | {results['rows'][0]['meshers'][name]['tets']:,} |" in text
    assert "| junction-centre | x8 | gmsh-hxt | " in text.split("### fuzzymesh / Gmsh")[1]
    assert (out / "scaling.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [r["mesher"] for r in results["scaling"]] == list(MESHERS)


def test_paper_scale_and_targets(tiny):
    """The paper-scale example is timed end to end, and every target row is the comparison it names."""
    out, results = tiny
    paper = results["paper_scale"]
    assert 5_000 < paper["tets"] < 9_000 and paper["repeats"] == 1
    # the stages are parts of the run they were timed in (two runs' times, mesh only against mesh and files, are
    # not ordered on a busy machine: 1.72 s against 1.56 s in one CI run)
    assert 0 < sum(paper["mesh"]["stages"].values()) <= paper["mesh"]["median"]
    assert paper["mesh_and_files"]["median"] > 0 and paper["command"]["median"] > 0
    assert set(paper["mesh"]["stages"]) >= set(MESH_STAGES["fuzzymesh"])
    (row,) = results["rows"]
    ours, hxt = row["meshers"]["fuzzymesh"], row["meshers"]["gmsh-hxt"]
    by_name = {t["target"].split(":")[0]: t for t in results["targets"]}
    assert by_name["junction-centre x8"]["met"] == (ours["min_dihedral"] >= hxt["min_dihedral"])
    paper_target = next(t for t in results["targets"] if t["target"].startswith("paper scale"))
    assert paper_target["met"] == (paper["command"]["median"] <= 2.0)
    text = (out / "results.md").read_text()
    assert all(t["target"] in text for t in results["targets"])


def test_targets_of_the_tiers():
    """Issue 20's targets: at 1M time against 3x Gmsh HXT's and the analysis stages against 15 % on top, memory
    against 2 GB; at 10k and 100k time against 2x Gmsh Delaunay's; at 10M memory against 10 GB and seconds per
    1k tets against 1.2x the 1M row's; on every row the angle against HXT's."""
    from results import targets

    def row(tier, tets, seconds, analysis, peak, hxt_seconds, delaunay_seconds, angle):
        gmsh = {"tets": 0.5 * tets, "peak_mb": 0.2 * peak, "start_mb": 50}
        return {
            "case": "junction-edge",
            "tier": tier,
            "meshers": {
                "fuzzymesh": {
                    "tets": tets,
                    "mesh_seconds": seconds,
                    "analysis_seconds": analysis,
                    "peak_mb": 0.5 * peak,
                    "start_mb": 200,
                    "peak_mb_pipeline": peak,
                    "min_dihedral": 20.0,
                },
                "gmsh-delaunay": {**gmsh, "mesh_seconds": delaunay_seconds, "min_dihedral": 11.0},
                "gmsh-hxt": {**gmsh, "mesh_seconds": hxt_seconds, "min_dihedral": angle},
            },
        }

    rows = [
        row("100k", 1.5e5, 4.0, 1.0, 400, 0.5, 1.9, 14.0),
        row("1M", 1.5e6, 9.0, 1.5, 2100, 3.1, 25.0, 20.5),
        row("10M", 1e7, 70.0, 12.0, 9000, 30.0, 300.0, 14.0),
    ]
    met = {t["target"]: t["met"] for t in targets({"rows": rows})}
    assert met == {
        "junction-edge 100k: meshing time <= 2x Gmsh Delaunay's": False,
        "junction-edge 100k: min dihedral >= Gmsh HXT's": True,
        "junction-edge 1M: meshing time <= 3x Gmsh HXT's": True,
        "junction-edge 1M: analysis stages <= 15 % on top of meshing": False,
        "junction-edge 1M: peak memory <= 2048 MB": False,
        "junction-edge 1M: min dihedral >= Gmsh HXT's": False,
        "junction-edge 10M: peak memory <= 10 GB": True,
        "junction-edge 10M: seconds per 1k tets <= 1.2x the 1M row's": True,  # 0.0070 / 0.0060 s
        "junction-edge 10M: min dihedral >= Gmsh HXT's": True,
    }


def test_missing_gmsh_is_one_line(monkeypatch):
    import importlib.util

    import run

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "gmsh" else real(name, *a))
    assert run.missing_requirement() == "'gmsh' is not installed; install the bench extra: pip install \".[bench]\""
