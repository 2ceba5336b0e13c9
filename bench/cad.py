"""CAD input (issue 17): fuzzymesh on STEP parts beside Gmsh's own CAD pipeline and beside fuzzymesh on the
part's STL export.

For each part (the STEP test parts of tests/test_cad.py and a few of the corpus, tests/parts/make_parts.py),
written as STEP by Gmsh's OpenCASCADE:

- fuzzymesh on the STEP file, its CLI in a subprocess, the default job (size = diagonal / 40; the
  always-placed curvature rule asks 24 elements per circle);
- fuzzymesh on the part's STL export (OpenCASCADE's tessellation at 5 deg, sagitta 5e-4 x the diagonal);
- Gmsh on the STEP file in its own subprocess: ``importShapes``, ``Mesh.MeshSizeMax`` = the same size,
  ``Mesh.MeshSizeFromCurvature`` = 24 (elements per full turn, as fuzzymesh's curvature rule), 3-D Delaunay.

Every mesh is measured here the same way: tets and minimum dihedral angle as ``bench/parts.py`` does, volume
by the engine's code (``engine.mesh.signed_volumes``) against the CAD's (``occ.getMass``). One run per case.

Assemblies (touching solids, ``ASSEMBLIES``: the test parts two_boxes and cylinder_on_plate): fuzzymesh's CLI on
the STEP file (its default job at the same H: each solid meshed, the shared face triangulated once) beside Gmsh's
own ``importShapes`` + ``occ.fragment`` + 3-D mesh with the same options as above; each body's volume (the VTU's
``body`` field, Gmsh's volume entity) against its CAD solid's, bodies matched by their centroids.

Writes ``bench/cad.json`` and ``bench/cad.md``; ``--only assemblies`` runs the assemblies alone and keeps the
parts' rows of ``bench/cad.json``.

    python bench/cad.py [--work DIR] [--timeout 300] [--only parts|assemblies]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from engine.mesh import signed_volumes

HERE = Path(__file__).resolve().parent
PER_TURN = 24  # elements per full turn: fuzzymesh's always-placed curvature rule, given to Gmsh too
STL_TESSELLATION = (5.0, 5e-4)  # degrees, sagitta x the diagonal


def _module(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


parts = _module("bench_parts", HERE / "parts.py")
test_cad = _module("test_cad", HERE.parent / "tests" / "test_cad.py")
BUILDERS = {name: test_cad.PARTS[name] for name in ("box_with_holes", "bracket", "junction")}
BUILDERS.update(
    {name: test_cad.make_parts.PARTS[name] for name in ("countersunk_plate", "filleted_hole_floor", "pillow_block")}
)
ASSEMBLIES = {name: test_cad.PARTS[name] for name in ("two_boxes", "cylinder_on_plate")}


def write_part(name: str, folder: Path) -> dict:
    """The part as STEP and as its STL export in ``folder``; paths, CAD volume and diagonal."""
    import gmsh

    gmsh.clear()
    BUILDERS[name]()
    gmsh.model.occ.synchronize()
    step, stl = folder / f"{name}.step", folder / f"{name}.stl"
    gmsh.write(str(step))
    lo, hi = np.reshape(gmsh.model.getBoundingBox(-1, -1), (2, 3))
    diagonal = float(np.linalg.norm(hi - lo))
    gmsh.option.setNumber("Mesh.Binary", 1)
    gmsh.option.setNumber("Mesh.StlLinearDeflectionRelative", 0)
    gmsh.option.setNumber("Mesh.StlLinearDeflection", STL_TESSELLATION[1] * diagonal)
    gmsh.option.setNumber("Mesh.StlAngularDeflection", math.radians(STL_TESSELLATION[0]))
    gmsh.write(str(stl))
    test_cad.make_parts._clean(stl)
    volume = sum(gmsh.model.occ.getMass(3, tag) for _, tag in gmsh.model.occ.getEntities(3))
    return {"step": step, "stl": stl, "cad_volume": volume, "diagonal": diagonal}


def run_gmsh(step: Path, folder: Path, size: float, timeout: float, fragment: bool = False) -> dict:
    """Gmsh (``--gmsh`` worker below) on ``step`` (its solids fragmented first, with ``fragment``); status, wall
    and meshing seconds, and the mesh (points, tets, body per tet) if any."""
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / "gmsh.npz"
    command = [sys.executable, str(Path(__file__).resolve()), "--gmsh", str(step), str(size), str(out)]
    code, stderr, seconds = parts._run(command + (["--fragment"] if fragment else []), timeout, folder)
    result = {"exit_code": code, "seconds": seconds}
    if code != 0:
        result["error"] = f"timeout after {timeout:g} s" if code is None else parts._error_line(stderr, code)
        return result
    saved = np.load(out)
    result["mesh_seconds"] = float(saved["seconds"])
    result["mesh"] = (saved["points"], saved["tets"], saved["body"])
    return result


def gmsh_worker(step: str, size: float, out: str, fragment: bool = False) -> None:
    """Mesh ``step`` with Gmsh's CAD pipeline (with ``fragment``: its solids fragmented first, as an assembly);
    save points, tets (0-based), the volume entity (0-based, in tag order) of each tet and the seconds from
    import to the end of the 3-D mesh into ``out`` (npz)."""
    import gmsh

    gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("General.NumThreads", 1)
    begin = time.perf_counter()
    gmsh.model.occ.importShapes(step)
    if fragment:
        gmsh.model.occ.fragment(gmsh.model.occ.getEntities(3), [])
    gmsh.model.occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMax", size)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", PER_TURN)
    gmsh.model.mesh.generate(3)
    seconds = time.perf_counter() - begin
    tags, coordinates, _ = gmsh.model.mesh.getNodes()
    index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    tets, body = [], []
    for b, (_, volume) in enumerate(sorted(gmsh.model.getEntities(3))):
        _, nodes = gmsh.model.mesh.getElementsByType(4, volume)
        tets.append(index[nodes.astype(np.int64)].reshape(-1, 4))
        body.append(np.full(len(tets[-1]), b))
    np.savez(
        out, points=coordinates.reshape(-1, 3), tets=np.concatenate(tets), body=np.concatenate(body), seconds=seconds
    )
    gmsh.finalize()


def write_assembly(name: str, folder: Path) -> dict:
    """The assembly as STEP in ``folder``; its path, diagonal and each solid's CAD volume and centroid."""
    import gmsh

    gmsh.clear()
    ASSEMBLIES[name]()
    occ = gmsh.model.occ
    occ.synchronize()
    step = folder / f"{name}.step"
    gmsh.write(str(step))
    lo, hi = np.reshape(gmsh.model.getBoundingBox(-1, -1), (2, 3))
    solids = [tag for _, tag in sorted(occ.getEntities(3))]
    return {
        "step": step,
        "diagonal": float(np.linalg.norm(hi - lo)),
        "cad_volumes": [occ.getMass(3, tag) for tag in solids],
        "cad_centroids": [list(occ.getCenterOfMass(3, tag)) for tag in solids],
    }


def body_figures(points, tets, body, part: dict) -> dict:
    """Tets, min dihedral (bench/parts.py's measure) and, per CAD solid, its mesh body's tets and volume error
    (bodies matched to solids by the nearest centroid)."""
    figures = parts.tet_measures(points, tets)
    volumes = signed_volumes(points, tets)
    centroids = points[tets].mean(axis=1)
    cad = np.array(part["cad_centroids"])
    errors, counts = [None] * len(cad), [0] * len(cad)
    for b in np.unique(body):
        mine = body == b
        volume = float(volumes[mine].sum())
        centroid = (centroids[mine] * volumes[mine, None]).sum(axis=0) / volume
        k = int(np.argmin(np.linalg.norm(cad - centroid, axis=1)))
        errors[k], counts[k] = volume / part["cad_volumes"][k] - 1, int(mine.sum())
    figures["body_tets"], figures["body_volume_error_cad"] = counts, errors
    return figures


def bench_assemblies(work: Path, timeout: float) -> dict:
    """fuzzymesh's CLI and Gmsh's fragment + mesh on each of ``ASSEMBLIES`` at H = diagonal / 40."""
    import gmsh
    import meshio

    load = os.getloadavg()[0]
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    rows = []
    for name in ASSEMBLIES:
        folder = work / name
        folder.mkdir(parents=True, exist_ok=True)
        part = write_assembly(name, folder)
        size = part["diagonal"] / parts.SIZE_FROM_SCALE
        runs = {
            "fuzzymesh STEP": parts.run_fuzzymesh(part["step"], folder / "step", None, timeout),
            "Gmsh STEP": run_gmsh(part["step"], folder / "gmsh", size, timeout, fragment=True),
        }
        mesh = runs["fuzzymesh STEP"].pop("mesh", None)
        if mesh is not None:
            body = meshio.read(folder / "step" / "out" / "mesh.vtu").cell_data["body"][0]
            runs["fuzzymesh STEP"]["mesh"] = (*mesh, body)
        for run, result in runs.items():
            result.pop("report_min_dihedral", None)
            mesh = result.pop("mesh", None)
            if mesh is not None and len(mesh[1]):
                result.update(body_figures(*mesh, part))
        rows.append({"name": name, "size": size, "cad_volumes": part["cad_volumes"], **runs})
        print(name, *(f"{run}: {r.get('error', 'ok')} {r['seconds']:.1f}s" for run, r in runs.items()), sep=" | ")
    gmsh.finalize()
    return {
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "commit": _commit(),
        "load_start": load,
        "load_end": os.getloadavg()[0],
        "rows": rows,
    }


def _commit() -> str:
    return subprocess.run(
        ["git", "describe", "--always", "--dirty"], capture_output=True, text=True, cwd=HERE
    ).stdout.strip()


def bench(work: Path, timeout: float) -> dict:
    import gmsh

    commit = _commit()
    load = os.getloadavg()[0]
    gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    rows = []
    for name in BUILDERS:
        folder = work / name
        folder.mkdir(parents=True, exist_ok=True)
        part = write_part(name, folder)
        size = part["diagonal"] / parts.SIZE_FROM_SCALE
        runs = {
            "fuzzymesh STEP": parts.run_fuzzymesh(part["step"], folder / "step", None, timeout),
            "fuzzymesh STL": parts.run_fuzzymesh(part["stl"], folder / "stl", None, timeout),
            "Gmsh STEP": run_gmsh(part["step"], folder / "gmsh", size, timeout),
        }
        for run, result in runs.items():
            mesh = result.pop("mesh", None)
            if mesh is not None and len(mesh[1]):
                figures = parts.tet_measures(*mesh)
                figures["volume"] = abs(float(signed_volumes(*mesh).sum()))  # the engine's (engine.mesh)
                figures["volume_error_cad"] = figures["volume"] / part["cad_volume"] - 1
                result.update(figures)
        rows.append({"name": name, "size": size, "cad_volume": part["cad_volume"], **runs})
        print(
            name,
            *(f"{run}: {r.get('error', 'ok')} {r['seconds']:.1f}s" for run, r in runs.items()),
            sep=" | ",
            flush=True,
        )
    gmsh.finalize()
    return {
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "commit": commit,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "load_start": load,
        "load_end": os.getloadavg()[0],
        "timeout": timeout,
        "rows": rows,
    }


def markdown(results: dict) -> str:
    lines = [
        "# CAD input: fuzzymesh and Gmsh on STEP parts",
        "",
        f"Run {results['date']} (code at {results['commit']}) on {results['machine']}, one run per case, load "
        f"average {results['load_start']:.1f} at the start and {results['load_end']:.1f} at the end. Made by "
        "`python bench/cad.py`. Size H = diagonal / 40 for all; fuzzymesh's default job (its curvature rule: 24 "
        "elements per circle), Gmsh with `Mesh.MeshSizeMax` = H and `Mesh.MeshSizeFromCurvature` = 24. Wall: the "
        "whole subprocess; mesh: fuzzymesh's geometry + sizing + packing + meshing stages, Gmsh's import to "
        "3-D mesh. Volume against the CAD's (`occ.getMass`) of the linear mesh.",
        "",
        "| part | H | run | status | wall s | mesh s | tets | min dih. | dV CAD % |",
        "|---|---:|---|---|---:|---:|---:|---:|---:|",
    ]
    for row in results["rows"]:
        for run in ("fuzzymesh STEP", "fuzzymesh STL", "Gmsh STEP"):
            r = row[run]
            status = r.get("error", "ok")
            figures = (
                [
                    f"{r['mesh_seconds']:.1f}",
                    str(r["tets"]),
                    f"{r['min_dihedral']:.1f}",
                    f"{100 * r['volume_error_cad']:+.3f}",
                ]
                if "tets" in r
                else ["", "", "", ""]
            )
            lines.append(
                f"| {row['name']} | {row['size']:.3g} | {run} | {status} | {r['seconds']:.1f} | "
                + " | ".join(figures)
                + " |"
            )
    if "assemblies" in results:
        lines += ["", *assembly_markdown(results["assemblies"])]
    return "\n".join(lines) + "\n"


def assembly_markdown(results: dict) -> list[str]:
    lines = [
        "## Assemblies (touching solids)",
        "",
        f"Run {results['date']} (code at {results['commit']}), one run per case, load average "
        f"{results['load_start']:.1f} at the start and {results['load_end']:.1f} at the end. Made by "
        "`python bench/cad.py --only assemblies`. H = diagonal / 40; fuzzymesh's default job on the STEP file (each "
        "solid meshed with the union's sizing, the shared face triangulated once, nodes merged); Gmsh: "
        "`importShapes`, `occ.fragment`, the options above, 3-D mesh. Volume: each body against its CAD solid "
        "(`occ.getMass`), in the file's solid order.",
        "",
        "| assembly | H | run | status | wall s | mesh s | tets (per body) | min dih. | dV per body % |",
        "|---|---:|---|---|---:|---:|---:|---:|---|",
    ]
    for row in results["rows"]:
        for run in ("fuzzymesh STEP", "Gmsh STEP"):
            r = row[run]
            figures = (
                [
                    f"{r['mesh_seconds']:.1f}",
                    f"{r['tets']} ({' + '.join(map(str, r['body_tets']))})",
                    f"{r['min_dihedral']:.1f}",
                    " / ".join("" if e is None else f"{100 * e:+.3f}" for e in r["body_volume_error_cad"]),
                ]
                if "tets" in r
                else ["", "", "", ""]
            )
            lines.append(
                f"| {row['name']} | {row['size']:.3g} | {run} | {r.get('error', 'ok')} | {r['seconds']:.1f} | "
                + " | ".join(figures)
                + " |"
            )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, default=None, help="working folder (default: a temporary one)")
    parser.add_argument("--timeout", type=float, default=300.0)
    parser.add_argument("--only", choices=("parts", "assemblies"), help="run one table, keep the other's rows")
    parser.add_argument("--gmsh", nargs=3, metavar=("STEP", "SIZE", "OUT"), help=argparse.SUPPRESS)
    parser.add_argument("--fragment", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.gmsh:
        gmsh_worker(args.gmsh[0], float(args.gmsh[1]), args.gmsh[2], args.fragment)
        return
    previous = json.loads((HERE / "cad.json").read_text()) if (HERE / "cad.json").is_file() else {}
    with tempfile.TemporaryDirectory() as temporary:
        work = args.work or Path(temporary)
        if args.only == "assemblies":
            results = {**previous, "assemblies": bench_assemblies(work / "assemblies", args.timeout)}
        else:
            results = bench(work, args.timeout)
            for row in results["rows"]:
                for run in ("fuzzymesh STEP", "fuzzymesh STL", "Gmsh STEP"):
                    row[run].pop("report_min_dihedral", None)
            if args.only == "parts":
                results["assemblies"] = previous.get("assemblies")
            else:
                results["assemblies"] = bench_assemblies(work / "assemblies", args.timeout)
            if results["assemblies"] is None:
                del results["assemblies"]
    (HERE / "cad.json").write_text(json.dumps(results, indent=1, default=str) + "\n")
    (HERE / "cad.md").write_text(markdown(results))
    print(markdown(results))


if __name__ == "__main__":
    main()
