"""End-to-end time at the paper's scale (about 7,000 tetrahedra; the paper: 6,896 elements, bubbles in
about 2 minutes and elements in about 3).

    python bench/paper_scale.py [--job examples/connected-uniform-nonuniform.yaml] [--repeats 5]

Runs the job (default: the Fig. 9 example, about 6,600 tetrahedra) once to warm up (numba loads or
compiles its kernels), then ``--repeats`` times in this process, and prints the median wall time of

- ``mesh``: job -> geometry -> sizing -> packing -> tetrahedra, with the quality, boundary and audit
  stages the pipeline always runs (``engine.pipeline.run(job, write=False)``);
- ``mesh + files``: the same plus writing VTU, .msh, audit legend and the HTML report;
- ``command``: ``fuzzymesh mesh JOB --quiet`` as a new process (Python start and imports included),

and the median time of every stage.
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from engine.job import load_job
from engine.pipeline import run

ROOT = Path(__file__).resolve().parents[1]


def timed(function, repeats: int):
    """(median seconds, every run's seconds, last result) of ``repeats`` calls."""
    seconds, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        seconds.append(time.perf_counter() - start)
    return statistics.median(seconds), seconds, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--job", type=Path, default=ROOT / "examples" / "connected-uniform-nonuniform.yaml")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    with tempfile.TemporaryDirectory() as folder:
        job = dataclasses.replace(load_job(args.job), output_dir=Path(folder) / "out")
        warm = run(job, write=False)
        print(f"{args.job.name}: {len(warm.mesh.tets):,} tetrahedra, {len(warm.mesh.points):,} nodes "
              f"(warm-up {sum(warm.timings.values()):.2f} s)")
        stages = []

        def mesh_only():
            result = run(job, write=False)
            stages.append(result.timings)
            return result

        median, runs, result = timed(mesh_only, args.repeats)
        print(f"  mesh:          median {median:.2f} s  (runs {', '.join(f'{s:.2f}' for s in runs)})")
        print("    stages (median): " + ", ".join(f"{k} {statistics.median(t[k] for t in stages):.3f}"
                                              for k in stages[0]) + " s")
        median, runs, _ = timed(lambda: run(job, write=True), args.repeats)
        print(f"  mesh + files:  median {median:.2f} s  (runs {', '.join(f'{s:.2f}' for s in runs)})")
        command = [sys.executable, "-m", "engine.cli", "mesh", str(args.job), "--out", str(Path(folder) / "cli"),
                   "--quiet"]
        median, runs, _ = timed(lambda: subprocess.run(command, check=True), args.repeats)
        print(f"  command:       median {median:.2f} s  (runs {', '.join(f'{s:.2f}' for s in runs)})")
        print(f"  quality: min dihedral {result.quality['min_dihedral']['min']:.1f} deg; "
              f"{len(result.mesh.tets):,} tetrahedra every run")


if __name__ == "__main__":
    main()
