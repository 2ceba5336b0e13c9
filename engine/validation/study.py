"""The convergence study of case ``plate-hole``: Kt error against node count, graded against uniform.

Two series of meshes of the same plate: *graded* is the static-stress recipe with every target size
times a scale s (s = 1 is the recipe's default mesh), *uniform* is the base pattern alone at global size
s x the default size. Both read the sizing defaults without the always-placed thin-wall, narrow-gap and
curvature rules (``plate_hole.STUDY_SIZING``): the study compares the hole pattern with a uniform size, down to
0.4 elements through the plate, as it was designed and published. Each scale is meshed with several
seeds (coarse meshes scatter by a few percent from seed to seed) and solved
(``plate_hole.solve_plate``); its Kt is compared with Peterson's. Per scale, the means over the seeds of
the node count and of the signed error make the series; the node count from which a series stays within
``TARGET`` |error| is interpolated (log-log) between its last scale above and the next one, and the
ratio uniform / graded says how many times fewer nodes the expert rules need. Writes
``fe_convergence.json``, ``.md`` and ``.png``.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from ..job import job_from_dict
from ..pipeline import run as mesh_job
from .plate_hole import PLATE, default_size, job, peterson_kt, solve_plate

TARGET = 0.03
SEEDS = (0, 1, 2)
GRADED_SCALES = (5.0, 4.5, 4.0, 3.5, 3.0, 2.5, 2.0, 1.5, 1.0)
UNIFORM_SCALES = (2.0, 1.5, 1.25, 1.1, 1.0, 0.9, 0.75, 0.6, 0.5)
COLOURS = {"graded": "#228833", "uniform": "#4477aa"}  # the report's palette


def measure(scale: float, graded: bool, seed: int = 0) -> dict:
    """Mesh and solve one member of a series; its counts, Kt, error and seconds."""
    start = time.perf_counter()
    result = mesh_job(job_from_dict(job(scale, graded, seed, rules=False), source="<fe convergence>"), write=False)
    meshed = time.perf_counter() - start
    solved = solve_plate(result)
    reference = peterson_kt(2 * PLATE["hole_radius"] / PLATE["width"])
    return {
        "series": "graded" if graded else "uniform",
        "scale": scale,
        "size": scale * default_size(),
        "nodes": len(result.mesh.points),
        "tetrahedra": len(result.mesh.tets),
        "quadratic_nodes": len(solved["model"].points),
        "dofs": int(solved["model"].basis.N),
        "Kt": solved["Kt"],
        "Kt_mid": solved["Kt_mid"],
        "error": (solved["Kt"] - reference) / reference,
        "seconds": {"mesh": meshed, **solved["timings"]},
    }


def nodes_at(rows: list[dict], target: float = TARGET) -> float | None:
    """Interpolated node count from which the series stays within ``target`` |error| (None: never, or
    already at its coarsest mesh: then nothing to interpolate)."""
    rows = sorted(rows, key=lambda r: r["nodes"])
    error = np.abs([r["error"] for r in rows])
    above = np.flatnonzero(error > target)
    if len(above) == 0 or above[-1] == len(rows) - 1:
        return None
    k = above[-1]
    (n0, e0), (n1, e1) = (rows[k]["nodes"], error[k]), (rows[k + 1]["nodes"], error[k + 1])
    if e1 <= 0:
        return float(n1)
    t = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
    return float(math.exp(math.log(n0) + t * (math.log(n1) - math.log(n0))))


def run_study(graded=GRADED_SCALES, uniform=UNIFORM_SCALES, seeds=SEEDS, progress=None) -> dict:
    """Both series, every scale with every seed; ``progress(row)`` is called after each mesh."""
    rows = []
    for scales, is_graded in ((graded, True), (uniform, False)):
        for scale in scales:
            for seed in seeds:
                rows.append({**measure(scale, is_graded, seed), "seed": seed})
                if progress:
                    progress(rows[-1])
    series = {name: means([r for r in rows if r["series"] == name]) for name in ("graded", "uniform")}
    at = {name: nodes_at(points) for name, points in series.items()}
    ratio = at["uniform"] / at["graded"] if at["graded"] and at["uniform"] else None
    reference = peterson_kt(2 * PLATE["hole_radius"] / PLATE["width"])
    return {
        "case": "plate-hole",
        "target": TARGET,
        "Kt_peterson": reference,
        "seeds": list(seeds),
        "rows": rows,
        "series": series,
        "nodes_at_target": at,
        "ratio": ratio,
    }


def means(rows: list[dict]) -> list[dict]:
    """Per scale (coarsest first): mean node count, mean and range of the signed error, mean Kt."""
    out = []
    for scale in sorted({r["scale"] for r in rows}, reverse=True):
        group = [r for r in rows if r["scale"] == scale]
        errors = [r["error"] for r in group]
        out.append(
            {
                "scale": scale,
                "size": group[0]["size"],
                "meshes": len(group),
                "nodes": float(np.mean([r["nodes"] for r in group])),
                "Kt": float(np.mean([r["Kt"] for r in group])),
                "error": float(np.mean(errors)),
                "error_min": min(errors),
                "error_max": max(errors),
                "seconds": float(np.mean([sum(r["seconds"].values()) for r in group])),
            }
        )
    return out


def write_study(study: dict, out: Path) -> list[Path]:
    """fe_convergence.json, .md (the table) and .png (the plot) in ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "fe_convergence.json", out / "fe_convergence.md", out / "fe_convergence.png"]
    paths[0].write_text(json.dumps(study, indent=1) + "\n")
    paths[1].write_text(markdown(study))
    plot(study, paths[2])
    return paths


def markdown(study: dict) -> str:
    at = study["nodes_at_target"]
    lines = [
        "# Plate with a hole: Kt error against node count, graded (static-stress recipe) and uniform meshes",
        "",
        f"Peterson's Kt (net section, d/W = 0.2): {study['Kt_peterson']:.4f}. Each scale meshed with seeds "
        f"{', '.join(map(str, study['seeds']))}; means over the seeds. Made by `fuzzymesh validate plate-hole "
        "--study`; see docs/validation.md.",
        "",
        "| series | scale | global size | nodes | Kt (thickness mean) | error | error range over the seeds | seconds |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, points in study["series"].items():
        for p in points:
            lines.append(
                f"| {name} | {p['scale']:g} | {p['size']:.3g} | {p['nodes']:,.0f} | {p['Kt']:.4f} | "
                f"{100 * p['error']:+.2f} % | {100 * p['error_min']:+.2f} to {100 * p['error_max']:+.2f} % | "
                f"{p['seconds']:.0f} |"
            )
    lines += [
        "",
        f"Nodes from which the |mean error| stays within {100 * study['target']:g} % "
        "(log-log interpolation): "
        f"graded {_count(at['graded'])}, uniform {_count(at['uniform'])}"
        + (f"; the uniform mesh needs {study['ratio']:.1f} times as many nodes." if study["ratio"] else "."),
        "",
    ]
    return "\n".join(lines)


def _count(value) -> str:
    return "not bracketed by the series" if value is None else f"{value:,.0f}"


def plot(study: dict, path: Path) -> None:
    """Signed Kt error against nodes (log), every mesh and the per-scale means, the +-TARGET band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(7.0, 4.5))
    target = 100 * study["target"]
    axis.axhspan(-target, target, color="#cc3311", alpha=0.08, label=f"within {target:g} % of Peterson")
    for name, colour in COLOURS.items():
        rows = [r for r in study["rows"] if r["series"] == name]
        axis.plot([r["nodes"] for r in rows], [100 * r["error"] for r in rows], ".", color=colour, alpha=0.5)
        points = study["series"][name]
        axis.plot(
            [p["nodes"] for p in points],
            [100 * p["error"] for p in points],
            "o-",
            color=colour,
            label="graded: static-stress recipe" if name == "graded" else "uniform: base pattern only",
        )
        if study["nodes_at_target"][name]:
            axis.axvline(study["nodes_at_target"][name], color=colour, linestyle=":")
    axis.axhline(0.0, color="k", linewidth=0.5)
    axis.set_xscale("log")
    axis.set_xlabel("nodes of the mesh")
    axis.set_ylabel("Kt error against Peterson (%)")
    title = "plate with a hole in tension, 10-node tetrahedra (dots: seeds, line: mean)"
    if study["ratio"]:
        title += (
            f"\nwithin {target:g} % from {study['nodes_at_target']['graded']:,.0f} nodes graded, "
            f"{study['nodes_at_target']['uniform']:,.0f} uniform: {study['ratio']:.1f}x fewer"
        )
    axis.set_title(title, fontsize=10)
    axis.legend(fontsize=8, loc="lower right")
    axis.grid(True, which="both", alpha=0.3)
    figure.savefig(path, format="png", dpi=90, bbox_inches="tight")
    plt.close(figure)
