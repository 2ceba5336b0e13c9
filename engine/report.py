"""The mesh report: ``<name>.report.json`` (figures) and a self-contained ``<name>.report.html``: an interactive
3-D view of the mesh with the audit of the element under the pointer (plotly.js, inlined), two cuts through the
most refined region coloured by winning pattern, target size and quality, element quality histograms, the
size-conformity histogram, stage timings and counts (inline SVG plots, engine/plots.py). See docs/report.md.

Everything the HTML shows is rebuilt from the written files (the VTU with its audit fields, the audit
legend and the report JSON), so ``fuzzymesh report OUT`` regenerates it without meshing again.
"""

from __future__ import annotations

import base64
import html
import json
import os
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .mesh import FACES
from .quality import EDGES, tet_quality

FORMAT = "fuzzymesh-report/1"
VIEW_FACES = 200_000  # the 3-D view holds at most this many distinct element faces (about 2 per element)


def report_summary(result) -> dict:
    """The JSON figures of a pipeline result (``engine.pipeline.Result``)."""
    from .audit import _plain

    return _plain(
        {
            "format": FORMAT,
            "job": str(result.job.source),
            "solid": result.job.shape or str(result.job.geometry_file),
            "timings": {k: round(v, 3) for k, v in result.timings.items()},
            "counts": {
                "bubbles": len(result.packing),
                "nodes": len(result.mesh.points),
                "tetrahedra": len(result.mesh.tets),
                "boundary_triangles": len(result.mesh.boundary),
            },
            "volume": {
                "mesh": result.mesh.volume,
                "solid": result.geometry.volume,
                "exact": result.geometry.exact_volume,
                "ten_node": result.quality.get("quadratic", {}).get("volume"),
            },
            "mesher": {k: v for k, v in result.mesh.stats.items()},
            "quality": result.quality,
            "size_conformity": result.conformity,
            "boundary": result.boundary,
        }
    )


def volume_errors(volume: float, solid: float, exact: float | None) -> str:
    """A mesh's ``volume`` against the input surface's (``solid``) and the exact solid's (``exact``: a CAD file's
    or a built-in shape's; None where not known), in percent."""
    against = [(solid, "the input surface"), (exact, "the exact solid")]
    return ", ".join(f"{100 * (volume / ref - 1):+.3f} % of {name}'s" for ref, name in against if ref)


def _volumes(volume: dict) -> str:
    """The mesh's volume against the input surface's and the exact solid's (when known), and the 10-node mesh's."""
    text = f"{volume['mesh']:.6g} ({volume_errors(volume['mesh'], volume['solid'], volume.get('exact'))})"
    if volume.get("ten_node"):
        errors = volume_errors(volume["ten_node"], volume["solid"], volume.get("exact"))
        text += f"; 10-node elements {volume['ten_node']:.6g} ({errors})"
    return text


def write_report(directory: Path, name: str, cut: tuple[int, float] | None = None) -> list[Path]:
    """(Re)write ``name.report.html`` in ``directory`` from the saved VTU, audit legend and report JSON.

    ``cut`` = (axis 0/1/2, value) draws the one cut x[axis] = value; None, the two through the finest element
    (see ``finest``).
    """
    import meshio

    from .atomic import write_all_or_nothing
    from .errors import JobError

    directory = Path(directory)
    summary = json.loads((directory / f"{name}.report.json").read_text())
    legend = json.loads((directory / f"{name}.audit.json").read_text())
    mesh = meshio.read(directory / f"{name}.vtu")
    tets = next(block.data for block in mesh.cells if block.type.startswith("tetra"))[:, :4]
    cells = {key: values[0] for key, values in mesh.cell_data.items()}
    if cut is not None:
        low, high = mesh.points[:, cut[0]].min(), mesh.points[:, cut[0]].max()
        if not low < cut[1] < high:
            raise JobError(
                f"the plane {'xyz'[cut[0]]} = {cut[1]:g} cuts no element",
                where=str(directory / f"{name}.vtu"),
                fix=f"give a value between {low:.6g} and {high:.6g}",
            )
    page = render_html(summary, legend, mesh.points, tets, cells, cut)
    path = directory / f"{name}.report.html"
    return write_all_or_nothing([(path, lambda tmp: Path(tmp).write_text(page))])


def report_targets(
    summary: dict, legend: dict, points: np.ndarray, tets: np.ndarray, cells: dict, directory: Path, name: str
) -> list:
    """``name.report.json`` (the figures) and ``name.report.html`` (the page) in ``directory``, as (path, write)
    targets for :func:`engine.atomic.write_all_or_nothing`; ``tets`` (m, 4)."""
    page = render_html(summary, legend, points, tets, cells)
    return [
        (Path(directory) / f"{name}.report.json", lambda tmp: Path(tmp).write_text(json.dumps(summary, indent=1))),
        (Path(directory) / f"{name}.report.html", lambda tmp: Path(tmp).write_text(page)),
    ]


def render_html(
    summary: dict, legend: dict, points: np.ndarray, tets: np.ndarray, cells: dict, cut: tuple[int, float] | None = None
) -> str:
    """The report page (see the module doc)."""
    quality = tet_quality(points, tets)
    focus = finest(points, tets, cells)
    planes = [cut] if cut is not None else focus.planes
    plots = {
        "Element quality": _quality_histograms(quality),
        "Size conformity": _conformity_histogram(summary["size_conformity"]),
        **{
            f"Cut at {'xyz'[axis]} = {value:.4g}": _cut(points, tets, cells, legend, quality, axis, value, focus)
            for axis, value in planes
        },
        "Stage timings": _timings(summary["timings"]),
    }
    q, c, b = summary["quality"], summary["size_conformity"], summary.get("boundary", {})
    rows = [
        ("solid", summary["solid"]),
        ("job", summary["job"]),
        (
            "bubbles / nodes / tetrahedra",
            f"{summary['counts']['bubbles']:,} / {summary['counts']['nodes']:,} / {summary['counts']['tetrahedra']:,}",
        ),
        ("volume", _volumes(summary["volume"])),
        (
            "finest target size",
            f"h = {cells['h_target'][focus.element]:.4g} at ({', '.join(f'{x:.4g}' for x in focus.point)}), "
            f"{_placed_by(legend, cells, focus.element)}",
        ),
        (
            "min dihedral angle",
            f"{q['min_dihedral']['min']:.2f}° (1st percentile {q['min_dihedral']['p01']:.2f}°); "
            f"{q['below']['min_dihedral_10']} below 10°, {q['below']['min_dihedral_5']} below 5°",
        ),
        ("max dihedral angle", f"{q['max_dihedral']['max']:.2f}°; {q['below']['max_dihedral_165']} above 165°"),
        (
            "radius ratio",
            f"min {q['radius_ratio']['min']:.3f}, median {q['radius_ratio']['median']:.3f}; "
            f"{q['below']['radius_ratio_0.1']} below 0.1, {q['below']['radius_ratio_0.3']} below 0.3",
        ),
        (
            "size conformity",
            f"edge / target size median {c['median']:.3f}; {100 * c['within']:.1f} % within "
            f"[{c['band'][0]}, {c['band'][1]}]",
        ),
    ]
    if b:
        there, back = b["hausdorff_input_to_mesh"], b["hausdorff_mesh_to_input"]
        rows.append(
            (
                "boundary",
                f"{b['triangles']:,} triangles, "
                f"{'two-manifold' if b['two_manifold'] else 'NOT two-manifold'}, {b['boundary_edges']} open edges; "
                f"Hausdorff input → mesh max {there['max']:.4g} ({there['max_over_h']:.3g} h), mean "
                f"{there['mean']:.4g}; mesh → input max {back['max']:.4g} ({back['max_over_h']:.3g} h), mean "
                f"{back['mean']:.4g}",
            )
        )
    rows += [("warning", warning) for warning in summary.get("warnings", [])]
    patterns = [
        (
            p["id"],
            p["pattern"],
            _feature_name(legend, p),
            p["placement"],
            f"{100 * np.mean(cells['winner'] == p['index']):.1f} %",
        )
        for p in legend["patterns"]
    ]
    table = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>" for k, v in rows)
    pattern_rows = "".join(
        "<tr>" + "".join(f"<td>{html.escape(str(x))}</td>" for x in row) + "</tr>" for row in patterns
    )
    figures = "".join(
        f'<h2>{html.escape(title)}</h2><figure role="img" aria-label="{html.escape(title)}">{plot}</figure>'
        for title, plot in plots.items()
    )
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>fuzzymesh report</title>
<style>body{{font-family:sans-serif;margin:2em;max-width:1100px}}table{{border-collapse:collapse;margin:1em 0}}
th,td{{border:1px solid #ccc;padding:4px 8px;text-align:left}}figure{{margin:0}}</style></head>
<body><h1>fuzzymesh report</h1><table>{table}</table>
<h2>Which pattern sized the elements</h2>
<table><tr><th>placed pattern</th><th>pattern</th><th>feature</th><th>placed at</th><th>elements</th></tr>
{pattern_rows}</table>
{view_section(points, tets, cells, quality, legend, focus)}
{figures}</body></html>
"""


@dataclass
class Finest:
    """The finest element: of the elements whose target size is within 1 % of the smallest (the most refined
    region), the one nearest the region's middle; and two cut planes (axis, value) through its centroid, normal
    to the axes along which it and that middle agree best."""

    element: int
    point: np.ndarray
    planes: list[tuple[int, float]]


def finest(points: np.ndarray, tets: np.ndarray, cells: dict) -> Finest:
    """See :class:`Finest`."""
    h = cells["h_target"]
    centroids = points[tets].mean(axis=1)
    region = np.flatnonzero(h <= 1.01 * h.min())
    middle = centroids[region].mean(axis=0)
    element = int(region[np.argmin(np.linalg.norm(centroids[region] - middle, axis=1))])
    point = centroids[element]
    off = np.abs(point - middle) / np.maximum(np.ptp(points, axis=0), 1e-300)
    return Finest(element, point, [(int(axis), float(point[axis])) for axis in np.argsort(off, kind="stable")[:2]])


def _feature_name(legend: dict, pattern: dict) -> str:
    """'curve-8 (junction)': the feature a placed pattern is bound to, with its names."""
    feature = pattern.get("feature")
    if not feature:
        return ""
    kind = {"corner": "corners", "curve": "curves", "patch": "patches"}.get(feature.split("-")[0])
    names = next((f["names"] for f in legend.get(kind, []) if f["id"] == feature), []) if kind else []
    return f"{feature} ({', '.join(names)})" if names else feature


def _placed_by(legend: dict, cells: dict, element: int) -> str:
    """Which placed pattern, feature and zone sized an element."""
    winner = int(cells["winner"][element])
    if winner < 0:
        return "no pattern: the global size"
    p = legend["patterns"][winner]
    zone = legend["zones"][int(cells["zone"][element])]
    on = _feature_name(legend, p)
    feature = f", on {on}" if on else ""
    return f"placed by {p['id']} (pattern '{p['pattern']}'{feature}, zone '{zone['id']}' {zone['source']})"


def _quality_histograms(quality) -> str:
    from .plots import histograms

    panels = (
        (quality.min_dihedral, "minimum dihedral angle (°)", 10.0),
        (quality.max_dihedral, "maximum dihedral angle (°)", 165.0),
        (quality.radius_ratio, "radius ratio 3 r_in / R_circ", 0.1),
    )
    return histograms(panels, "#4477aa", "tetrahedra")


def _conformity_histogram(conformity: dict) -> str:
    from .plots import bar_chart

    bins, counts = np.asarray(conformity["histogram"]["bins"]), np.asarray(conformity["histogram"]["counts"])
    return bar_chart(
        bins[:-1],
        np.diff(bins),
        counts,
        "#228833",
        "edge length / target size at its midpoint",
        "edges",
        marks=conformity["band"],
    )


def cut_polygons(points: np.ndarray, tets: np.ndarray, axis: int, value: float):
    """Where the plane x[axis] = value cuts the tets: (tet indices, (k, 4, 2) polygons; a triangle repeats
    its last corner)."""
    other = [i for i in range(3) if i != axis]
    side = points[tets, axis] - value  # (m, 4)
    crossing = np.flatnonzero((side.min(axis=1) < 0) & (side.max(axis=1) > 0))
    s = side[crossing]
    corners = points[tets[crossing]][:, :, other]  # (k, 4, 2)
    si, sj = s[:, EDGES[:, 0]], s[:, EDGES[:, 1]]
    cuts = si * sj < 0  # (k, 6): 3 or 4 edges cross the plane
    t = np.where(cuts, si / np.where(cuts, si - sj, 1.0), 0.0)[..., None]
    at = corners[:, EDGES[:, 0]] + t * (corners[:, EDGES[:, 1]] - corners[:, EDGES[:, 0]])  # (k, 6, 2)
    centre = (at * cuts[..., None]).sum(axis=1) / cuts.sum(axis=1)[:, None]
    angle = np.where(cuts, np.arctan2(at[..., 1] - centre[:, 1:2], at[..., 0] - centre[:, 0:1]), np.inf)
    order = np.argsort(angle, axis=1)[:, :4]
    order[:, 3] = np.where(cuts.sum(axis=1) == 4, order[:, 3], order[:, 2])
    return crossing, np.take_along_axis(at, order[..., None], axis=1)


PALETTE = ("#4477aa", "#ee6677", "#228833", "#ccbb44", "#66ccee", "#aa3377", "#bbbbbb")  # winning patterns


def _cut(points, tets, cells, legend, quality, axis: int, value: float, focus: Finest) -> str:
    """The plane x[axis] = value in three panels: winning pattern, target size, element quality; the finest
    element marked with a cross."""
    from .plots import colourmap, cut_panels

    crossing, polygons = cut_polygons(points, tets, axis, value)
    other = [i for i in range(3) if i != axis]
    winners = cells["winner"][crossing]
    palette = np.array([[int(c[i : i + 2], 16) for i in (1, 3, 5)] for c in PALETTE], dtype=np.uint8)
    names = {p["index"]: p["id"] for p in legend["patterns"]}
    legend_entries = [(PALETTE[index % len(PALETTE)], names.get(int(index), "none")) for index in np.unique(winners)]
    panels = [("winning pattern", palette[np.mod(winners, len(PALETTE))], legend_entries, None)]
    for values, title, cmap in (
        (cells["h_target"][crossing], "target size h_target", "viridis"),
        (quality.min_dihedral[crossing], "minimum dihedral angle (°)", "magma"),
    ):
        low, high = (float(values.min()), float(values.max())) if len(values) else (0.0, 1.0)
        colours = colourmap(cmap, (values - low) / (high - low) if high > low else np.zeros(len(values)))
        panels.append((title, colours, None, (cmap, low, high)))
    return cut_panels(
        polygons,
        (points[:, other[0]].min(), points[:, other[0]].max()),
        (points[:, other[1]].min(), points[:, other[1]].max()),
        ("xyz"[other[0]], "xyz"[other[1]]),
        panels,
        focus.point[other],
    )


def _timings(timings: dict) -> str:
    from .plots import horizontal_bars

    return horizontal_bars(list(timings), [timings[n] for n in timings], "#aa3377", "seconds")


def neighbours(tets: np.ndarray) -> np.ndarray:
    """(m, 4): the element across face k of each element (face k opposite vertex k), -1 on the boundary."""
    faces = np.sort(tets[:, FACES].reshape(-1, 3), axis=1)
    order = np.lexsort(faces.T[::-1])
    same = np.flatnonzero((faces[order[1:]] == faces[order[:-1]]).all(axis=1))
    across = np.full(len(faces), -1, dtype=np.int64)
    across[order[same]], across[order[same + 1]] = order[same + 1] // 4, order[same] // 4
    return across.reshape(-1, 4)


def view_section(points, tets, cells, quality, legend, focus: Finest) -> str:
    """The interactive 3-D view: plotly.js and the mesh, each gzipped and base64-encoded into the page (no
    network when viewed), and engine/report_view.js, which draws the elements on one side of a movable plane
    and shows the audit of the element under the pointer."""
    keep, note = _view_elements(points, tets, focus)
    used, local = np.unique(tets[keep], return_inverse=True)
    across = neighbours(tets[keep])  # an element dropped from the view is the boundary of the view
    arrays = {
        "points": points[used].astype(np.float32),
        "tets": local.reshape(-1, 4).astype(np.int32),
        "neighbours": across.astype(np.int32),
        "element": keep.astype(np.int32),
        "quality": quality.min_dihedral[keep].astype(np.float32),
        **{
            name: cells[name][keep].astype(np.float32 if cells[name].dtype.kind == "f" else np.int16)
            for name in (
                "h_target",
                "h_actual",
                "size_ratio",
                "winner",
                "winner_mu",
                "runner_up",
                "runner_up_mu",
                "graded",
                "gradation",
                "zone",
            )
        },
    }
    header, blob = {}, b""
    for name, values in arrays.items():
        header[name] = [len(blob), values.dtype.str[1:], values.size]
        blob += values.tobytes()
    meta = {
        "arrays": header,
        "palette": PALETTE,
        "focus": [focus.planes[0][0], focus.planes[0][1]],
        "patterns": [
            {
                "id": p["id"],
                "pattern": p["pattern"],
                "feature": _feature_name(legend, p),
                "placed": legend["placements"][p["placement_index"]]["source"],
            }
            for p in legend["patterns"]
        ],
        "zones": [{"id": z["id"], "source": z["source"]} for z in legend["zones"]],
        "gradation_limit": legend["gradation_limit"],
    }
    script = Path(__file__).with_name("report_view.js").read_text()
    meta_json = json.dumps(meta).replace("</", "<\\/")  # no '</script>' inside the script element
    return f"""<h2>3-D view</h2>
<p>{html.escape(note)} Drag to turn, scroll to zoom; the slider moves the cut (the elements whose centroid lies
on the kept side are drawn whole); hover over or click an element for its audit.</p>
<div id="view-controls">colour by <select id="view-colour"><option value="winner">winning pattern</option>
<option value="h_target" selected>target size h_target</option><option value="size_ratio">size ratio
h_actual / h_target</option><option value="quality">minimum dihedral angle (°)</option></select>
cut <select id="view-axis"><option>x</option><option>y</option><option>z</option></select>
<input id="view-cut" type="range" min="0" max="1000" value="1000" style="width:20em">
<select id="view-side"><option value="1">keep below</option><option value="-1">keep above</option></select>
<span id="view-legend"></span></div>
<div id="view" style="width:100%;height:640px"></div>
<pre id="view-audit" style="white-space:pre-wrap;background:#f4f4f4;padding:6px;min-height:8em">
loading the 3-D view…</pre>
<script type="application/json" id="view-meta">{meta_json}</script>
<script type="application/octet-stream" id="view-mesh">{_packed(blob)}</script>
<script type="application/octet-stream" id="view-plotly">{plotly_packed()}</script>
<script>{script}</script>"""


def plotly_packed() -> str:
    """plotly.js as :func:`_packed`, kept per plotly version in the user's cache folder (``$XDG_CACHE_HOME``
    or ``~/.cache``, then ``fuzzymesh/``): compressing its 4.8 MB took 0.1 s of every report. Compressed here
    when the file is missing or unreadable, and written (atomically) if the folder can be."""
    import plotly

    try:
        folder = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "fuzzymesh"
    except RuntimeError:  # no home folder: no cache
        folder = None
    path = folder / f"plotly-{plotly.__version__}.js.gz.b64" if folder else None
    if path is not None and path.is_file():
        try:
            return path.read_text(encoding="ascii")
        except (OSError, ValueError):
            pass
    from plotly.offline import get_plotlyjs

    packed = _packed(get_plotlyjs().encode())
    if path is not None:
        partial = path.with_name(f"{path.name}.{os.getpid()}.partial")
        try:
            folder.mkdir(parents=True, exist_ok=True)
            partial.write_text(packed, encoding="ascii")
            os.replace(partial, path)
        except OSError:
            try:
                partial.unlink(missing_ok=True)
            except OSError:
                pass
    return packed


def _packed(data: bytes) -> str:
    """Gzip at level 6, in base64. Level 9 took 2.3x as long (1.42 s against 0.62 s for plotly.js and the default
    job's mesh) for 0.2 % less."""
    return base64.b64encode(zlib.compress(data, wbits=31)).decode("ascii")  # wbits 31: the gzip format


def _view_elements(points, tets, focus: Finest) -> tuple[np.ndarray, str]:
    """The elements the view holds and a sentence that says which: all of them, or, when their faces (about 2
    per element) exceed VIEW_FACES, the ones nearest the finest element."""
    faces = 2 * len(tets)
    if faces <= VIEW_FACES:
        return np.arange(len(tets)), f"All {len(tets):,} elements."
    count = VIEW_FACES // 2
    distance = np.linalg.norm(points[tets].mean(axis=1) - focus.point, axis=1)
    keep = np.sort(np.argpartition(distance, count)[:count])
    return keep, (
        f"Reduced for the view: the mesh has {len(tets):,} elements (about {faces:,} faces, more than "
        f"{VIEW_FACES:,}); the view holds the {count:,} nearest the finest element, within "
        f"{distance[keep].max():.4g} of ({', '.join(f'{x:.4g}' for x in focus.point)})."
    )
