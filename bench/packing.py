"""Bubble packer speed and memory on the junction (issue 4): about 170,000 bubbles.

    python bench/packing.py [--size 1.8] [--repeats 3]

Junction near the plate edge, recipe junction-edge, global size 1.8 (h = 1.5 at the junction,
1.8 elsewhere: the Gmsh reference case of ../shared/reference/NOTES.md). Prints the time per
level (median of the repeats), the count against the estimate, the spacing quality and the
peak resident memory of the process.
"""

from __future__ import annotations

import argparse
import logging
import resource
import statistics
import time

from cases import junction_edge

from engine.packing import get_packer


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--size", type=float, default=1.8)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    kb, geometry, features, sizing = junction_edge(args.size)
    runs = []
    for _ in range(args.repeats):
        start = time.perf_counter()
        packing = get_packer("bubble")(geometry, features, sizing, seed=0, knowledge=kb)
        runs.append((time.perf_counter() - start, packing))
    total = statistics.median(t for t, _ in runs)
    packing = runs[-1][1]
    stats = packing.stats
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(
        f"junction-edge, size {args.size}: {len(packing):,} bubbles "
        f"(estimate {stats['expected_nodes']:,.0f}, ratio {len(packing) / stats['expected_nodes']:.3f})"
    )
    print(
        f"packing time: median {total:.2f} s of {args.repeats} "
        f"({', '.join(f'{t:.2f}' for t, _ in runs)}); per level (last run): "
        + ", ".join(f"{k} {v:.2f} s" for k, v in stats["seconds"].items())
    )
    print(
        f"nearest neighbour / r0: median {stats['nearest_over_r0']['median']:.3f}, "
        f"within [0.85, 1.15]: {stats['nearest_over_r0']['within_0.85_1.15']:.3f} "
        f"(initial placement {stats['initial_nearest_over_r0']['within_0.85_1.15']:.3f}); "
        f"deleted {stats['deleted']}, inserted {stats['inserted']}"
    )
    print(f"peak resident memory of the process: {peak:.0f} MB")


if __name__ == "__main__":
    main()
