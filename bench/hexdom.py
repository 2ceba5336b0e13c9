"""Hex-dominant meshes (issue 23): fuzzymesh against Gmsh's 3-D recombination, the same solid and h(x).

Cases: the junction-edge example (examples/junction-edge.yaml, the paper's sizing) at size 12 and the L-bracket
(shape l_bracket) at size 8. fuzzymesh runs the pipeline (output.elements: hex-dominant, i.e. the grid packer
and the hex-core mesher, then engine.recombine), in this process. Gmsh runs in a process of its own (this file
with ``--gmsh``) on its own OpenCASCADE model of the solid, with our sizing field as its only size source (a
``Structured`` field of our graded grid, bench/gmsh_junction.py), the frame-field "R-tree" point insertion
(Mesh.Algorithm3D 9; Gmsh 4.15 recombines nothing after Delaunay, 1), then Mesh.Recombine3DAll with hexahedra,
prisms and pyramids (Recombine3DLevel 2) made conforming by pyramids and trihedra (Recombine3DConformity 2; a
trihedron is a flat four-node element of no volume that Gmsh puts where a quad meets two triangles, not an FE
element). Both meshes are measured by our code (engine.recombine: the scaled corner Jacobian, the volume of each cell).

    python bench/hexdom.py            # bench/hexdom.json, bench/hexdom.md
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path[:0] = [str(ROOT), str(HERE)]

CASES = {
    "junction-edge, size 12": {"example": "junction-edge.yaml", "size": 12.0, "solid": "junction"},
    "L-bracket, size 8": {"job": {"geometry": {"shape": "l_bracket"}}, "size": 8.0, "solid": "l_bracket"},
}
# Gmsh 4.15 recombines in 3-D after its R-tree algorithm only: with Delaunay (1) Recombine3DAll leaves tets
GMSH_ALGORITHMS = {"gmsh-rtree": 9}
TRIHEDRON = "trihedron"
GATE = 0.2  # the scaled Jacobian fuzzymesh's gate asks of a hexahedron, prism or pyramid (acceptance.hex_jacobian)
GMSH_TYPES = {5: "hexahedron", 6: "wedge", 7: "pyramid", 4: "tetra"}


def fuzzymesh_case(case: dict):
    """(figures, the job's sizing field, its shape parameters)."""
    import yaml

    from engine.job import job_from_dict
    from engine.pipeline import run

    if "example" in case:
        data = yaml.safe_load((ROOT / "examples" / case["example"]).read_text())
        base = ROOT / "examples"
    else:
        data, base = dict(case["job"]), ROOT
    data["size"] = case["size"]
    data["output"] = {"directory": tempfile.mkdtemp(), "formats": ["vtu"], "elements": "hex-dominant"}
    job = job_from_dict(data, base_dir=base)
    begin = time.perf_counter()
    result = run(job, write=False)
    seconds = time.perf_counter() - begin
    hexdom = result.quality["hex_dominant"]
    figures = {
        "seconds": seconds,
        "mesh_seconds": sum(result.timings[k] for k in ("geometry", "sizing", "packing", "meshing", "recombine")),
        "hex_volume_share": hexdom["hex_volume_share"],
        "cells": {k: v["cells"] for k, v in hexdom["cells"].items()},
        "volume_share": {k: v["volume_share"] for k, v in hexdom["cells"].items()},
        "scaled_jacobian": {k: v["scaled_jacobian"] for k, v in hexdom["cells"].items()},
        "core": result.mesh.stats.get("hex_core"),
        "hexahedra_below_gate": 0,  # the gate passed: every cell's corners >= GATE
        "valid_hex_volume_share": hexdom["hex_volume_share"],
    }
    from engine.schema import validate
    from engine.shapes import SHAPES

    schema = SHAPES.details(job.shape)["parameters"]
    return figures, result.sizing, dict(validate(dict(job.shape_parameters), schema))


def gmsh_case(solid: str, parameters: dict, grid_path: Path, algorithm: int, out: Path) -> None:
    """(in a process of its own) Mesh and recombine; the cells to ``out`` (npz) and the times to out.json."""
    import gmsh
    import gmsh_junction as gj

    gj.start(threads=1)
    begin = time.perf_counter()
    if solid == "junction":
        gj.build_junction(**{k: parameters[k] for k in ("length", "width", "thickness", "radius", "height", "offset")})
    else:
        build_l_bracket(**parameters)
    gj.use_size_grid(grid_path)
    gmsh.option.setNumber("Mesh.Algorithm3D", algorithm)
    gmsh.option.setNumber("Mesh.Recombine3DAll", 1)
    gmsh.option.setNumber("Mesh.Recombine3DLevel", 2)
    gmsh.option.setNumber("Mesh.Recombine3DConformity", 2)
    gmsh.model.mesh.generate(3)
    seconds = time.perf_counter() - begin
    tags, coordinates, _ = gmsh.model.mesh.getNodes()
    index = np.zeros(int(tags.max()) + 1, np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    cells, other = {}, {}
    types, _, nodes = gmsh.model.mesh.getElements(3)
    for kind, rows in zip(types, nodes):
        if kind in GMSH_TYPES:
            cells[GMSH_TYPES[kind]] = index[np.asarray(rows, np.int64)].reshape(-1, {5: 8, 6: 6, 7: 5, 4: 4}[kind])
        else:  # the trihedron (type 140, four nodes), which getElementProperties does not know
            other[TRIHEDRON if kind == 140 else str(kind)] = len(rows) // 4
    gmsh.finalize()
    np.savez(out, points=np.asarray(coordinates).reshape(-1, 3), **cells)
    out.with_suffix(".json").write_text(json.dumps({"seconds": seconds, "other_cells": other}))


def build_l_bracket(leg_length, leg_height, thickness, width, fillet_radius) -> None:
    """engine.shapes.l_bracket as an OpenCASCADE solid: the profile in x-z (filleted inner corner) along y."""
    import gmsh

    t, r = thickness, fillet_radius
    occ = gmsh.model.occ
    corners = [(0, 0), (leg_length, 0), (leg_length, t), (t + r, t), (t, t + r), (t, leg_height), (0, leg_height)]
    points = [occ.addPoint(x, -width / 2, z) for x, z in corners]
    centre = occ.addPoint(t + r, -width / 2, t + r)
    lines = [occ.addLine(points[0], points[1]), occ.addLine(points[1], points[2]), occ.addLine(points[2], points[3])]
    lines.append(occ.addCircleArc(points[3], centre, points[4]))
    lines += [occ.addLine(points[4], points[5]), occ.addLine(points[5], points[6]), occ.addLine(points[6], points[0])]
    face = occ.addPlaneSurface([occ.addCurveLoop(lines)])
    occ.extrude([(2, face)], 0, width, 0)
    occ.synchronize()


def measure(points, cells: dict) -> dict:
    from engine.recombine import CELL_TYPES, SIZES, cell_qualities, cell_volumes

    cells = {k: cells.get(k, np.zeros((0, SIZES[i]), np.int64)) for i, k in enumerate(CELL_TYPES)}
    volumes = {k: cell_volumes(points, cells[k], i) for i, k in enumerate(CELL_TYPES)}
    total = sum(float(np.abs(v).sum()) for v in volumes.values())
    out = {"cells": {}, "volume_share": {}, "scaled_jacobian": {}}
    for i, kind in enumerate(CELL_TYPES):
        c = cells[kind]
        q = cell_qualities(points, c, i)
        out["cells"][kind] = len(c)
        out["volume_share"][kind] = float(np.abs(volumes[kind]).sum() / total)
        out["scaled_jacobian"][kind] = {"min": float(q.min()), "p01": float(np.percentile(q, 1))} if len(q) else None
    out["hex_volume_share"] = out["volume_share"]["hexahedron"]
    q = cell_qualities(points, cells["hexahedron"], 0)
    out["hexahedra_below_gate"] = int((q < GATE).sum())
    out["valid_hex_volume_share"] = float(np.abs(volumes["hexahedron"][q >= GATE]).sum() / total)
    return out


def run_gmsh(solid, parameters, sizing, algorithm) -> dict:
    from gmsh_junction import write_size_grid

    with tempfile.TemporaryDirectory() as folder:
        grid, out = Path(folder) / "h.bin", Path(folder) / "cells.npz"
        write_size_grid(sizing, grid)
        spec = json.dumps([solid, parameters, str(grid), algorithm, str(out)])
        done = subprocess.run(  # in the temporary folder: the R-tree algorithm writes new_points.pos there
            [sys.executable, str(HERE / "hexdom.py"), "--gmsh", spec], capture_output=True, text=True, cwd=folder
        )
        if done.returncode != 0 or not out.exists():
            return {"error": (done.stderr.strip().splitlines() or ["no output"])[-1]}
        data = np.load(out)
        figures = measure(data["points"], {k: data[k] for k in data.files if k != "points"})
        figures.update(json.loads(out.with_suffix(".json").read_text()))
    return figures


def table(results: dict) -> str:
    lines = [
        "| case | mesher | hexahedra: share of the volume | ... in hexahedra of scaled Jacobian >= 0.2 "
        "| min scaled Jacobian: hex / prism / pyramid / tet | cells: hex / prism / pyramid / tet | time (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for case, rows in results.items():
        for mesher, f in rows.items():
            if "error" in f:
                lines.append(f"| {case} | {mesher} | failed: {f['error']} | | | | |")
                continue
            jac = " / ".join(
                f"{f['scaled_jacobian'][k]['min']:.2f}" if f["scaled_jacobian"][k] else "-"
                for k in ("hexahedron", "wedge", "pyramid", "tetra")
            )
            counts = " / ".join(str(f["cells"][k]) for k in ("hexahedron", "wedge", "pyramid", "tetra"))
            extra = f" (+ {sum(f['other_cells'].values())} trihedra)" if f.get("other_cells") else ""
            below = f" ({f['hexahedra_below_gate']} hexahedra below)" if f["hexahedra_below_gate"] else ""
            lines.append(
                f"| {case} | {mesher} | {100 * f['hex_volume_share']:.1f} % "
                f"| {100 * f['valid_hex_volume_share']:.1f} %{below} | {jac} | {counts}{extra} | {f['seconds']:.2f} |"
            )
    return "\n".join(lines)


def _commit() -> str:
    done = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    return done.stdout.strip()


def main() -> None:
    results = {}
    for name, case in CASES.items():
        figures, sizing, parameters = fuzzymesh_case(case)
        rows = {"fuzzymesh": figures}
        for mesher, algorithm in GMSH_ALGORITHMS.items():
            rows[mesher] = run_gmsh(case["solid"], dict(parameters), sizing, algorithm)
        results[name] = rows
        print(table({name: rows}), flush=True)
    import gmsh

    meta = {"gmsh": gmsh.__version__, "commit": _commit(), "date": time.strftime("%Y-%m-%d")}
    (HERE / "hexdom.json").write_text(json.dumps({"meta": meta, "results": results}, indent=1) + "\n")
    print(table(results))


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--gmsh":
        solid, parameters, grid, algorithm, out = json.loads(sys.argv[2])
        gmsh_case(solid, parameters, Path(grid), algorithm, Path(out))
    else:
        main()
