"""The convergence study of case ``plate-hole``: Kt error against node count, graded against uniform.

Two series of meshes of the same plate: *graded* is the static-stress recipe with every target size
times a scale s (s = 1 is the recipe's default mesh), *uniform* is the base pattern alone at global
size s x the default size. Each mesh is solved (``plate_hole.solve_plate``) and its Kt compared with
Peterson's. The node count at which a series reaches ``TARGET`` error is interpolated (log-log)
between the last mesh above it and the next one, and the ratio uniform / graded says how many times
fewer nodes the expert rules need. Writes ``fe_convergence.json``, ``.md`` and ``.png``.
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
GRADED_SCALES = (6.0, 5.0, 4.0, 3.0, 2.0, 1.0)
UNIFORM_SCALES = (1.5, 1.0, 0.75, 0.6, 0.5, 0.4)
COLOURS = {"graded": "#228833", "uniform": "#4477aa"}   # the report's palette


def measure(scale: float, graded: bool, seed: int = 0) -> dict:
    """Mesh and solve one member of a series; its counts, Kt, error and seconds."""
    start = time.perf_counter()
    result = mesh_job(job_from_dict(job(scale, graded, seed), source="<fe convergence>"), write=False)
    meshed = time.perf_counter() - start
    solved = solve_plate(result)
    reference = peterson_kt(2 * PLATE["hole_radius"] / PLATE["width"])
    return {"series": "graded" if graded else "uniform", "scale": scale, "size": scale * default_size(),
            "nodes": len(result.mesh.points), "tetrahedra": len(result.mesh.tets),
            "quadratic_nodes": len(solved["model"].points), "dofs": int(solved["model"].basis.N),
            "Kt": solved["Kt"], "Kt_mid": solved["Kt_mid"], "error": (solved["Kt"] - reference) / reference,
            "seconds": {"mesh": meshed, **solved["timings"]}}


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


def run_study(graded=GRADED_SCALES, uniform=UNIFORM_SCALES, seed: int = 0, progress=None) -> dict:
    """Both series; ``progress(row)`` is called after each mesh."""
    rows = []
    for scales, is_graded in ((graded, True), (uniform, False)):
        for scale in scales:
            rows.append(measure(scale, is_graded, seed))
            if progress:
                progress(rows[-1])
    at = {name: nodes_at([r for r in rows if r["series"] == name]) for name in ("graded", "uniform")}
    ratio = at["uniform"] / at["graded"] if at["graded"] and at["uniform"] else None
    return {"case": "plate-hole", "target": TARGET, "Kt_peterson": peterson_kt(2 * PLATE["hole_radius"] / PLATE["width"]),
            "rows": rows, "nodes_at_target": at, "ratio": ratio}


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
    lines = ["# Plate with a hole: Kt error against node count, graded (static-stress recipe) and uniform meshes",
             "", f"Peterson's Kt (net section, d/W = 0.2): {study['Kt_peterson']:.4f}. Made by "
             "`fuzzymesh validate plate-hole --study`; see docs/validation.md.", "",
             "| series | scale | global size | nodes | tetrahedra | dofs | Kt (thickness mean) | error | Kt mid-plane | seconds |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in study["rows"]:
        lines.append(f"| {r['series']} | {r['scale']:g} | {r['size']:.3g} | {r['nodes']:,} | {r['tetrahedra']:,} | "
                     f"{r['dofs']:,} | {r['Kt']:.4f} | {100 * r['error']:+.2f} % | {r['Kt_mid']:.4f} | "
                     f"{sum(r['seconds'].values()):.0f} |")
    lines += ["", f"Nodes at {100 * study['target']:g} % error (log-log interpolation): graded "
              f"{_count(at['graded'])}, uniform {_count(at['uniform'])}"
              + (f"; the uniform mesh needs {study['ratio']:.1f} times as many nodes." if study["ratio"] else "."), ""]
    return "\n".join(lines)


def _count(value) -> str:
    return "not bracketed by the series" if value is None else f"{value:,.0f}"


def plot(study: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(7.0, 4.5))
    for name, colour in COLOURS.items():
        rows = sorted((r for r in study["rows"] if r["series"] == name), key=lambda r: r["nodes"])
        axis.loglog([r["nodes"] for r in rows], [100 * abs(r["error"]) for r in rows], "o-", color=colour,
                    label="graded: static-stress recipe" if name == "graded" else "uniform: base pattern only")
        if study["nodes_at_target"][name]:
            axis.axvline(study["nodes_at_target"][name], color=colour, linestyle=":")
    axis.axhline(100 * study["target"], color="#cc3311", linestyle="--", label=f"{100 * study['target']:g} % error")
    axis.set_xlabel("nodes of the mesh")
    axis.set_ylabel("|Kt error| against Peterson (%)")
    title = "plate with a hole in tension, 10-node tetrahedra"
    if study["ratio"]:
        title += f": {study['ratio']:.1f}x fewer nodes graded at {100 * study['target']:g} %"
    axis.set_title(title, fontsize=10)
    axis.legend(fontsize=8)
    axis.grid(True, which="both", alpha=0.3)
    figure.savefig(path, format="png", dpi=90, bbox_inches="tight")
    plt.close(figure)
