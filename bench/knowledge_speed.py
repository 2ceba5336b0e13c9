"""Speed of the fuzzy engine and of the sizing field (issue 3 targets), as medians of repeated runs.

    python bench/knowledge_speed.py

Targets on the 2-core reference machine: 1,000,000 inputs through a 3-rule base <= 0.5 s;
1,000,000 points x 10 placed patterns <= 1 s.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from engine.job import job_from_dict
from engine.knowledge import load_knowledge
from engine.pipeline import build_geometry, build_sizing

REPEATS = 7


def median_time(function, *args) -> float:
    function(*args)  # warm up (JIT, caches)
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        function(*args)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    kb = load_knowledge()
    rng = np.random.default_rng(0)
    delete = kb.rulebases["population.delete"]
    overlap = rng.uniform(0.9, 3.1, 1_000_000)
    t = median_time(delete.evaluate, {"overlap": overlap})
    print(f"fuzzy: 1,000,000 inputs x {len(delete.rules)} rules (Mamdani, centroid): {t:.3f} s (median of {REPEATS})")

    spheres = [
        {
            "pattern": "uniform-region",
            "region": {"sphere": {"centre": [float(x), 0.0, 10.0], "radius": 5.0}},
            "parameters": {"size": 2.0, "transition": 10.0},
        }
        for x in np.linspace(-80, 80, 8)
    ]
    job = job_from_dict(
        {"geometry": {"shape": "plate_cylinder_junction"}, "size": 8.0, "recipe": "junction-edge", "place": spheres}
    )
    geometry, features = build_geometry(job)
    start = time.perf_counter()
    sizing = build_sizing(job, geometry, features, kb)
    build = time.perf_counter() - start
    points = rng.uniform(*geometry.bounds, size=(1_000_000, 3))
    audited = median_time(sizing.evaluate, points)
    fast = median_time(sizing, points)
    print(f"sizing: {len(sizing.placed)} placed patterns, field built in {build:.2f} s")
    print(f"sizing: 1,000,000 points with the full audit (mu, h of every pattern, winner, runner-up): {audited:.3f} s")
    print(f"sizing: 1,000,000 points, size only: {fast:.3f} s")


if __name__ == "__main__":
    main()
