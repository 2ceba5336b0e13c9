"""Real parts (issue 14): fuzzymesh and Gmsh side by side on the machined-style corpus of tests/parts.

For every part and tessellation (coarse, fine) of ``tests/parts/make_parts.py``:

- fuzzymesh, through its CLI in a subprocess (``fuzzymesh mesh job.yaml --quiet``), twice: the default job
  (global size = bounding-box diagonal / 40, the base pattern alone) and ``recipe: static-stress``;
- Gmsh, in its own subprocess: the STL merged, ``classifySurfaces`` (40 deg, boundary, parametrizable
  patches, curve angle 180 deg), ``createGeometry``, one volume, meshed in 3-D (Delaunay) with
  ``Mesh.MeshSizeMax`` = the same diagonal / 40.

Each case gets a wall-clock timeout; one run per case (the times are single runs, not medians). Every mesh
is measured here, the same way whoever made it: tetrahedra, minimum dihedral angle, volume
error against the STL's and the CAD volume, and a two-sided Hausdorff distance between the mesh boundary
and the STL (sampled), by the engine's own measures (``quality.tet_quality``,
``quality.surface_distances``: those of the acceptance gate). Writes ``bench/parts.json`` and ``bench/parts.md``.

    python bench/parts.py [--parts DIR] [--work DIR] [--names NAME ...] [--timeout 300]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
MAKE_PARTS = HERE.parent / "tests" / "parts" / "make_parts.py"
SIZE_FROM_SCALE = 40.0  # fuzzymesh's default global size: bounding-box diagonal / 40
RUNS = ("default", "static-stress")
ENV = {**os.environ, "OMP_WAIT_POLICY": os.environ.get("OMP_WAIT_POLICY", "PASSIVE")}


# ----------------------------------------------------------------------------------------------- measures


def measure(points, tets, stl, cad_volume: float, size: float) -> dict:
    """All figures of a tet mesh against its STL (a trimesh) and CAD volume, by the engine's own measures
    (the ones the acceptance gate uses): tets, min dihedral, volume (|sum of signed volumes|) and the tets
    whose sign differs from the total's, volume errors, and the two-sided Hausdorff distance between the
    tets' boundary and the STL (``quality.surface_distances``, seeded samples)."""
    from engine.acceptance import boundary_topology
    from engine.mesh import signed_volumes
    from engine.quality import surface_distances, tet_quality

    tets = np.asarray(tets, dtype=np.int64)
    signed = signed_volumes(points, tets)
    total = signed.sum()
    oriented = tets if total >= 0 else tets[:, [0, 2, 1, 3]]  # Gmsh's may run the other way
    distances = surface_distances(points, boundary_topology(oriented)["faces"], stl, lambda x: size, 20000)
    hausdorff = max(distances["input_to_mesh"]["max"], distances["mesh_to_input"]["max"])
    figures = {
        "tets": len(tets),
        "min_dihedral": float(tet_quality(points, oriented).min_dihedral.min()),
        "volume": float(abs(total)),
        "inverted": int((np.sign(signed) != np.sign(total)).sum()),
        "hausdorff": float(hausdorff),
        "hausdorff_over_h": float(hausdorff / size),
    }
    figures["volume_error_stl"] = float(figures["volume"] / stl.volume - 1)
    figures["volume_error_cad"] = float(figures["volume"] / cad_volume - 1)
    return figures


# ----------------------------------------------------------------------------------------------- runs


def _error_line(stderr: str, code: int) -> str:
    """The first error line of a failed run (a traceback's last line)."""
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    if any(line.startswith("Traceback") for line in lines):
        return lines[-1]
    errors = [line for line in lines if "error" in line.lower()]
    return (errors or lines or [f"exit code {code}"])[0]


def _run(command, timeout: float, cwd: Path) -> tuple[int | None, str, float]:
    """Run ``command``; (exit code or None on timeout, stderr, wall seconds)."""
    begin = time.perf_counter()
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout, cwd=cwd, env=ENV)
    except subprocess.TimeoutExpired:
        return None, "", time.perf_counter() - begin
    return done.returncode, done.stderr, time.perf_counter() - begin


def run_fuzzymesh(stl: Path, folder: Path, recipe: str | None, timeout: float) -> dict:
    """fuzzymesh's CLI on ``stl`` in ``folder``; status, wall seconds, and the mesh (points, tets) if any."""
    import meshio
    import yaml

    folder.mkdir(parents=True, exist_ok=True)
    job = {"geometry": {"file": str(stl)}, "output": {"directory": "out", "formats": ["vtu"]}}
    if recipe:
        job["recipe"] = recipe
    (folder / "job.yaml").write_text(yaml.safe_dump(job))
    code, stderr, seconds = _run(["fuzzymesh", "mesh", "job.yaml", "--quiet"], timeout, folder)
    result = {"exit_code": code, "seconds": seconds}
    if code != 0:
        result["error"] = f"timeout after {timeout:g} s" if code is None else _error_line(stderr, code)
        return result
    report = json.loads((folder / "out" / "mesh.report.json").read_text())
    result["mesh_seconds"] = sum(report["timings"][s] for s in ("geometry", "sizing", "packing", "meshing"))
    result["report_min_dihedral"] = report["quality"]["min_dihedral"]["min"]
    mesh = meshio.read(folder / "out" / "mesh.vtu")
    result["mesh"] = (mesh.points, mesh.cells_dict["tetra"])
    return result


def run_gmsh(stl: Path, folder: Path, size: float, timeout: float) -> dict:
    """Gmsh (``--gmsh`` worker below) on ``stl``; status, wall and meshing seconds, and the mesh if any."""
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / "gmsh.npz"
    code, stderr, seconds = _run(
        [sys.executable, str(Path(__file__).resolve()), "--gmsh", str(stl), str(size), str(out)], timeout, folder
    )
    result = {"exit_code": code, "seconds": seconds}
    if code != 0:
        result["error"] = f"timeout after {timeout:g} s" if code is None else _error_line(stderr, code)
        return result
    saved = np.load(out)
    result["mesh_seconds"] = float(saved["seconds"])
    result["mesh"] = (saved["points"], saved["tets"])
    if not len(saved["tets"]):
        result["error"] = "no tetrahedra"
    return result


def gmsh_worker(stl: str, size: float, out: str) -> None:
    """Mesh ``stl`` with Gmsh from its triangles alone; save points, tets (0-based) and the seconds from
    merge to the end of the 3-D mesh into ``out`` (npz)."""
    import gmsh

    gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("General.NumThreads", 1)
    begin = time.perf_counter()
    gmsh.merge(stl)
    gmsh.model.mesh.classifySurfaces(np.radians(40), True, True, np.pi)
    gmsh.model.mesh.createGeometry()
    loop = gmsh.model.geo.addSurfaceLoop([tag for _, tag in gmsh.model.getEntities(2)])
    gmsh.model.geo.addVolume([loop])
    gmsh.model.geo.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMax", size)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.model.mesh.generate(3)
    seconds = time.perf_counter() - begin
    tags, coordinates, _ = gmsh.model.mesh.getNodes()
    _, nodes = gmsh.model.mesh.getElementsByType(4)
    index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    np.savez(out, points=coordinates.reshape(-1, 3), tets=index[nodes.astype(np.int64)].reshape(-1, 4), seconds=seconds)
    gmsh.finalize()


# ----------------------------------------------------------------------------------------------- bench


def bench(parts_dir: Path, work: Path, names, timeout: float) -> dict:
    """Generate the corpus into ``parts_dir`` and run every case; the results (JSON-ready)."""
    import trimesh

    commit = subprocess.run(
        ["git", "describe", "--always", "--dirty"], capture_output=True, text=True, cwd=HERE
    ).stdout.strip()
    spec = importlib.util.spec_from_file_location("make_parts", MAKE_PARTS)
    make_parts = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make_parts)
    load = os.getloadavg()[0]
    begin = time.perf_counter()
    make_parts.make_parts(parts_dir, names)
    generation = time.perf_counter() - begin
    manifest = json.loads((parts_dir / "manifest.json").read_text())
    rows = []
    for entry in manifest:
        stl_path = parts_dir / entry["path"]
        stl = trimesh.load(stl_path)
        size = float(np.linalg.norm(stl.extents)) / SIZE_FROM_SCALE
        case = f"{entry['name']}-{entry['tessellation']}"
        row = {**entry, "size": size, "stl_volume": float(stl.volume)}
        runs = {
            run: run_fuzzymesh(stl_path, work / case / run, None if run == "default" else run, timeout) for run in RUNS
        }
        runs["gmsh"] = run_gmsh(stl_path, work / case / "gmsh", size, timeout)
        for run, result in runs.items():
            mesh = result.pop("mesh", None)
            if mesh is not None and len(mesh[1]):
                result.update(measure(*mesh, stl, entry["cad_volume"], size))
            row[run] = result
        rows.append(row)
        print(
            case,
            *(f"{run}: {r.get('error', 'ok')} {r['seconds']:.1f}s" for run, r in runs.items()),
            sep=" | ",
            flush=True,
        )
    return {
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "commit": commit,
        "machine": platform.node(),
        "cpus": os.cpu_count(),
        "load_average": [load, os.getloadavg()[0]],
        "timeout": timeout,
        "runs_per_case": 1,
        "generation_seconds": generation,
        "rows": rows,
    }


def _cell(result: dict, key: str, scale: float = 1.0, digits: int = 1) -> str:
    value = result.get(key)
    return "" if value is None else f"{value * scale:.{digits}f}"


def markdown(results: dict) -> str:
    """The results as a page: a summary, then one table per mesher run."""
    rows = results["rows"]
    titles = {
        "default": "fuzzymesh, default job (no recipe, size = diagonal / 40)",
        "static-stress": "fuzzymesh, `recipe: static-stress`",
        "gmsh": "Gmsh 3-D Delaunay from the STL (classifySurfaces 40 deg + createGeometry, MeshSizeMax = "
        "diagonal / 40)",
    }
    ok = {run: sum("error" not in row[run] for row in rows) for run in titles}
    lines = [
        "# Real parts: fuzzymesh and Gmsh on the machined-style corpus",
        "",
        f"{len(rows)} cases ({len(rows) // 2} parts of `tests/parts/make_parts.py`, each at a coarse 15 deg and a "
        f"fine 5 deg CAD tessellation), generated in {results['generation_seconds']:.1f} s. Run "
        f"{results['date']} (code at {results['commit']}) on {results['cpus']} cores, one run per case "
        f"(times are single runs, not medians), "
        f"timeout {results['timeout']:g} s per run. Made by `python bench/parts.py`.",
        "",
        f"Meshed: fuzzymesh default {ok['default']}/{len(rows)}, fuzzymesh static-stress "
        f"{ok['static-stress']}/{len(rows)}, Gmsh {ok['gmsh']}/{len(rows)}.",
        "",
        *(
            [
                f"One-minute load average at the start and the end: {results['load_average'][0]:.1f}, "
                f"{results['load_average'][1]:.1f} on {results['cpus']} cores"
                + (
                    " (above the core count: the times include waiting)."
                    if max(results["load_average"]) > results["cpus"]
                    else "."
                ),
                "",
            ]
            if "load_average" in results
            else []
        ),
        "Every mesh is measured by this script, the same way for both meshers: tets, minimum dihedral angle "
        "(degrees), volume error against the STL's volume and the exact CAD volume (%), two-sided Hausdorff "
        "distance between the mesh boundary and the STL (sampled, in units of the size H). Wall: the whole "
        "subprocess (interpreter start, reading, meshing, writing; fuzzymesh also its report); mesh: "
        "fuzzymesh's geometry + sizing + packing + meshing stages, Gmsh's merge to 3-D mesh.",
        "",
    ]
    for run, title in titles.items():
        lines += [
            f"## {title}",
            "",
            "| part | tess. | STL tris | status | wall s | mesh s | tets | min dih. | dV STL % | dV CAD % "
            "| Hausdorff / H |",
            "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|",
        ]
        for row in rows:
            r = row[run]
            status = "ok" if "error" not in r else "FAIL: " + r["error"].replace("|", "\\|")
            lines.append(
                f"| {row['name']} | {row['tessellation']} | {row['triangles']} | {status} | "
                f"{r['seconds']:.1f} | {_cell(r, 'mesh_seconds')} | {r.get('tets', '')} | "
                f"{_cell(r, 'min_dihedral')} | {_cell(r, 'volume_error_stl', 100, 3)} | "
                f"{_cell(r, 'volume_error_cad', 100, 3)} | {_cell(r, 'hausdorff_over_h', 1, 3)} |"
            )
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--parts", type=Path, help="folder for the corpus (default: a temporary one)")
    parser.add_argument("--work", type=Path, help="folder for the runs (default: a temporary one)")
    parser.add_argument("--names", nargs="*", help="only these parts")
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds per run")
    parser.add_argument("--out", type=Path, default=HERE / "parts", help="results: OUT.json and OUT.md")
    parser.add_argument("--gmsh", nargs=3, metavar=("STL", "SIZE", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.gmsh:
        gmsh_worker(args.gmsh[0], float(args.gmsh[1]), args.gmsh[2])
        return
    with tempfile.TemporaryDirectory() as scratch:
        results = bench(
            args.parts or Path(scratch) / "parts", args.work or Path(scratch) / "work", args.names, args.timeout
        )
    args.out.with_suffix(".json").write_text(json.dumps(results, indent=1) + "\n")
    args.out.with_suffix(".md").write_text(markdown(results))


if __name__ == "__main__":
    main()
