"""The mesh report: ``<name>.report.json`` (figures) and a self-contained ``<name>.report.html`` (tables and
PNG plots embedded as data URIs): element quality histograms, the size-conformity histogram, a cut through
the mesh coloured by winning pattern and by element quality, stage timings and counts.

Everything the HTML shows is rebuilt from the written files (the VTU with its audit fields, the audit
legend and the report JSON), so ``fuzzymesh report OUT`` regenerates it without meshing again.
"""
from __future__ import annotations

import base64
import html
import io
import json
from pathlib import Path

import numpy as np

from .quality import EDGES, tet_quality

FORMAT = "fuzzymesh-report/1"


def report_summary(result) -> dict:
    """The JSON figures of a pipeline result (``engine.pipeline.Result``)."""
    from .audit import _plain

    return _plain({
        "format": FORMAT, "job": str(result.job.source), "solid": result.job.shape or str(result.job.geometry_file),
        "timings": {k: round(v, 3) for k, v in result.timings.items()},
        "counts": {"bubbles": len(result.packing), "nodes": len(result.mesh.points), "tetrahedra": len(result.mesh.tets),
                   "boundary_triangles": len(result.mesh.boundary)},
        "volume": {"mesh": result.mesh.volume, "solid": result.geometry.volume},
        "mesher": {k: v for k, v in result.mesh.stats.items()},
        "quality": result.quality, "size_conformity": result.conformity, "boundary": result.boundary,
    })


def write_report(directory: Path, name: str, cut: tuple[int, float] | None = None) -> list[Path]:
    """(Re)write ``name.report.html`` in ``directory`` from the saved VTU, audit legend and report JSON.

    ``cut`` = (axis 0/1/2, value) places the cut plane x[axis] = value; None chooses it (see ``_cuts``).
    """
    import meshio

    from .errors import JobError
    from .io import write_all_or_nothing

    directory = Path(directory)
    summary = json.loads((directory / f"{name}.report.json").read_text())
    legend = json.loads((directory / f"{name}.audit.json").read_text())
    mesh = meshio.read(directory / f"{name}.vtu")
    tets = next(block.data for block in mesh.cells if block.type.startswith("tetra"))[:, :4]
    cells = {key: values[0] for key, values in mesh.cell_data.items()}
    if cut is not None:
        low, high = mesh.points[:, cut[0]].min(), mesh.points[:, cut[0]].max()
        if not low < cut[1] < high:
            raise JobError(f"the plane {'xyz'[cut[0]]} = {cut[1]:g} cuts no element", where=str(directory / f"{name}.vtu"),
                           fix=f"give a value between {low:.6g} and {high:.6g}")
    page = render_html(summary, legend, mesh.points, tets, cells, cut)
    path = directory / f"{name}.report.html"
    return write_all_or_nothing([(path, lambda tmp: Path(tmp).write_text(page))])


def render_html(summary: dict, legend: dict, points: np.ndarray, tets: np.ndarray, cells: dict,
                cut: tuple[int, float] | None = None) -> str:
    quality = tet_quality(points, tets)
    plots = {
        "Element quality": _quality_histograms(quality),
        "Size conformity": _conformity_histogram(summary["size_conformity"]),
        "Cut through the mesh": _cuts(points, tets, cells, legend, quality, cut),
        "Stage timings": _timings(summary["timings"]),
    }
    q, c, b = summary["quality"], summary["size_conformity"], summary.get("boundary", {})
    rows = [
        ("solid", summary["solid"]), ("job", summary["job"]),
        ("bubbles / nodes / tetrahedra", f"{summary['counts']['bubbles']:,} / {summary['counts']['nodes']:,} / "
                                         f"{summary['counts']['tetrahedra']:,}"),
        ("volume", f"{summary['volume']['mesh']:.6g} ({100 * (summary['volume']['mesh'] / summary['volume']['solid'] - 1):+.3f} % of the solid)"),
        ("min dihedral angle", f"{q['min_dihedral']['min']:.2f}° (1st percentile {q['min_dihedral']['p01']:.2f}°); "
                               f"{q['below']['min_dihedral_10']} below 10°, {q['below']['min_dihedral_5']} below 5°"),
        ("max dihedral angle", f"{q['max_dihedral']['max']:.2f}°; {q['below']['max_dihedral_165']} above 165°"),
        ("radius ratio", f"min {q['radius_ratio']['min']:.3f}, median {q['radius_ratio']['median']:.3f}; "
                         f"{q['below']['radius_ratio_0.1']} below 0.1, {q['below']['radius_ratio_0.3']} below 0.3"),
        ("size conformity", f"edge / target size median {c['median']:.3f}; {100 * c['within']:.1f} % within "
                            f"[{c['band'][0]}, {c['band'][1]}]"),
    ]
    if b:
        rows.append(("boundary (pymeshlab)", f"{b['triangles']:,} triangles, "
                     f"{'two-manifold' if b['two_manifold'] else 'NOT two-manifold'}, {b['boundary_edges']} open edges; "
                     f"Hausdorff to the input max {b['hausdorff_input_to_mesh']['max']:.4g}, "
                     f"mean {b['hausdorff_input_to_mesh']['mean']:.4g}"))
    patterns = [(p["id"], p["pattern"], p.get("feature") or "", p["placement"],
                 f"{100 * np.mean(cells['winner'] == p['index']):.1f} %") for p in legend["patterns"]]
    table = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>" for k, v in rows)
    pattern_rows = "".join("<tr>" + "".join(f"<td>{html.escape(str(x))}</td>" for x in row) + "</tr>"
                           for row in patterns)
    figures = "".join(f'<h2>{html.escape(title)}</h2><img alt="{html.escape(title)}" src="data:image/png;base64,{png}">'
                      for title, png in plots.items())
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>fuzzymesh report</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:1100px}}table{{border-collapse:collapse;margin:1em 0}}
th,td{{border:1px solid #ccc;padding:4px 8px;text-align:left}}img{{max-width:100%}}</style></head>
<body><h1>fuzzymesh report</h1><table>{table}</table>
<h2>Which pattern sized the elements</h2>
<table><tr><th>placed pattern</th><th>pattern</th><th>feature</th><th>placed at</th><th>elements</th></tr>{pattern_rows}</table>
{figures}</body></html>
"""


def _png(figure) -> str:
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=90, bbox_inches="tight")
    plt.close(figure)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _figure(columns: int = 1, width: float = 5.0, height: float = 3.6):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(1, columns, figsize=(width * columns, height))


def _quality_histograms(quality) -> str:
    figure, axes = _figure(3)
    for axis, values, title, mark in ((axes[0], quality.min_dihedral, "minimum dihedral angle (°)", 10.0),
                                      (axes[1], quality.max_dihedral, "maximum dihedral angle (°)", 165.0),
                                      (axes[2], quality.radius_ratio, "radius ratio 3 r_in / R_circ", 0.1)):
        axis.hist(values, bins=60, color="#4477aa")
        axis.axvline(mark, color="#cc3311", linestyle="--")
        axis.set_xlabel(title)
        axis.set_yscale("log")
    axes[0].set_ylabel("tetrahedra")
    return _png(figure)


def _conformity_histogram(conformity: dict) -> str:
    figure, axis = _figure(1, 7.0)
    bins, counts = np.asarray(conformity["histogram"]["bins"]), np.asarray(conformity["histogram"]["counts"])
    axis.bar(bins[:-1], counts, width=np.diff(bins), align="edge", color="#228833")
    for edge in conformity["band"]:
        axis.axvline(edge, color="#cc3311", linestyle="--")
    axis.set_xlabel("edge length / target size at its midpoint")
    axis.set_ylabel("edges")
    return _png(figure)


def cut_polygons(points: np.ndarray, tets: np.ndarray, axis: int, value: float):
    """Where the plane x[axis] = value cuts the tets: (tet indices, (k, 4, 2) polygons; a triangle repeats
    its last corner)."""
    other = [i for i in range(3) if i != axis]
    side = points[tets, axis] - value                       # (m, 4)
    crossing = np.flatnonzero((side.min(axis=1) < 0) & (side.max(axis=1) > 0))
    s = side[crossing]
    corners = points[tets[crossing]][:, :, other]           # (k, 4, 2)
    si, sj = s[:, EDGES[:, 0]], s[:, EDGES[:, 1]]
    cuts = si * sj < 0                                      # (k, 6): 3 or 4 edges cross the plane
    t = np.where(cuts, si / np.where(cuts, si - sj, 1.0), 0.0)[..., None]
    at = corners[:, EDGES[:, 0]] + t * (corners[:, EDGES[:, 1]] - corners[:, EDGES[:, 0]])   # (k, 6, 2)
    centre = (at * cuts[..., None]).sum(axis=1) / cuts.sum(axis=1)[:, None]
    angle = np.where(cuts, np.arctan2(at[..., 1] - centre[:, 1:2], at[..., 0] - centre[:, 0:1]), np.inf)
    order = np.argsort(angle, axis=1)[:, :4]
    order[:, 3] = np.where(cuts.sum(axis=1) == 4, order[:, 3], order[:, 2])
    return crossing, np.take_along_axis(at, order[..., None], axis=1)


def _cuts(points, tets, cells, legend, quality, cut=None) -> str:
    """The plane x[axis] = value of ``cut``; by default the one holding the longest and shortest extents,
    at the nodes' median."""
    from matplotlib.collections import PolyCollection

    if cut is None:
        axis = int(np.argsort(np.ptp(points, axis=0))[1])
        value = float(np.median(points[:, axis]))
    else:
        axis, value = int(cut[0]), float(cut[1])
    crossing, polygons = cut_polygons(points, tets, axis, value)
    figure, axes = _figure(2, 6.0, 5.0)
    winners = cells["winner"][crossing]
    names = {p["index"]: p["id"] for p in legend["patterns"]}
    palette = np.array(["#4477aa", "#ee6677", "#228833", "#ccbb44", "#66ccee", "#aa3377", "#bbbbbb"])
    colours = palette[np.mod(winners, len(palette))]
    axes[0].add_collection(PolyCollection(polygons, facecolors=colours, edgecolors="k", linewidths=0.1))
    for index in np.unique(winners):
        axes[0].plot([], [], "s", color=palette[index % len(palette)], label=names.get(int(index), "none"))
    axes[0].legend(fontsize=7, loc="upper right")
    axes[0].set_title("winning pattern")
    cut = PolyCollection(polygons, array=quality.min_dihedral[crossing], cmap="viridis", edgecolors="k",
                         linewidths=0.1)
    axes[1].add_collection(cut)
    figure.colorbar(cut, ax=axes[1], label="minimum dihedral angle (°)")
    axes[1].set_title("element quality")
    labels = "xyz"
    for ax in axes:
        ax.autoscale()
        ax.set_aspect("equal")
        ax.set_xlabel(labels[[i for i in range(3) if i != axis][0]])
        ax.set_ylabel(labels[[i for i in range(3) if i != axis][1]])
    figure.suptitle(f"cut at {labels[axis]} = {value:.4g}")
    return _png(figure)


def _timings(timings: dict) -> str:
    figure, axis = _figure(1, 7.0, 3.0)
    names = list(timings)
    axis.barh(names, [timings[n] for n in names], color="#aa3377")
    axis.invert_yaxis()
    axis.set_xlabel("seconds")
    return _png(figure)
