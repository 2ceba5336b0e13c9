"""Throughput of batch meshing (engine/batch.py): meshes per minute of a study on an embedded LocalCluster of 1
and 2 worker processes, against the same jobs run one after another in this process (engine.batch.mesh_variant,
i.e. engine.pipeline.run, in a loop). Every run starts from empty output folders; the cluster's start and stop
are inside its time, this process's imports are not inside the sequential time (they are warmed up first).

    python bench/batch.py                    # the 10 junctions of examples/studies/junction-family.yaml x seeds
    python bench/batch.py --seeds 1 --workers 1 2

Prints a Markdown table (bench/batch.md holds one run's figures).
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

from engine.batch import batch, load_study, mesh_variant

ROOT = Path(__file__).resolve().parents[1]
BASE = ROOT / "examples" / "studies" / "junction-family-base.yaml"


def study_file(folder: Path, seeds: int) -> Path:
    """The junction family (radius 15-25 x offset 60, 75) crossed with ``seeds`` seeds, in ``folder``."""
    shutil.copy(BASE, folder / "base.yaml")
    text = (BASE.parent / "junction-family.yaml").read_text().replace("junction-family-base.yaml", "base.yaml")
    (folder / "base.yaml").write_text(
        (folder / "base.yaml")
        .read_text()
        .replace("../knowledge/paper-sizing.yaml", str(ROOT / "examples" / "knowledge" / "paper-sizing.yaml"))
    )
    text = text.replace("  offset: [60, 75]", f"  offset: [60, 75]\n  seed: {{from: 0, to: {seeds - 1}, step: 1}}")
    path = folder / "study.yaml"
    path.write_text(text)
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=2, help="seeds per shape (default 2: 12 variants, 10 meshed)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2], help="cluster sizes (default 1 2)")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        path = study_file(Path(scratch), args.seeds)
        study = load_study(path)
        mesh_variant(study.variants[0])  # imports and numba's kernels, once
        shutil.rmtree(study.directory)
        start = time.perf_counter()
        results = [mesh_variant(v) for v in study.variants]
        rows.append(("one after another (this process)", time.perf_counter() - start, results))
        for workers in args.workers:
            shutil.rmtree(study.directory)
            start = time.perf_counter()
            results, _ = batch(path, workers=workers)
            rows.append(
                (f"LocalCluster, {workers} worker process{'es' * (workers > 1)}", time.perf_counter() - start, results)
            )
    meshed = sum(r["status"] == "ok" for r in rows[0][2])
    print(f"{len(study.variants)} variants, {meshed} meshed (the others refused: no mesh)\n")
    print("| run | wall time (s) | meshes per minute | speed-up |\n|---|---|---|---|")
    for name, seconds, results in rows:
        assert sum(r["status"] == "ok" for r in results) == meshed
        print(f"| {name} | {seconds:.1f} | {60 * meshed / seconds:.1f} | {rows[0][1] / seconds:.2f} |")


if __name__ == "__main__":
    main()
