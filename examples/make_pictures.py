"""Mesh the two junction examples (the paper's Fig. 10 a/b) more finely and copy their report's cut
pictures to ``docs/images/`` for the README.

    python examples/make_pictures.py [--size 16] [--near 0.06]

Each job is ``examples/junction-centre.yaml`` / ``junction-edge.yaml`` with the global size and the
junction pattern's ``near`` replaced (default: the recipe junction-edge's 0.06 x the radius, twice as
fine as the examples), meshed into ``examples/out/pictures/NAME/``. The report is then rebuilt with
its cut in the plane y = 0 (through the cylinder's axis and the ligament to the near plate edge) and
z = 10 (mid-plate), and those figures, taken from the report page (inline SVG), drawn by headless
Chromium (Playwright, as tests/test_report.py) and re-encoded with a 256-colour palette (so they can be
committed), are written as ``docs/images/NAME-cut-y0.png`` and ``NAME-cut-z10.png``. About 45,000-55,000
tetrahedra per case.
"""

from __future__ import annotations

import argparse
import io
import logging
import re
import shutil
from pathlib import Path

import yaml
from PIL import Image

from engine.job import job_from_dict
from engine.pipeline import run
from engine.report import write_report

EXAMPLES = Path(__file__).resolve().parent
IMAGES = EXAMPLES.parent / "docs" / "images"
CASES = ("junction-centre", "junction-edge")
CUTS = {"y0": (1, 0.0), "z10": (2, 10.0)}
FIGURE = re.compile(r'<h2>([^<]*)</h2><figure role="img" aria-label="[^"]*">(<svg .*?</svg>)</figure>')


def report_pictures(html: str) -> dict[str, bytes]:
    """Title -> PNG bytes of every figure of a report page, drawn by headless Chromium."""
    from playwright.sync_api import sync_playwright

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    pictures = {}
    with sync_playwright() as driver:
        browser = driver.chromium.launch(executable_path=chromium, args=["--no-sandbox", "--disable-gpu"])
        page = browser.new_page()
        for title, svg in FIGURE.findall(html):
            page.set_content(f"<body style='margin:0'>{svg}</body>")
            pictures[title] = page.locator("svg").first.screenshot()
        browser.close()
    return pictures


def palette_png(png: bytes) -> bytes:
    """The picture with 256 colours, no dithering: the plots' flat colours survive, the file shrinks 3x."""
    buffer = io.BytesIO()
    Image.open(io.BytesIO(png)).convert("RGB").quantize(
        256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE
    ).save(buffer, "PNG", optimize=True)
    return buffer.getvalue()


def finer_job(name: str, size: float, near: float):
    data = yaml.safe_load((EXAMPLES / f"{name}.yaml").read_text())
    data["size"] = size
    (junction,) = [p for p in data["place"] if p["pattern"] == "plate-edge-junction"]
    junction.setdefault("parameters", {})["near"] = near
    data["output"] = {"directory": f"out/pictures/{name}", "formats": ["vtu"]}
    return job_from_dict(data, base_dir=EXAMPLES, source=f"{name}.yaml (pictures: size {size}, near {near})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=float, default=16.0, help="global size H (examples: 20)")
    parser.add_argument("--near", type=float, default=0.06, help="junction size / radius (examples: 0.12)")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    IMAGES.mkdir(parents=True, exist_ok=True)
    for name in CASES:
        job = finer_job(name, args.size, args.near)
        result = run(job)
        print(f"{name}: {len(result.mesh.tets):,} tetrahedra in {sum(result.timings.values()):.1f} s")
        for label, cut in CUTS.items():
            (page,) = write_report(job.output_dir, job.output_name, cut)
            axis, value = cut
            png = palette_png(report_pictures(page.read_text())[f"Cut at {'xyz'[axis]} = {value:.4g}"])
            target = IMAGES / f"{name}-cut-{label}.png"
            target.write_bytes(png)
            print(f"  wrote {target.relative_to(EXAMPLES.parent)} ({len(png) / 1024:.0f} KB)")


if __name__ == "__main__":
    main()
