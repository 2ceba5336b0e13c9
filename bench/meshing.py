"""Mesher speed and quality on the junction (issue 5): about 180,000 bubbles, about 1M tetrahedra.

    python bench/meshing.py [--size 1.8] [--repeats 3] [--qhull]

Packs the junction near the plate edge once (recipe junction-edge, global size 1.8: the Gmsh
reference case of ../shared/reference/NOTES.md), then connects it with the default ``delaunay``
mesher ``--repeats`` times and prints the median time per stage (surface triangulation,
constrained Delaunay + IN/OUT, quality improvement), the element quality before and after
improvement, the volume error and the boundary's distance from the input surface. ``--qhull``
adds the paper's method (unconstrained Qhull + centroid test) for comparison.
"""

from __future__ import annotations

import argparse
import logging
import resource
import statistics
import time

from cases import junction_edge

from engine.meshing import get_mesher
from engine.packing import get_packer
from engine.quality import surface_deviation, tet_quality


def report(name, mesh, geometry, sizing, seconds):
    quality = tet_quality(mesh.points, mesh.tets).summary()
    print(f"{name}: {len(mesh.tets):,} tets, {len(mesh.points):,} nodes; median {seconds:.2f} s")
    print(
        f"  min dihedral {quality['min_dihedral']['min']:.2f} deg"
        f" (1st percentile {quality['min_dihedral']['p01']:.2f}),"
        f" {quality['below']['min_dihedral_10']} below 10 deg; radius ratio min {quality['radius_ratio']['min']:.3f}"
        f" (1st percentile {quality['radius_ratio']['p01']:.3f})"
    )
    print(f"  volume {100 * (mesh.volume / geometry.volume - 1):+.3f} % of the solid", end="")
    if len(mesh.boundary):
        deviation = surface_deviation(mesh, geometry, sizing)
        print(
            f"; input surface to mesh boundary max {deviation['input_to_mesh']:.4f} "
            f"({deviation['input_to_mesh_over_h']:.3f} h)",
            end="",
        )
    print()
    print("  " + ", ".join(f"{k} {v}" for k, v in mesh.stats.items() if k != "seconds"))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--size", type=float, default=1.8)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--qhull", action="store_true")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    kb, geometry, features, sizing = junction_edge(args.size)
    packing = get_packer("bubble")(geometry, features, sizing, seed=0, knowledge=kb)
    print(f"junction-edge, size {args.size}: {len(packing):,} bubbles")
    runs = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        mesh = get_mesher("delaunay")(packing, geometry, features, seed=0)
        runs.append((time.perf_counter() - start, mesh.stats["seconds"]))
    stages = {k: statistics.median(r[1][k] for r in runs) for k in runs[0][1]}
    report("delaunay", mesh, geometry, sizing, statistics.median(t for t, _ in runs))
    print(
        "  per stage (median): "
        + ", ".join(f"{k} {v:.2f} s" for k, v in stages.items())
        + f"; all runs: {', '.join(f'{t:.2f}' for t, _ in runs)} s"
    )
    if args.qhull:
        start = time.perf_counter()
        mesh = get_mesher("qhull")(packing, geometry, features, seed=0)
        report("qhull (the paper's method)", mesh, geometry, sizing, time.perf_counter() - start)
    print(f"peak resident memory of the process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
