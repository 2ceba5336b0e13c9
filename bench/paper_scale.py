"""End-to-end time at the paper's scale (about 7,000 tetrahedra; the paper: 6,896 elements, bubbles in
about 2 minutes and elements in about 3).

    python bench/paper_scale.py [--job examples/connected-uniform-nonuniform.yaml] [--repeats 5] [--json FILE]

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
import json
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


def measure(job_path: Path, repeats: int) -> dict:
    """Warm-up, then ``repeats`` timed runs of each of the three measures (module doc); medians and every run."""
    with tempfile.TemporaryDirectory() as folder:
        job = dataclasses.replace(load_job(job_path), output_dir=Path(folder) / "out")
        warm = run(job, write=False)
        stages = []

        def mesh_only():
            result = run(job, write=False)
            stages.append(result.timings)
            return result

        figures = {
            "job": job_path.name,
            "tets": len(warm.mesh.tets),
            "nodes": len(warm.mesh.points),
            "warm_up_seconds": sum(warm.timings.values()),
            "repeats": repeats,
        }
        median, runs, result = timed(mesh_only, repeats)
        figures["mesh"] = {
            "median": median,
            "runs": runs,
            "stages": {k: statistics.median(t[k] for t in stages) for k in stages[0]},
        }
        median, runs, _ = timed(lambda: run(job, write=True), repeats)
        figures["mesh_and_files"] = {"median": median, "runs": runs}
        command = [
            sys.executable,
            "-m",
            "engine.cli",
            "mesh",
            str(job_path),
            "--out",
            str(Path(folder) / "cli"),
            "--quiet",
        ]
        median, runs, _ = timed(lambda: subprocess.run(command, check=True), repeats)
        figures["command"] = {"median": median, "runs": runs}
        figures["min_dihedral"] = result.quality["min_dihedral"]["min"]
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--job", type=Path, default=ROOT / "examples" / "connected-uniform-nonuniform.yaml")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    figures = measure(args.job, args.repeats)

    def runs(key):
        return f"median {figures[key]['median']:.2f} s  (runs {', '.join(f'{s:.2f}' for s in figures[key]['runs'])})"

    print(
        f"{figures['job']}: {figures['tets']:,} tetrahedra, {figures['nodes']:,} nodes "
        f"(warm-up {figures['warm_up_seconds']:.2f} s)"
    )
    print(f"  mesh:          {runs('mesh')}")
    print("    stages (median): " + ", ".join(f"{k} {v:.3f}" for k, v in figures["mesh"]["stages"].items()) + " s")
    print(f"  mesh + files:  {runs('mesh_and_files')}")
    print(f"  command:       {runs('command')}")
    print(f"  quality: min dihedral {figures['min_dihedral']:.1f} deg; {figures['tets']:,} tetrahedra every run")
    if args.json:
        args.json.write_text(json.dumps(figures, indent=1))


if __name__ == "__main__":
    main()
