"""The report: JSON figures, a self-contained HTML page with plots, regenerated from the saved files, and
rendered by a real headless browser."""
from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from engine.cli import main

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def meshed(junction_run):
    return junction_run


def test_report_json_holds_the_run_figures(meshed):
    out, result = meshed
    summary = json.loads((out / "mesh.report.json").read_text())
    assert summary["counts"]["tetrahedra"] == len(result.mesh.tets)
    assert summary["quality"]["min_dihedral"]["min"] == pytest.approx(result.quality["min_dihedral"]["min"])
    assert summary["size_conformity"]["within"] == pytest.approx(result.conformity["within"])
    assert sum(summary["size_conformity"]["histogram"]["counts"]) == summary["size_conformity"]["edges"]
    assert summary["boundary"]["two_manifold"] and summary["boundary"]["boundary_edges"] == 0
    assert set(summary["timings"]) >= {"geometry", "sizing", "packing", "meshing", "quality", "audit"}
    assert isinstance(summary["mesher"]["min_dihedral_before_improvement"], float)


def test_html_is_self_contained_and_regenerated_from_the_saved_files(meshed, capsys):
    out, _ = meshed
    page = (out / "mesh.report.html").read_text()
    images = re.findall(r'src="data:image/png;base64,([^"]+)"', page)
    assert len(images) == 4 and all(base64.b64decode(i).startswith(b"\x89PNG") for i in images)
    assert "http" not in page.replace("https://", "").split("<body>")[0], "no external resources"
    assert "plate-edge-junction" in page and "junction-edge.yaml" in page
    (out / "mesh.report.html").unlink()
    assert main(["report", str(out)]) == 0
    assert (out / "mesh.report.html").read_text() == page
    assert main(["report", str(out.parent)]) == 2
    assert capsys.readouterr().err.count("\n") == 1


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (Debian package 'chromium'); "
                                             "the browser rendering check needs it")
def test_a_headless_browser_shows_the_plots(meshed, tmp_path):
    import matplotlib.image

    out, _ = meshed
    shot = tmp_path / "report.png"
    subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                    "--disable-background-networking", "--disable-component-update", "--disable-sync",
                    f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1200,2600",
                    f"--screenshot={shot}", (out / "mesh.report.html").as_uri()],
                   check=True, capture_output=True, timeout=120)
    pixels = matplotlib.image.imread(shot)[..., :3]
    assert pixels.shape[:2] == (2600, 1200)
    # the plots' colours are on the page: histogram blue, conformity green, timing purple
    for colour in ("#4477aa", "#228833", "#aa3377"):
        rgb = np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)]) / 255
        assert (np.abs(pixels - rgb).max(axis=2) < 0.02).sum() > 2000, colour


def test_the_cut_plane_can_be_chosen(meshed, tmp_path, capsys):
    out, _ = meshed
    folder = shutil.copytree(out, tmp_path / "out")
    images = lambda: re.findall(r'src="data:image/png;base64,([^"]+)"', (folder / "mesh.report.html").read_text())
    default = images()
    assert main(["report", str(folder), "--cut", "z=10"]) == 0
    chosen = images()
    assert chosen[2] != default[2], "the cut differs"
    assert chosen[:2] == default[:2] and chosen[3] == default[3], "the other plots do not"
    capsys.readouterr()
    for bad in ("w=1", "z"):
        with pytest.raises(SystemExit) as exit_:
            main(["report", str(folder), "--cut", bad])
        err = capsys.readouterr().err
        assert exit_.value.code == 2 and err.count("\n") == 1 and "AXIS=VALUE" in err, err
    assert main(["report", str(folder), "--cut", "z=500"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("fuzzymesh: error:") and "between 0 and 120" in err, err
