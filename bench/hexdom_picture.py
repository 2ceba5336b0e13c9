"""The README's picture of a hex-dominant junction (issue 23): the junction-edge example at size 12 meshed with
``output: {elements: hex-dominant}``, cut at y = 0 (through the cylinder's axis and the ligament to the near plate
edge), the cells of the half y <= 0 drawn by matplotlib with their type's colour.

    python bench/hexdom_picture.py      # docs/images/junction-edge-hexdom-cut-y0.png
"""

from __future__ import annotations

import io
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(ROOT)]
TARGET = ROOT / "docs" / "images" / "junction-edge-hexdom-cut-y0.png"
COLOURS = ("#4c78a8", "#f2cf5b", "#e45756", "#d9d9d9")  # hexahedron, prism, pyramid, tetrahedron
ELEVATION, AZIMUTH = 24.0, 58.0  # deg: the eye looks at the cut from +y
NAMES = ("hexahedra", "prisms", "pyramids", "tetrahedra")


def mesh():
    """(the mixed mesh, its summary) of the junction-edge example at size 12, hex-dominant."""
    import yaml

    from engine.job import job_from_dict
    from engine.pipeline import run
    from engine.recombine import recombine

    data = yaml.safe_load((ROOT / "examples" / "junction-edge.yaml").read_text())
    data["size"] = 12.0
    data["output"] = {"directory": tempfile.mkdtemp(), "formats": ["vtu"], "elements": "hex-dominant"}
    result = run(job_from_dict(data, base_dir=ROOT / "examples"), write=False)
    return recombine(result.mesh.points, result.mesh.tets, 0.2), result.quality["hex_dominant"]


def cut_faces(mixed, keep_side):
    """(polygons (list of (k, 3) arrays), their cell type): the faces bounding the cells ``keep_side`` keeps."""
    from engine.recombine import CELL_FACES

    faces, kinds = [], []
    for kind, cells in enumerate(mixed.cells):
        if len(cells) == 0:
            continue
        cells = cells[keep_side(mixed.points[cells].mean(axis=1))]
        for face in CELL_FACES[kind]:
            f = cells[:, face]
            faces.append(np.where(f < 0, f[:, :1], f) if face[3] < 0 else f)  # a triangle repeats its first node
            kinds.append(np.full(len(f), kind))
    faces, kinds = np.concatenate(faces), np.concatenate(kinds)
    _, inverse, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    # a triangle's key holds its first node twice; a quad's four; two cells share a face with the same key
    single = counts[inverse.ravel()] == 1
    return faces[single], kinds[single]


def draw(mixed, summary, target: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    from PIL import Image

    faces, kinds = cut_faces(mixed, lambda c: c[:, 1] <= 0)
    polygons = mixed.points[faces]
    fig = plt.figure(figsize=(9, 6.2), dpi=110)
    ax = fig.add_subplot(projection="3d", computed_zorder=False)
    collection = Poly3DCollection(
        polygons, facecolors=np.array(COLOURS)[kinds], edgecolors="#222222", linewidths=0.15, shade=True
    )
    ax.add_collection3d(collection)
    lo, hi = mixed.points.min(axis=0), mixed.points.max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], 0)
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect((hi[0] - lo[0], -lo[1], hi[2] - lo[2]))
    ax.view_init(elev=ELEVATION, azim=AZIMUTH)
    ax.set_axis_off()
    cells = summary["cells"]
    handles = [
        Patch(
            facecolor=c, edgecolor="#222222", label=f"{n}: {cells[k]['cells']} ({100 * cells[k]['volume_share']:.1f} %)"
        )
        for c, n, k in zip(COLOURS, NAMES, ("hexahedron", "wedge", "pyramid", "tetra"))
    ]
    ax.legend(handles=handles, loc="upper left", fontsize=8, title="cells (share of the volume)", title_fontsize=8)
    fig.subplots_adjust(0, 0, 1, 1)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    image = Image.open(io.BytesIO(buffer.getvalue())).convert("RGB")
    box = Image.eval(image, lambda v: 255 - v).getbbox()  # trim the white margins
    image = image.crop(box) if box else image
    out = io.BytesIO()
    image.quantize(colors=128, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(
        out, "PNG", optimize=True
    )
    target.write_bytes(out.getvalue())
    print(f"wrote {target.relative_to(ROOT)} ({len(out.getvalue()) / 1024:.0f} KB)")


def main() -> None:
    mixed, summary = mesh()
    print(f"hexahedra: {100 * summary['hex_volume_share']:.1f} % of the volume")
    draw(mixed, summary, TARGET)


if __name__ == "__main__":
    main()
