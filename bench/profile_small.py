"""Where the time of a ``fuzzymesh mesh`` goes: by default the paper's scale, the junction near the plate edge
at the uniform size 9.3 (about 6,900 tetrahedra; the paper's mesh has 6,896); with ``--scale S`` the
benchmark's junction-edge case (bench/cases.py) with every size x S (S = 1: about 1M tetrahedra).

    python bench/profile_small.py [--size 9.3 | --scale 1] [--repeats 3] [--profile]

Runs what ``fuzzymesh mesh --size SIZE`` runs (imports, the pipeline, the files: VTU, MSH, audit, report),
each time in a fresh process, and prints the medians of the wall time, of the imports and of every pipeline
stage. ``--profile`` adds one run under cProfile and the cumulative time of what the profile showed to matter
(imports, numba loading or compiling its kernels, Gmsh, pymeshlab, the report, the file writers), which
overlap (an import inside the report counts for both).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# (label, file suffix, function) of the profile entries whose cumulative time is reported
ENTRIES = [
    ("imports (wherever they happen)", "<frozen importlib._bootstrap>", "_find_and_load"),
    ("numba: load cached kernels or compile", "numba/core/dispatcher.py", "_compile_for_args"),
    ("packing: start (curves, patches, volume)", "engine/packing/bubble.py", "_initial"),
    ("packing: force kernel", "engine/packing/forces.py", "forces"),
    ("packing: neighbour lists", "engine/packing/forces.py", "neighbour_lists"),
    ("packing: projection onto curves, patches", "engine/packing/constraints.py", "closest"),
    ("packing: population control", "engine/packing/bubble.py", "_control"),
    ("sizing: element-count estimate", "engine/sizing/counts.py", "estimate_counts"),
    ("meshing: Gmsh constrained Delaunay", "engine/meshing/tetra.py", "tetrahedralize"),
    ("meshing: surface triangulation", "engine/meshing/surface.py", "triangulate_boundary"),
    ("meshing: Gmsh optimiser", "engine/meshing/improve.py", "gmsh_optimize"),
    ("meshing: node relocation", "engine/meshing/improve.py", "relocate"),
    ("boundary: pymeshlab report", "engine/quality.py", "boundary_report"),
    ("output: VTU (meshio, zlib)", "meshio/vtu/_vtu.py", "write"),
    ("output: report HTML (SVG plots, 3-D view)", "engine/report.py", "render_html"),
    ("output: all files", "engine/atomic.py", "write_all_or_nothing"),
]


def once(size: float, scale: float | None, profile: str | None) -> dict:
    """One run in this process: seconds of the imports, of every stage and of the whole."""
    import cProfile
    import dataclasses
    import logging

    logging.basicConfig(level=logging.WARNING)
    profiler = cProfile.Profile() if profile else None
    if profiler:
        profiler.enable()
    begin = time.perf_counter()
    from engine.job import job_from_dict
    from engine.pipeline import run

    imports = time.perf_counter() - begin
    if scale is None:
        job = job_from_dict(
            {"geometry": {"shape": "plate_cylinder_junction"}, "size": size},  # uniform, no recipe
            base_dir=Path.cwd(),
            source="<profile>",
        )
    else:
        from cases import junction_job

        job = job_from_dict(junction_job("junction-edge", scale))
    with tempfile.TemporaryDirectory() as out:
        result = run(dataclasses.replace(job, output_dir=out))
    wall = time.perf_counter() - begin
    if profiler:
        profiler.disable()
        profiler.dump_stats(profile)
    return {"wall": wall, "imports": imports, "stages": result.timings, "tets": len(result.mesh.tets)}


def entries(path: str) -> list[tuple[str, float]]:
    import pstats

    stats = pstats.Stats(path).stats  # (file, line, function) -> (calls, primitive calls, total, cumulative, callers)
    return [
        (
            label,
            sum(value[3] for (file, _, function), value in stats.items() if file.endswith(suffix) and function == name),
        )
        for label, suffix, name in ENTRIES
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=float, default=9.3)
    parser.add_argument("--scale", type=float, help="the junction-edge benchmark case, every size x SCALE")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--once", metavar="PROFILE_PATH", nargs="?", const="", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.once is not None:
        print(json.dumps(once(args.size, args.scale, args.once or None)))
        return

    def fresh(profile=""):
        scale = ["--scale", str(args.scale)] if args.scale is not None else []
        done = subprocess.run(
            [sys.executable, __file__, "--size", str(args.size), *scale, "--once", profile],
            capture_output=True,
            text=True,
            check=True,
        )
        return json.loads(done.stdout.splitlines()[-1])

    runs = [fresh() for _ in range(args.repeats)]
    median = statistics.median
    what = f"junction-edge x {args.scale:g}" if args.scale is not None else f"fuzzymesh mesh --size {args.size}"
    print(f"{what}: {runs[0]['tets']:,} tets; medians of {args.repeats} fresh processes")
    walls = [r["wall"] for r in runs]
    print(f"  whole run {median(walls):.2f} s (runs: {', '.join(f'{w:.2f}' for w in walls)})")
    print(f"  imports of engine.pipeline {median(r['imports'] for r in runs):.2f} s")
    for stage in runs[0]["stages"]:
        print(f"  {stage:12s} {median(r['stages'][stage] for r in runs):6.2f} s")
    if args.profile:
        with tempfile.NamedTemporaryFile(suffix=".prof") as file:
            profiled = fresh(file.name)
            print(f"one run under cProfile: {profiled['wall']:.2f} s; cumulative (overlapping):")
            for label, seconds in entries(file.name):
                print(f"  {label:40s} {seconds:6.2f} s")


if __name__ == "__main__":
    main()
