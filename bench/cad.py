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
Writes ``bench/cad.json`` and ``bench/cad.md``.

    python bench/cad.py [--work DIR] [--timeout 300]
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


def run_gmsh(step: Path, folder: Path, size: float, timeout: float) -> dict:
    """Gmsh (``--gmsh`` worker below) on ``step``; status, wall and meshing seconds, and the mesh if any."""
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / "gmsh.npz"
    code, stderr, seconds = parts._run(
        [sys.executable, str(Path(__file__).resolve()), "--gmsh", str(step), str(size), str(out)], timeout, folder
    )
    result = {"exit_code": code, "seconds": seconds}
    if code != 0:
        result["error"] = f"timeout after {timeout:g} s" if code is None else parts._error_line(stderr, code)
        return result
    saved = np.load(out)
    result["mesh_seconds"] = float(saved["seconds"])
    result["mesh"] = (saved["points"], saved["tets"])
    return result


def gmsh_worker(step: str, size: float, out: str) -> None:
    """Mesh ``step`` with Gmsh's CAD pipeline; save points, tets (0-based) and the seconds from import to the
    end of the 3-D mesh into ``out`` (npz)."""
    import gmsh

    gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("General.NumThreads", 1)
    begin = time.perf_counter()
    gmsh.model.occ.importShapes(step)
    gmsh.model.occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMax", size)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", PER_TURN)
    gmsh.model.mesh.generate(3)
    seconds = time.perf_counter() - begin
    tags, coordinates, _ = gmsh.model.mesh.getNodes()
    _, nodes = gmsh.model.mesh.getElementsByType(4)
    index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    np.savez(out, points=coordinates.reshape(-1, 3), tets=index[nodes.astype(np.int64)].reshape(-1, 4), seconds=seconds)
    gmsh.finalize()


def bench(work: Path, timeout: float) -> dict:
    import gmsh

    commit = subprocess.run(
        ["git", "describe", "--always", "--dirty"], capture_output=True, text=True, cwd=HERE
    ).stdout.strip()
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
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, default=None, help="working folder (default: a temporary one)")
    parser.add_argument("--timeout", type=float, default=300.0)
    parser.add_argument("--gmsh", nargs=3, metavar=("STEP", "SIZE", "OUT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.gmsh:
        gmsh_worker(args.gmsh[0], float(args.gmsh[1]), args.gmsh[2])
        return
    with tempfile.TemporaryDirectory() as temporary:
        results = bench(args.work or Path(temporary), args.timeout)
    for row in results["rows"]:
        for run in ("fuzzymesh STEP", "fuzzymesh STL", "Gmsh STEP"):
            row[run].pop("report_min_dihedral", None)
    (HERE / "cad.json").write_text(json.dumps(results, indent=1, default=str) + "\n")
    (HERE / "cad.md").write_text(markdown(results))
    print(markdown(results))


if __name__ == "__main__":
    main()
