"""The report: JSON figures, a self-contained HTML page with plots and an interactive 3-D view, regenerated from
the saved files, and rendered by a real headless browser."""

from __future__ import annotations

import base64
import gzip
import json
import os
import re
import shutil

import numpy as np
import pytest

from engine import report
from engine.cli import main
from engine.job import default_job

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
FIGURES = r'<figure role="img" aria-label="[^"]*">(<svg .*?</svg>)</figure>'  # the plots, inline SVG
RASTERS = r'href="data:image/png;base64,([^"]+)"'  # a cut panel's elements


@pytest.fixture(scope="module")
def meshed(junction_run):
    return junction_run


def page_of(folder) -> str:
    return (folder / "mesh.report.html").read_text()


def view_data(page: str):
    """(meta, arrays) of the page's 3-D view, decoded as report_view.js decodes them."""
    meta = json.loads(re.search(r'<script type="application/json" id="view-meta">(.*?)</script>', page).group(1))
    blob = gzip.decompress(base64.b64decode(re.search(r'id="view-mesh">([^<]*)<', page).group(1)))
    arrays = {
        name: np.frombuffer(blob, dtype=kind, count=size, offset=offset)
        for name, (offset, kind, size) in meta["arrays"].items()
    }
    return meta, arrays


def test_the_default_job_is_the_papers_fig_10b_with_its_recipe():
    job = default_job()
    assert job.shape == "plate_cylinder_junction" and job.recipe == "junction-edge" and job.size == 12.0
    assert job.shape_parameters["offset"] == 60.0, "the cylinder near the plate edge"


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


def test_html_is_self_contained_small_and_regenerated_from_the_saved_files(meshed, capsys):
    out, _ = meshed
    page = page_of(out)
    figures = re.findall(FIGURES, page)
    assert len(figures) == 5 and all(f.startswith('<svg xmlns="http://www.w3.org/2000/svg"') for f in figures)
    rasters = [re.findall(RASTERS, f) for f in figures]
    assert [len(r) for r in rasters] == [0, 0, 3, 3, 0], "a cut: three panels, each its elements as a PNG"
    assert all(base64.b64decode(r).startswith(b"\x89PNG") for r in rasters[2] + rasters[3])
    assert not re.search(r'\b(src|href)="(?!data:)', page), "no external resources"
    assert "plate-edge-junction" in page and "junction-edge.yaml" in page
    assert len(page.encode()) < 7e6, f"{len(page.encode()):,} bytes"
    (out / "mesh.report.html").unlink()
    assert main(["report", str(out)]) == 0
    assert page_of(out) == page
    assert main(["report", str(out.parent)]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_the_cuts_go_through_the_finest_element_at_the_junction(meshed):
    out, result = meshed
    cells, legend = result.audit.cells, json.loads((out / "mesh.audit.json").read_text())
    finest = report.finest(result.mesh.points, result.mesh.tets, cells)
    h = cells["h_target"]
    assert h[finest.element] <= 1.01 * h.min()
    winner = legend["patterns"][cells["winner"][finest.element]]
    assert winner["pattern"] == "plate-edge-junction" and report._feature_name(legend, winner) == "curve-8 (junction)"
    # at the junction (cylinder x = 35..85), on the side of the ligament to the plate edge x = 100
    assert 80 < finest.point[0] < 100 and abs(finest.point[1]) < 5
    assert sorted(axis for axis, _ in finest.planes) == [1, 2], "the planes y = const and z = const"
    titles = re.findall(r"<h2>(Cut at [^<]*)</h2>", page_of(out))
    assert titles == [f"Cut at {'xyz'[axis]} = {value:.4g}" for axis, value in finest.planes]
    assert f"h = {h[finest.element]:.4g}" in page_of(out) and "on curve-8 (junction)" in page_of(out)


def test_the_cut_plane_can_be_chosen(meshed, tmp_path, capsys):
    out, _ = meshed
    folder = shutil.copytree(out, tmp_path / "out")
    default = re.findall(FIGURES, page_of(folder))
    assert main(["report", str(folder), "--cut", "z=10"]) == 0
    chosen = re.findall(FIGURES, page_of(folder))
    assert len(chosen) == 4 and chosen[2] not in default[2:4], "one cut, the chosen one"
    assert chosen[:2] == default[:2] and chosen[3] == default[4], "the other plots do not change"
    assert "Cut at z = 10" in page_of(folder)
    capsys.readouterr()
    for bad in ("w=1", "z"):
        with pytest.raises(SystemExit) as exit_:
            main(["report", str(folder), "--cut", bad])
        err = capsys.readouterr().err
        assert exit_.value.code == 2 and err.count("\n") == 1 and "AXIS=VALUE" in err, err
    assert main(["report", str(folder), "--cut", "z=500"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("fuzzymesh: error:") and "between 0 and 120" in err, err


def test_neighbours_across_faces():
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4], [2, 3, 4, 5]])
    across = report.neighbours(tets)
    # face k is opposite vertex k: tet 0's face opposite 0 is (1, 2, 3), shared with tet 1 (opposite its 4)
    assert across.tolist() == [[1, -1, -1, -1], [2, -1, -1, 0], [-1, -1, -1, 1]]


def test_the_view_holds_every_element_with_its_audit(meshed):
    out, result = meshed
    meta, a = view_data(page_of(out))
    m = len(result.mesh.tets)
    assert len(a["element"]) == m and (a["element"] == np.arange(m)).all()
    assert np.allclose(
        a["points"].reshape(-1, 3)[a["tets"].reshape(-1, 4)], result.mesh.points[result.mesh.tets], atol=1e-4
    )
    assert (a["neighbours"] >= 0).sum() % 2 == 0 and (a["neighbours"] < 0).sum() == len(result.mesh.boundary)
    for name in ("h_target", "winner", "zone", "runner_up", "graded"):
        assert np.allclose(a[name], result.audit.cells[name], rtol=1e-6), name
    assert [p["id"] for p in meta["patterns"]] == [
        p["id"] for p in json.loads((out / "mesh.audit.json").read_text())["patterns"]
    ]
    assert f"All {m:,} elements." in page_of(out)


def test_a_large_mesh_is_reduced_for_the_view_and_the_page_says_so(meshed, monkeypatch):
    out, result = meshed
    monkeypatch.setattr(report, "VIEW_FACES", 20_000)
    points, tets, cells = result.mesh.points, result.mesh.tets, result.audit.cells
    focus = report.finest(points, tets, cells)
    legend = json.loads((out / "mesh.audit.json").read_text())
    page = report.view_section(points, tets, cells, report.tet_quality(points, tets), legend, focus)
    _, a = view_data(page)
    assert len(a["element"]) == 10_000 and cells["h_target"][a["element"]].min() == cells["h_target"].min()
    assert f"the mesh has {len(tets):,} elements" in page and "the view holds the 10,000 nearest the finest" in page


def test_view_opens_the_report_in_the_default_browser(meshed, monkeypatch, capsys, tmp_path):
    out, _ = meshed
    opened = []
    monkeypatch.setattr("webbrowser.open", lambda uri: opened.append(uri) or True)
    assert main(["view", str(out)]) == 0
    assert opened == [(out / "mesh.report.html").resolve().as_uri()]
    assert capsys.readouterr().out.startswith("opened ")
    monkeypatch.setattr("webbrowser.open", lambda uri: False)
    assert main(["view", str(out)]) == 2
    assert "no web browser" in capsys.readouterr().err
    assert main(["view", str(tmp_path)]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def browser_or_skip():
    """Playwright driving Debian's Chromium; in CI (.ci/run installs both) a missing one fails the test."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        sync_playwright = None
    if CHROMIUM is None or sync_playwright is None:
        missing = "Chromium (Debian package 'chromium')" if CHROMIUM is None else "playwright (the 'test' extra)"
        if os.environ.get("CI"):
            pytest.fail(f"{missing} is not installed; .ci/run installs it")
        pytest.skip(f"{missing} is not installed; the browser check needs it")
    return sync_playwright


def colours_present(pixels: np.ndarray, colour: str) -> int:
    rgb = np.array([int(colour[i : i + 2], 16) for i in (1, 3, 5)]) / 255
    return int((np.abs(pixels - rgb).max(axis=2) < 0.02).sum())


def test_a_headless_browser_shows_the_3d_view_and_an_elements_audit(meshed, tmp_path):
    import matplotlib.image

    out, _ = meshed
    sync_playwright = browser_or_skip()
    problems = []
    with sync_playwright() as driver:
        browser = driver.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        page = browser.new_page(viewport={"width": 1200, "height": 900})
        page.on("console", lambda message: message.type == "error" and problems.append(message.text))
        page.on("pageerror", lambda error: problems.append(str(error)))
        page.goto((out / "mesh.report.html").as_uri())
        page.wait_for_selector("body[data-view=ready]", timeout=120_000)
        view = page.locator("#view")
        view.scroll_into_view_if_needed()
        page.wait_for_timeout(500)
        view.screenshot(path=tmp_path / "view.png")
        box = view.bounding_box()
        page.mouse.click(box["x"] + 0.4 * box["width"], box["y"] + 0.6 * box["height"])
        page.wait_for_function(
            "document.getElementById('view-audit').textContent.startsWith('element ')", timeout=20_000
        )
        audit = page.inner_text("#view-audit")
        page.select_option("#view-colour", "winner")
        page.fill("#view-cut", "300")
        page.dispatch_event("#view-cut", "input")
        page.wait_for_timeout(500)
        view.screenshot(path=tmp_path / "winner.png")
        page.screenshot(path=tmp_path / "page.png", full_page=True)
        browser.close()
    assert not problems, problems
    for line in (
        "pattern: ",
        "zone: ",
        "membership: mu = ",
        "h_target = ",
        "h_actual = ",
        "runner-up: ",
        "graded: ",
        "rule: placed at ",
    ):
        assert line in audit, audit
    assert re.search(r"\.yaml:\d+:\d+", audit), "the rule's file:line"
    pixels = matplotlib.image.imread(tmp_path / "view.png")[..., :3]
    coloured = (pixels.max(axis=2) - pixels.min(axis=2)) > 0.15  # not white, grey or black: the mesh's colours
    assert coloured.mean() > 0.1, f"the canvas is blank ({coloured.mean():.3f} coloured)"
    assert len(np.unique((pixels[coloured] * 16).astype(int), axis=0)) > 20, "a colour scale, not one flat colour"
    winner = matplotlib.image.imread(tmp_path / "winner.png")[..., :3]
    red, green, blue = winner[..., 0], winner[..., 1], winner[..., 2]
    pink = (red - green > 0.2) & (red - blue > 0.1)  # the junction pattern's #ee6677, shaded; not in viridis
    assert pink.sum() > 500, "coloured by winning pattern"
    whole = matplotlib.image.imread(tmp_path / "page.png")[..., :3]
    for colour in ("#4477aa", "#228833", "#aa3377"):  # the plots: histogram blue, conformity green, timing purple
        assert colours_present(whole, colour) > 2000, colour
